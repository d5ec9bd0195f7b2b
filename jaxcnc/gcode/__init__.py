"""ISO-7bit / RS274NGC G-code front end: text into a :class:`~jaxcnc.program.Program`."""

from jaxcnc.gcode.interpreter import ARC_RADIUS_TOL_MM, load_gcode, parse_gcode

__all__ = ["ARC_RADIUS_TOL_MM", "load_gcode", "parse_gcode"]
