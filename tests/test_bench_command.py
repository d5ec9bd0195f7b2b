"""``jaxcnc bench command`` runs the whole command in fresh processes, cold and warm (figures, not speeds, are
asserted); a program it cannot find is an error, not a substitute."""

from __future__ import annotations

import pytest

from jaxcnc.bench.command import run_command_benchmarks
from jaxcnc.bench.common import BenchInputMissing
from tests.conftest import REPO

PEERS = REPO.parent / "shared" / "peers"


def test_a_missing_program_is_an_error(tmp_path):
    (tmp_path / "README.md").write_text("no table\n")
    with pytest.raises(BenchInputMissing, match="nothere.ngc is neither in"):
        run_command_benchmarks(peers=tmp_path, repeats=1, programs=("nothere",))


@pytest.mark.slow
@pytest.mark.skipif(not (PEERS / "README.md").is_file(), reason="../shared/peers is absent")
def test_the_command_cold_and_warm(capsys):
    res = run_command_benchmarks(repeats=1, programs=("line2000",))
    row = res["programs"]["line2000"]
    out = capsys.readouterr().out
    assert "load average" in out and "line2000" in out
    for run in ("cold", "warm"):
        assert row[run]["repeats"] == 1 and row[run]["wall_min_s"] > 0 and row[run]["cpu_min_s"] > 0
    assert row["warm"]["wall_min_s"] < row["cold"]["wall_min_s"]  # the cache the first run left serves the others
