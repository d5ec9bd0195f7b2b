"""The geometry benchmark behind ``jaxcnc bench geometry``: NURBS evaluation and tick generation."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.bench.plan import _best, tick_rate
from jaxcnc.bench.programs import BENCH_MACHINE, find_butterfly, random_cubic_nurbs
from jaxcnc.machine import parse_machine
from jaxcnc.planners import plan_job


def bench_curve(name: str, curve: tuple, n_eval: int = 1_000_000, repeats: int = 3, feed: float = 10.0) -> dict:
    """Evaluation points/s (jaxcnc vs scipy vs geomdl) and tick generation ticks/s on one curve."""
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

    t = jnp.asarray(np.random.default_rng(2).uniform(knots[0], knots[-1], n_eval))
    t0 = time.perf_counter()
    ref = np.asarray(eval_params(t))
    compile_s = time.perf_counter() - t0
    t_jax = _best(lambda: eval_params(t).block_until_ready(), repeats)
    spl = BSpline(knots, np.c_[pts * w[:, None], w], p)
    t_np = np.asarray(t)

    def scipy_eval():
        h = spl(t_np)
        return h[:, :3] / h[:, 3:]

    t_scipy = _best(scipy_eval, repeats)
    err = float(np.max(np.abs(scipy_eval() - ref)))
    print(f"  {name}: {len(pts)} control points, degree {p}, {len(iv)} Bezier spans")
    print(
        f"    evaluation of {n_eval:,} points (compile {compile_s:.2f} s apart): jaxcnc {n_eval / t_jax:,.0f} pts/s; "
        f"scipy BSpline {n_eval / t_scipy:,.0f} pts/s (jaxcnc {t_scipy / t_jax:.2f}x); max |diff| {err:.1e} mm"
    )
    out = {"eval_jax_pts_s": n_eval / t_jax, "eval_scipy_pts_s": n_eval / t_scipy, "eval_compile_s": compile_s}
    try:
        from geomdl import NURBS

        crv = NURBS.Curve()
        crv.degree = p
        crv.ctrlptsw = (np.c_[pts * w[:, None], w]).tolist()
        crv.knotvector = knots.tolist()
        n_g = 20_000
        tg = ((np.asarray(t[:n_g]) - knots[0]) / (knots[-1] - knots[0])).tolist()
        t_geomdl = _best(lambda: crv.evaluate_list(tg), 1)
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
    rate, tick_compile = tick_rate(job, 30, repeats)
    print(
        f"    plan (incl. span certification and compile) {plan_first:.2f} s; tick generation t -> s -> u(s) -> "
        f"position -> integers: {rate:,.0f} ticks/s = {rate / 1e4:,.0f}x the documents' 10 kHz "
        f"(compile {tick_compile:.2f} s apart)"
    )
    out.update({"ticks_per_s": rate, "tick_compile_s": tick_compile, "plan_first_s": plan_first})
    return out


def run_geometry_benchmarks(n_eval: int = 1_000_000, repeats: int = 3) -> dict:
    print(f"jaxcnc bench (geometry): NURBS evaluation and tick generation, JAX on {jax.devices()[0]}")
    out = {}
    bfly = find_butterfly()
    if bfly is not None:
        out["butterfly"] = bench_curve("butterfly (corpus)", bfly, n_eval, repeats, feed=2.0)
    else:
        print("  butterfly: shared/corpus not found, skipped")
    out["nurbs1000"] = bench_curve("random cubic NURBS", random_cubic_nurbs(1000), n_eval, repeats)
    return out
