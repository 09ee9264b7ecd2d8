"""What a `collide run` process loads before its first step, and the start-up probe
(benchmarks/bench_startup.py measures the time; these check behaviour only)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
# Loaded to write or show a recording: a run that writes none has no use for them.
RECORDING_MODULES = ("collide.recording", "rerun", "viser", "viewer", "matplotlib")

LOADED = """
import json, sys
sys.argv = ["collide", *sys.argv[1:]]
from cli.main import main
try:
    main()
except SystemExit as exc:
    code = exc.code
watched = {watched!r}
print(json.dumps({{"code": code, "loaded": sorted(w for w in watched if any(m == w or m.startswith(w + ".")
                                                                            for m in sys.modules))}}))
"""


def _run(*args: str, env: dict | None = None,
         watched: tuple[str, ...] = RECORDING_MODULES) -> tuple[int, list[str], str]:
    """`collide ARGS` in a fresh process: its exit code, which of `watched` it loaded, its output."""
    done = subprocess.run([sys.executable, "-c", LOADED.format(watched=watched), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "COLLIDE_JIT": "0", **(env or {})})
    assert done.returncode == 0, done.stderr
    *output, last = done.stdout.strip().splitlines()
    result = json.loads(last)
    return result["code"], result["loaded"], "\n".join(output)


def test_a_run_without_a_recording_loads_no_recorder(tmp_path):
    code, loaded, output = _run("run", "demo-bonus", "--no-record", "--json")
    assert code == 0 and json.loads(output)["scene"] == "demo-bonus"
    assert loaded == []
    # The same run writing its recording loads the recorder: the check above can fail.
    code, loaded, _ = _run("run", "demo-bonus", "--out", str(tmp_path / "demo.rrd"))
    assert code == 0 and (tmp_path / "demo.rrd").stat().st_size > 0
    assert {"collide.recording", "rerun"} <= set(loaded)


@pytest.mark.parametrize("scene", ["billiards-break", "bounce"])
def test_loading_the_compiled_engine_loads_no_array_maths(scene):
    """A cached kernel that uses one of numba's numpy reductions makes every process that loads
    it import numba's array maths, whose BLAS probe imports scipy's linear algebra (0.3 s of a
    0.6 s start): the event engine and the DEM kernel use loops instead."""
    args = ("run", scene, "--no-record", "--set", "duration=0.01")
    # The warm-up leaves a sphere alone's kernel to its first compiled run, which compiles it (and
    # a compile types numpy's maths): that run first, then the process that only loads it.
    _run(*args, env={"COLLIDE_JIT": "1"})
    code, loaded, _ = _run(*args, env={"COLLIDE_JIT": "1"}, watched=("numba.np.arraymath", "scipy.linalg"))
    assert code == 0 and loaded == []


def test_the_probe_records_the_cpu_at_the_first_step_once(tmp_path):
    """A run with a measured error estimate steps several times (collide.run's tighter runs);
    the probe writes one line, at the first, with less CPU than the whole process spent."""
    probe = tmp_path / "probe.jsonl"
    before = os.times()
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", "newtons-cradle", "--no-record", "--json"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, COLLIDE_JIT="0", COLLIDE_STARTUP_PROBE=str(probe)))
    after = os.times()
    assert done.returncode == 0, done.stderr
    lines = probe.read_text().splitlines()
    assert len(lines) == 1
    line = json.loads(lines[0])
    process = after.children_user + after.children_system - before.children_user - before.children_system
    assert 0 < line["cpu"] < process + 0.02  # os.times counts in clock ticks
    assert line["compiled"] is False


def test_values_that_need_no_conversion_come_out_as_typer_converts_them():
    """cli.coercion passes an option's value as it is where typer's own conversion would give
    it back unchanged: for every parameter of every command, on values of each kind, the result
    (or the error) is typer's."""
    typer = pytest.importorskip("typer")
    from typer import core
    from typer._coercion import build_runtime_param

    from cli.main import app

    group = typer.main.get_command(app)
    ctx = group.make_context("collide", ["run", "x"], resilient_parsing=True)
    values = [None, (), ("a",), ["a", "b"], "x", "1", "2.5", 1, 0, 2, -1, 10**9, 1.0, 0.5, float("nan"), True]
    compared = 0
    for command in group.commands.values():
        for param in command.params:
            if not isinstance(param, core._TyperParameter):
                continue
            for value in [*values, param.default]:
                param._runtime_param = None
                ours = _outcome(param.get_runtime_param(), value, param, ctx)
                typers = _outcome(build_runtime_param(param.type_descriptor), value, param, ctx)
                assert ours == typers, (command.name, param.name, value)
                compared += 1
    assert compared > 500


def _outcome(runtime, value, param, ctx) -> tuple:
    try:
        result = runtime.coerce(value, param=param, ctx=ctx)
    except Exception as exc:  # typer's own error, compared as type and message
        return "error", type(exc).__name__, str(exc)
    return "value", type(result), repr(result)


def test_a_module_loaded_when_used_works_as_if_imported():
    """collide.engine.tier defers numba's unused imports: such a module stays unloaded until
    something uses it, and then works as imported."""
    code = """
import sys
from collide.engine.tier import _load_when_used
assert "colorsys" not in sys.modules
_load_when_used("colorsys")
module = sys.modules["colorsys"]
assert type(module).__name__ == "_LazyModule"
from colorsys import rgb_to_hsv
assert rgb_to_hsv(1.0, 0.0, 0.0) == (0.0, 1.0, 1.0) and type(module).__name__ == "module"
"""
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, COLLIDE_JIT="0"))
    assert done.returncode == 0, done.stderr


PUT_OFF = """
import json, sys
sys.argv = ["collide", "run", "billiards-break", "--no-record", "--set", "duration=0.01"]
from cli.main import main
try:
    main()
except SystemExit:
    pass
state = lambda name: type(sys.modules[name]).__name__ if name in sys.modules else "absent"
before = {name: state(name) for name in ("numba.np.arrayobj", "yaml", "scipy")}
from collide.engine import jit
kernels = [k for name, m in list(sys.modules.items()) if name.startswith("collide.engine")
           for k in vars(m).values() if isinstance(k, jit._Kernel)]
made = sorted({k.__qualname__ for k in kernels if k._dispatcher is not None})
import numpy as np
from numba import njit

@njit
def filled(n):
    out = np.empty(n)
    out[:] = 2.0
    return out.sum()

print(json.dumps({"kernels": len({id(k) for k in kernels}), "made": made, "before": before,
                  "compiled": filled(3), "after": state("numba.np.arrayobj")}))
"""


def test_a_compiled_run_makes_and_imports_only_what_it_calls():
    """collide.engine.jit: a run that loads its kernels from the cache makes numba dispatchers
    for the kernels it calls from Python only, leaves the numba modules that the kernels'
    environments name unloaded, and imports neither yaml nor scipy with numba; a compile later in
    the same process loads those modules first and works."""
    done = subprocess.run([sys.executable, "-c", PUT_OFF], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "COLLIDE_JIT": "1"})
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert "simulate" in found["made"] and len(found["made"]) <= 10 < found["kernels"]
    assert found["before"] == {"numba.np.arrayobj": "_LazyModule", "yaml": "absent", "scipy": "absent"}
    assert found["compiled"] == 6.0 and found["after"] == "module"
