"""The beam of a galvo job (issue 18): commanded vs actual path, coloured by the laser's state.

Left: the whole field — the commanded beam (thin grey), the actual beam (the head model's mirrors) red where the
laser is on and blue dashed where it is off, and the programmed paths if given (thin black). Right: a zoom on the
lit tick where the actual beam is farthest from the command, where delays and sky-writing show.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

#: Colours of the actual beam: laser on, laser off.
LIT_COLOR, DARK_COLOR = "#d62728", "#1f77b4"


def _draw(ax, commanded: np.ndarray, actual: np.ndarray, lit: np.ndarray, paths, lw: float) -> None:
    ax.plot(commanded[:, 0], commanded[:, 1], color="0.65", lw=0.6 * lw, label="commanded")
    seg = np.stack([actual[:-1], actual[1:]], axis=1)
    on = lit[1:] & lit[:-1]
    ax.add_collection(LineCollection(seg[~on], colors=DARK_COLOR, linewidths=0.7 * lw, linestyles="--"))
    ax.add_collection(LineCollection(seg[on], colors=LIT_COLOR, linewidths=1.4 * lw))
    for p in paths or ():
        ax.plot(p[:, 0], p[:, 1], color="k", lw=0.4 * lw)
    ax.set_aspect("equal")
    ax.set_xlabel("X [mm]")
    ax.set_ylabel("Y [mm]")


def plot_beam(
    commanded_mm: np.ndarray, actual_mm: np.ndarray, power: np.ndarray, out: str | Path,
    paths: list[np.ndarray] | None = None, title: str = "galvo beam", zoom_mm: float = 0.5,
) -> Path:  # fmt: skip
    """Write a PNG of the beam: ``commanded_mm``, ``actual_mm`` ``(n, 2)`` per board tick, ``power`` ``(n,)``
    (> 0: lit), ``paths`` the programmed polylines ``(m_i, 2)`` mm. Returns the PNG's path."""
    cmd = np.asarray(commanded_mm, np.float64)[:, :2]
    act = np.asarray(actual_mm, np.float64)[:, :2]
    lit = np.asarray(power) > 0
    if cmd.shape != act.shape or lit.shape != (cmd.shape[0],) or cmd.shape[0] < 2:
        raise ValueError("plot_beam: commanded, actual (n, 2) and power (n,) with n >= 2")
    fig, (ax_all, ax_zoom) = plt.subplots(1, 2, figsize=(15, 7.5), constrained_layout=True)
    _draw(ax_all, cmd, act, lit, paths, 1.0)
    ax_all.autoscale()
    ax_all.set_title(title)
    dev = np.hypot(*(act - cmd).T)
    i = int(np.argmax(np.where(lit, dev, -1.0))) if lit.any() else int(np.argmax(dev))
    _draw(ax_zoom, cmd, act, lit, paths, 2.0)
    cx, cy = act[i]
    ax_zoom.set_xlim(cx - zoom_mm, cx + zoom_mm)
    ax_zoom.set_ylim(cy - zoom_mm, cy + zoom_mm)
    ax_zoom.set_title(f"zoom: largest lag while lit, {dev[i] * 1000:.1f} µm from the command (tick {i})")
    handles = [plt.Line2D([], [], color="0.65", lw=1, label="commanded")]
    if lit.any():
        handles.append(plt.Line2D([], [], color=LIT_COLOR, lw=2, label="actual, laser on"))
    if not lit.all():
        handles.append(plt.Line2D([], [], color=DARK_COLOR, lw=1, ls="--", label="actual, laser off"))
    if paths:
        handles.append(plt.Line2D([], [], color="k", lw=0.6, label="programmed"))
    ax_zoom.legend(handles=handles, loc="upper right")
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
