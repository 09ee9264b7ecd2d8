"""The compiled engine's life: one compile at a time (a lock held by a live process), a failed
compile recorded with its cause and not retried by later runs, progress that other processes
can read, and a cache that cannot go stale when a function's callee changes in another file."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _env(cache: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COLLIDE_JIT", "COLLIDE_COMPIL"))}
    env.update(NUMBA_CACHE_DIR=str(cache), **extra)
    return env


def _python(code: str, env: dict[str, str], cwd: Path = ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=timeout)


def _state(cache: Path) -> dict:
    out = subprocess.run([sys.executable, "-m", "cli.main", "engine", "--json"], capture_output=True, text=True,
                         env=_env(cache), cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


# A process that holds the compile lock the way a compile does, then reports it is holding it.
HOLD = """
import fcntl, os, sys, time
from collide.engine import tier
tier.compile_lock().parent.mkdir(parents=True, exist_ok=True)
fd = os.open(tier.compile_lock(), os.O_RDWR | os.O_CREAT)
fcntl.flock(fd, fcntl.LOCK_EX)
tier.write_status(state="compiling", started=time.time(), done=30, curve=[[0, 0.0], [30, 0.25], [31, 0.5],
                  [120, 1.0]], reference_seconds=1e6)
print("holding", flush=True)
time.sleep(float(sys.argv[1]))
"""


def _hold(cache: Path, seconds: float) -> subprocess.Popen:
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(seconds)], stdout=subprocess.PIPE, text=True,
                              env=_env(cache, COLLIDE_JIT="0"), cwd=ROOT)
    assert holder.stdout.readline().strip() == "holding"
    return holder


def test_a_live_compile_is_seen_with_its_progress_and_a_dead_one_is_not(tmp_path: Path) -> None:
    """The lock is held by a live process, not judged by its age: a killed compile releases it
    at once, and its state reads 'interrupted', not 'compiling'."""
    holder = _hold(tmp_path, 600)
    try:
        state = _state(tmp_path)
        assert state["state"] == "compiling"
        # At the reference's 30th function it had spent a quarter of its time, and the 31st ended
        # at half: a compile that has spent little time since stays near the quarter.
        assert state["functions"] == 30 and state["fraction"] == 0.25
    finally:
        holder.kill()
        holder.wait()
    assert _state(tmp_path)["state"] == "interrupted"


def test_a_command_that_needs_the_compiled_engine_waits_for_the_running_compile(tmp_path: Path) -> None:
    """`python -m collide.warmup` (the test script's, `collide engine --compile`'s) takes the
    lock only when the compile that holds it ends: never a second compile beside it."""
    holder = _hold(tmp_path, 1.5)
    code = """
    import time
    from collide import warmup as warm
    started = time.perf_counter()
    fd = warm._take_lock(None)
    print(time.perf_counter() - started)
    """
    out = _python(code, _env(tmp_path, COLLIDE_JIT="0"))
    holder.wait()
    assert out.returncode == 0, out.stderr
    assert float(out.stdout) >= 1.0


def _fail_compile(cache: Path) -> None:
    """A compile that fails as one did without scipy: its cause is recorded."""
    code = """
    from collide import warmup as warm
    def broken():
        raise ImportError("scipy 0.16+ is required for linear algebra")
    warm.warm = broken
    try:
        warm.compile_now()
    except ImportError:
        pass
    """
    out = _python(code, _env(cache, COLLIDE_COMPILING="1", COLLIDE_JIT="1"))
    assert out.returncode == 0, out.stderr


def test_a_failed_compile_says_why_and_is_not_retried_by_later_runs(tmp_path: Path) -> None:
    _fail_compile(tmp_path)
    state = _state(tmp_path)
    assert state["state"] == "failed"
    assert state["reason"] == "ImportError: scipy 0.16+ is required for linear algebra"
    # A later run stays interpreted, says why in its summary, and starts no compile.
    run = subprocess.run([sys.executable, "-m", "cli.main", "run", "demo-bonus", "--no-record", "--tol", "1e-9"],
                         capture_output=True, text=True, env=_env(tmp_path), cwd=ROOT, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "the compile failed: ImportError: scipy 0.16+ is required" in run.stdout
    assert "`collide engine --compile` tries again" in run.stdout
    assert _state(tmp_path)["state"] == "failed"
    # Asking for the compiled engine is one line and a non-zero exit, not a traceback.
    forced = subprocess.run([sys.executable, "-m", "cli.main", "run", "demo-bonus", "--no-record"],
                            capture_output=True, text=True, env=_env(tmp_path, COLLIDE_JIT="1"), cwd=ROOT,
                            timeout=300)
    assert forced.returncode != 0
    assert forced.stderr.count("\n") == 1 and forced.stderr.startswith("error: the compiled engine is not available")


def test_a_large_scene_after_a_failed_compile_is_refused_with_the_cause(tmp_path: Path) -> None:
    _fail_compile(tmp_path)
    run = subprocess.run([sys.executable, "-m", "cli.main", "run", "gas-box", "--no-record"], capture_output=True,
                         text=True, env=_env(tmp_path), cwd=ROOT, timeout=300)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "bodies need the compiled engine" in run.stderr
    assert "scipy 0.16+" in run.stderr


CALLEE = """
from collide.engine.jit import jit_inline


@jit_inline
def scale(x):
    return {factor} * x
"""

CALLER = """
from collide.engine.probe_callee import scale
from collide.engine.jit import jit


@jit
def twice_scaled(x):
    return 2.0 * scale(x)
"""


def test_the_compiled_cache_follows_a_change_in_a_callee_in_another_file(tmp_path: Path) -> None:
    """numba keys a cached function on its own file only: with the caller's file unchanged it
    would return the old callee's result. The cache folder is named after every engine source."""
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "collide", copy / "collide", ignore=shutil.ignore_patterns("__pycache__"))
    engine = copy / "collide" / "engine"
    (engine / "probe_caller.py").write_text(CALLER)
    code = "from collide.engine.probe_caller import twice_scaled\nprint(twice_scaled(1.0))\n"
    env = _env(tmp_path / "cache", COLLIDE_JIT="1", COLLIDE_COMPILING="1", PYTHONPATH=str(copy))
    results = []
    for factor in ("4.0", "40.0"):
        (engine / "probe_callee.py").write_text(CALLEE.format(factor=factor))
        out = _python(code, env, cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        results.append(float(out.stdout))
    assert results == [8.0, 80.0]
    assert len(list((tmp_path / "cache").glob("collide-*"))) == 2  # one cache per source


def test_the_cache_key_covers_what_the_kernels_import() -> None:
    """Constants the kernels import from other modules are frozen into the machine code."""
    from collide.engine import tier

    names = {p.relative_to(ROOT).as_posix() for p in tier.engine_sources()}
    assert {"collide/engine/event/run.py", "collide/engine/event/island.py", "collide/engine/layout.py",
            "collide/engine/dem/loop.py", "collide/engine/dem/contact.py", "collide/engine/dem/layout.py",
            "collide/engine/jit.py", "collide/integrators.py"} <= names
    # The choice of compiled or interpreted, and what it imports, never reach the machine code.
    assert not {"collide/engine/tier.py", "collide/scene.py"} & names


@pytest.mark.slow
def test_engine_command_reports_the_compiled_engine_here() -> None:
    """In this checkout (the test script compiles first), `collide engine` says compiled."""
    out = subprocess.run([sys.executable, "-m", "cli.main", "engine"], capture_output=True, text=True, cwd=ROOT,
                         env={k: v for k, v in os.environ.items() if k != "COLLIDE_JIT"}, timeout=120)
    assert out.returncode == 0
    from collide.engine import tier

    if not tier.compiled_ready():
        pytest.skip("the compiled kernels are not built here (collide engine --compile)")
    assert out.stdout.startswith("engine: compiled (in ")


def test_waiting_reports_a_running_compile_then_its_end(tmp_path: Path) -> None:
    holder = _hold(tmp_path, 3.0)
    started = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "cli.main", "engine", "--wait"], capture_output=True, text=True,
                         env=_env(tmp_path), cwd=ROOT, timeout=120)
    holder.wait()
    assert time.perf_counter() - started >= 1.0
    assert "engine: compiling: about 25% (30 functions)" in out.stderr
    assert out.returncode == 1 and "interrupted" in out.stdout  # the holder never marked the cache ready


KERNELS = """
from collide.engine.jit import jit, jit_call


@jit_call
def weighted(x, k, flag):
    return x * (k + 1) * (2.0 if flag else 1.0)


@jit
def total(x):
    return weighted(x, 0, False) + weighted(x, 1, True) + weighted(x, 2, x > 0.0)
"""

LOAD_THEN_LINK = """
from numba import njit
from collide.engine.probe_kernels import total, weighted
first = total(1.5)

@njit
def again(x):
    return weighted(x, 3, False)

print(first, again(1.5), sum(total.stats.cache_hits.values()), sum(weighted.stats.cache_hits.values()),
      len(weighted.signatures))
"""


def test_a_kernel_loaded_from_the_cache_links_into_a_new_compile(tmp_path: Path) -> None:
    """A callee is compiled once for its argument types, whatever constants its callers pass;
    a kernel loaded from the cache (its bitcode parsed only when needed) is linked into a
    kernel compiled later in the same process and gives the same numbers."""
    copy = tmp_path / "src"
    shutil.copytree(ROOT / "collide", copy / "collide", ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "collide" / "engine" / "probe_kernels.py").write_text(KERNELS)
    env = _env(tmp_path / "cache", COLLIDE_JIT="1", COLLIDE_COMPILING="1", PYTHONPATH=str(copy))
    runs = []
    for _ in range(2):
        out = _python(LOAD_THEN_LINK, env, cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        runs.append(out.stdout.split())
    x = 1.5
    expected = x * 1 + x * 2 * 2.0 + x * 3 * 2.0
    for total, again, *_, signatures in runs:
        assert float(total) == expected and float(again) == x * 4
        assert signatures == "1"
    # Compiled in the first process; in the second, both loaded from the cache, the callee's
    # bitcode parsed to link it into `again`.
    assert runs[0][2:4] == ["0", "0"] and runs[1][2:4] == ["1", "1"]
