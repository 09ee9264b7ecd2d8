"""Every process that compiles the kernels compiles them the same way, and a kernel part, which
has no entry from Python, is safe to call from Python.

numba's cache keys a compiled function on its signature and the CPU, not on the optimisation
settings (`collide.engine.jit.CODE_GENERATION`): the engine sets them itself whatever the
environment says. The parts (`jit_inline`, `jit_call`) are compiled without numba's entry from
Python; a call from Python runs the Python function. The second test compiles two small
functions (a few seconds).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _env(cache: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COLLIDE_JIT", "COLLIDE_COMPIL", "NUMBA_"))}
    env.update(NUMBA_CACHE_DIR=str(cache), COLLIDE_JIT="1", COLLIDE_COMPILING="1", **extra)
    return env


def test_the_code_generation_is_the_engines_whatever_the_environment(tmp_path: Path) -> None:
    code = """
import json
from collide.engine import jit
from numba.core import config
print(json.dumps([jit.CODE_GENERATION, int(config.OPT), config.LOOP_VECTORIZE, config.SLP_VECTORIZE]))
"""
    contrary = {"NUMBA_OPT": "0", "NUMBA_LOOP_VECTORIZE": "0", "NUMBA_SLP_VECTORIZE": "1"}
    for extra in ({}, contrary):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120,
                             env=_env(tmp_path, **extra))
        assert out.returncode == 0, out.stderr
        wanted, opt, loop, slp = json.loads(out.stdout)
        assert [opt, loop, slp] == [int(wanted["NUMBA_OPT"]), int(wanted["NUMBA_LOOP_VECTORIZE"]),
                                    int(wanted["NUMBA_SLP_VECTORIZE"])]


PART = """
from collide.engine.jit import jit_call


@jit_call
def scaled(x, out):
    out[0] = 3.0 * x
    return out[0] + 1.0
"""

KERNEL = """
import numpy as np

from collide.engine.jit import jit
from collide.engine.probe.part import scaled


@jit
def kernel(x):
    out = np.zeros(1)
    return scaled(x, out) + out[0]
"""

RUN = """
import json
import numpy as np
from numba.core import event
from collide.engine.probe.kernel import kernel
from collide.engine.probe.part import scaled

compiled = []


class Compiles(event.Listener):
    def on_start(self, ev):
        function = ev.data["dispatcher"].py_func
        if function.__module__.startswith("collide"):  # not numba's own helpers (np.zeros)
            compiled.append(function.__name__)

    def on_end(self, ev):
        pass


event.register("numba:compile", Compiles())
out = np.zeros(1)
print(json.dumps([kernel(2.0), scaled(2.0, out), out[0], compiled]))
"""


def test_a_part_called_from_python_runs_as_python_and_a_second_process_compiles_nothing(tmp_path: Path) -> None:
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "collide", copy / "collide", ignore=shutil.ignore_patterns("__pycache__"))
    probe = copy / "collide" / "engine" / "probe"
    probe.mkdir()
    (probe / "__init__.py").write_text("")
    (probe / "part.py").write_text(PART)
    (probe / "kernel.py").write_text(KERNEL)
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", RUN], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                             env=_env(tmp_path / "cache", PYTHONPATH=str(copy)))
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout))
    (first, *values_first), (second, *values_second) = [(r[3], *r[:3]) for r in runs]
    assert values_first == values_second == [13.0, 7.0, 6.0]
    assert sorted(first) == ["kernel", "scaled"]  # the part compiled for the kernel, not for Python
    assert second == []  # loaded from the cache, with the same settings
