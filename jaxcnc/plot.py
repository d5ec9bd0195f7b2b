"""Plots of a tick table: the path coloured by speed, and v, a, j against time per axis.

Everything is measured on the table itself (positions plus fine residual) — what the drives will
be asked to do, not what the planner intended. Long tables are reduced to per-bin envelopes
(min and max of each bin) so peaks survive decimation.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from jaxcnc.hw.tablefile import EventKind, TableFile  # noqa: E402
from jaxcnc.machine import MachineConfig  # noqa: E402

MAX_POINTS = 20000


def _derivatives(p_mm: np.ndarray, tick_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Central-difference v, a, j ``(n, n_axes)`` of positions ``(n, n_axes)`` (rest outside)."""
    pad = np.concatenate([p_mm[:1].repeat(2, 0), p_mm, p_mm[-1:].repeat(2, 0)])
    v = np.diff(pad, axis=0) * tick_hz
    a = np.diff(v, axis=0) * tick_hz
    j = np.diff(a, axis=0) * tick_hz
    return v[1:-2], a[:-1], j


def _envelope(t: np.ndarray, y: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = y.shape[0]
    if n <= n_bins:
        return t, y, y
    edges = np.linspace(0, n, n_bins + 1).astype(int)
    lo = np.minimum.reduceat(y, edges[:-1], axis=0)
    hi = np.maximum.reduceat(y, edges[:-1], axis=0)
    return t[edges[:-1]], lo, hi


def lit_mask(table: TableFile) -> np.ndarray:
    """``(n_rows,)`` bool: the laser is on at that tick (from the table's LASER events)."""
    mask = np.zeros(table.n_rows, bool)
    ev = table.events[table.events["kind"] == EventKind.LASER]
    on_since = None
    for tick, value in zip(ev["tick"], ev["value"], strict=False):
        if value > 0 and on_since is None:
            on_since = int(tick)
        elif value == 0 and on_since is not None:
            mask[on_since : int(tick)] = True
            on_since = None
    if on_since is not None:
        mask[on_since:] = True
    return mask


def plot_table(
    table: TableFile, out: str | Path, machine: MachineConfig | None = None, title: str | None = None
) -> Path:
    """Write a PNG: XY path coloured by speed (rapids dashed grey) and v/a/j per axis."""
    h = table.header
    p = table.exact_mm()
    t = np.arange(h.n_rows) / h.tick_hz
    v, a, j = _derivatives(p, h.tick_hz)
    speed = np.linalg.norm(v, axis=1)
    lit = lit_mask(table)
    axes = h.axes
    fig = plt.figure(figsize=(15, 8.5), constrained_layout=True)
    gs = fig.add_gridspec(3, 2, width_ratios=[1.15, 1])
    ax_path = fig.add_subplot(gs[:, 0])
    step = max(1, h.n_rows // (4 * MAX_POINTS))
    ix, iy = axes.index("x"), axes.index("y")
    xy = p[::step][:, [ix, iy]]
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    sp = speed[::step][:-1]
    on = lit[::step][:-1]
    lc = LineCollection(seg[on], array=sp[on], cmap="viridis", linewidths=1.6)
    ax_path.add_collection(lc)
    ax_path.add_collection(LineCollection(seg[~on], colors="0.6", linewidths=0.6, linestyles="--"))
    ax_path.autoscale()
    ax_path.set_aspect("equal")
    ax_path.set_xlabel("X [mm]")
    ax_path.set_ylabel("Y [mm]")
    ax_path.set_title(title or Path(h.meta.get("source", table.path.name)).name)
    fig.colorbar(lc, ax=ax_path, label="path speed while cutting [mm/s]  (rapids: grey dashes)", shrink=0.7)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for row, (name, data, unit) in enumerate((("v", v, "mm/s"), ("a", a, "mm/s²"), ("j", j, "mm/s³"))):
        ax = fig.add_subplot(gs[row, 1])
        for i, axis in enumerate(axes):
            if np.ptp(p[:, i]) == 0:
                continue
            tt, lo, hi = _envelope(t, data[:, i], MAX_POINTS)
            c = colors[i % len(colors)]
            ax.fill_between(tt, lo, hi, color=c, alpha=0.35, lw=0)
            ax.plot(tt, (lo + hi) / 2 if tt.size < data.shape[0] else lo, color=c, lw=0.6, label=axis)
            if machine is not None and axis in machine.axis_names:
                lim = {"v": machine.axis(axis).v_max, "a": machine.axis(axis).a_max, "j": machine.axis(axis).j_max}[
                    name
                ]
                if lim is not None and name != "j":
                    ax.axhline(lim, color=c, ls=":", lw=0.8)
                    ax.axhline(-lim, color=c, ls=":", lw=0.8)
        ax.set_ylabel(f"{name} [{unit}]")
        if name == "j":
            ax.set_yscale("symlog", linthresh=1e4)
        ax.grid(alpha=0.3)
        if row == 0:
            ax.legend(loc="upper right", ncol=len(axes))
            ax.set_title(f"per axis, measured on the table at {h.tick_hz:g} Hz (dotted: limits)")
        if row == 2:
            ax.set_xlabel("time [s]")
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return Path(out)
