"""``jaxcnc bench pulsed-windows``: planners against the window optimum and the certified bound, per hard case.

Two tables (issue 21):

1. :func:`bound_rows` — the certified bounds per hard-case cloud: ``LB`` (intervals × shortest period), the
   axis-only travel bound, and the bound at the path limits (its window sum and chain parts), with the time
   each takes.
2. :func:`window_rows` — on a window of consecutive points from each cloud (from a third of the way in):
   ``sync`` and ``bang`` planned on the window alone (from rest to rest), the optimum of the verifying LP's
   motion model (:func:`~jaxcnc.planners.pulsed.optimum.optimum_window`) with free end speeds and at rest,
   the CasADi reference with its descent (:func:`~jaxcnc.planners.pulsed.exact.exact_window`, where CasADi
   is installed) and the certified path bound. ``bang`` is at rest at the window's first and last pulse, so it
   is compared with the optimum at rest; ``sync`` reaches the first point through an auxiliary knot (moving at
   its pulse, the approach not counted), so with the optimum with free ends, as is the bound (which assumes
   nothing at the ends). ``sync``'s cubic splines are not in the LP's motion model, so ``sync/free`` may
   fall below 1.
"""

from __future__ import annotations

import time

import numpy as np

from jaxcnc.bench.pulsed import glass_engraver, hard_case_clouds, program_points
from jaxcnc.io.points import PointJob
from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.bound import lower_bound_travel
from jaxcnc.planners.pulsed.optimum import optimum_window


def _clouds(names: tuple[str, ...] | None) -> dict[str, np.ndarray]:
    out = hard_case_clouds()
    out["program 8"] = program_points(8, 8_600)
    return {k: v for k, v in out.items() if names is None or k in names}


def bound_rows(names: tuple[str, ...] | None = None) -> list[dict]:
    """The certified bounds on each whole cloud (seconds), axis-only and at the path limits; printed."""
    machine = glass_engraver()
    win = pulse_window(machine)
    V, A, _ = machine_limits(machine)
    print("certified bounds per cloud (s): LB, axis-only LBt, path-limited LBt (window sum, chain) and its time")
    head = (
        f"{'cloud':>13} {'points':>7} | {'LB':>8} {'LBt axis':>9} {'windows':>9} {'chain':>9} {'LBt path':>9} "
        f"| {'s':>5}"
    )
    print(head)
    print("-" * len(head))
    rows = []
    for name, pts in _clouds(names).items():
        axis = lower_bound_travel(pts, win, V, A)
        t0 = time.perf_counter()
        path = lower_bound_travel(pts, win, V, A, feed_mm_s=machine.path.feed, rapid_mm_s=machine.path.rapid)
        wall = time.perf_counter() - t0
        f = win.tick_hz
        row = {
            "cloud": name,
            "n_points": len(pts),
            "lower_bound_s": (len(pts) - 1) * win.shortest_period_s,
            "axis_s": axis.seconds,
            "path_windows_s": path.window_sum_ticks / f,
            "path_chain_s": path.chain_ticks / f,
            "path_s": path.seconds,
            "path_wall_s": wall,
        }
        rows.append(row)
        print(
            f"{name:>13} {len(pts):>7} | {row['lower_bound_s']:>8.1f} {row['axis_s']:>9.3f} "
            f"{row['path_windows_s']:>9.3f} {row['path_chain_s']:>9.3f} {row['path_s']:>9.3f} | {wall:>5.2f}"
        )
    return rows


def window_rows(
    n_points: int = 40,
    names: tuple[str, ...] | None = None,
    start_fraction: float = 1.0 / 3.0,
    exact: bool = True,
    max_seconds: float = 120.0,
) -> list[dict]:
    """Planners, the optimum and the bound on a window of ``n_points`` of each cloud (seconds); printed.

    The window starts ``start_fraction`` of the way into the cloud. ``exact``: also the CasADi reference
    (skipped where CasADi is absent). ``max_seconds``: each optimum's search budget (``proven`` says
    whether it finished; else its lower end is given too).
    """
    machine = glass_engraver()
    win = pulse_window(machine)
    V, A, _ = machine_limits(machine)
    V_req, A_req, _ = request_limits(machine)
    caps = {"feed_mm_s": with_margin(machine.path.feed), "rapid_mm_s": with_margin(machine.path.rapid)}
    if exact:
        try:
            import casadi  # noqa: F401
        except ImportError:
            exact = False
    f = win.tick_hz
    print(
        f"windows of {n_points} points (s): sync and bang planned on the window alone (rest to rest); the optimum"
        " of the LP's motion model at rest and with free ends; the certified path bound LBt"
    )
    head = (
        f"{'cloud':>13} {'first':>6} | {'sync':>7} {'bang':>7} {'exact':>7} {'opt rest':>8} {'opt free':>8} "
        f"{'LBt':>7} | {'bang/rest':>9} {'sync/free':>9} {'opt/LBt':>7} | {'nodes':>5} {'opt s':>6}"
    )
    print(head)
    print("-" * len(head))
    rows = []
    for name, cloud in _clouds(names).items():
        first = int(len(cloud) * start_fraction)
        pts = cloud[first : first + n_points]
        job = PointJob(pts, None, np.arange(1, len(pts) + 1), name)
        ticks = {p: np.diff(plan_points(job, machine, p).plan.work_tick) for p in ("sync", "bang")}
        bound = lower_bound_travel(pts, win, V, A, feed_mm_s=machine.path.feed, rapid_mm_s=machine.path.rapid)
        ex_s, starts = None, [ticks["bang"]]
        if exact:
            from jaxcnc.planners.pulsed.exact import exact_window

            try:
                ex = exact_window(pts, win, V_req, A_req, guess_ticks=ticks["bang"], descend=True, **caps)
                ex_s = ex.seconds
                starts.append(ex.ticks)  # a verified motion with free ends: a first incumbent for that optimum
            except Exception as exc:  # noqa: BLE001 - a local solver's failure is a result here, not an error
                print(f"{name}: exact reference failed: {exc}")
        opt = {}
        for ends in ("rest", "free"):
            opt[ends] = optimum_window(
                pts,
                win,
                V_req,
                A_req,
                bound.gap_ticks,
                start_ticks=np.array(starts),
                max_seconds=max_seconds,
                rest_ends=ends == "rest",
                **caps,
            )
        rest, free = opt["rest"], opt["free"]
        row = {
            "cloud": name,
            "first": first,
            "n_points": len(pts),
            "sync_s": ticks["sync"].sum() / f,
            "bang_s": ticks["bang"].sum() / f,
            "exact_s": ex_s,
            "optimum_rest_s": rest.seconds,
            "optimum_rest_proven": rest.proven,
            "optimum_rest_lower_s": rest.lower_ticks / f,
            "optimum_free_s": free.seconds,
            "optimum_free_proven": free.proven,
            "optimum_free_lower_s": free.lower_ticks / f,
            "bound_s": bound.seconds,
            "nodes": rest.nodes + free.nodes,
            "optimum_wall_s": rest.seconds_wall + free.seconds_wall,
        }
        rows.append(row)

        def fmt(o) -> str:
            return f"{o.seconds:.3f}" + ("" if o.proven else f" (>= {o.lower_ticks / f:.3f})")

        print(
            f"{name:>13} {first:>6} | {row['sync_s']:>7.3f} {row['bang_s']:>7.3f} "
            f"{(f'{ex_s:.3f}' if ex_s is not None else '-'):>7} {fmt(rest):>8} {fmt(free):>8} {bound.seconds:>7.3f} | "
            f"{row['bang_s'] / rest.seconds:>9.4f} {row['sync_s'] / free.seconds:>9.4f} "
            f"{free.seconds / bound.seconds:>7.4f} | {row['nodes']:>5} {row['optimum_wall_s']:>6.1f}"
        )
    return rows


def run_pulsed_windows(
    n_points: int = 40, names: tuple[str, ...] | None = None, exact: bool = True, max_seconds: float = 120.0
) -> dict:
    """Both tables (``jaxcnc bench pulsed-windows``): bounds per cloud, then the window comparison."""
    return {
        "bounds": bound_rows(names),
        "windows": window_rows(n_points, names, exact=exact, max_seconds=max_seconds),
    }
