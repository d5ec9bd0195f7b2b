"""The CasADi reference on 200-point windows of every hard-case cloud beside `bang` and the certified bound (issue 21).

    python benchmarks/pulsed_exact_windows.py [N]

For each cloud of `jaxcnc.bench.pulsed_windows._clouds()`: N points (default 200) from a third of the way in,
`bang` planned on them alone (from rest), `exact_window` (CasADi/IPOPT, then verified by a linear program: a
motion that exists; free ends, each axis within min(v_max, feed)) started from bang's ticks, and the window's
certified path-limited bound. Needs `pip install 'jaxcnc[ref]'` (CasADi).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from jaxcnc.bench.pulsed import glass_engraver
from jaxcnc.bench.pulsed_windows import _clouds
from jaxcnc.io.points import PointJob
from jaxcnc.planners.protocol import machine_limits, request_limits, with_margin
from jaxcnc.planners.pulsed import plan_points, pulse_window
from jaxcnc.planners.pulsed.bound import lower_bound_travel
from jaxcnc.planners.pulsed.exact import exact_window


def main(n: int = 200) -> None:
    """Print one line per cloud: bang, the reference, their ratio, the window's bound."""
    machine = glass_engraver()
    win = pulse_window(machine)
    v_max, a_max, _ = machine_limits(machine)
    v_req, a_req, _ = request_limits(machine)
    v_ref = np.minimum(v_req, with_margin(machine.path.feed))
    f = win.tick_hz
    for name, cloud in _clouds(None).items():
        s = len(cloud) // 3
        pts = cloud[s : s + n]
        t0 = time.perf_counter()
        planned = plan_points(PointJob(pts, None, np.arange(1, n + 1), name), machine, "bang")
        bt = np.diff(planned.plan.work_tick)
        ex = exact_window(pts, win, v_ref, a_req, guess_ticks=bt)
        lb = lower_bound_travel(pts, win, v_max, a_max, feed_mm_s=machine.path.feed, rapid_mm_s=machine.path.rapid)
        print(
            f"{name:>13} {s}..{s + n - 1}: bang {bt.sum() / f:.3f} exact {ex.ticks.sum() / f:.3f} "
            f"bang/exact {bt.sum() / ex.ticks.sum():.4f} LBt {lb.seconds:.3f} bang/LBt {bt.sum() / lb.ticks:.4f} "
            f"({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
