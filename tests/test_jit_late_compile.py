"""A kernel compiled in a process after another kernel it calls has run from Python.

`collide.engine.jit` gives a kernel an entry that is compiled at its first call from Python, and
swaps the compiled entry into the dispatcher then. A kernel compiled later in the same process
that calls it must still find its code: this failed with "No definition for lowering" (seen when
the DEM's threaded driver had called `numerics.grow` from Python, and the sphere-alone kernel was
then compiled for a signature the cache did not hold). Both ways the callee can come: compiled
in the process, and loaded from a cache that holds it as bitcode only (a part no Python call ran,
as the warm-up leaves `grow`). Each process compiles a few small functions (a few seconds).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

GROW = """
import numpy as np

from collide.engine.jit import jit


@jit
def grow(buf, n):
    if n < buf.shape[0]:
        return buf
    out = np.empty((max(2 * buf.shape[0] + 16, n + 1), buf.shape[1]))
    out[:buf.shape[0]] = buf
    return out


@jit
def first(buf):
    return grow(buf, 40).shape[0]
"""

LATER = """
from collide.engine.jit import jit
from late_probe.grow import grow


@jit
def second(buf):
    return grow(buf, 80).shape[0]
"""

# Run `first` (its callee `grow` linked into it), then `grow` from Python, then compile `second`.
RUN = """
import numpy as np
from late_probe import grow as kernels
buf = np.zeros((3, 2))
print(kernels.first(buf), kernels.grow(buf, 50).shape[0], end=" ")
if {later}:
    from late_probe import later
    print(later.second(buf), end=" ")
"""


def _env(cache: Path, path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COLLIDE_JIT", "COLLIDE_COMPIL", "NUMBA_"))}
    env.update(NUMBA_CACHE_DIR=str(cache), COLLIDE_JIT="1", COLLIDE_COMPILING="1", PYTHONPATH=f"{path}:{ROOT}")
    return env


def _run(tmp_path: Path, later: bool) -> str:
    out = subprocess.run([sys.executable, "-c", RUN.format(later=later)], capture_output=True, text=True,
                         cwd=ROOT, timeout=300, env=_env(tmp_path / "cache", tmp_path / "src"))
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def _probe(tmp_path: Path) -> None:
    package = tmp_path / "src" / "late_probe"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "grow.py").write_text(GROW)
    (package / "later.py").write_text(LATER)


def test_a_kernel_compiled_after_its_callee_ran_from_python_finds_the_callee(tmp_path: Path) -> None:
    _probe(tmp_path)
    assert _run(tmp_path, later=True).split() == ["41", "51", "81"]


def test_the_same_with_the_callee_loaded_from_the_cache_as_bitcode(tmp_path: Path) -> None:
    """The first process leaves `grow` cached as bitcode only (never called from Python there);
    the second loads it so, calls it from Python, then compiles `second`."""
    _probe(tmp_path)
    code = "from late_probe import grow as k; import numpy as np; print(k.first(np.zeros((3, 2))))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300,
                         env=_env(tmp_path / "cache", tmp_path / "src"))
    assert out.returncode == 0 and out.stdout.split() == ["41"], out.stderr[-3000:]
    assert _run(tmp_path, later=True).split() == ["41", "51", "81"]
