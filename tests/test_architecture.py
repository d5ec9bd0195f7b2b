"""The architecture as checks: the layer contracts (import-linter, configured in pyproject.toml), no stage
outside ``planners`` asking which planner made a time law, and JAX configured by a call, not by importing."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "jaxcnc"


def test_the_layer_contracts_hold():
    """``lint-imports`` (import-linter): the layers of docs/architecture.md and the NumPy-only player side."""
    exe = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    if not Path(exe).exists():
        pytest.fail("import-linter is not installed: pip install '.[test]'")
    r = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "2 kept, 0 broken" in r.stdout, r.stdout[-2000:]


# Types that only the planners know; the tick stage and the rest use the TimeLaw / Planner protocols.
PLANNER_TYPES = {"Plan", "SmoothPlan", "PulsePlan", "ToppPlanner", "LookaheadPlanner", "FunctionPlanner"}


def _isinstance_targets(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("isinstance", "issubclass"):
            if len(node.args) == 2:
                second = node.args[1]
                names = second.elts if isinstance(second, ast.Tuple) else [second]
                for n in names:
                    yield node.lineno, getattr(n, "id", None) or getattr(n, "attr", None)


def test_no_isinstance_on_planner_types_outside_planners():
    found = []
    for path in PACKAGE.rglob("*.py"):
        if (PACKAGE / "planners") in path.parents:
            continue
        for line, name in _isinstance_targets(ast.parse(path.read_text(), str(path))):
            if name in PLANNER_TYPES:
                found.append(f"{path.relative_to(ROOT)}:{line}: isinstance(..., {name})")
    assert not found, found


def test_importing_the_planning_stack_writes_nothing(tmp_path):
    """Importing planning modules switches JAX to float64 (the one process-wide switch every planning
    module needs before tracing) and does nothing else: no compile-cache directory is created or set.
    The planning entry points set the cache up (:func:`jaxcnc.jaxconfig.configure_jax`)."""
    code = (
        "import os, jax\n"
        "import jaxcnc.planners, jaxcnc.ticks.table, jaxcnc.geometry, jaxcnc.jobs\n"
        "assert jax.config.jax_enable_x64\n"
        "assert jax.config.jax_compilation_cache_dir is None, 'cache set by an import'\n"
        "assert not os.path.exists(os.environ['JAXCNC_CACHE_DIR']), 'cache created by an import'\n"
        "from jaxcnc.jaxconfig import configure_jax\n"
        "assert configure_jax() == os.environ['JAXCNC_CACHE_DIR'] and os.path.isdir(os.environ['JAXCNC_CACHE_DIR'])\n"
        "print('ok')\n"
    )
    env = dict(os.environ)
    env["JAXCNC_CACHE_DIR"] = str(tmp_path / "jax-cache")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]


def test_planners_run_on_the_host_cpu_device():
    """``plan_job`` runs the planner on the host CPU (jaxconfig: the sequential passes are latency-bound; on a GPU
    they took 30–40× the CPU's time): with a GPU the default, inside ``jax.default_device(cpu)``; where the default
    is the CPU already, without any context (threads would not inherit it and compile every program again). Here
    a non-CPU default is stood in for by the default device set to a string the scope must replace."""
    import jax

    from jaxcnc.bench.plan import bench_machine
    from jaxcnc.bench.programs import cam_polyline
    from jaxcnc.jaxconfig import on_cpu, planning_device, planning_scope
    from jaxcnc.machine import parse_machine
    from jaxcnc.planners import Planner, get_planner, plan_job

    seen = {}

    class Recording(Planner):
        name = "recording"

        def plan(self, request):
            seen["device"] = jax.config.jax_default_device
            seen["on_cpu"] = on_cpu()
            return get_planner("topp").plan(request)

    assert planning_device().platform == "cpu"
    machine = parse_machine(bench_machine(0.01), "<test>")
    before = jax.config.jax_default_device
    job = plan_job(cam_polyline(30), machine, Recording())
    assert seen == {"device": before, "on_cpu": True} and jax.config.jax_default_device is before
    assert job.plan.total_time_s > 0
    with jax.default_device("cpu"):  # a default set by the caller: the scope sets the planning device
        with planning_scope():
            assert jax.config.jax_default_device == planning_device() and on_cpu()


def test_spans_are_built_on_the_planning_device(monkeypatch):
    """The blends' kernels (``build_spans``) run in the planning scope too. Built on a GPU default, the spans of the
    100k-block contour differed in their last bits from a CPU machine's (so did the plan), and its first plan took
    18.0 s against 11.3 s, compiling the kernels for the GPU (H200, 2026-11-28, docs/planning.md). A caller's default
    device stands in for the GPU, as above: inside the build the scope's device must replace it."""
    import jax

    import jaxcnc.planners.job as job_module
    from jaxcnc.bench.plan import bench_machine
    from jaxcnc.bench.programs import cam_polyline
    from jaxcnc.jaxconfig import planning_device
    from jaxcnc.machine import parse_machine

    seen = []
    build = job_module.build_spans

    def recording(*args, **kwargs):
        seen.append(jax.config.jax_default_device)
        return build(*args, **kwargs)

    monkeypatch.setattr(job_module, "build_spans", recording)
    machine = parse_machine(bench_machine(0.01), "<test>")
    with jax.default_device("cpu"):
        job_module.plan_job(cam_polyline(30), machine)
    assert seen == [planning_device()]
