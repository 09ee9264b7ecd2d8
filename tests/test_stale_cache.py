"""The compiled cache never serves a kernel whose callee changed, wherever the two files live.

numba keys a cached function on its own file only; the engine names its cache folder after every
kernel source (`collide.engine.tier.engine_sources`), found in the engine's subpackages too. Here a
kernel and its callee live in a subpackage of a copy of the engine, each decorated as the engine's
kernels are; the callee's file changes between two processes that run the compiled kernel with
the cache on (a few seconds: numba compiles only these two small functions).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CALLEE = """
from collide.engine.jit import {decorator}


@{decorator}
def scale(x):
    return {factor} * x
"""

CALLER = """
from collide.engine.jit import jit
from collide.engine.probe.callee import scale


@jit
def twice_scaled(x):
    return 2.0 * scale(x)
"""


def _run(copy: Path, cache: Path) -> float:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COLLIDE_JIT", "COLLIDE_COMPIL"))}
    env.update(NUMBA_CACHE_DIR=str(cache), COLLIDE_JIT="1", COLLIDE_COMPILING="1", PYTHONPATH=str(copy))
    code = "from collide.engine.probe.caller import twice_scaled\nprint(twice_scaled(1.5))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=copy.parent,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return float(out.stdout)


@pytest.mark.parametrize("decorator", ["jit_inline", "jit_call"])
def test_a_changed_callee_in_a_subpackage_is_compiled_again(tmp_path: Path, decorator: str) -> None:
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "collide", copy / "collide", ignore=shutil.ignore_patterns("__pycache__"))
    probe = copy / "collide" / "engine" / "probe"
    probe.mkdir()
    (probe / "__init__.py").write_text("")
    (probe / "caller.py").write_text(CALLER)
    results = []
    for factor in ("4.0", "40.0"):
        (probe / "callee.py").write_text(CALLEE.format(decorator=decorator, factor=factor))
        results.append(_run(copy, tmp_path / "cache"))
    # 2 x factor x 1.5, each time from the callee the process read: never the first one's cache.
    assert results == [2.0 * 4.0 * 1.5, 2.0 * 40.0 * 1.5]
    assert len(list((tmp_path / "cache").glob("collide-*"))) == 2  # one cache per source
