"""A picture of a simulated table: commanded against simulated positions, the error and the stops."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxcnc.dynamics.simulate import Simulation  # noqa: E402


def plot_simulation(sim: Simulation, out: str | Path, title: str = "") -> Path:
    """Draw ``sim`` (simulated with ``keep=True``) to a PNG at ``out``: the tool path commanded and simulated
    (error magnified so that it shows), and per axis the error over time with the stops marked."""
    if sim.commanded is None or sim.error is None:
        raise ValueError("simulate_table(..., keep=True) keeps the per-tick arrays a picture needs")
    u, e = sim.commanded, sim.error
    t = np.arange(u.shape[0]) / sim.tick_hz
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5))
    gain = 1.0
    if u.shape[1] >= 2:
        span = float(np.ptp(u[:, :2], axis=0).max()) or 1.0
        peak = float(np.abs(e[:, :2]).max()) or 1.0
        gain = max(1.0, round(0.03 * span / peak))
        ax0.plot(u[:, 0], u[:, 1], "k-", lw=0.8, label="commanded")
        ax0.plot(u[:, 0] + gain * e[:, 0], u[:, 1] + gain * e[:, 1], "r-", lw=0.6, label=f"simulated (error x{gain:g})")
        ax0.set_aspect("equal")
        ax0.set_xlabel(f"{sim.axes[0]} (mm)")
        ax0.set_ylabel(f"{sim.axes[1]} (mm)")
        ax0.legend(loc="best", fontsize=8)
    for i, a in enumerate(sim.axes):
        if a in sim.modes:
            ax1.plot(
                t,
                e[:, i] * 1e3,
                lw=0.7,
                label=f"{a}: " + ", ".join(f"{m.f_hz:g} Hz ζ={m.zeta:g}" for m in sim.modes[a]),
            )
    for k in sim.stop_ticks:
        ax1.axvline(k / sim.tick_hz, color="0.8", lw=0.5, zorder=0)
    ax1.set_xlabel("time (s); grey: stops")
    ax1.set_ylabel("simulated - commanded (µm)")
    ax1.legend(loc="best", fontsize=8)
    fig.suptitle(
        (title + "\n" if title else "")
        + f"residual after stops max {sim.max_residual_mm * 1e3:.3g} µm, "
        + f"contour error max {sim.max_contour_mm * 1e3:.3g} µm"
    )
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return Path(out)
