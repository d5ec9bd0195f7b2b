"""The planner's margin below the machine's limits: none on speed and acceleration where the float64 rounding
of the table's positions provably reads within the check's slack, so an optimum of whole ticks is met."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.planners.motion import trapezoid_position
from jaxcnc.planners.protocol import (
    CHECK_REL_SLACK,
    NUMERIC_MARGIN,
    POSITION_ULPS,
    coordinate_extent_mm,
    request_limits,
    rounding_fits,
)
from jaxcnc.ticks.sample import TickSampler
from jaxcnc.ticks.verify import REL_SLACK
from tests.conftest import make_machine
from tests.helpers import plan_text, table_of


def test_the_planner_and_the_check_agree_on_the_slack():
    assert CHECK_REL_SLACK == REL_SLACK


def test_rounding_fits_at_low_tick_rates_and_small_extents_only():
    # 4 · 8 · ulp(300 mm) · f² against half of 1e-9 of 10,000 mm/s²: fits at 1 kHz, not at 10 kHz
    assert rounding_fits(10000.0, 2, 300.0, 1000.0)
    assert not rounding_fits(10000.0, 2, 300.0, 10000.0)
    assert not rounding_fits(10000.0, 2, 1.0e5, 1000.0)  # a far arc centre makes the rounding coarser
    assert rounding_fits(500.0, 1, 300.0, 10000.0)  # speed: one difference, one power of f
    assert bool(rounding_fits(np.inf, 2, 300.0, 1.0e5))
    m = make_machine(tick_hz=1000, v=500.0, a=10000.0, rapid=500.0)
    v, a, j = request_limits(m, 300.0)
    assert v[0] == 500.0 and a[0] == 10000.0 and np.isinf(j[0])
    v, a, _ = request_limits(m)  # no extent: the margin everywhere, as before
    assert a[0] == 10000.0 * (1 - NUMERIC_MARGIN) and v[0] == 500.0 * (1 - NUMERIC_MARGIN)
    v, a, _ = request_limits(make_machine(tick_hz=10000, v=500.0, a=10000.0, rapid=500.0), 300.0)
    assert v[0] == 500.0 and a[0] == 10000.0 * (1 - NUMERIC_MARGIN)


def _line_job(tick_hz: float, tmp_path):
    """300 mm at 500 mm/s and 10,000 mm/s² from rest to rest: the optimum is 0.6 + 0.05 = 0.65 s exactly."""
    m = make_machine(tick_hz=tick_hz, v=500.0, a=10000.0, rapid=500.0)
    return table_of("G91 G1 X300 F30000\nM2\n", m, tmp_path, name=f"{tick_hz:g}.ticks")


def test_an_optimum_of_whole_ticks_is_met_where_rounding_allows_and_the_check_passes(tmp_path):
    job, table, meas = _line_job(1000, tmp_path)
    assert job.plan.n_ticks == 650  # 0.650 s: the continuous optimum, no tick more
    assert meas.violations == []
    assert meas.max_abs_a["x"] <= 10000.0 * (1 + REL_SLACK) + 1e-6  # at the limit, within rounding
    assert meas.max_abs_a["x"] >= 10000.0 * (1 - 1e-9)
    # at 10 kHz rounding could read past the check's slack: acceleration keeps the margin, one tick more
    job10, _, meas10 = _line_job(10000, tmp_path)
    assert job10.plan.n_ticks == 6501 and meas10.violations == []


def _position_errors(job) -> float:
    """Largest distance (mm) between the tick stage's float64 positions and a long-double evaluation of the
    same plan (the same formulas, in 64-bit-mantissa arithmetic)."""
    ld = np.longdouble
    plan, sampler = job.plan, TickSampler(job)
    arrays = {
        k: (np.asarray(v).astype(ld) if np.asarray(v).dtype.kind == "f" else np.asarray(v))
        for k, v in span_arrays(job.spans, xp=np).items()
    }
    tick = np.arange(plan.n_ticks + 1, dtype=np.int64)
    assert tick.size <= sampler.chunk  # one chunk holds the whole job
    p, _ = sampler.program_positions(0, tick.size)
    seg = np.clip(np.searchsorted(plan.first_tick, tick, side="right") - 1, 0, len(plan.first_tick) - 1)
    tau = np.maximum(
        ((tick - plan.group_tick[seg]).astype(ld) - plan.offset_ticks[seg].astype(ld)) / ld(plan.tick_hz), 0
    )
    law = [
        np.asarray(getattr(plan, k))[seg].astype(ld) for k in ("v0", "vp", "a_acc", "a_dec", "t_acc", "t_cru", "t_dec")
    ]
    s_local = np.clip(trapezoid_position(*law, tau, xp=np), 0, np.asarray(plan.length)[seg].astype(ld))
    s = np.asarray(plan.s_start)[seg].astype(ld) + s_local
    (exact,) = evaluate_path(arrays, np.asarray(plan.span)[seg], s, xp=np)
    return float(np.max(np.abs(p.astype(ld) - exact)))


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 60, reason="needs an extended long double (x86)")
def test_the_tick_stage_positions_are_within_the_bound_the_margin_assumes(tmp_path):
    """Lines and arcs (one with its centre 400 mm away) far from the origin, at 1 kHz: the float64
    positions stay within POSITION_ULPS units in the last place of the coordinates' extent."""
    m = make_machine(tick_hz=1000, v=500.0, a=10000.0, rapid=500.0)
    text = (
        "G90 G1 X450 Y-420 F30000\nG2 X470 Y-400 R20\nG1 X470 Y300\nG3 X430 Y300 R20\n"
        "G2 X400 Y300 R400\nG1 X-480 Y480\nG2 X-480 Y470 I0 J-5\nM2\n"
    )
    job = plan_text(text, m)
    extent = coordinate_extent_mm(job.spans)
    assert extent > 600.0  # the far centre counts
    err = _position_errors(job)
    assert 0.0 < err <= POSITION_ULPS * np.spacing(extent)
