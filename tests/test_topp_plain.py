"""``topp``'s windows without blends (:func:`jaxcnc.planners.topp._plain_window`): the same plan, bit for bit, as
the general grid (:func:`~jaxcnc.planners.grid.build_grid`, ``_solve_grid``, ``interior_excess``)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcnc.planners.grid as grid
import jaxcnc.planners.topp as topp
from jaxcnc.bench.programs import BENCH_MACHINE, cam_polyline
from jaxcnc.geometry import build_spans
from jaxcnc.geometry.evaluate import evaluate_path
from jaxcnc.geometry.kinds import SpanKind
from jaxcnc.io.curves import curves_program
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job
from jaxcnc.planners.grid import build_grid, device_spans, frames_at, interval_counts, is_curved
from jaxcnc.planners.topp import BIG
from tests.helpers import random_cubic_nurbs
from tests.test_plan_memory import _same_plan


def _general_window(req, facts, counts, arrays, curved_span, compact, first, last, x_start):
    """What a window planned before the plain path: the general grid, its solve and the NumPy interior check."""
    arrays = device_spans(req.spans, first, last) if curved_span.any() else None
    grid = topp.build_grid(req.spans, counts, arrays, first, last)
    out = topp._solve_grid(req, facts, grid, x_start)
    acc = np.minimum(np.asarray(req.a_max), BIG)[None, :] * out["share"][: len(grid), None]
    out["bad"] = topp.interior_excess(arrays, grid, out["x_node"][: len(grid) + 1], acc, first)
    return grid, out


def _programs():
    curve = random_cubic_nurbs(40, seed=7)
    fast = BENCH_MACHINE.replace("a_max = 3000.0", "a_max = 1.0e5")
    return [
        ("cam", cam_polyline(3000), parse_machine(BENCH_MACHINE + "corner_tol_mm = 0\n", "<bench>")),
        ("nurbs", curves_program([curve], 50.0, start=curve[1][0]), parse_machine(fast, "<bench>")),
    ]


@pytest.mark.parametrize("window", [1 << 17, 1 << 8])
@pytest.mark.parametrize("which", [0, 1])
def test_plain_windows_plan_what_the_general_grid_plans(monkeypatch, which, window):
    name, prog, machine = _programs()[which]
    monkeypatch.setattr(topp, "WINDOW_INTERVALS", window)  # 1 << 8: many windows, each from the last's speed
    plain = plan_job(prog, machine).plan
    monkeypatch.setattr(topp, "_plain_window", _general_window)
    general = plan_job(prog, machine).plan
    assert len(plain) > 500, name
    _same_plan(plain, general)


def test_the_compiled_interior_check_flags_what_the_numpy_check_flags():
    """Speeds raised above the plan make some curved intervals exceed their budget inside: both checks
    flag the same ones (and the plain path's mask is the compiled one)."""
    prog = cam_polyline(600)
    machine = parse_machine(BENCH_MACHINE + "corner_tol_mm = 0\n", "<bench>")
    job = plan_job(prog, machine)
    spans = build_spans(prog, 0.0)
    counts = interval_counts(spans)
    arrays = device_spans(spans)
    grid = build_grid(spans, counts, arrays)
    m = len(grid)
    assert np.array_equal(grid.span, job.plan.span)  # one window, no refinement: the grid is the plan's
    x = np.append(job.plan.v0, job.plan.v1[-1]) ** 2
    share = topp.interval_share(np.zeros(m, bool), grid.curved)
    a_max = np.array([3000.0, 3000.0, 3000.0])
    idx = np.flatnonzero(grid.curved)
    t_m, k_m = frames_at(arrays, grid.span[idx], grid.s_start[idx] + grid.delta[idx] / 2)
    mid_t, mid_k = np.zeros((m, 3)), np.zeros((m, 3))
    mid_t[idx], mid_k[idx] = t_m, k_m
    check = {"t_a": grid.t_a.T, "k_a": grid.k_a.T, "t_b": grid.t_b.T, "k_b": grid.k_b.T, "t_m": mid_t.T}
    check |= {"k_m": mid_k.T, "a_max": a_max}
    flagged = 0
    for scale in (0.5, 1.0, 1.02, 1.2, 2.0):
        acc = np.minimum(a_max, BIG)[None, :] * share[:, None]
        expected = topp.interior_excess(arrays, grid, x * scale, acc)
        got = np.asarray(topp._interior_bad(check, x * scale, grid.delta, grid.curved, share))
        np.testing.assert_array_equal(got, expected, err_msg=f"scale {scale}")
        flagged += int(expected.sum())
    assert flagged > 100  # the comparison saw intervals flagged, not only clean ones
    assert is_curved(spans.kind).any()


def test_frames_from_the_separate_trig_program_are_the_same_bits():
    """``frame_columns`` given ``arc_trig_columns``'s cosines and sines (one evaluation per point) returns what it
    returns computing them itself, bit for bit, on the arcs of a CAM contour."""
    spans = build_spans(cam_polyline(5000), 0.0)
    rows = np.flatnonzero(spans.kind == SpanKind.ARC)
    arrays = topp._compact_device_spans(spans, rows)
    rng = np.random.default_rng(3)
    which = rng.integers(0, rows.size, 4096)
    where = rng.uniform(-0.1, 1.1, 4096) * spans.length[rows][which]  # clipped inside, both ways
    trig = grid.arc_trig_columns(arrays, which, where)
    got = [np.asarray(c) for c in grid.frame_columns(arrays, which, where, "arc", trig)]
    alone = [np.asarray(c) for c in grid.frame_columns(arrays, which, where, "arc")]
    _, t, k = evaluate_path(arrays, jnp.asarray(which), jnp.asarray(where), 2, xp=jnp, only="arc")
    for a, b, c in zip(got, alone, [*np.asarray(t).T, *np.asarray(k).T], strict=True):
        assert np.array_equal(a.view(np.int64), b.view(np.int64))
        np.testing.assert_allclose(a, c, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="arcs alone"):
        evaluate_path(arrays, which, where, 2, xp=jnp, trig=trig)


def test_the_curved_intervals_check_flags_what_the_numpy_check_flags(monkeypatch):
    """The plain windows' interior check (:func:`topp._curved_excess`, curved intervals alone, moving axes alone,
    read from the nodes' frames) flags what the NumPy check on the general grid flags, with speeds raised above
    the plan so that some intervals exceed their budget inside."""
    prog = cam_polyline(600)
    machine = parse_machine(BENCH_MACHINE + "corner_tol_mm = 0\n", "<bench>")
    seen = []
    solve = topp._plain_solve

    def spy(*args, **kwargs):
        seen.append((args, kwargs))
        return solve(*args, **kwargs)

    monkeypatch.setattr(topp, "_plain_solve", spy)
    job = plan_job(prog, machine)
    assert len(seen) == 1  # one window, no refinement
    args, kwargs = seen[0]
    _, laws, _, frames, check = args[:5]
    axes = args[5] if len(args) > 5 else kwargs["axes"]
    spans = build_spans(prog, 0.0)
    arrays = device_spans(spans)
    grid = build_grid(spans, interval_counts(spans), arrays)
    m = len(grid)
    assert np.array_equal(grid.span, job.plan.span)
    idx = np.flatnonzero(grid.curved)
    x = np.append(job.plan.v0, job.plan.v1[-1]) ** 2
    share = np.asarray(laws["share"])[:m]
    acc = np.minimum(np.asarray(check["a_max"]), BIG)[None, :] * share[:, None]
    excess = jax.jit(topp._curved_excess, static_argnames=("axes",))
    flagged = 0
    for scale in (0.5, 1.0, 1.02, 1.2, 2.0):
        x_pad = np.zeros(np.asarray(laws["delta"]).size + 1)
        x_pad[: m + 1] = x * scale
        got = np.asarray(excess(x_pad, laws, frames, check, axes=axes))
        expected = topp.interior_excess(arrays, grid, x * scale, acc)
        np.testing.assert_array_equal(got[: idx.size], expected[idx], err_msg=f"scale {scale}")
        assert not got[idx.size :].any() and not expected[np.flatnonzero(~grid.curved)].any()
        flagged += int(expected.sum())
    assert flagged > 100
