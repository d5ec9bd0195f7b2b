"""Ticks: sample a Plan at the machine's tick rate into an integer table; verify tables.

Import the submodules: :mod:`jaxcnc.ticks.table` (writes tables, uses JAX) and
:mod:`jaxcnc.ticks.verify` (checks tables, NumPy only).
"""
