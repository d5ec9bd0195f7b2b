"""Velocity planners: machine limits → the time law ``s(t)`` of the whole program.

Importing this package registers the built-in planners (``lookahead``, ``topp``).
"""

from jaxcnc.planners import casadi_ref, topp, toppra_ref, trapezoid  # noqa: F401  (register the planners)
from jaxcnc.planners.job import PlannedJob, plan_job, program_start
from jaxcnc.planners.registry import PlanRequest, get_planner, planner_names, register_planner
from jaxcnc.planners.timelaw import Plan, sample_plan

__all__ = [
    "Plan",
    "PlanRequest",
    "PlannedJob",
    "get_planner",
    "plan_job",
    "planner_names",
    "program_start",
    "register_planner",
    "sample_plan",
]
