"""The planning grid: spans cut into intervals of the path parameter, with the path's derivatives at their ends.

Along the path ``q(s)`` every axis moves as ``q̇ = q' ṡ`` and ``q̈ = q' s̈ + q'' ṡ²``, with ``q'`` and
``q''`` the derivatives in the path parameter ``s`` (:mod:`jaxcnc.geometry.evaluate`; on lines and
arcs ``s`` is arc length, ``q'`` the unit tangent and ``q''`` the curvature vector; on polynomial
spans ``|q'|`` is close to 1). The phase-plane planner (:mod:`jaxcnc.planners.phaseplane`) needs
``q'`` and ``q''`` at the ends of each interval on which it holds ``s̈`` constant:

* a line has constant ``q'`` and ``q'' = 0``: one interval per line is exact;
* an arc, NURBS piece or blend is cut into equal intervals turning by at most ``MAX_TURN_RAD``
  each, so that ``q'`` and ``q''`` change little inside one (the planner keeps ``GRID_MARGIN`` of
  the acceleration for what they do change and checks interval midpoints; the tick table is
  verified independently); a blend gets at least ``MIN_BLEND_INTERVALS``, so that a node sits at
  its curvature peak;
* a point span (dwell, event) is one interval of zero length.

The grid depends on the geometry alone — not on the feed or the tick rate — so a program plans to
the same motion at any tick rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.geometry.evaluate import evaluate_path, span_arrays
from jaxcnc.geometry.kinds import CURVED_KINDS, SpanKind
from jaxcnc.geometry.spans import Spans, pad_spans
from jaxcnc.planners.buckets import bucket_size

MAX_TURN_RAD = 0.0175  # 1°
#: Intervals of a blend before refinement (the middle node sits on its curvature peak).
MIN_BLEND_INTERVALS = 2
#: Fraction of the acceleration kept back on curved intervals for the change of q' and q'' inside one.
GRID_MARGIN = 2e-3
MAX_INTERVALS_PER_SPAN = 1 << 16


@dataclass(frozen=True, eq=False)
class Grid:
    """Intervals in path order (NumPy arrays with ``m`` rows).

    Attributes:
        span: ``(m,)`` the span each interval lies on.
        s_start: ``(m,)`` path parameter from the span's start to the interval's start (mm).
        delta: ``(m,)`` mm, the interval's length in the path parameter (0 for point spans).
        t_a, k_a: ``(m, 3)`` ``q'`` and ``q''`` (1/mm) at the interval's start.
        t_b, k_b: ``(m, 3)`` the same at its end.
        curved: ``(m,)`` bool, the interval lies on an arc, NURBS piece or blend.
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
    """``(n,)`` bool: the span kind has curvature (arc, NURBS piece or blend)."""
    return np.isin(kind, CURVED_KINDS)


def interval_counts(spans: Spans) -> np.ndarray:
    """``(n,)`` number of grid intervals of each span (1 for lines and points), from its turning."""
    turning = spans.length * spans.kappa_max
    n = np.ceil(turning / MAX_TURN_RAD)
    n = np.where(spans.kind == SpanKind.BLEND, np.maximum(n, MIN_BLEND_INTERVALS), n)
    n = np.where(is_curved(spans.kind), np.clip(n, 1, MAX_INTERVALS_PER_SPAN), 1)
    return n.astype(np.int64)


@jax.jit
def path_frame(arrays: dict, span: jnp.ndarray, s: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """``q'`` and ``q''`` ``(m, 3)`` at ``s`` along span ``span`` ``(m,)``."""
    _, d1, d2 = evaluate_path(arrays, span, s, 2, xp=jnp)
    return d1, d2


def device_spans(spans: Spans) -> dict[str, jnp.ndarray]:
    """The span arrays :func:`frames_at` reads, padded to a bucket (upload once, query often)."""
    return span_arrays(pad_spans(spans, bucket_size(len(spans))), xp=jnp)


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
