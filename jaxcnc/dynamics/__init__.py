"""Vibration (issue 20): simulated axes driven by a table, input shaping and speed-band avoidance as a
planner stage. See ``docs/vibration.md``."""

from jaxcnc.dynamics.axis import Mode, ModeFilter, discretise
from jaxcnc.dynamics.simulate import Simulation, machine_modes, simulate_table

__all__ = ["Mode", "ModeFilter", "Simulation", "discretise", "machine_modes", "simulate_table"]
