"""The player side without the planning stack: ``jaxcnc.format`` and ``jaxcnc.hw`` need NumPy alone.

A controller installs ``jaxcnc`` without extras (docs/player.md): it reads and plays tables and never
imports JAX, SciPy or matplotlib; the commands that plan say in one line which extra they need. Checked
three ways: the player-side modules' imports in a fresh interpreter, the command line with the planning
stack blocked, and (slow) a real player-only install in a new virtual environment holding only NumPy.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import venv
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PLANNING_STACK = ("jax", "jaxlib", "scipy", "matplotlib", "tqdm")

# Imports every module of jaxcnc.format and jaxcnc.hw (and the play command's operator controls), then
# prints what came along: no planning stack, and of jaxcnc only the errors, the format and the player.
IMPORT_PLAYER_SIDE = textwrap.dedent(
    """
    import importlib, json, pkgutil, sys
    import jaxcnc.format, jaxcnc.hw
    names = ["jaxcnc.cli.control"]
    for pkg in (jaxcnc.format, jaxcnc.hw):
        names += [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
    for name in names:
        importlib.import_module(name)
    allowed = ("jaxcnc.format", "jaxcnc.hw", "jaxcnc.cli", "jaxcnc.plugins")  # plugins: the standard library only
    print(json.dumps({
        "imported": sorted(names),
        "stack": sorted(m for m in sys.modules if m.partition(".")[0] in PLANNING_STACK),
        "jaxcnc": sorted(
            m for m in sys.modules
            if m.startswith("jaxcnc.") and m != "jaxcnc.errors" and not m.startswith(allowed)
        ),
    }))
    """
).replace("PLANNING_STACK", repr(PLANNING_STACK))

# Makes the planning stack unimportable in this interpreter, as in a player-only install: importing it raises
# ModuleNotFoundError and importlib.util.find_spec finds nothing.
BLOCK_STACK = f"import sys; sys.modules.update(dict.fromkeys({PLANNING_STACK!r})); "

# Writes job.ticks with the format module alone (a 5 mm cosine move in x at 1 kHz, a block and laser events)
# and its positions to expected.npy, in the current folder.
WRITE_TABLE = textwrap.dedent(
    """
    import numpy as np
    from jaxcnc.format import EVENT_DTYPE, FINE_SCALE, EventKind, TableWriter
    n = 3000
    t = np.arange(n) / (n - 1)
    exact = np.zeros((n, 3))
    exact[:, 0] = 5000.0 * (1 - np.cos(np.pi * t)) / 2  # discretes of 1 um
    pos = np.round(exact).astype(np.int32)
    fine = np.clip(np.round((exact - pos) * FINE_SCALE), -(2**31), 2**31 - 1).astype(np.int32)
    with TableWriter("job.ticks", axes=["x", "y", "z"], tick_hz=1000.0, discrete_mm=0.001, n_rows=n) as w:
        w.write(pos, fine)
        w.events = np.array(
            [(0, EventKind.BLOCK, 1, 0.0), (10, EventKind.LASER, 3, 50.0), (n - 1, EventKind.LASER, 0, 0.0)],
            EVENT_DTYPE,
        )
    np.save("expected.npy", pos)
    """
)


def _run_json(code: str, **kw) -> dict:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, **kw).stdout
    return json.loads(out)


def test_player_side_imports_no_planning_stack():
    got = _run_json(IMPORT_PLAYER_SIDE, cwd=REPO)
    assert {"jaxcnc.format.tablefile", "jaxcnc.format.events", "jaxcnc.hw.player", "jaxcnc.hw.sinks.stream"} <= set(
        got["imported"]
    )
    assert got["stack"] == [], f"the player side imports the planning stack: {got['stack']}"
    assert got["jaxcnc"] == [], f"the player side imports planning modules: {got['jaxcnc']}"


MACHINE = """\
[machine]
name = "player-only"
tick_hz = 1000
discrete_mm = 0.001

[axes.x]
v_max = 100.0
a_max = 1000.0
min = -500.0
max = 500.0

[axes.y]
v_max = 100.0
a_max = 1000.0
min = -500.0
max = 500.0

[axes.z]
v_max = 50.0
a_max = 500.0
min = -100.0
max = 100.0

[path]
feed = 50.0
rapid = 100.0
chord_tol_mm = 0.001
corner_tol_mm = 0.0
"""


def test_cli_plays_and_names_the_extra_with_the_planning_stack_blocked(tmp_path):
    """``jaxcnc play`` without tqdm or JAX; ``plan``, ``demo``, ``plot`` refuse in one line, exit 2, writing nothing."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([sys.executable, "-c", BLOCK_STACK + WRITE_TABLE], cwd=tmp_path, env=env, check=True)
    (tmp_path / "m.toml").write_text(MACHINE)
    (tmp_path / "part.ngc").write_text("G1 X1 F600\nM2\n")

    def cli(*args: str) -> subprocess.CompletedProcess:
        code = BLOCK_STACK + f"from jaxcnc.cli.main import main; sys.exit(main({list(args)!r}))"
        return subprocess.run(
            [sys.executable, "-c", code],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            stdin=subprocess.DEVNULL,
        )

    r = cli("play", "job.ticks", "--sink", "sim", "--record", "drives.npy", "-m", "m.toml")
    assert r.returncode == 0, r.stderr
    assert "played job.ticks into sim: 3000 ticks executed" in r.stdout
    assert np.array_equal(np.load(tmp_path / "drives.npy"), np.load(tmp_path / "expected.npy"))
    for args, command in (
        (("plan", "part.ngc", "-m", "m.toml", "-o", "part.ticks"), "plan"),
        (("demo", "--out", "demo"), "demo"),
        (("plot", "job.ticks", "-o", "job.png"), "plot"),
    ):
        r = cli(*args)
        assert r.returncode == 2, r.stderr
        assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.startswith(f"jaxcnc: error: 'jaxcnc {command}' needs the planning extra"), r.stderr
        assert "pip install 'jaxcnc[plan]'" in r.stderr
    assert not any((tmp_path / p).exists() for p in ("part.ticks", "demo", "job.png"))


def _player_only_venv(root: Path) -> Path:
    """A new virtual environment holding jaxcnc without extras and NumPy (tomli below 3.11); its bin folder."""
    env_dir = root / "venv"
    try:
        venv.EnvBuilder(with_pip=True, symlinks=os.name != "nt").create(env_dir)
    except Exception as exc:  # no ensurepip / venv module on this machine
        pytest.skip(f"cannot create a virtual environment here: {exc}")
    bindir = env_dir / ("Scripts" if os.name == "nt" else "bin")
    if not (bindir / "python").exists() and not (bindir / "python.exe").exists():
        pytest.skip("cannot create a virtual environment here: no interpreter in it")
    # build from a copy of the sources: pip's in-tree build would leave build/ and *.egg-info in the checkout
    src = root / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    shutil.copytree(REPO / "jaxcnc", src / "jaxcnc", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    wanted = [str(src), f"numpy=={np.__version__}"]
    if sys.version_info < (3, 11):
        wanted.append("tomli>=2.0")
    r = subprocess.run(
        [str(bindir / "python"), "-m", "pip", "install", "--no-deps", "--quiet", *wanted],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, f"pip could not install the player side:\n{r.stdout}\n{r.stderr}"
    return bindir


@pytest.mark.slow
def test_player_only_install_in_a_fresh_venv(tmp_path):
    """The README's promise for a controller: ``pip install jaxcnc`` (no extras) plays tables with NumPy alone."""
    bindir = _player_only_venv(tmp_path)
    py, jaxcnc = str(bindir / "python"), str(bindir / "jaxcnc")
    work = tmp_path / "work"  # not the checkout: the installed package is what is imported
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PYTHONNOUSERSITE"] = "1"

    def run(*cmd: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            cmd, cwd=work, env=env, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=300
        )

    pip_list = run(py, "-m", "pip", "list", "--format=freeze").stdout
    installed = {line.split("==")[0].lower() for line in pip_list.split()}
    assert {"jaxcnc", "numpy"} <= installed and not installed & {"jax", "jaxlib", "scipy", "matplotlib", "tqdm"}

    # the format and the player import with NumPy alone, from the install, and pull in nothing of the planning side
    r = run(py, "-c", IMPORT_PLAYER_SIDE)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert got["stack"] == [] and got["jaxcnc"] == [], got
    code = "import importlib.util as u, jaxcnc; print(jaxcnc.__file__); print([m for m in %r if u.find_spec(m)])"
    r = run(py, "-c", code % (PLANNING_STACK,))
    where, importable = r.stdout.splitlines()
    assert Path(where).resolve().is_relative_to(tmp_path.resolve()) and importable == "[]", r.stdout

    # a table written there with the format module, played through the simulated drives by the command
    r = run(py, "-c", WRITE_TABLE)
    assert r.returncode == 0, r.stderr
    (work / "m.toml").write_text(MACHINE)
    for args in (("--help",), ("play", "--help")):
        r = run(jaxcnc, *args)
        assert r.returncode == 0 and "usage: jaxcnc" in r.stdout, r.stderr
    r = run(jaxcnc, "play", "job.ticks", "--sink", "sim", "--record", "drives.npy", "-m", "m.toml")
    assert r.returncode == 0, r.stderr
    assert "played job.ticks into sim: 3000 ticks executed" in r.stdout
    assert np.array_equal(np.load(work / "drives.npy"), np.load(work / "expected.npy"))
    r = run(jaxcnc, "play", "job.ticks", "--sink", "scanner", "-q")
    assert r.returncode == 0, r.stderr

    # a planning command: one line naming the extra, exit 2, nothing written
    (work / "part.ngc").write_text("G1 X1 F600\nM2\n")
    r = run(jaxcnc, "plan", "part.ngc", "-m", "m.toml", "-o", "part.ticks")
    assert r.returncode == 2, r.stderr
    assert r.stderr == (
        "jaxcnc: error: 'jaxcnc plan' needs the planning extra, which is not installed (no module 'jax'): "
        "pip install 'jaxcnc[plan]'\n"
    )
    assert not (work / "part.ticks").exists()
