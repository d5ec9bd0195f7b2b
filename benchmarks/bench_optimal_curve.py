"""How far the look-ahead is from time-optimal on a curve: jaxcnc's plan beside a fine-grid reference.

    python benchmarks/bench_optimal_curve.py [--points 40000] [--feed 100] [--a 1000] [--v 100]

The curve is the corpus butterfly (../shared/corpus) or, without it, a built-in cubic NURBS. The
reference is the classic phase-plane method on a fine grid of path length ``s``: with unit tangent
``T`` and curvature vector ``K = d²P/ds²``, each axis obeys ``|a_t T_i + v² K_i| ≤ A_i`` and
``|v T_i| ≤ V_i``; the maximum-velocity curve comes from bisection on ``v²``, then a backward and a
forward integration of ``d(v²)/ds = 2 a_t`` with the tangential acceleration the axes allow at each
point (the approach of TOPP / toppra, here without a solver). It is a second method for the planner
issue's "within 1 % of the optimum"; it is not a test.
"""

from __future__ import annotations

import argparse

import jax.numpy as jnp
import numpy as np

from jaxcnc.bench import _find_butterfly, random_cubic_nurbs
from jaxcnc.geometry.evaluate import evaluate_spans
from jaxcnc.geometry.inverse import span_arrays, u_of_s
from jaxcnc.geometry.spans import SpanKind
from jaxcnc.io.curves import curves_program
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job

MACHINE = """\
[machine]
tick_hz = 10000
[axes.x]
v_max = {v}
a_max = {a}
min = -1000.0
max = 1000.0
[axes.y]
v_max = {v}
a_max = {a}
min = -1000.0
max = 1000.0
[path]
feed = {feed}
rapid = {feed}
"""


def path_samples(job, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc length ``s``, unit tangent ``T`` and curvature vector ``K`` at ``n`` points of the curve spans."""
    sp = job.spans
    cur = np.flatnonzero(sp.kind == SpanKind.CURVE)
    ends = np.concatenate([[0.0], np.cumsum(sp.length[cur])])
    s = np.linspace(0.0, ends[-1], n)
    k = np.clip(np.searchsorted(ends, s, side="right") - 1, 0, cur.size - 1)
    arrays = span_arrays(sp)
    u = u_of_s(arrays, jnp.asarray(cur[k]), jnp.asarray(s - ends[k]))
    _, d1, d2 = (
        np.asarray(x) for x in evaluate_spans(arrays["coeffs_t"], arrays["origin_t"], jnp.asarray(cur[k]), u, 2)
    )
    speed = np.linalg.norm(d1, axis=1, keepdims=True)
    t = d1 / speed
    curv = (d2 - t * np.sum(t * d2, axis=1, keepdims=True)) / speed**2
    return s, t[:, :2], curv[:, :2]


def tangential_range(t: np.ndarray, k: np.ndarray, x: np.ndarray, a_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Admissible tangential acceleration ``[lo, hi]`` at ``v² = x`` (arrays over points)."""
    lo = np.full(x.shape, -np.inf)
    hi = np.full(x.shape, np.inf)
    for i in range(t.shape[1]):
        ti, ki = t[:, i], k[:, i] * x
        with np.errstate(divide="ignore", invalid="ignore"):
            a1, a2 = (-a_max[i] - ki) / ti, (a_max[i] - ki) / ti
        tiny = np.abs(ti) <= 1e-12
        feasible = np.abs(ki) <= a_max[i]
        lo = np.maximum(lo, np.where(tiny, np.where(feasible, -np.inf, np.inf), np.minimum(a1, a2)))
        hi = np.minimum(hi, np.where(tiny, np.where(feasible, np.inf, -np.inf), np.maximum(a1, a2)))
    return lo, hi


def reference_time(s: np.ndarray, t: np.ndarray, k: np.ndarray, v_max: float, a_max: float, feed: float) -> float:
    a = np.full(t.shape[1], a_max)
    x_cap = np.full(s.size, feed**2)
    for i in range(t.shape[1]):
        with np.errstate(divide="ignore"):
            x_cap = np.minimum(x_cap, np.where(np.abs(t[:, i]) > 1e-12, v_max**2 / t[:, i] ** 2, np.inf))
    lo_x, hi_x = np.zeros(s.size), x_cap.copy()
    for _ in range(60):  # largest v² at which some tangential acceleration is admissible
        mid = (lo_x + hi_x) / 2
        lo, hi = tangential_range(t, k, mid, a)
        ok = lo <= hi
        lo_x, hi_x = np.where(ok, mid, lo_x), np.where(ok, hi_x, mid)
    x = np.minimum(x_cap, lo_x)
    x[0] = x[-1] = 0.0
    ds = np.diff(s)
    for j in range(s.size - 2, -1, -1):  # backward: the most deceleration allowed at j + 1
        lo, _ = tangential_range(t[j + 1 : j + 2], k[j + 1 : j + 2], x[j + 1 : j + 2], a)
        x[j] = min(x[j], x[j + 1] + 2 * max(-lo[0], 0.0) * ds[j])
    for j in range(1, s.size):  # forward: the most acceleration allowed at j - 1
        _, hi = tangential_range(t[j - 1 : j], k[j - 1 : j], x[j - 1 : j], a)
        x[j] = min(x[j], x[j - 1] + 2 * max(hi[0], 0.0) * ds[j - 1])
    v = np.sqrt(np.maximum(x, 0.0))
    return float(np.sum(2 * ds / np.maximum(v[1:] + v[:-1], 1e-12)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=40_000)
    ap.add_argument("--feed", type=float, default=100.0)
    ap.add_argument("--v", type=float, default=100.0)
    ap.add_argument("--a", type=float, default=1000.0)
    args = ap.parse_args()
    curve = _find_butterfly()
    name = "butterfly (corpus)"
    if curve is None:
        curve, name = random_cubic_nurbs(60), "cubic NURBS, 60 points"
    pts = curve[1] if curve[1].shape[1] == 3 else np.c_[curve[1], np.zeros(len(curve[1]))]
    machine = parse_machine(MACHINE.format(v=args.v, a=args.a, feed=args.feed), "<bench>")
    job = plan_job(curves_program([curve], args.feed, start=pts[0]), machine)
    ref = reference_time(*path_samples(job, args.points), args.v, args.a, args.feed)
    mine = job.plan.total_time_s
    print(f"{name}: v {args.v:g} mm/s, a {args.a:g} mm/s², feed {args.feed:g} mm/s")
    print(
        f"  jaxcnc look-ahead {mine:.4f} s; fine-grid phase-plane reference ({args.points} points) {ref:.4f} s; "
        f"jaxcnc / reference = {mine / ref:.3f}"
    )


if __name__ == "__main__":
    main()
