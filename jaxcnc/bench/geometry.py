"""The geometry benchmark behind ``jaxcnc bench geometry``: NURBS evaluation and tick generation."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.bench.common import REPEATS, BenchInputMissing, measure, run_header
from jaxcnc.bench.plan import tick_rate
from jaxcnc.bench.programs import BENCH_MACHINE, find_butterfly, random_cubic_nurbs
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job


def bench_curve(name: str, curve: tuple, n_eval: int = 1_000_000, repeats: int = REPEATS, feed: float = 10.0) -> dict:
    """Evaluation points/s (jaxcnc vs scipy vs geomdl; random and sorted parameters) and tick generation
    ticks/s on one curve, min/median of ``repeats`` with CPU time beside wall time."""
    from scipy.interpolate import BSpline

    from jaxcnc.geometry.bezier import homogeneous_power, nurbs_to_bezier
    from jaxcnc.geometry.evaluate import evaluate_bezier
    from jaxcnc.io.curves import curves_program

    p, pts, w, knots = curve
    pts = np.c_[pts, np.zeros(len(pts))] if pts.shape[1] == 2 else pts
    bp, bw, iv = nurbs_to_bezier(p, pts, w, knots)
    coeffs_t = jnp.asarray(np.ascontiguousarray(np.transpose(homogeneous_power(bp, bw, bp[:, 0]), (1, 2, 0))))
    origin_t = jnp.asarray(np.ascontiguousarray(bp[:, 0].T))
    breaks = jnp.asarray(iv[:, 0])
    width = jnp.asarray(iv[:, 1] - iv[:, 0])

    @jax.jit
    def eval_params(t):  # NURBS parameter -> span -> local u -> position, all on the device
        k = jnp.clip(jnp.searchsorted(breaks, t, side="right") - 1, 0, breaks.shape[0] - 1)
        (pos,) = evaluate_bezier(coeffs_t, origin_t, k, (t - breaks[k]) / width[k], xp=jnp)
        return pos

    spl = BSpline(knots, np.c_[pts * w[:, None], w], p)
    print(f"  {name}: {len(pts)} control points, degree {p}, {len(iv)} Bezier spans")
    out = {}
    draws = np.random.default_rng(2).uniform(knots[0], knots[-1], n_eval)
    # random parameters, and sorted ones (a tick stream reads its curve in order: scipy's knot search caches)
    for order, values in (("random", draws), ("sorted", np.sort(draws))):
        t = jax.device_put(values)
        t0 = time.perf_counter()
        ref = np.asarray(eval_params(t))
        compile_s = time.perf_counter() - t0

        def scipy_eval(values=values):
            h = spl(values)
            return h[:, :3] / h[:, 3:]

        s_jax = measure(lambda t=t: eval_params(t).block_until_ready(), repeats)
        s_scipy = measure(scipy_eval, repeats)
        err = float(np.max(np.abs(scipy_eval() - ref)))
        print(
            f"    evaluation of {n_eval:,} {order} parameters (compile {compile_s:.2f} s apart): jaxcnc "
            f"{n_eval / s_jax.wall_min:,.0f} pts/s, scipy BSpline {n_eval / s_scipy.wall_min:,.0f} pts/s "
            f"(jaxcnc {s_scipy.wall_min / s_jax.wall_min:.2f}x; min of {repeats}, CPU-time ratio "
            f"{s_scipy.cpu_min / s_jax.cpu_min:.2f}x); max |diff| {err:.1e} mm"
        )
        print(f"      jaxcnc {s_jax}; scipy {s_scipy}")
        out[order] = {"jax": s_jax.as_dict(), "scipy": s_scipy.as_dict(), "compile_s": compile_s, "max_diff_mm": err}
    t = jax.device_put(draws)
    t_jax = out["random"]["jax"]["wall_min_s"]
    try:
        from geomdl import NURBS

        crv = NURBS.Curve()
        crv.degree = p
        crv.ctrlptsw = (np.c_[pts * w[:, None], w]).tolist()
        crv.knotvector = knots.tolist()
        n_g = 20_000
        tg = ((np.asarray(t[:n_g]) - knots[0]) / (knots[-1] - knots[0])).tolist()
        t_geomdl = measure(lambda: crv.evaluate_list(tg), 1).wall_min
        print(
            f"    geomdl (pure Python) {n_g / t_geomdl:,.0f} pts/s on {n_g:,} points (jaxcnc "
            f"{(n_g / t_geomdl) and (n_eval / t_jax) / (n_g / t_geomdl):.0f}x)"
        )
        out["eval_geomdl_pts_s"] = n_g / t_geomdl
    except ImportError:
        print("    geomdl not installed (pip install geomdl): skipped")

    m = parse_machine(BENCH_MACHINE.replace("a_max = 3000.0", "a_max = 1.0e5"), "<bench>")
    prog = curves_program([(p, pts, w, knots)], feed, start=pts[0])
    t0 = time.perf_counter()
    job = plan_job(prog, m)
    plan_first = time.perf_counter() - t0
    n_ticks, stat, tick_compile = tick_rate(job, 30, repeats)
    rate = n_ticks / stat.wall_min
    print(
        f"    plan (incl. span certification and compile) {plan_first:.2f} s; tick generation t -> s -> "
        f"position -> integers: {rate:,.0f} ticks/s (min; median {n_ticks / stat.wall_median:,.0f}) = "
        f"{rate / 1e4:,.0f}x the documents' 10 kHz (compile {tick_compile:.2f} s apart; {stat})"
    )
    out.update(
        {"ticks_per_s": rate, "ticks": stat.as_dict(), "tick_compile_s": tick_compile, "plan_first_s": plan_first}
    )
    return out


def run_geometry_benchmarks(n_eval: int = 1_000_000, repeats: int = REPEATS) -> dict:
    """Run the suite on the corpus butterfly and a random 1000-point NURBS; print and return the figures."""
    bfly = find_butterfly()
    if bfly is None:  # before anything is printed: a missing input is an error, not a smaller run
        raise BenchInputMissing(
            "shared/corpus/nurbs/butterfly_deg3_iges.json not found (the geometry benchmark's input)"
        )
    out = {"info": run_header("geometry")}
    out["butterfly"] = bench_curve("butterfly (corpus)", bfly, n_eval, repeats, feed=2.0)
    out["nurbs1000"] = bench_curve("random cubic NURBS", random_cubic_nurbs(1000), n_eval, repeats)
    return out
