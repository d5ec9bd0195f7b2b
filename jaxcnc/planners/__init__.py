"""Velocity planners: machine limits → the time law ``s(t)`` of the whole program.

The protocols (:mod:`jaxcnc.planners.protocol`): a :class:`Planner` answers a :class:`PlanRequest` with a
:class:`TimeLaw` (built-ins: a :class:`Plan`). Importing this package registers the built-in planners
(``topp``, ``lookahead``, ``toppra``, ``casadi``); others come from the ``jaxcnc.planners`` entry-point
group (:mod:`jaxcnc.plugins`).
"""

from jaxcnc.planners import casadi_ref, lookahead_planner, topp, toppra_ref  # noqa: F401  (register the planners)
from jaxcnc.planners.job import PlannedJob, plan_job
from jaxcnc.planners.protocol import NUMERIC_MARGIN, DeviceLaw, Planner, PlanRequest, TimeLaw, with_margin
from jaxcnc.planners.registry import PLANNERS, get_planner, planner_names, register_planner
from jaxcnc.planners.timelaw import Plan, sample_plan
from jaxcnc.program import program_start

__all__ = [
    "NUMERIC_MARGIN",
    "PLANNERS",
    "DeviceLaw",
    "Plan",
    "PlanRequest",
    "PlannedJob",
    "Planner",
    "TimeLaw",
    "get_planner",
    "plan_job",
    "planner_names",
    "program_start",
    "register_planner",
    "sample_plan",
    "with_margin",
]
