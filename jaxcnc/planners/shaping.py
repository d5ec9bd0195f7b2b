"""Input shapers and speed-band avoidance: the planner options against vibration (issue 20).

**Input shaping.** A shaper is a short train of impulses ``A_i`` at delays ``t_i`` (``A_i > 0``,
``Σ A_i = 1``); the reference ``p(t)`` is replaced by ``Σ A_i p(t - t_i)``. For a mode of natural
frequency ``f`` and damping ratio ``ζ`` the residual vibration after a move is the move's own times the
shaper's percentage vibration (Singer & Seering 1990)

    V(f, ζ) = e^{-ζ ω t_n} · |Σ A_i e^{ζ ω t_i} e^{j ω_d t_i}|,   ω = 2πf, ω_d = ω √(1 - ζ²)

which the shapers below make zero (ZV, ZVD, MZV) or below a tolerance ``V_tol`` over a band of
frequencies (the extra-insensitive family). Formulas, with ``K = exp(-ζπ/√(1-ζ²))`` and the damped period
``T_d = 1 / (f √(1-ζ²))``:

* **ZV** (Singer & Seering, "Preshaping command inputs to reduce system vibration", J. Dyn. Sys. Meas.
  Control 112, 1990): ``A = [1, K] / (1 + K)``, ``t = [0, T_d/2]``.
* **ZVD** (same paper, zero derivative of V in ω): ``A = [1, 2K, K²] / (1 + K)²``, ``t = [0, T_d/2, T_d]``.
* **MZV** (the three-impulse "modified ZV" of Klipper's ``shaper_defs.py``, D. Butyugin): impulses at
  ``[0, 3/8, 3/4] T_d`` with ``A ∝ [1 - 1/√2, (√2 - 1) K', (1 - 1/√2) K'²]``, ``K' = exp(-0.75 ζπ/√(1-ζ²))``:
  shorter than ZVD, zero vibration at ``f`` and low sensitivity near it.
* **EI** (extra-insensitive, Singhose, Seering & Singer, "Residual vibration reduction using vector
  diagrams to generate shaping inputs", J. Mech. Des. 116, 1994), ``V_tol = 5 %``: undamped
  ``A = [(1+V)/4, (1-V)/2, (1+V)/4]`` at ``[0, T_d/2, T_d]``; for ``ζ > 0`` the amplitudes and the middle
  delay follow the published curve fits in ``ζ`` and ``V_tol`` (Singhose's fits, as tabulated in Klipper).
* **2HUMP_EI**, **3HUMP_EI** (Singhose, Porter, Tuttle & Singer, "Vibration reduction using multi-hump
  input shapers", J. Dyn. Sys. Meas. Control 119, 1997): four and five impulses over ``1.5`` and ``2``
  periods, ``V ≤ 5 %`` over two and three humps of frequency; amplitudes and delays as cubic expansions
  in ``ζ`` (the coefficients of that paper as Klipper tabulates them).

Shaping the *table* rather than the steps (:mod:`jaxcnc.dynamics.shaped`): the shaped position of tick
``k`` is a convex combination of unshaped positions (the delays fall between ticks; linear interpolation
between the two neighbouring ticks is a convex combination too). Every quantity the independent check
limits — per-axis finite differences of first, second and third order at the tick rate, the speed, the
acceleration and the jerk — is linear in the positions, so ``|Δⁿ p_shaped| ≤ Σ w |Δⁿ p| ≤ max |Δⁿ p|``:
a table planned at the machine's limits stays within them once shaped (the shaped table is verified
anyway). What shaping does change is the *path* (a convex combination of points of a curve lies inside
it) and the job's duration (each stop waits for the shaper); :func:`shaping_program` bounds the first.

**Speed-band avoidance** (the Tianjin documents' "dynamic NURBS" speed curve, ``SEEDS.md`` §5): a feature
repeated every ``pitch`` mm cut at ``v`` mm/s excites ``f = v / pitch``; :func:`resonant_bands` turns the
machine's modes and a part's repeat lengths into feed bands, :func:`avoid_bands` keeps every programmed
feed out of them (below the band), so the planner never cruises inside one — it only crosses a band while
accelerating at full acceleration.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from jaxcnc.errors import JaxcncError
from jaxcnc.machine import MachineConfig
from jaxcnc.planners.job import PlannedJob
from jaxcnc.planners.smoothing import SmoothPlan
from jaxcnc.planners.timelaw import Plan
from jaxcnc.program import Kind, Program

#: The shapers by name (lower case, as ``--shaper`` takes them).
SHAPER_NAMES = ("zv", "mzv", "zvd", "ei", "2hump_ei", "3hump_ei")
#: Vibration tolerance of the extra-insensitive shapers (5 %).
EI_V_TOL = 0.05


@dataclass(frozen=True)
class Shaper:
    """An impulse train: ``amplitudes`` ``(n,)`` (positive, sum 1) at ``times_s`` ``(n,)`` (from 0, ascending),
    designed for the mode ``f_hz``, ``zeta``."""

    name: str
    amplitudes: np.ndarray
    times_s: np.ndarray
    f_hz: float
    zeta: float

    @property
    def duration_s(self) -> float:
        """The delay of the last impulse: how much longer a shaped move takes."""
        return float(self.times_s[-1])

    @property
    def centroid_s(self) -> float:
        """``Σ A_i t_i``: the mean delay of the shaped reference."""
        return float(np.dot(self.amplitudes, self.times_s))

    @property
    def spread_s2(self) -> float:
        """``Σ A_i (t_i - t̄)²``: the variance of the delays (the sagitta a shaper puts on an arc, see
        :func:`shaping_program`)."""
        return float(np.dot(self.amplitudes, (self.times_s - self.centroid_s) ** 2))

    @property
    def mean_abs_s(self) -> float:
        """``Σ A_i |t_i - t̄|``: the mean distance of the delays from their centroid (corner smoothing)."""
        return float(np.dot(self.amplitudes, np.abs(self.times_s - self.centroid_s)))

    def vibration(self, f_hz: float | np.ndarray, zeta: float) -> np.ndarray:
        """The percentage vibration ``V`` (0..1, 1 = unshaped) this shaper leaves on a mode ``f_hz``, ``zeta``
        (Singer & Seering 1990; module docstring). ``f_hz``: scalar or array; the result has its shape."""
        f = np.asarray(f_hz, np.float64)[..., None]
        w = 2 * np.pi * f
        wd = w * math.sqrt(1.0 - zeta**2)
        t = self.times_s
        decay = np.exp(zeta * w * (t - t[-1]))
        c = np.sum(self.amplitudes * decay * np.cos(wd * t), axis=-1)
        s = np.sum(self.amplitudes * decay * np.sin(wd * t), axis=-1)
        return np.hypot(c, s)


def _expansion(coeffs: list[list[float]], zeta: float) -> np.ndarray:
    """Each row's polynomial ``c0 + c1 ζ + c2 ζ² + c3 ζ³``."""
    c = np.asarray(coeffs, np.float64)
    return c @ (zeta ** np.arange(c.shape[1]))


#: 2-hump EI (Singhose et al. 1997): delays (in periods 1/f) and amplitudes as cubics in ζ.
_HUMP2_T = [[0.0, 0.0, 0.0, 0.0], [0.49890, 0.16270, -0.54262, 6.16180], [0.99748, 0.18382, -1.58270, 8.17120],
            [1.49920, -0.09297, -0.28338, 1.85710]]  # fmt: skip
_HUMP2_A = [[0.16054, 0.76699, 2.26560, -1.22750], [0.33911, 0.45081, -2.58080, 1.73650],
            [0.34089, -0.61533, -0.68765, 0.42261], [0.15997, -0.60246, 1.00280, -0.93145]]  # fmt: skip
#: 3-hump EI (same paper).
_HUMP3_T = [[0.0, 0.0, 0.0, 0.0], [0.49974, 0.23834, 0.44559, 12.4720], [0.99849, 0.29808, -2.36460, 23.3990],
            [1.49870, 0.10306, -2.01390, 17.0320], [1.99960, -0.28231, 0.61536, 5.40450]]  # fmt: skip
_HUMP3_A = [[0.11275, 0.76632, 3.29160, -1.44380], [0.23698, 0.61164, -2.57850, 4.85220],
            [0.30008, -0.19062, -2.14560, 0.13744], [0.23775, -0.73297, 0.46885, -2.08650],
            [0.11244, -0.45439, 0.96382, -1.46000]]  # fmt: skip
#: Largest damping ratio each shaper's formulas are valid for (the fits' range).
MAX_ZETA = {"zv": 0.99, "mzv": 0.99, "zvd": 0.99, "ei": 0.4, "2hump_ei": 0.3, "3hump_ei": 0.2}


def make_shaper(name: str, f_hz: float, zeta: float) -> Shaper:
    """The shaper ``name`` (one of :data:`SHAPER_NAMES`, any case) for a mode of ``f_hz`` Hz and damping
    ratio ``zeta``; formulas and sources in the module docstring. Bad input raises
    :class:`~jaxcnc.errors.JaxcncError` (one line)."""
    key = name.lower()
    if key not in SHAPER_NAMES:
        raise JaxcncError(f"unknown input shaper {name!r}; known: {', '.join(SHAPER_NAMES)}")
    if not (math.isfinite(f_hz) and f_hz > 0):
        raise JaxcncError(f"shaper {name}: the mode's frequency {f_hz!r} Hz must be positive and finite")
    if not (0 <= zeta <= MAX_ZETA[key]):
        raise JaxcncError(f"shaper {name}: damping ratio {zeta!r} outside [0, {MAX_ZETA[key]}] (its formulas' range)")
    df = math.sqrt(1.0 - zeta**2)
    t_d = 1.0 / (f_hz * df)
    k = math.exp(-zeta * math.pi / df)
    if key == "zv":
        a, t = [1.0, k], [0.0, 0.5 * t_d]
    elif key == "zvd":
        a, t = [1.0, 2 * k, k * k], [0.0, 0.5 * t_d, t_d]
    elif key == "mzv":
        k3 = math.exp(-0.75 * zeta * math.pi / df)
        a1 = 1.0 - 1.0 / math.sqrt(2.0)
        a, t = [a1, (math.sqrt(2.0) - 1.0) * k3, a1 * k3 * k3], [0.0, 0.375 * t_d, 0.75 * t_d]
    elif key == "ei":
        v, z = EI_V_TOL, zeta
        a1 = (0.24968 + 0.24961 * v) + ((0.80008 + 1.23328 * v) + (0.49599 + 3.17316 * v) * z) * z
        a3 = (0.25149 + 0.21474 * v) + ((-0.83249 + 1.41498 * v) + (0.85181 - 4.90094 * v) * z) * z
        c1, c2, c3 = (0.46159 + 8.57843 * v) * v, (4.26169 - 108.644 * v) * v, (1.75601 + 336.989 * v) * v
        t2 = 0.4999 + (c1 + (c2 + c3 * z) * z) * z
        a, t = [a1, 1.0 - a1 - a3, a3], [0.0, t2 * t_d, t_d]
    else:
        tt, aa = (_HUMP2_T, _HUMP2_A) if key == "2hump_ei" else (_HUMP3_T, _HUMP3_A)
        a, t = list(_expansion(aa, zeta)), list(_expansion(tt, zeta) / f_hz)
    amp = np.asarray(a, np.float64)
    return Shaper(key, amp / amp.sum(), np.asarray(t, np.float64), float(f_hz), float(zeta))


def fir_taps(shaper: Shaper, tick_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The shaper on the tick grid: ``(delays, weights)``, ``delays`` int64 ticks ascending, ``weights`` > 0
    summing to 1, such that ``shaped[k] = Σ weights[i] · p[k - delays[i]]``. An impulse at a delay between
    two ticks is split between them linearly (a convex combination, so limits are kept)."""
    d = shaper.times_s * tick_hz
    lo = np.floor(d + 1e-9).astype(np.int64)
    frac = np.clip(d - lo, 0.0, 1.0)
    delays = np.concatenate([lo, lo + 1])
    weights = np.concatenate([shaper.amplitudes * (1 - frac), shaper.amplitudes * frac])
    keep = weights > 1e-15
    u, inv = np.unique(delays[keep], return_inverse=True)
    w = np.bincount(inv, weights=weights[keep])
    return u, w / w.sum()


# -------------------------------------------------------------------------------------------------
# Contour: what shaping does to the path, bounded before planning


@dataclass(frozen=True)
class ShapingPlan:
    """How a program was prepared for shaping: the program planned, and what was changed.

    Attributes:
        program: the program to plan (the given one with extra stops and feed caps).
        n_stops_added: junctions turned into exact stops (the shaper would round them off further than
            ``tol_mm``).
        n_feed_caps: arcs whose feed was lowered so that the shaper's sagitta stays within ``tol_mm``.
        tol_mm: the contour error allowed to shaping (the tolerance, at least 1 µm: the sagitta arcs are held to).
    """

    program: Program
    n_stops_added: int
    n_feed_caps: int
    tol_mm: float


def _turn_angles(program: Program) -> np.ndarray:
    """``(n,)`` the change of direction (rad) at the start of each row, from the previous moving row's end
    direction to this row's start direction (lines and arcs; 0 where unknown)."""
    n = len(program)
    d_out = program.end - program.start
    d_in = d_out.copy()
    arc = program.kind == Kind.ARC
    if np.any(arc):  # arcs: tangents at the ends (in the XY plane; other planes counted as lines, conservatively)
        r0 = program.start[arc] - program.center[arc]
        r1 = program.end[arc] - program.center[arc]
        turn = program.turn[arc].astype(np.float64)[:, None]
        d_out[arc] = np.c_[-r0[:, 1], r0[:, 0], np.zeros(r0.shape[0])] * np.sign(turn)
        d_in[arc] = np.c_[-r1[:, 1], r1[:, 0], np.zeros(r1.shape[0])] * np.sign(turn)
    moving = program.is_motion & (np.linalg.norm(program.end - program.start, axis=1) > 0) | arc
    prev = np.full(n, -1)
    idx = np.where(moving, np.arange(n), -1)
    prev[1:] = np.maximum.accumulate(idx)[:-1]
    out = np.zeros(n)
    ok = moving & (prev >= 0)
    a = d_in[prev[ok]]  # the previous moving row's end direction
    b = d_out[ok]
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    good = (na > 0) & (nb > 0)
    cos = np.ones(a.shape[0])
    cos[good] = np.sum(a[good] * b[good], axis=1) / (na[good] * nb[good])
    out[ok] = np.arccos(np.clip(cos, -1.0, 1.0))
    return out


def shaping_program(
    program: Program, machine: MachineConfig, shaper: Shaper, tol_mm: float | None = None
) -> ShapingPlan:
    """Prepare ``program`` for ``shaper`` so that the shaped path stays within ``tol_mm`` of it.

    Two bounds (``t̄`` the shaper's centroid, ``E = Σ A_i |t_i - t̄|``, ``σ² = Σ A_i (t_i - t̄)²``):

    * **corners**: passed at ``v`` with a turn ``φ``, a convex combination of points within ``±v·t`` of the
      corner lies at most ``v·E·sin(φ/2)`` from it; a junction where the row's feed gives more than
      ``tol_mm / 2`` becomes an exact stop (the shaper then waits there: no rounding at all);
    * **arcs** of radius ``r``: the combination of points of a circle lies ``v²σ²/(2r)`` inside it; the
      feed is capped at ``√(r · tol_mm / σ²)`` (half the tolerance).

    ``tol_mm``: default the machine's ``corner_tol_mm`` (when that is 0, every corner stops and arcs are
    capped at a 1 µm sagitta). Splines are left as they are (the check measures them).
    """
    tol = machine.path.corner_tol_mm if tol_mm is None else float(tol_mm)
    if not (math.isfinite(tol) and tol >= 0):
        raise JaxcncError(f"shaping tolerance {tol_mm!r} mm must be zero or positive")
    tol_eff = max(tol, 1e-3)
    feed = np.where(
        program.rapid, machine.path.rapid, np.where(np.isnan(program.feed), machine.path.feed, program.feed)
    )
    phi = _turn_angles(program)
    rounding = feed * shaper.mean_abs_s * np.sin(phi / 2)
    add_stop = (phi > 1e-6) & ((rounding > tol / 2) | (tol == 0)) & ~program.stop_before
    arc = program.kind == Kind.ARC
    radius = np.linalg.norm(program.start - program.center, axis=1)
    cap = np.sqrt(radius * tol_eff / max(shaper.spread_s2, 1e-30))
    capped = arc & (feed > cap)
    new_feed = np.where(capped & ~program.rapid, cap, program.feed)
    prog = dataclasses.replace(program, stop_before=program.stop_before | add_stop, feed=new_feed)
    # the contour error shaping may cause: the tolerance, or the 1 µm sagitta arcs are held to when it is 0
    return ShapingPlan(prog, int(np.count_nonzero(add_stop)), int(np.count_nonzero(capped & ~program.rapid)), tol_eff)


# -------------------------------------------------------------------------------------------------
# Speed bands


def resonant_bands(
    modes_hz: list[float] | np.ndarray, pitches_mm: list[float] | np.ndarray, width: float = 0.2
) -> np.ndarray:
    """Feed bands ``(k, 2)`` mm/s (low, high) that excite a mode: a feature repeated every ``pitch`` mm
    cut at ``v`` excites ``v / pitch`` Hz, so each mode ``f`` and pitch ``p`` give ``f·p·(1 ± width)``.
    Overlapping bands are merged; sorted by their low edge."""
    f = np.asarray(modes_hz, np.float64).reshape(-1, 1)
    p = np.asarray(pitches_mm, np.float64).reshape(1, -1)
    if f.size == 0 or p.size == 0:
        return np.zeros((0, 2))
    if not (np.all(f > 0) and np.all(p > 0) and 0 < width < 1):
        raise JaxcncError("speed bands: modes and pitches must be positive, the band width a fraction in (0, 1)")
    centre = (f * p).ravel()
    return merge_bands(np.stack([centre * (1 - width), centre * (1 + width)], axis=1))


def merge_bands(bands: np.ndarray) -> np.ndarray:
    """Overlapping bands ``(k, 2)`` merged, sorted by the low edge."""
    b = np.asarray(bands, np.float64).reshape(-1, 2)
    if b.shape[0] == 0:
        return b
    if not np.all(np.isfinite(b)) or np.any(b[:, 0] < 0) or np.any(b[:, 1] <= b[:, 0]):
        raise JaxcncError(f"speed bands must be finite with 0 <= low < high (mm/s), got {b.tolist()}")
    b = b[np.argsort(b[:, 0])]
    out = [b[0].copy()]
    for lo, hi in b[1:]:
        if lo <= out[-1][1]:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append(np.array([lo, hi]))
    return np.asarray(out)


def repeat_pitches(program: Program, min_count: int = 4, rel: float = 0.02) -> np.ndarray:
    """A part's repeat lengths (mm): lengths of moving feed rows that occur at least ``min_count`` times
    (within ``rel``) — the teeth of a serration, the pitch of a dotted line. A zigzag of rows of length
    ``L`` repeats every ``2L`` (two rows per period): both ``L`` and ``2L`` are returned."""
    moving = program.is_motion & ~program.rapid
    length = np.linalg.norm(program.end - program.start, axis=1)[moving]
    length = np.sort(length[length > 0])
    out: list[float] = []
    i = 0
    while i < length.size:
        j = int(np.searchsorted(length, length[i] * (1 + rel), side="right"))
        if j - i >= min_count:
            m = float(np.median(length[i:j]))
            out += [m, 2 * m]
        i = j
    return np.unique(np.round(np.asarray(out), 9))


@dataclass(frozen=True)
class BandPlan:
    """The program with its feeds kept out of ``bands`` (mm/s), and how many rows were slowed."""

    program: Program
    bands: np.ndarray
    n_rows_slowed: int


def avoid_bands(
    program: Program, machine: MachineConfig, bands: np.ndarray, planned_mm_s: np.ndarray | None = None
) -> BandPlan:
    """Keep every feed move's speed out of ``bands`` ``(k, 2)`` mm/s: a row whose speed lies inside a band
    gets the band's low edge as its feed (never raised: the programmed feed is the user's cap for the cut).
    The speed tested is the programmed feed or, when given, ``planned_mm_s`` ``(n_rows,)`` (the highest speed
    a plan reached on each row: corners and short rows may hold it below the feed, inside a band). The
    planner then cruises below the band and crosses a band only while accelerating or braking, at the full
    acceleration (the time-optimal planner's ramps). Rapids are left at the rapid cap."""
    bands = merge_bands(bands)
    feed = np.where(np.isnan(program.feed), machine.path.feed, program.feed)
    speed = feed if planned_mm_s is None else np.minimum(np.asarray(planned_mm_s, np.float64), feed)
    new = speed.copy()
    for lo, hi in bands[::-1]:  # highest band first: a lowered feed may fall into a lower band next
        new = np.where((new > lo) & (new < hi), lo, new)
    slowed = (new < speed) & ~program.rapid & program.is_motion
    if np.any(slowed & (new <= 0)):
        raise JaxcncError("speed bands: a band reaches down to 0 mm/s, leaving no feed to cut with")
    out = np.where(slowed, new, program.feed)
    return BandPlan(dataclasses.replace(program, feed=out), bands, int(np.count_nonzero(slowed)))


# -------------------------------------------------------------------------------------------------
# What the shaping stage reads of a plan


def rest_ticks(job: PlannedJob) -> np.ndarray:
    """Ticks ``> 0`` where the planned motion is at rest (group starts of a :class:`Plan`, and the end),
    sorted (an S-curve plan: its groups' starts). Other time laws: only the end (their stops are shaped
    through, and the path check says so)."""
    n = job.plan.n_ticks
    plan = job.plan
    if isinstance(plan, Plan):
        starts = np.asarray(plan.group_tick)[np.asarray(plan.offset_ticks) == 0.0]
        ticks = np.unique(np.concatenate([starts, [n]]))
    elif isinstance(plan, SmoothPlan):  # the S-curve stage averages within rest-to-rest groups: still at rest
        ticks = np.unique(np.concatenate([np.asarray(plan.g_new_start), [n]]))
    else:
        ticks = np.array([n])
    return ticks[ticks > 0].astype(np.int64)


def row_peak_speeds(job: PlannedJob) -> np.ndarray | None:
    """``(n_rows,)`` the highest speed (mm/s) the plan reaches on each program row (0 where it does not
    move); ``None`` for time laws that are not a :class:`Plan`."""
    plan = job.plan.base if isinstance(job.plan, SmoothPlan) else job.plan  # averaging raises no speed
    if not isinstance(plan, Plan):
        return None
    rows = job.spans.block[plan.span]
    peak = np.zeros(len(job.program))
    np.maximum.at(peak, rows, np.maximum(np.asarray(plan.vp), np.maximum(plan.v0, plan.v1)))
    return peak


def parse_bands(text: str) -> np.ndarray | str:
    """``"auto"`` or speed bands written ``LOW-HIGH[,LOW-HIGH...]`` in mm/s (``"60-95,140-160"``) as
    ``(k, 2)``; anything else raises :class:`~jaxcnc.errors.JaxcncError` naming the part it cannot read."""
    t = text.strip()
    if t == "auto":
        return t
    out = []
    for part in t.split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            if not sep:
                raise ValueError
            out.append((float(lo), float(hi)))
        except ValueError:
            raise JaxcncError(f"speed band {part.strip()!r}: write LOW-HIGH in mm/s (e.g. 60-95), or 'auto'") from None
    return merge_bands(np.asarray(out))
