"""Plug-ins through real entry points: a distribution's metadata on ``sys.path`` declares a planner, a front
end and a sink; ``jaxcnc`` finds them by name from the command line, and reports broken ones in one line."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from jaxcnc.errors import JaxcncError
from jaxcnc.plugins import PluginError, Registry
from tests.conftest import machine_text

ROOT = Path(__file__).resolve().parents[1]

PLUGIN_MODULE = '''
"""Test plug-ins: a front end for '.pts' files (one 'x y' per line, cut at 10 mm/s) and a sink."""
from pathlib import Path

import numpy as np

from jaxcnc.front_ends import FrontEnd
from jaxcnc.hw.sinks.sim import SimSink
from jaxcnc.program import Kind, program_from_columns, program_start


class PtsFrontEnd(FrontEnd):
    name = "pts polyline"
    produces = "program"

    def load(self, path, machine, **options):
        self.refuse_options(path, options)
        xy = np.loadtxt(path, ndmin=2)
        end = np.column_stack([xy, np.zeros(len(xy))])
        start = np.vstack([program_start(machine), end[:-1]])
        n = len(end)
        return program_from_columns(
            str(path), kind=np.full(n, Kind.LINE), start=start, end=end, feed=np.full(n, 10.0),
            line=np.arange(1, n + 1),
        )


def open_counting(spec, **options):
    sink = SimSink(**options)
    Path(spec.split("://", 1)[1]).write_text("opened")
    return sink


def broken(request):
    raise RuntimeError("this plug-in is broken")
'''


def _install(tmp_path: Path, entry_points: str) -> dict:
    """A distribution ``jaxcnc-test-plugins`` on a fresh ``sys.path`` entry: its ``.dist-info`` metadata
    declares ``entry_points`` (what pip writes on install), its modules beside it. The environment for a
    subprocess that sees it."""
    site = tmp_path / "site"
    info = site / "jaxcnc_test_plugins-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: jaxcnc-test-plugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    (site / "test_plugins_mod.py").write_text(PLUGIN_MODULE)
    for example in ("slow_planner.py", "involute_block.py"):
        (site / example).write_text((ROOT / "examples" / example).read_text())
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(ROOT), env.get("PYTHONPATH", "")])
    return env


ENTRY_POINTS = """
    [jaxcnc.planners]
    gentle = slow_planner:GentlePlanner
    broken = test_plugins_mod:broken
    unloadable = test_plugins_no_such_module:Planner

    [jaxcnc.front_ends]
    pts = test_plugins_mod:PtsFrontEnd

    [jaxcnc.sinks]
    counting = test_plugins_mod:open_counting

    [jaxcnc.block_kinds]
    G2.2 = involute_block:Involute
    G3.2 = involute_block:Involute
"""


def _jaxcnc(env: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "jaxcnc", *args], env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plugins")
    env = _install(tmp, ENTRY_POINTS)
    (tmp / "m.toml").write_text(machine_text())
    (tmp / "p.ngc").write_text("G21 G90\nG1 X20 Y5 F3000\nG1 X40 Y0\nM2\n")
    return tmp, env


def test_the_example_planner_runs_by_name_from_the_command_line(installed):
    """``--planner gentle`` loads the example plug-in through its entry point; its table checks, and it is
    slower than topp by the factor it scales the limits and feeds with."""
    tmp, env = installed
    times = {}
    for planner in ("topp", "gentle"):
        out, rep = tmp / f"{planner}.ticks", tmp / f"{planner}.json"
        r = _jaxcnc(env, "plan", str(tmp / "p.ngc"), "-m", str(tmp / "m.toml"), "-o", str(out), "-r", str(rep), "-q",
                    "--planner", planner)  # fmt: skip
        assert r.returncode == 0, r.stderr
        report = json.loads(rep.read_text())
        assert report["planner"] == planner and report["violations"] == []
        times[planner] = report["total_time_s"]
        assert _jaxcnc(env, "check", str(out), "-m", str(tmp / "m.toml")).returncode == 0
    assert 1.5 < times["gentle"] / times["topp"] < 2.5  # half the speed, half the acceleration


def test_the_machine_file_names_the_planner(installed):
    tmp, env = installed
    text = machine_text().replace("[machine]\n", '[machine]\nplanner = "gentle"\n', 1)
    (tmp / "gentle.toml").write_text(text)
    rep = tmp / "mf.json"
    r = _jaxcnc(env, "plan", str(tmp / "p.ngc"), "-m", str(tmp / "gentle.toml"), "-o", str(tmp / "mf.ticks"),
                "-r", str(rep), "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(rep.read_text())["planner"] == "gentle"


def test_a_front_end_plug_in_reads_its_suffix_and_a_sink_plug_in_plays(installed):
    tmp, env = installed
    (tmp / "part.pts").write_text("10 0\n10 10\n0 10\n")
    out = tmp / "pts.ticks"
    r = _jaxcnc(env, "plan", str(tmp / "part.pts"), "-m", str(tmp / "m.toml"), "-o", str(out), "-q")
    assert r.returncode == 0, r.stderr
    marker = tmp / "opened.txt"
    r = _jaxcnc(env, "play", str(out), "--sink", f"counting://{marker}", "-q")
    assert r.returncode == 0, r.stderr
    assert marker.read_text() == "opened"


def test_a_broken_or_unknown_plug_in_is_one_line(installed):
    tmp, env = installed
    r = _jaxcnc(env, "plan", str(tmp / "p.ngc"), "-m", str(tmp / "m.toml"), "-o", str(tmp / "b.ticks"), "-q",
                "--planner", "broken")  # fmt: skip
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert "planner plug-in 'broken'" in r.stderr and "jaxcnc-test-plugins" in r.stderr
    assert "failed: RuntimeError: this plug-in is broken" in r.stderr
    r = _jaxcnc(env, "plan", str(tmp / "p.ngc"), "-m", str(tmp / "m.toml"), "-o", str(tmp / "b.ticks"), "-q",
                "--planner", "unloadable")  # fmt: skip
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert "planner plug-in 'unloadable'" in r.stderr and "failed to load: ModuleNotFoundError" in r.stderr
    table = tmp / "s.ticks"
    assert _jaxcnc(env, "plan", str(tmp / "p.ngc"), "-m", str(tmp / "m.toml"), "-o", str(table), "-q").returncode == 0
    r = _jaxcnc(env, "play", str(table), "--sink", "nosuch://x", "-q")
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert "unknown sink 'nosuch://x'; available: " in r.stderr and "counting" in r.stderr


def test_registry_lookups():
    """Unit: built-ins win over entry points; lazy built-ins import on first use; unknown names list the known."""
    reg: Registry = Registry("widget", "jaxcnc.test_widgets")
    reg.register("a", 1)
    reg.register_lazy("json", "json:dumps")
    assert reg.names() == ["a", "json"] and "json" in reg
    assert reg.get("json") is json.dumps
    with pytest.raises(PluginError, match="unknown widget 'z'; known: a, json"):
        reg.get("z")
    assert issubclass(PluginError, JaxcncError)


# ------------------------------------------------------------------------------------- block kinds

R_BASE, T_IN, T_OUT = 10.0, 0.3, 1.2  # a gear flank: base circle radius, involute parameters of its ends


def _on_involute(t: float) -> tuple[float, float]:
    """The counter-clockwise unwinding involute of the base circle about the origin, phase 0, at ``t``."""
    return (R_BASE * (math.cos(t) + t * math.sin(t)), R_BASE * (math.sin(t) - t * math.cos(t)))


def _flank_program() -> str:
    (sx, sy), (ex, ey) = _on_involute(T_IN), _on_involute(T_OUT)
    return (
        "G21 G90 G17\n"
        f"G0 X{sx:.9f} Y{sy:.9f}\n"
        "M3 S1\n"
        f"G3.2 X{ex:.9f} Y{ey:.9f} I{-sx:.9f} J{-sy:.9f} R{R_BASE} F600\n"  # out, turning counter-clockwise
        f"G2.2 X{sx:.9f} Y{sy:.9f} I{-ex:.9f} J{-ey:.9f} R{R_BASE}\n"  # back in: clockwise
        "M5\nM2\n"
    )


def test_a_block_kind_plug_in_plans_fanuc_involutes_on_the_involute(installed):
    """G3.2/G2.2 from the example plug-in (entry points) in a Fanuc program: planned, checked, and every tick of
    the flank lies on the analytic involute (angle of the radius against the involute's, independent of the
    plug-in's lowering) within the tolerance."""
    import numpy as np

    from jaxcnc.format import EventKind, TableFile

    tmp, env = installed
    prog = tmp / "flank.nc"
    prog.write_text(_flank_program())
    out = tmp / "flank.ticks"
    r = _jaxcnc(env, "plan", str(prog), "-m", str(tmp / "m.toml"), "-o", str(out), "-q", "--dialect", "fanuc")
    assert r.returncode == 0, r.stderr
    r = _jaxcnc(env, "check", str(out), "-m", str(tmp / "m.toml"))
    assert r.returncode == 0 and "path: max deviation" in r.stdout, r.stdout + r.stderr
    table = TableFile(out)
    xy = table.positions_mm()[:, :2]
    blocks = table.events[table.events["kind"] == EventKind.BLOCK]
    first = int(blocks["tick"][blocks["aux"] == 4][0])  # source line 4: the G3.2; then the G2.2 back, then rest
    p = xy[first:]
    rad = np.linalg.norm(p, axis=1)
    t = np.sqrt(np.maximum(rad**2 / R_BASE**2 - 1, 0))
    # the involute at radius r lies at angle t - atan(t) (phase 0): the distance off it is r * |angle error|
    err = np.angle(np.exp(1j * (np.arctan2(p[:, 1], p[:, 0]) - (t - np.arctan(t)))))
    assert np.all(rad >= R_BASE * math.sqrt(1 + T_IN**2) - 2e-3) and np.all(
        rad <= R_BASE * math.sqrt(1 + T_OUT**2) + 2e-3
    )
    assert np.max(np.abs(rad * err)) <= 1e-3 + 1e-5  # one discrete (1 µm) of quantisation + the lowering
    # the same words in the LinuxCNC dialect are refused, naming the kind's dialect
    r = _jaxcnc(env, "plan", str(prog), "-m", str(tmp / "m.toml"), "-o", str(tmp / "x.ticks"), "-q")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "G3.2 (involute interpolation) is not part of the linuxcnc dialect (it is of: fanuc)" in r.stderr


def test_block_kind_errors_are_located(monkeypatch, tmp_path):
    """In-process: the interpreter reports a kind's refusal at the block's word; an end off the involute is
    refused with the distance; without the kind registered the word is unknown."""
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        from involute_block import Involute
    finally:
        sys.path.remove(str(ROOT / "examples"))
    from jaxcnc.blocks import BLOCK_KINDS
    from jaxcnc.errors import SourceError
    from jaxcnc.gcode.dialect import load_dialect
    from jaxcnc.gcode.interpreter import parse_gcode

    fanuc = load_dialect("fanuc")
    text = _flank_program()
    with pytest.raises(SourceError, match="unknown or unsupported word G3.2"):
        parse_gcode(text, file="f.nc", dialect=fanuc)
    monkeypatch.setitem(BLOCK_KINDS._items, "G3.2", Involute())
    monkeypatch.setitem(BLOCK_KINDS._items, "G2.2", Involute())
    prog = parse_gcode(text, file="f.nc", dialect=fanuc)
    assert prog.curves is not None and len(prog.curves) == 2
    bad = text.replace(f"R{R_BASE} F600", f"R{R_BASE * 1.01} F600")
    with pytest.raises(SourceError, match=r"f.nc:4:1: G3.2: the end point is .* mm off the involute"):
        parse_gcode(bad, file="f.nc", dialect=fanuc)
    with pytest.raises(SourceError, match=r"f.nc:4:1: G3.2: needs I, J .* and R"):
        parse_gcode(text.replace(f" R{R_BASE} F600", " F600"), file="f.nc", dialect=fanuc)


def test_a_block_kind_lowered_to_an_arc_keeps_its_plane(monkeypatch):
    """A kind's Arc pieces become ARC rows in the plane the piece names (here G18, ZX), whatever plane the
    program is in; a line piece after it continues from the arc's end."""
    import numpy as np

    from jaxcnc.blocks import BLOCK_KINDS, Arc, BlockKind, Line
    from jaxcnc.gcode.interpreter import parse_gcode
    from jaxcnc.program import Kind

    class QuarterZX(BlockKind):
        name = "quarter circle in ZX, then a line"

        def lower(self, block):
            s = block.start_mm
            mid = s + np.array([5.0, 0.0, 5.0])
            return [Arc(mid, s + np.array([0.0, 0.0, 5.0]), -1, 18), Line(block.end_mm)]

    monkeypatch.setitem(BLOCK_KINDS._items, "G7.1", QuarterZX())
    prog = parse_gcode("G17 G1 X0 Y0 Z0 F600\nG7.1 X10 Y0 Z5\nG1 X11\n", file="q.ngc")
    assert prog.kind.tolist() == [Kind.LINE, Kind.ARC, Kind.LINE, Kind.LINE]
    assert prog.plane.tolist() == [17, 18, 17, 17]
    assert np.allclose(prog.end[1], [5, 0, 5]) and np.allclose(prog.start[2], prog.end[1])
    assert np.allclose(prog.end[2], [10, 0, 5]) and prog.line.tolist() == [1, 2, 2, 3]
