"""A planner plug-in: the default planner with every axis limit and feed scaled down (e.g. for a first test run).

Installed as a distribution that declares the entry point::

    [project.entry-points."jaxcnc.planners"]
    gentle = "slow_planner:GentlePlanner"

it is used by name — ``jaxcnc plan part.ngc -m machine.toml -o part.ticks --planner gentle``, ``[machine]
planner = "gentle"`` or ``plan_job(program, machine, "gentle")``. Without installing anything::

    python examples/slow_planner.py PROGRAM.ngc MACHINE.toml

The tick table is verified against the machine's real limits, as for any planner. The request's limits are
already below the machine's by the numeric margin (``jaxcnc.planners.protocol``): a plug-in plans *at* them.
"""

from __future__ import annotations

import dataclasses
import sys

from jaxcnc.planners import Planner, PlanRequest, TimeLaw, get_planner

SCALE = 0.5


class GentlePlanner(Planner):
    """``topp`` with half the speed and acceleration of every axis, and half the programmed feeds."""

    name = "gentle"
    handles_jerk = False  # under j_max the S-curve stage averages the Plan it returns
    honours_holds = True  # topp honours the S-curve stage's speed holds, and so does this

    def plan(self, request: PlanRequest) -> TimeLaw:
        slower = dataclasses.replace(
            request,
            v_max=request.v_max * SCALE,
            a_max=request.a_max * SCALE,
            feed_mm_s=request.feed_mm_s * SCALE,
        )
        return get_planner("topp").plan(slower)


if __name__ == "__main__":
    from jaxcnc.jobs import load_program
    from jaxcnc.machine import load_machine
    from jaxcnc.planners import plan_job

    machine = load_machine(sys.argv[2])
    program = load_program(sys.argv[1], machine)
    for planner in ("topp", GentlePlanner()):
        job = plan_job(program, machine, planner)
        print(f"{job.planner:8s} {job.plan.total_time_s:.3f} s")
