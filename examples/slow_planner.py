"""A planner plug-in: the default planner with every axis limit scaled down (e.g. for a first test run).

    python examples/slow_planner.py PROGRAM.ngc MACHINE.toml

Registering under a name makes it available to ``plan_job(..., planner="gentle")``; the tick table is
verified against the machine's real limits as for any planner.
"""

from __future__ import annotations

import dataclasses
import sys

from jaxcnc.gcode import load_gcode
from jaxcnc.machine import load_machine
from jaxcnc.planners import Plan, PlanRequest, get_planner, plan_job, program_start, register_planner

SCALE = 0.5


@register_planner("gentle")
def plan_gentle(req: PlanRequest) -> Plan:
    """``topp`` with half the speed and acceleration of every axis."""
    slower = dataclasses.replace(req, v_max=req.v_max * SCALE, a_max=req.a_max * SCALE, feed_mm_s=req.feed_mm_s * SCALE)
    return get_planner("topp")(slower)


if __name__ == "__main__":
    machine = load_machine(sys.argv[2])
    start = program_start(machine)
    program = load_gcode(sys.argv[1], start=start, home=start)
    for name in ("topp", "gentle"):
        print(f"{name:8s} {plan_job(program, machine, name).plan.total_time_s:.3f} s")
