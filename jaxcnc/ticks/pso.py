"""Position-synchronised output (PSO): a laser pulse every ``pso_mm`` of lit path, as tick events.

Marking and cutting with a pulsed source at constant spot spacing: the pulse rate follows the
path speed, so the spacing stays ``pso_mm`` through every acceleration and corner. Each lit run
(consecutive spans with the beam on) gets pulses at ``s = 0, pso_mm, 2 pso_mm, ...`` of its own
arc length. The tick of a pulse comes from inverting the span's trapezoid exactly:

    ramp up:    s = v0 τ + a τ²/2      →  τ = 2 s / (v0 + sqrt(v0² + 2 a s))
    cruise:     s = l_acc + vp (τ - t_acc)
    ramp down:  s' = vp τ' - a τ'²/2   →  τ' = 2 s' / (vp + sqrt(vp² - 2 a s'))

(the rationalised roots lose no digits when ``a`` is small), rounded to the nearest tick.
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind
from jaxcnc.planners.smoothing import SmoothPlan
from jaxcnc.planners.timelaw import Plan


def _time_in_span(plan: Plan, k: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Seconds from the start of span ``k`` until its path length reaches ``s`` (arrays ``(m,)``)."""
    v0, vp, aa, ad = plan.v0[k], plan.vp[k], plan.a_acc[k], plan.a_dec[k]
    ta, tc, td = plan.t_acc[k], plan.t_cru[k], plan.t_dec[k]
    l_acc = v0 * ta + 0.5 * aa * ta**2
    l_cru = vp * tc
    with np.errstate(divide="ignore", invalid="ignore"):
        up = 2.0 * s / (v0 + np.sqrt(np.maximum(v0 * v0 + 2.0 * aa * s, 0.0)))
        cru = ta + (s - l_acc) / vp
        s3 = np.clip(s - l_acc - l_cru, 0.0, None)
        down = ta + tc + 2.0 * s3 / (vp + np.sqrt(np.maximum(vp * vp - 2.0 * ad * s3, 0.0)))
    tau = np.where(s <= l_acc, up, np.where(s <= l_acc + l_cru, cru, down))
    return np.clip(np.nan_to_num(tau), 0.0, ta + tc + td)


def pso_events(plan: Plan | SmoothPlan, lit: np.ndarray, pso_mm: float) -> np.ndarray:
    """``PSO_PULSE`` events ``(EVENT_DTYPE)`` every ``pso_mm`` along the lit segments (``lit``: ``(n_segments,)``)."""
    length = np.where(lit, plan.length, 0.0)
    run_start = lit & ~np.concatenate([[False], lit[:-1]])
    run = np.cumsum(run_start) - 1  # run index of each lit span
    s_end = np.cumsum(length)
    s_begin = s_end - length
    run_s0 = s_begin[run_start]  # absolute arc length where each run starts
    run_len = np.bincount(run[lit], weights=length[lit], minlength=run_start.sum()) if lit.any() else np.zeros(0)
    counts = np.floor(run_len / pso_mm + 1e-9).astype(np.int64) + 1
    if counts.size == 0:
        return np.zeros(0, EVENT_DTYPE)
    which = np.repeat(np.arange(counts.size), counts)
    j = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    s_run = j * pso_mm
    s_abs = run_s0[which] + s_run
    lit_idx = np.flatnonzero(lit)
    # span holding each pulse: the last lit span starting at or before it
    pos = np.clip(np.searchsorted(s_begin[lit_idx], s_abs, side="right") - 1, 0, lit_idx.size - 1)
    k = lit_idx[pos]
    if isinstance(plan, SmoothPlan):  # a jerk-limited time law: the tick where s_W reaches each pulse
        tick = plan.ticks_at_s(s_abs)
    else:
        tau = _time_in_span(plan, k, s_abs - s_begin[k])
        tick = np.rint(plan.group_tick[k] + plan.offset_ticks[k] + tau * plan.tick_hz).astype(np.int64)
    out = np.zeros(tick.shape[0], EVENT_DTYPE)
    out["tick"], out["kind"], out["aux"], out["value"] = tick, EventKind.PSO_PULSE, np.arange(tick.shape[0]), s_run
    return out
