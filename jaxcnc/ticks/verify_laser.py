"""Independent check of a table's laser channel against its positions, events and the machine file (NumPy only).

For every tick the expected output is recomputed from the table alone (``docs/laser.md``): the latest ``laser``
event gives the mode and S, the latest ``feed`` event the programmed feed F, the unquantised positions of the
tick and the next the tool's mean speed v over the tick; M3 → S, M4 → ``S · max(floor, curve(v / F))``, dark → 0.
The stored power must equal it within :data:`POWER_TOL` of S. For tables whose header marks them
``constant_speed_laser`` (raster jobs: the beam may fire only at the programmed speed) every lit tick's speed must
also be within ``speed_tol`` of F. Nothing here reads the plan.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from jaxcnc.format import EventKind, TableFile
from jaxcnc.machine import MachineConfig
from jaxcnc.ticks.laser import delivered_power, reachable_power, shift_laser_events
from jaxcnc.ticks.verify import TableRows, Violation, _runs

#: Tolerance on the power, as a fraction of S (float32 storage is 6e-8; positions carry ~1e-13 mm of noise).
POWER_TOL = 1e-4
#: Relative speed tolerance of a constant-speed (raster) table's lit ticks.
SPEED_TOL = 1e-3


@dataclass
class LaserCheck:
    """What the laser check measured: ticks lit, ticks under M4, the largest power error (fraction of S), and on
    constant-speed tables the largest relative speed deviation of a lit tick."""

    n_lit: int = 0
    n_m4: int = 0
    max_power_error: float = 0.0
    max_speed_deviation: float = 0.0
    constant_speed: bool = False
    violations: list[Violation] = field(default_factory=list)
    #: raster jobs: the energy each pixel received against the image (axis-aligned scans), and why the pixel
    #: powers were not checked when they were not (the source image is not here).
    pixels: object = None
    raster_note: str = ""
    #: laser latency in ticks (on, off): then the output checked is the command delayed by the laser model
    #: (:func:`jaxcnc.ticks.laser.delivered_power`), and ``max_hold_error`` is how far the output the delays let
    #: the laser reach (each burn's last off - on ticks held at one level) is from the programmed one, of S.
    delay_ticks: tuple[int, int] = (0, 0)
    max_hold_error: float = 0.0


def _held(events: np.ndarray, kind: int, ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ev = events[events["kind"] == kind]
    i = np.searchsorted(ev["tick"], ticks, side="right")
    return np.r_[0, ev["aux"].astype(np.int64)][i], np.r_[0.0, ev["value"]][i]


def check_laser(
    table: TableFile, machine: MachineConfig, chunk_rows: int = 1 << 16, speed_tol: float = SPEED_TOL
) -> LaserCheck | None:
    """Check the power channel of ``table`` tick by tick (see the module); ``None`` when it has none."""
    h = table.header
    if not h.has_power:
        return None
    las = machine.laser
    out = LaserCheck(constant_speed=bool(h.meta.get("constant_speed_laser")))
    image = None
    if "raster" in h.meta:  # a raster image: each lit tick's power is S times the level under it
        from jaxcnc.ticks.raster import axes_xy, pixel_energy, pixel_of, raster_of_table

        image, out.raster_note = raster_of_table(table, machine)
        xy = axes_xy(h.axes)
        energy = np.zeros(image.levels.size if image is not None else 0)
    d_on, d_off = las.delay_ticks(h.tick_hz)
    out.delay_ticks = (d_on, d_off)
    rec = tuple(int(x) for x in h.meta.get("laser_delay_ticks", (0, 0)))
    bad_power: list[tuple[int, int, float]] = []
    bad_speed: list[tuple[int, int, float]] = []
    if rec != (d_on, d_off):
        why = (
            f"the power channel was commanded for laser delays of {list(rec)} ticks (on, off); the machine file's "
            f"[laser] on_delay_s/off_delay_s are {[d_on, d_off]} ticks"
        )
        out.violations.append(Violation(0, h.n_rows - 1, why, "laser", float("inf"), 0.0))
    hi, lo = max(d_on, d_off), min(d_on, d_off)
    pad = hi + 1
    events = table.events if hi == 0 else shift_laser_events(table.events, d_on, d_off, +1)  # programmed ticks
    with TableRows(table) as rows:

        def wanted(a: int, b: int) -> tuple[np.ndarray, ...]:
            """The programmed output of ticks a .. b-1 (within the table), with mode, S, feed, speed, pixels."""
            p = rows.exact_mm(a, min(b + 1, h.n_rows))
            if p.shape[0] == b - a:  # the last row: at rest after it
                p = np.vstack([p, p[-1:]])
            ticks = np.arange(a, b, dtype=np.int64)
            mode, s = _held(events, EventKind.LASER, ticks)
            _, feed = _held(events, EventKind.FEED, ticks)
            v = np.sqrt((np.diff(p, axis=0) ** 2).sum(axis=1)) * h.tick_hz
            ratio = np.clip(np.where(feed > 0, v / np.where(feed > 0, feed, 1.0), 0.0), 0.0, 1.0)
            if las.m4_curve_speed is not None and las.m4_curve_power is not None:
                ratio = np.interp(ratio, las.m4_curve_speed, las.m4_curve_power)
            m4 = (mode == 4) & (feed > 0)
            want = np.where(mode == 0, 0.0, s * np.where(m4, np.maximum(ratio, las.m4_floor), 1.0))
            pix = None
            if image is not None:
                pix = pixel_of(image, p, xy)
                want = want * np.where(pix >= 0, image.levels.reshape(-1)[np.maximum(pix, 0)], 0.0)
            return want, mode, s, feed, v, m4, pix

        for start in range(0, h.n_rows, chunk_rows):
            stop = min(start + chunk_rows, h.n_rows)
            want, mode, s, feed, v, m4, pix = wanted(start, stop)
            if hi:  # the laser's output from the (early) command; the output the delays let it reach
                a, b = max(start - pad, 0), min(stop + pad, h.n_rows)  # ticks start - pad .. stop + pad - 1
                w_ext = np.concatenate([np.zeros(pad - (start - a)), wanted(a, b)[0], np.zeros(pad - (b - stop))])
                hd = d_off - d_on  # reachable_power wants ticks start - hd - 1 .. stop + hd - 1
                reach = (
                    reachable_power(w_ext[pad - hd - 1 : pad + stop - start + hd], d_on, d_off)
                    if hd > 0
                    else (w_ext[pad : pad + stop - start])
                )
                out.max_hold_error = max(
                    out.max_hold_error, float((np.abs(reach - want) / np.maximum(s, 1e-12)).max(initial=0.0))
                )
                tail = hi if stop == h.n_rows else 0  # after the table the output must be dark
                c_lo, c_hi = start - hi, stop - lo + tail  # the command of these ticks gives the output's
                a, b = max(c_lo, 0), min(c_hi, h.n_rows)
                cmd = np.concatenate([np.zeros(a - c_lo), table.read_power(a, b), np.zeros(c_hi - b)])
                y = delivered_power(cmd.astype(np.float32), d_on, d_off).astype(np.float64)
                if tail and (after := np.flatnonzero(y[stop - start :] > 0)).size:
                    why = f"the laser still fires {int(after[-1]) + 1} ticks after the table ends"
                    out.violations.append(Violation(h.n_rows - 1, h.n_rows - 1, why, "laser", float("inf"), 0.0))
                got, want = y[: stop - start], reach.astype(np.float64)
            else:
                got = table.read_power(start, stop).astype(np.float64)
            if image is not None:
                on = (got > 0) & (pix >= 0)
                energy += np.bincount(pix[on], weights=got[on] / h.tick_hz, minlength=energy.size)
            elif "raster" in h.meta:
                want = np.minimum(want, got)  # the levels are not here: only "never above S" is checked
            err = np.abs(got - want) / np.maximum(s, 1e-12)
            err = np.where((want == 0) & (got == 0), 0.0, np.where(mode == 0, np.inf, err))
            out.n_lit += int((got > 0).sum())
            out.n_m4 += int(m4.sum())
            out.max_power_error = max(out.max_power_error, float(err.max(initial=0.0)))
            for r0, r1 in _runs(err > POWER_TOL):
                bad_power.append((start + r0, start + r1, float(err[r0 : r1 + 1].max())))
            if out.constant_speed:
                lit = got > 0
                dev = np.where(lit & (feed > 0), np.abs(v - feed) / np.where(feed > 0, feed, 1.0), 0.0)
                out.max_speed_deviation = max(out.max_speed_deviation, float(dev.max(initial=0.0)))
                for r0, r1 in _runs(dev > speed_tol):
                    bad_speed.append((start + r0, start + r1, float(dev[r0 : r1 + 1].max())))
    if image is not None:
        out.pixels = pixel_energy(image, energy, h.tick_hz, speed_tol)
        if out.pixels is not None and out.pixels.n_bad:
            r, c = divmod(out.pixels.bad[0], image.levels.shape[1])
            why = (
                f"{out.pixels.n_bad} pixels (first: row {r}, column {c}) received an energy "
                f"{out.pixels.max_error_ticks:.3g} ticks' worth away from S · level · pixel / F"
            )
            out.violations.append(Violation(0, h.n_rows - 1, why, "laser", out.pixels.max_error_ticks, 1.0))
    for r0, r1, e in _merge(bad_power):
        why = f"power differs from the mode, S, feed and speed by {e:.3g} of S (allowed {POWER_TOL:g})"
        out.violations.append(Violation(r0, r1, why, "laser", e, POWER_TOL))
    for r0, r1, e in _merge(bad_speed):
        why = (
            f"lit at {100 * e:.3g} % away from the programmed speed (a constant-speed job; "
            f"allowed {100 * speed_tol:g} %)"
        )
        out.violations.append(Violation(r0, r1, why, "laser", e, speed_tol))
    return out


def _merge(runs: list[tuple[int, int, float]]) -> list[tuple[int, int, float]]:
    """Join runs split by chunk boundaries."""
    merged: list[list] = []
    for r0, r1, v in runs:
        if merged and r0 == merged[-1][1] + 1:
            merged[-1][1], merged[-1][2] = r1, max(merged[-1][2], v)
        else:
            merged.append([r0, r1, v])
    return [tuple(m) for m in merged]
