"""``benchmarks/tick_rates.py``: a program planned at two tick rates; a missing input is an error, never replaced."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT.parent / "shared" / "peers"


def _script():
    spec = importlib.util.spec_from_file_location("tick_rates", ROOT / "benchmarks" / "tick_rates.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_missing_program_is_an_error(capsys):
    assert _script().main(["--programs", "no-such-program"]) == 2
    assert "no-such-program" in capsys.readouterr().err


@pytest.mark.skipif(not (PEERS / "machines").is_dir(), reason="../shared/peers absent")
def test_a_program_that_cannot_be_planned_is_an_error(capsys):
    """The first line of circle2000 alone has no motion, and ``no-such-planner`` is no planner: one line each, exit
    2."""
    script = _script()
    assert script.main(["--programs", "circle2000", "--planners", "lookahead", "--head", "1"]) == 2
    assert "no motion" in capsys.readouterr().err
    assert script.main(["--programs", "circle2000", "--planners", "no-such-planner", "--j-max", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no-such-planner" in err and len(err.splitlines()) == 1


@pytest.mark.skipif(not (PEERS / "machines").is_dir(), reason="../shared/peers absent")
def test_it_prints_both_rates_and_their_ratio(capsys):
    """circle2000 with ``lookahead`` and no jerk limit (0.710 s at 1 kHz, 0.7094 s at 10 kHz when written)."""
    assert _script().main(["--programs", "circle2000", "--planners", "lookahead", "--j-max", "0"]) == 0
    row = [line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("circle2000")]
    (line,) = row
    t_lo, t_hi = (float(x) for x in line.split()[2:5:2])
    ratio = float(line.split("ratio")[1].split()[0])
    assert 0.5 < t_lo < 1.0 and abs(ratio - t_hi / t_lo) < 1e-4 and abs(ratio - 1) <= 0.01
