"""Position-synchronised output (PSO): a laser pulse every ``pso_mm`` of lit path, as tick events.

Marking and cutting with a pulsed source at constant spot spacing: the pulse rate follows the
path speed, so the spacing stays ``pso_mm`` through every acceleration and corner. Each lit run
(consecutive segments with the beam on) gets pulses at ``s = 0, pso_mm, 2 pso_mm, ...`` of its own
arc length; the time law says at which tick its segment reaches each
(:meth:`~jaxcnc.planners.protocol.TimeLaw.ticks_at`: for a trapezoid plan the exact inverse of the
trapezoid, rounded to the nearest tick).
"""

from __future__ import annotations

import numpy as np

from jaxcnc.format import EVENT_DTYPE, EventKind
from jaxcnc.planners.protocol import TimeLaw


def pso_events(plan: TimeLaw, lit: np.ndarray, pso_mm: float) -> np.ndarray:
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
    tick = plan.ticks_at(k, s_abs - s_begin[k])
    out = np.zeros(tick.shape[0], EVENT_DTYPE)
    out["tick"], out["kind"], out["aux"], out["value"] = tick, EventKind.PSO_PULSE, np.arange(tick.shape[0]), s_run
    return out
