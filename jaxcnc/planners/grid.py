"""The planning grid: spans cut into intervals of arc length, with the path's frame at their ends.

Along a fixed path ``q(s)`` (``s`` arc length) every axis moves as ``q̇ = T ṡ`` and
``q̈ = T s̈ + K ṡ²``, with the unit tangent ``T = dq/ds`` and the curvature vector ``K = d²q/ds²``.
The phase-plane planner (:mod:`jaxcnc.planners.phaseplane`) needs ``T`` and ``K`` at the ends of
each interval on which it holds ``s̈`` constant:

* a line has constant ``T`` and ``K = 0``: one interval per line is exact;
* an arc or B-spline piece is cut into equal intervals, each at most ``TICKS_PER_INTERVAL`` ticks
  of travel at the span's speed cap and turning at most ``MAX_TURN_RAD``, so that ``T`` and ``K``
  change little inside one (the planner keeps ``GRID_MARGIN`` of the acceleration for what they
  do change; the tick table is verified independently);
* a point span (dwell, event) is one interval of zero length.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry.evaluate import evaluate_spans
from jaxcnc.geometry.inverse import span_arrays, u_of_s
from jaxcnc.geometry.spans import SpanKind, Spans, pad_spans
from jaxcnc.planners.trapezoid import bucket_size

TICKS_PER_INTERVAL = 4.0
MAX_TURN_RAD = 0.0175  # 1°
#: The tick rule does not cut intervals shorter than this (slow feeds need no finer time resolution).
MIN_INTERVAL_MM = 0.02
#: Fraction of the acceleration kept back on curved intervals for the change of T and K inside one.
GRID_MARGIN = 2e-3
MAX_INTERVALS_PER_SPAN = 1 << 16


@dataclass(frozen=True, eq=False)
class Grid:
    """Intervals in path order (NumPy arrays with ``m`` rows).

    Attributes:
        span: ``(m,)`` the span each interval lies on.
        s_start: ``(m,)`` mm from the span's start to the interval's start.
        delta: ``(m,)`` mm, the interval's length (0 for point spans).
        t_a, k_a: ``(m, 3)`` unit tangent and curvature vector (1/mm) at the interval's start.
        t_b, k_b: ``(m, 3)`` the same at its end.
        curved: ``(m,)`` bool, the interval lies on an arc or B-spline piece.
    """

    span: np.ndarray
    s_start: np.ndarray
    delta: np.ndarray
    t_a: np.ndarray
    k_a: np.ndarray
    t_b: np.ndarray
    k_b: np.ndarray
    curved: np.ndarray

    def __len__(self) -> int:
        return int(self.span.shape[0])


def is_curved(kind: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: the span kind has curvature (arc or B-spline piece)."""
    return (kind == SpanKind.ARC) | (kind == SpanKind.CURVE)


def interval_counts(spans: Spans, v_cap_mm_s: np.ndarray, tick_hz: float) -> np.ndarray:
    """``(n,)`` number of grid intervals of each span (1 for lines and points).

    Args:
        v_cap_mm_s: ``(n,)`` an upper bound of the speed on each span (feed and axis limits).
    """
    ticks_mm = np.maximum(v_cap_mm_s, 1e-9) * TICKS_PER_INTERVAL / tick_hz
    turn_mm = np.where(spans.kappa_max > 0, MAX_TURN_RAD / np.maximum(spans.kappa_max, 1e-300), np.inf)
    h = np.minimum(np.maximum(ticks_mm, MIN_INTERVAL_MM), turn_mm)
    n = np.ceil(spans.length / h)
    n = np.where(is_curved(spans.kind), np.clip(n, 1, MAX_INTERVALS_PER_SPAN), 1)
    return n.astype(np.int64)


@jax.jit
def path_frame(spans: dict, span: jnp.ndarray, s: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Unit tangent ``T`` and curvature vector ``K = d²q/ds²`` ``(m, 3)`` at ``s`` mm along ``span`` ``(m,)``.

    From the span derivatives in ``u``: ``T = P'/|P'|`` and ``K = (P'' - T (T·P''))/|P'|²``.
    """
    u = u_of_s(spans, span, s, newton_steps=1)
    _, d1, d2 = evaluate_spans(spans["coeffs_t"], spans["origin_t"], span, u, 2)
    speed = jnp.linalg.norm(d1, axis=1, keepdims=True)
    t = d1 / jnp.where(speed > 0, speed, 1.0)
    k = (d2 - t * jnp.sum(t * d2, axis=1, keepdims=True)) / jnp.where(speed > 0, speed, 1.0) ** 2
    return t, k


def device_spans(spans: Spans) -> dict[str, jnp.ndarray]:
    """The span arrays :func:`frames_at` reads, padded to a bucket (upload once, query often)."""
    return span_arrays(pad_spans(spans, bucket_size(len(spans))))


def frames_at(arrays: dict, span: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`path_frame` for NumPy queries ``(q,)``, padded to a bucket (few compiled sizes).

    ``arrays`` comes from :func:`device_spans`.
    """
    q = span.size
    m = bucket_size(q)
    which = np.zeros(m, np.int64)
    where = np.zeros(m)
    which[:q], where[:q] = span, s
    t, k = path_frame(arrays, jnp.asarray(which), jnp.asarray(where))
    return np.asarray(t)[:q], np.asarray(k)[:q]


def build_grid(spans: Spans, counts: np.ndarray, arrays: dict | None = None) -> Grid:
    """Cut ``spans`` into ``counts[k]`` equal intervals each and evaluate the frame at their ends.

    ``arrays``: :func:`device_spans` of ``spans`` when the caller has them already.
    """
    n = len(spans)
    span = np.repeat(np.arange(n), counts)
    j = np.arange(span.size) - np.repeat(np.cumsum(counts) - counts, counts)
    step = spans.length / counts
    s_start = j * step[span]
    last = j == counts[span] - 1
    s_end = np.where(last, spans.length[span], (j + 1) * step[span])  # the span's end exactly
    delta = s_end - s_start
    curved = is_curved(spans.kind)[span]
    t_a = np.array(spans.tangent_in[span])
    t_b = np.array(spans.tangent_out[span])
    k_a = np.zeros_like(t_a)
    k_b = np.zeros_like(t_b)
    idx = np.flatnonzero(curved)
    if idx.size:
        arrays = device_spans(spans) if arrays is None else arrays
        t, k = frames_at(arrays, np.concatenate([span[idx], span[idx]]), np.concatenate([s_start[idx], s_end[idx]]))
        t_a[idx], t_b[idx] = t[: idx.size], t[idx.size :]
        k_a[idx], k_b[idx] = k[: idx.size], k[idx.size :]
    return Grid(span=span, s_start=s_start, delta=delta, t_a=t_a, k_a=k_a, t_b=t_b, k_b=k_b, curved=curved)
