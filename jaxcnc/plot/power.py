"""The laser's power plot (issue 16): the path coloured by power, and power over time beside the path speed.

Measured on the table: the power channel (what the laser is commanded; version 1 tables: held from their
``laser`` events) and the speed from the unquantised positions. Where the header records laser latency
(``laser_delay_ticks``) the laser's output (:func:`jaxcnc.ticks.laser.delivered_power`) is drawn over the command.
Long tables are reduced to per-bin envelopes (min and max of each bin) so a short burn or a dip survives.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from jaxcnc.format import TableFile  # noqa: E402
from jaxcnc.ticks.laser import delivered_power  # noqa: E402

MAX_POINTS = 20000


def power_series(table: TableFile, n_bins: int = MAX_POINTS, chunk_rows: int = 1 << 20) -> dict[str, np.ndarray]:
    """Per-bin series of a table, read chunk by chunk: ``t`` (bin start, s), ``p`` (positions ``(n, n_axes)``),
    ``speed`` (mm/s at the bin's first tick), ``speed_lo``/``speed_hi``, ``power_lo``/``power_hi`` (the command)
    and ``out_lo``/``out_hi`` (the laser's output; the command itself without latency), each ``(n,)``."""
    h = table.header
    n, f = h.n_rows, h.tick_hz
    d_on, d_off = (int(x) for x in h.meta.get("laser_delay_ticks", (0, 0)))
    hi, lo = max(d_on, d_off), min(d_on, d_off)
    b = max(1, -(-n // n_bins))
    chunk = b * max(1, chunk_rows // b)
    keys = ("t", "p", "speed", "speed_lo", "speed_hi", "power_lo", "power_hi", "out_lo", "out_hi")
    out: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        p = table.exact_mm(start, min(stop + 1, n))
        if p.shape[0] == stop - start:
            p = np.vstack([p, p[-1:]])  # at rest after the last row
        speed = np.linalg.norm(np.diff(p, axis=0), axis=1) * f
        power = table.read_power(start, stop).astype(np.float64)
        if hi:
            a, z = max(start - hi, 0), min(stop - lo, n)
            cmd = np.r_[np.zeros(a - (start - hi)), table.read_power(a, z), np.zeros(stop - lo - z)]
            emitted = delivered_power(cmd.astype(np.float32), d_on, d_off).astype(np.float64)
        else:
            emitted = power
        edges = np.arange(0, stop - start, b)
        for name, data in (("speed", speed), ("power", power), ("out", emitted)):
            out[name + "_lo"].append(np.minimum.reduceat(data, edges))
            out[name + "_hi"].append(np.maximum.reduceat(data, edges))
        out["t"].append((start + edges) / f)
        out["p"].append(p[edges])
        out["speed"].append(speed[edges])
    return {k: np.concatenate(v) for k, v in out.items()}


def plot_power(table: TableFile, out: str | Path, title: str | None = None) -> Path:
    """Write a PNG: the XY path coloured by the laser's output power (dark moves grey dashes), and over time the
    power (command and, with latency, output) above the path speed."""
    h = table.header
    ser = power_series(table)
    fig = plt.figure(figsize=(15, 8.0), constrained_layout=True)
    gs = fig.add_gridspec(2, 2, width_ratios=[1.15, 1])
    ax_path = fig.add_subplot(gs[:, 0])
    ix, iy = (h.axes.index(a) for a in ("x", "y")) if {"x", "y"} <= set(h.axes) else (0, min(1, h.n_axes - 1))
    xy = ser["p"][:, [ix, iy]]
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    level = ser["out_hi"][:-1]
    lit = level > 0
    s_max = float(max(ser["out_hi"].max(initial=0.0), ser["power_hi"].max(initial=0.0))) or 1.0
    lc = LineCollection(seg[lit], array=level[lit], cmap="plasma_r", linewidths=1.8)
    lc.set_clim(0.0, s_max)
    ax_path.add_collection(lc)
    ax_path.add_collection(LineCollection(seg[~lit], colors="0.65", linewidths=0.6, linestyles="--"))
    ax_path.autoscale()
    ax_path.set_aspect("equal")
    ax_path.set_xlabel(f"{h.axes[ix].upper()} [mm]")
    ax_path.set_ylabel(f"{h.axes[iy].upper()} [mm]")
    name = title or Path(h.meta.get("source", table.path.name)).name
    ax_path.set_title(name if len(name) <= 60 else "…" + name[-59:])
    fig.colorbar(lc, ax=ax_path, label="laser power [S]  (dark: grey dashes)", shrink=0.7)
    t = ser["t"]
    ax_p = fig.add_subplot(gs[0, 1])
    ax_p.fill_between(t, ser["power_lo"], ser["power_hi"], color="#ff7f0e", alpha=0.35, lw=0)
    ax_p.plot(t, ser["power_hi"], color="#ff7f0e", lw=0.7, label="power channel (commanded)")
    delays = h.meta.get("laser_delay_ticks")
    if delays:
        ax_p.plot(t, ser["out_hi"], color="#d62728", lw=0.7, ls="--", label=f"laser output (delays {delays} ticks)")
    ax_p.set_ylabel("power [S]")
    ax_p.set_title(f"measured on the table at {h.tick_hz:g} Hz (per-bin min/max)")
    ax_p.legend(loc="upper right")
    ax_p.grid(alpha=0.3)
    ax_v = fig.add_subplot(gs[1, 1], sharex=ax_p)
    ax_v.fill_between(t, ser["speed_lo"], ser["speed_hi"], color="#1f77b4", alpha=0.35, lw=0)
    ax_v.plot(t, ser["speed_hi"], color="#1f77b4", lw=0.7)
    ax_v.set_ylabel("path speed [mm/s]")
    ax_v.set_xlabel("time [s]")
    ax_v.grid(alpha=0.3)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return Path(out)
