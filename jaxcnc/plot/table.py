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

from jaxcnc.format import EventKind, TableFile  # noqa: E402
from jaxcnc.machine import MachineConfig  # noqa: E402

MAX_POINTS = 20000


def _series(table: TableFile, n_bins: int, chunk_rows: int = 1 << 20) -> dict[str, np.ndarray]:
    """Per-bin min/max of v, a, j ``(n_bins, n_axes)`` and a decimated path, read chunk by chunk.

    At row k: ``v = (p_k - p_{k-1}) f``, ``a = (p_{k+1} - 2 p_k + p_{k-1}) f²``,
    ``j = (p_{k+2} - 3 p_{k+1} + 3 p_k - p_{k-1}) f³``, with rest before and after the table.
    Memory stays bounded by the chunk, so tables of any length can be plotted.
    """
    h = table.header
    n, f = h.n_rows, h.tick_hz
    b = max(1, -(-n // n_bins))
    chunk = b * max(1, chunk_rows // b)
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("t", "p", "speed", "vlo", "vhi", "alo", "ahi", "jlo", "jhi")}
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        idx = np.clip(np.arange(start - 1, stop + 2), 0, n - 1)
        p = table.exact_mm(int(idx[0]), int(idx[-1]) + 1)[idx - idx[0]]
        v = np.diff(p, axis=0)[: stop - start] * f
        a = np.diff(p, n=2, axis=0)[: stop - start] * f**2
        j = np.diff(p, n=3, axis=0)[: stop - start] * f**3
        edges = np.arange(0, stop - start, b)
        for name, data in (("v", v), ("a", a), ("j", j)):
            out[name + "lo"].append(np.minimum.reduceat(data, edges, axis=0))
            out[name + "hi"].append(np.maximum.reduceat(data, edges, axis=0))
        out["t"].append((start + edges) / f)
        out["p"].append(p[1:-2][edges])
        out["speed"].append(np.linalg.norm(v[edges], axis=1))
    return {k: np.concatenate(v) for k, v in out.items()}


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
    ser = _series(table, MAX_POINTS)
    lit = lit_mask(table)[(ser["t"] * h.tick_hz).round().astype(np.int64)]
    if not lit.any():  # a job without laser events (a dry run): colour the whole path by speed
        lit[:] = True
    axes = h.axes
    fig = plt.figure(figsize=(15, 8.5), constrained_layout=True)
    gs = fig.add_gridspec(3, 2, width_ratios=[1.15, 1])
    ax_path = fig.add_subplot(gs[:, 0])
    ix, iy = axes.index("x"), axes.index("y")
    xy = ser["p"][:, [ix, iy]]
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    sp = ser["speed"][:-1]
    on = lit[:-1]
    lc = LineCollection(seg[on], array=sp[on], cmap="viridis", linewidths=1.6)
    ax_path.add_collection(lc)
    ax_path.add_collection(LineCollection(seg[~on], colors="0.6", linewidths=0.6, linestyles="--"))
    ax_path.autoscale()
    ax_path.set_aspect("equal")
    ax_path.set_xlabel("X [mm]")
    ax_path.set_ylabel("Y [mm]")
    name = title or Path(h.meta.get("source", table.path.name)).name
    ax_path.set_title(name if len(name) <= 60 else "…" + name[-59:])
    fig.colorbar(lc, ax=ax_path, label="path speed while the laser is on [mm/s]  (off: grey dashes)", shrink=0.7)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    moving = np.ptp(ser["p"], axis=0) > 0
    for row, (name, unit) in enumerate((("v", "mm/s"), ("a", "mm/s²"), ("j", "mm/s³"))):
        ax = fig.add_subplot(gs[row, 1])
        for i, axis in enumerate(axes):
            if not moving[i]:
                continue
            lo, hi = ser[name + "lo"][:, i], ser[name + "hi"][:, i]
            c = colors[i % len(colors)]
            ax.fill_between(ser["t"], lo, hi, color=c, alpha=0.35, lw=0)
            ax.plot(ser["t"], hi, color=c, lw=0.6, label=axis)
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
