"""Galvo scanners as boards drive them: plans compiled into vector lists, the scan-head model, the board emulator.

- :mod:`jaxcnc.scanner.compile` — tables into lists (``exact``: tick for tick; ``board``: polylines at mark speed
  with delays and sky-writing chosen from the head model by :func:`~jaxcnc.scanner.compile.auto_settings`);
- :mod:`jaxcnc.scanner.head` — the second-order tracking model of the mirrors;
- :mod:`jaxcnc.scanner.emulator` — lists executed at the board tick with two list buffers (underrun: laser off);
- :mod:`jaxcnc.scanner.metrics` — deviation while lit and dose along the path.

The list format itself is :mod:`jaxcnc.format.vectors` (NumPy only); ``docs/scanner.md`` describes it all.
"""
