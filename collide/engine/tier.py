"""How the engine's kernels run: compiled by numba, or the same code interpreted.

numba compiles the kernels once per machine (about a minute and a half here) and keeps them in
its on-disk cache; a compiled run then costs a few tenths of a second to load. So that the
first run after install does not wait for that, `auto` runs the kernels interpreted (plain
Python: the bonus demo in about 0.05 s rather than 0.3 ms) and compiles them in a background
process, once; every later run loads the compiled code.

COLLIDE_JIT=1 compiles (waiting for it if needed), COLLIDE_JIT=0 interprets, unset means auto.
The decision is made once, when the engine is first imported.

A command that runs one small scene can ask for the interpreted kernels even when the compiled
ones are ready (`collide.engine.hint`): loading numba and the compiled cache costs a process
more than such a run takes interpreted.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from collide.engine.hint import HINT_VARIABLE, jit_setting

_KERNELS = Path(__file__).with_name("kernels.py")


def _stamp() -> dict:
    """What the compiled cache depends on: the kernels' source and the numba and Python versions."""
    try:
        from importlib.metadata import version

        numba_version = version("numba")
    except Exception:
        numba_version = "unknown"
    sources = [_KERNELS, _KERNELS.with_name("dem.py")]
    return {"sources": [[s.name, s.stat().st_size, s.stat().st_mtime] for s in sources], "numba": numba_version,
            "python": sys.version.split()[0]}


def cache_dir() -> Path:
    """Where numba keeps the compiled kernels (beside the source, or NUMBA_CACHE_DIR)."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    return Path(root) if root else _KERNELS.parent / "__pycache__"


def _marker() -> Path:
    return cache_dir() / "collide-compiled.json"


def compiled_ready() -> bool:
    """Whether the background (or an explicit) compile finished for this exact source."""
    try:
        return json.loads(_marker().read_text()) == _stamp()
    except (OSError, ValueError):
        return False


def mark_compiled() -> None:
    _marker().parent.mkdir(parents=True, exist_ok=True)
    _marker().write_text(json.dumps(_stamp()))


LOCK_FRESH = 600.0  # s: a compile lock older than this is a dead compile's, not a running one


def compile_lock() -> Path:
    """The file a background compile holds while it runs."""
    return cache_dir() / "collide-compiling.lock"


def compiling_elsewhere() -> bool:
    """Whether a background compile is running (its lock is fresh)."""
    try:
        return time.time() - compile_lock().stat().st_mtime < LOCK_FRESH
    except OSError:
        return False


def _start_background_compile() -> None:
    """Compile the kernels in a detached process, unless one is already at it."""
    lock = compile_lock()
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        if compiling_elsewhere():
            return
        lock.write_text(str(os.getpid()))
        log = open(cache_dir() / "collide-compile.log", "w")
        env = dict(os.environ, COLLIDE_JIT="1")
        subprocess.Popen([sys.executable, "-m", "collide.engine.warm", "--lock", str(lock)], stdout=log,
                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env, start_new_session=True)
    except OSError:
        pass  # a read-only install: runs stay interpreted; `python -m collide.engine.warm` compiles


# Set by a command for a run that is quicker interpreted (collide.engine.hint); read once and
# removed, so that no child process (a background compile, a viewer) inherits it.
_HINT = os.environ.pop(HINT_VARIABLE, "")


def _choose() -> tuple[bool, bool]:
    """(compiled, compiling in the background while this process interprets)."""
    setting = jit_setting()
    if setting != "auto":
        return setting == "compiled", False
    if compiled_ready():
        return _HINT != "interpreted", False
    _start_background_compile()
    return False, True


COMPILED, BACKGROUND = _choose()

# Seconds this process spent loading compiled kernels from numba's cache (once per kernel): a
# batch reports its runs' cost apart from this one-time cost.
_loading = [0.0]


@contextmanager
def loading() -> Iterator[None]:
    """Time a kernel's loading (add it to `load_seconds`)."""
    started = time.perf_counter()
    try:
        yield
    finally:
        _loading[0] += time.perf_counter() - started


def load_seconds() -> float:
    """Seconds this process has spent loading compiled kernels."""
    return _loading[0]

if COMPILED:
    from numba import njit

    # error_model="numpy": a division by zero gives inf or NaN (checked after each step) instead
    # of raising, which also keeps the compiled code smaller.
    jit = njit(cache=True, error_model="numpy", nogil=True)
    # Pieces called per contact, per body or per substep, which allocate nothing (a contact
    # law's parts, a body's turn; the event engine's step with its kicks, friction solve,
    # geometry and mode values): inlined into the loops, and without reference counting
    # (`_nrt=False`, as numba's own sort and string helpers): a call each time, and the atomic
    # counts of each array passed, cost more than the physics (a quarter of the DEM step; the
    # event engine's steps 2-5 times, measured).
    jit_inline = njit(cache=True, error_model="numpy", nogil=True, forceinline=True, _nrt=False)
else:
    def jit(function):
        """Interpreted: the kernel as plain Python."""
        return function

    jit_inline = jit
