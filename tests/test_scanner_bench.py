"""``jaxcnc bench scanner`` runs end to end on a tiny job (figures, not speeds, are asserted)."""

from __future__ import annotations

import pytest

from jaxcnc.bench.scanner import marking_program, run_scanner_benchmarks


@pytest.mark.slow
def test_bench_scanner_small(capsys):
    res = run_scanner_benchmarks(n_glyphs=1, repeats=1)
    out = capsys.readouterr().out
    assert "load average" in out and "x real time" in out
    for name in ("compile exact", "compile board", "scanner sink", "execute exact", "execute board", "head model"):
        assert res[name]["repeats"] == 5 and res[name]["wall_median_s"] > 0  # at least five repeats
    assert res["compile exact"]["vectors"] < res["ticks"]
    assert res["head model"]["first_call_s"] >= 0 and res["auto_settings"]["first_call_s"] > 0
    assert marking_program(4).count("G2 ") == 4
