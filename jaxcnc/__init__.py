"""jaxcnc: ahead-of-time motion planning for laser machines.

G-code (and later DXF, STL, point clouds) becomes a Program, then rational Bézier spans, a
whole-program time law and finally a tick table of integer axis positions that a thin player
streams to drives. Planning runs as batched JAX float64 array programs on CPU or GPU.

This package's top level imports no JAX, so the player side (:mod:`jaxcnc.hw`) stays light.
"""

__version__ = "0.1.0"
