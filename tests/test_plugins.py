"""Plug-ins through real entry points: a distribution's metadata on ``sys.path`` declares a planner, a front
end and a sink; ``jaxcnc`` finds them by name from the command line, and reports broken ones in one line."""

from __future__ import annotations

import json
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
    (site / "slow_planner.py").write_text((ROOT / "examples" / "slow_planner.py").read_text())
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
