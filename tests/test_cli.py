"""The command line: plan → check on real programs, failing checks, play, plot, demo, errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from jaxcnc.cli.main import main
from jaxcnc.format import TableFile
from tests.conftest import EXAMPLE_MACHINE, corpus_file, machine_text

REPORT_KEYS = {
    "total_time_s",
    "n_blocks",
    "n_ticks",
    "tick_hz",
    "path_length_mm",
    "plan_wall_s",
    "max_abs_v",
    "max_abs_a",
    "max_abs_j",
}


@pytest.fixture(scope="module")
def planned_corpus(tmp_path_factory):
    out = {}
    folder = tmp_path_factory.mktemp("corpus")
    for name in ("51MeanderAve", "plasmatest"):
        src = corpus_file(name)
        table, report = folder / f"{name}.ticks", folder / f"{name}.json"
        rc = main(
            ["plan", str(src), "--machine", str(EXAMPLE_MACHINE), "-o", str(table), "--report", str(report), "--quiet"]
        )
        out[name] = (rc, table, json.loads(report.read_text()))
    return out


@pytest.mark.parametrize("name", ["51MeanderAve", "plasmatest"])
def test_plan_then_check_corpus(planned_corpus, name, capsys):
    rc, table, report = planned_corpus[name]
    assert rc == 0
    assert REPORT_KEYS <= set(report)
    assert report["n_ticks"] == TableFile(table).n_rows
    assert report["total_time_s"] == pytest.approx((report["n_ticks"] - 1) / report["tick_hz"])
    for axis, lim in report["limits"].items():
        assert report["max_abs_v"][axis] <= lim["v_max"] * (1 + 1e-9)
        assert report["max_abs_a"][axis] <= lim["a_max"] * (1 + 1e-9)
    # the planner uses the machine: the cut reaches speeds and accelerations near the limits
    assert max(report["max_abs_v"].values()) > 0.9 * 250
    assert max(report["max_abs_a"].values()) > 0.9 * 3000
    assert main(["check", str(table), "--machine", str(EXAMPLE_MACHINE)]) == 0
    assert capsys.readouterr().out.startswith("OK ")


def test_check_fails_against_tighter_machine(planned_corpus, tmp_path, capsys):
    _, table, report = planned_corpus["plasmatest"]
    tight = tmp_path / "tight.toml"
    tight.write_text(
        EXAMPLE_MACHINE.read_text()
        .replace("a_max = 3000.0", "a_max = 2000.0")
        .replace("v_max = 250.0\na_max = 4000.0", "v_max = 200.0\na_max = 4000.0")
    )
    capsys.readouterr()
    assert main(["check", str(table), "--machine", str(tight), "--max-lines", "0"]) == 1
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln]
    assert len(lines) > 10
    pat = r"^tick \d+( \(to \d+\))? axis [xyz]: \|[va]\| = [\d.e+-]+ mm/s(\^2)? > limit [\d.e+-]+$"
    import re

    assert all(re.match(pat, ln) for ln in lines), lines[:5]
    assert any(" axis x: |a| " in ln and "limit 2000" in ln for ln in lines)
    assert any(" axis y: |v| " in ln and "limit 200" in ln for ln in lines)


def test_check_refuses_flipped_byte(planned_corpus, tmp_path, capsys):
    _, table, _ = planned_corpus["51MeanderAve"]
    data = bytearray(table.read_bytes())
    h = TableFile(table).header
    for k, spot in enumerate((h.data_offset + 123_457, h.fine_offset + 99, 20)):
        bad = bytearray(data)
        bad[spot] ^= 0x01
        p = tmp_path / f"flip{k}.ticks"
        p.write_bytes(bytes(bad))
        assert main(["check", str(p), "--machine", str(EXAMPLE_MACHINE)]) == 2
        assert str(p) in capsys.readouterr().err


def test_play_sim_records_the_table(planned_corpus, tmp_path):
    _, table, _ = planned_corpus["plasmatest"]
    rec = tmp_path / "drives.npy"
    assert main(["play", str(table), "--sink", "sim", "--record", str(rec), "--quiet"]) == 0
    np.testing.assert_array_equal(np.load(rec), TableFile(table).positions)


def test_play_refuses_damaged_table_before_moving(planned_corpus, tmp_path):
    _, table, _ = planned_corpus["plasmatest"]
    bad = bytearray(table.read_bytes())
    bad[-30] ^= 0xFF  # an event record
    p = tmp_path / "bad.ticks"
    p.write_bytes(bytes(bad))
    rec = tmp_path / "drives.npy"
    assert main(["play", str(p), "--sink", "sim", "--record", str(rec), "--quiet"]) == 2
    assert not rec.exists()


def test_plot_writes_png(planned_corpus, tmp_path):
    _, table, _ = planned_corpus["51MeanderAve"]
    out = tmp_path / "fig.png"
    assert main(["plot", str(table), "-o", str(out), "--machine", str(EXAMPLE_MACHINE)]) == 0
    blob = out.read_bytes()
    assert blob[:8] == b"\x89PNG\r\n\x1a\n" and len(blob) > 50_000


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "jaxcnc", *args], capture_output=True, text=True, cwd=cwd)


def test_demo_runs_in_a_fresh_folder(tmp_path):
    r = _run("demo", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "check: OK" in r.stdout
    folder = tmp_path / "jaxcnc-demo"
    for name in ("demo-bracket.ngc", "demo-machine.toml", "demo-bracket.ticks", "demo-bracket.png", "demo-report.json"):
        assert (folder / name).stat().st_size > 0


@pytest.mark.parametrize("cmd", ["plan", "check", "play", "plot", "demo", "bench"])
def test_help(cmd, capsys):
    with pytest.raises(SystemExit) as info:
        main([cmd, "--help"])
    assert info.value.code == 0
    assert "usage: jaxcnc " + cmd in capsys.readouterr().out


@pytest.mark.parametrize(
    ("program", "needle"),
    [
        ("G1 X10 F600\nG1 X1.2.3\n", "prog.ngc:2:4: malformed number"),
        ("G1 X10 F600\nG1 X2000\n", "prog.ngc:2: X reaches 2000 mm, outside the travel"),
        # past the edge by less than the 6 digits show: by how much (a red-team pass: "reaches 1000 mm" read oddly)
        ("G1 X10 F600\nG1 X500.000002\n", "prog.ngc:2: X reaches 500.000002 mm (0.002 µm beyond), outside"),
        ("G1 X10 F600\nG1 Z5\n", "prog.ngc:2: the program moves axis Z"),
    ],
)
def test_bad_program_exits_2_with_location_and_no_table(tmp_path, program, needle):
    prog = tmp_path / "prog.ngc"
    prog.write_text(program)
    m = tmp_path / "m.toml"
    m.write_text(machine_text().split("[axes.z]")[0] + "[path]" + machine_text().split("[path]")[1])
    out = tmp_path / "o.ticks"
    r = _run("plan", str(prog), "-m", str(m), "-o", str(out))
    assert r.returncode == 2
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


def test_unsupported_input_type(tmp_path, capsys):
    f = tmp_path / "part.svg"
    f.write_text("<svg/>")
    assert main(["plan", str(f), "-m", str(EXAMPLE_MACHINE), "-o", str(tmp_path / "o.ticks")]) == 2
    err = capsys.readouterr().err
    assert "part.svg: unknown input type '.svg'; jaxcnc reads " in err and ".ngc" in err and ".xyz" in err


def test_unknown_planner(tmp_path, capsys):
    prog = tmp_path / "p.ngc"
    prog.write_text("G1 X1 F60\n")
    assert main(["plan", str(prog), "-m", str(EXAMPLE_MACHINE), "-o", str(tmp_path / "o.ticks"), "--planner", "x"]) == 2
    assert "unknown planner 'x'; known: casadi, lookahead, topp, toppra" in capsys.readouterr().err


@pytest.mark.parametrize("failing", [False, True])
def test_a_reader_that_leaves_early_gets_no_traceback_and_the_status_stays(tmp_path, failing):
    """``jaxcnc check t.ticks | head -1``: the reader closes the pipe before the command has written; the command
    still exits with its check's status (0 passed, 1 failed), and says nothing of a broken pipe."""
    machine = tmp_path / "m.toml"
    machine.write_text(machine_text())
    program = tmp_path / "p.ngc"
    program.write_text("G1 X10 Y5 F3000\nG1 X0\n")  # 50 mm/s
    table = tmp_path / "p.ticks"
    assert main(["plan", str(program), "-m", str(machine), "-o", str(table), "--quiet"]) == 0
    against = machine
    if failing:  # the same table against a machine half as fast
        against = tmp_path / "slow.toml"
        against.write_text(machine_text(v=20.0))
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxcnc", "check", str(table), "-m", str(against)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader is gone before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == (1 if failing else 0), err
    assert "Traceback" not in err and "BrokenPipe" not in err
