"""Pictures of jobs (matplotlib): what people would rather look at than read.

- :func:`plot_table` (:mod:`jaxcnc.plot.table`): a table's path coloured by speed, and its speed,
  acceleration and jerk per axis over time against the machine's limits (``jaxcnc plot``).
- :func:`plot_power` (:mod:`jaxcnc.plot.power`): the path coloured by laser power, and power over time beside
  the path speed (``jaxcnc plot --power``).

Plotting is the top of the stack beside the command line: it reads tables (:mod:`jaxcnc.format`) and
machine files, and nothing below imports it. Matplotlib comes with the ``plan`` extra.
"""

from jaxcnc.plot.power import plot_power
from jaxcnc.plot.table import lit_mask, plot_table

__all__ = ["lit_mask", "plot_power", "plot_table"]
