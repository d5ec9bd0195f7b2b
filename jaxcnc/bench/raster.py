"""``jaxcnc bench raster`` (issue 16): a raster image planned natively beside the same image as per-pixel G-code.

One synthetic greyscale picture (``size`` × ``size`` pixels, 0.1 mm, white margins, a ring of stripes) on a CO₂
engraver (500 mm/s, 5000 mm/s², 10 kHz ticks) scanned serpentine at 200 mm/s. Both sides in one run:

- native: ``plan_file`` on the PNG — one overscan/burn/overscan line per scan line, power per tick from the image;
  then ``check`` (laser on only at the feed, power per tick, energy per pixel) and the table played into ``sim``;
- per-pixel G-code: the same path written as one ``G1 X… Y… S…`` per pixel (:func:`jaxcnc.io.image.gcode_per_pixel`,
  as common raster tools emit it) planned through the G-code path.

Planning is parse + plan (the Program and its time law: what the per-pixel detour costs); the table written
(ticks, the same count on both sides) is reported beside it as parse + plan + ticks. Each side runs once to
compile (JIT) and is then timed ``repeats`` times (the least taken). Figures: ratios of the two, both run times.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

MACHINE = """[machine]
name = "co2-engraver"
tick_hz = 10000
discrete_mm = 0.001
[axes.x]
v_max = 500
a_max = 5000
min = 0
max = 400
[axes.y]
v_max = 500
a_max = 5000
min = 0
max = 400
[path]
feed = 200
rapid = 500
"""


def picture(size: int) -> np.ndarray:
    """A ``size`` × ``size`` greyscale test picture (uint8): a disc whose grey rises outward, striped, white
    margins."""
    y, x = np.mgrid[0:size, 0:size] / size
    r = np.hypot(x - 0.5, y - 0.5)
    g = np.where(r < 0.45, 255 * (r / 0.45) ** 0.7 * (0.5 + 0.5 * np.cos(40 * x)), 255)
    return np.clip(g, 0, 255).astype(np.uint8)


def _timed(fn, repeats: int) -> tuple[float, float, dict]:
    """The least parse + plan time, the least parse + plan + ticks time, and the last report."""
    plan, wall, out = np.inf, np.inf, {}
    for _ in range(repeats):
        out = fn()
        plan = min(plan, out["timings_s"]["parse"] + out["timings_s"]["plan"])
        wall = min(wall, out["plan_wall_s"])
    return plan, wall, out


def run_raster_benchmark(size: int = 1000, repeats: int = 2, pixel_mm: float = 0.1) -> dict:
    """Measure both sides (see the module); print and return the figures."""
    from PIL import Image

    from jaxcnc.format import TableFile
    from jaxcnc.hw.player import play
    from jaxcnc.hw.sinks.sim import SimSink
    from jaxcnc.io.image import RasterOptions, gcode_per_pixel, raster_job
    from jaxcnc.jobs import JobBounds, check_table, plan_file
    from jaxcnc.machine import load_machine

    opts = {"pixel_mm": pixel_mm}
    bounds = JobBounds(max_ticks=10**9, max_bytes=2**40, max_duration_s=10 * 86400)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        mfile = tmp / "co2.toml"
        mfile.write_text(MACHINE)
        m = load_machine(mfile)
        png = tmp / "picture.png"
        Image.fromarray(picture(size)).save(png)
        gcode = tmp / "picture.ngc"
        t0 = time.perf_counter()
        gcode.write_text(gcode_per_pixel(raster_job(png, m, RasterOptions(**opts))))
        gen_s = time.perf_counter() - t0
        n_lines = sum(1 for _ in gcode.open())

        def native():
            return plan_file(png, m, tmp / "native.ticks", progress=False, input_options=opts, bounds=bounds)

        def per_pixel():
            return plan_file(gcode, m, tmp / "gcode.ticks", progress=False, bounds=bounds)

        native_s, native_wall_s, rn = _timed(native, repeats + 1)
        gcode_s, gcode_wall_s, rg = _timed(per_pixel, repeats + 1)
        t0 = time.perf_counter()
        _, meas = check_table(tmp / "native.ticks", mfile)
        check_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        table = TableFile(tmp / "native.ticks")
        sink = SimSink(buffer_rows=65536, keep=False)
        play(table, sink, chunk_rows=65536)
        play_s = time.perf_counter() - t0
    las = meas.laser
    res = {
        "pixels": size * size,
        "scan_lines": rn["n_blocks"] // 4,
        "native_rows": rn["n_blocks"],
        "gcode_lines": n_lines,
        "gcode_write_s": gen_s,
        "native_plan_s": native_s,
        "gcode_plan_s": gcode_s,
        "plan_speedup": gcode_s / native_s,
        "native_plan_ticks_s": native_wall_s,
        "gcode_plan_ticks_s": gcode_wall_s,
        "plan_ticks_speedup": gcode_wall_s / native_wall_s,
        "native_timings_s": rn["timings_s"],
        "gcode_timings_s": rg["timings_s"],
        "native_run_s": rn["total_time_s"],
        "gcode_run_s": rg["total_time_s"],
        "run_ratio": rn["total_time_s"] / rg["total_time_s"],
        "n_ticks": rn["n_ticks"],
        "check_s": check_s,
        "check_violations": [str(v) for v in meas.violations],
        "lit_ticks": las.n_lit,
        "max_lit_speed_deviation": las.max_speed_deviation,
        "max_power_error": las.max_power_error,
        "pixel_energy_max_error_ticks": las.pixels.max_error_ticks if las.pixels else None,
        "pixels_checked": las.pixels.n_pixels if las.pixels else None,
        "play_sim_s": play_s,
    }
    print(f"jaxcnc bench (raster): {size} x {size} pixels at {pixel_mm} mm, 200 mm/s serpentine, 10 kHz ticks")
    print(
        f"  native  : {res['native_rows']} rows ({res['scan_lines']} lines) parsed+planned in {native_s:.3f} s, "
        f"{native_wall_s:.2f} s with its {res['n_ticks']} ticks written (min of {repeats}); runs "
        f"{res['native_run_s']:.1f} s"
    )
    print(
        f"  G-code  : {n_lines} lines (one G1 X Y S per pixel) parsed+planned in {gcode_s:.3f} s, "
        f"{gcode_wall_s:.2f} s with its ticks; runs {res['gcode_run_s']:.1f} s"
    )
    print(
        f"  ratio   : native plans {res['plan_speedup']:.1f}x faster ({res['plan_ticks_speedup']:.1f}x with the "
        f"ticks written); run time native/G-code {res['run_ratio']:.4f}"
    )
    print(
        f"  check   : {check_s:.2f} s, {len(meas.violations)} violations; lit ticks {las.n_lit} within "
        f"{las.max_speed_deviation:.2g} of the feed; power error {las.max_power_error:.2g} of S; "
        f"{res['pixels_checked']} pixels within {res['pixel_energy_max_error_ticks']:.3g} tick of their energy"
    )
    print(f"  play    : into sim in {play_s:.2f} s ({res['n_ticks'] / play_s / 1e6:.2f} M ticks/s)")
    return res
