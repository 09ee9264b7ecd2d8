"""How the engine's kernels run: compiled by numba, or the same code interpreted.

numba compiles the kernels once per machine (a few minutes) into an on-disk cache; a compiled
run then costs a fraction of a second to load. So that the first run after install does not
wait for that, `auto` runs the kernels interpreted (plain Python: the bonus demo in about 0.05 s
rather than 0.3 ms) and compiles them in a background process, once; every later run loads the
compiled code. `collide engine` shows the compile's state and progress.

COLLIDE_JIT=1 runs compiled (waiting for a compile that is running, or starting one),
COLLIDE_JIT=0 interprets, unset means auto. The decision is made once, when the engine is first
imported.

One compile at a time: the compiling process holds an exclusive lock (`flock`) on a file in the
cache for as long as it lives, so a compile that died releases it at once and a live one is
never judged dead by its age. A compile that fails records why, and is not retried by later
runs (`collide engine --compile` retries).

The cache cannot go stale: numba keys a cached function on its own file only, not on the files
of the functions it calls or the constants it imports, so the cache folder is named after a
hash of every source the kernels are built from and of the numba and Python versions.

The decorators themselves live in `collide.engine.jit`.

A command that runs one small scene can ask for the interpreted kernels even when the compiled
ones are ready (`collide.hint`): loading numba and the compiled cache costs a process
more than such a run takes interpreted.
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import importlib.util
import json
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from collide.engine.hint import HINT_VARIABLE, jit_setting
from collide.errors import RunError

_ENGINE = Path(__file__).parent
_PACKAGE_ROOT = _ENGINE.parent.parent
# Set in the process that compiles (collide.warmup): it must not wait for its own lock.
COMPILING_VARIABLE = "COLLIDE_COMPILING"
LOCK_FD_VARIABLE = "COLLIDE_COMPILE_LOCK_FD"


class EngineUnavailable(RunError):
    """The compiled engine was asked for and cannot be had (its compile failed)."""


# ---------------------------------------------------------------- what the cache depends on

# (A parenthesised list of names, one a line, as ruff wraps a long import, is followed too.)
_IMPORT = re.compile(r"^from (collide(?:\.\w+)*) import (?:\(([\w,\s]+)\)|([\w, ]+))|^import (collide(?:\.\w+)+)",
                     re.M)


def _module_file(name: str) -> Path | None:
    path = _PACKAGE_ROOT.joinpath(*name.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _engine_files() -> list[Path]:
    """The engine's Python files, its subpackages' included; not its __pycache__ folders, whose
    hundreds of compiled files made a glob over the tree most of a process's look-up."""
    files = []
    for folder, subfolders, names in os.walk(_ENGINE):
        subfolders[:] = [d for d in subfolders if d != "__pycache__"]
        files.extend(Path(folder, name) for name in names if name.endswith(".py"))
    return sorted(files)


def engine_sources() -> list[Path]:
    """Every file whose code or constants the compiled kernels hold: the engine's modules that
    define kernels, and what they import from collide, followed to the end. This file, which
    only chooses between compiled and interpreted, is not among them.

    Following the imports costs a process about 8 ms, so the list is kept beside the caches
    under a signature of every collide source's size and modification time: any edit anywhere
    in collide follows them again. (The cache key hashes the listed files' contents each time.)"""
    signature = _tree_signature()
    memo = cache_root() / "engine-sources.json"
    kept = _read_json(memo)
    if kept.get("signature") == signature and isinstance(kept.get("sources"), list):
        return [_PACKAGE_ROOT / name for name in kept["sources"]]
    sources = _follow_imports()
    try:
        memo.parent.mkdir(parents=True, exist_ok=True)
        scratch = memo.with_name(f"{memo.name}.{os.getpid()}")
        scratch.write_text(json.dumps({"signature": signature,
                                       "sources": [p.relative_to(_PACKAGE_ROOT).as_posix() for p in sources]}))
        os.replace(scratch, memo)
    except OSError:
        pass  # a read-only install follows the imports each time
    return sources


def _tree_signature() -> str:
    """A hash of every collide source file's path, size and modification time."""
    digest = hashlib.sha256()
    for folder, subfolders, names in os.walk(_PACKAGE_ROOT / "collide"):
        subfolders[:] = sorted(d for d in subfolders if d != "__pycache__")
        for name in sorted(names):
            if name.endswith(".py"):
                stat = os.stat(os.path.join(folder, name))
                digest.update(f"{folder}/{name}\0{stat.st_size}\0{stat.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def _follow_imports() -> list[Path]:
    """engine_sources, worked out: the kernel modules and their collide imports, transitively."""
    pending = [p for p in _engine_files() if re.search(r"^@jit", p.read_text(), re.M)]
    found: dict[Path, None] = {}
    while pending:
        path = pending.pop()
        if path in found:
            continue
        if path == Path(__file__):
            continue
        found[path] = None
        for match in _IMPORT.finditer(path.read_text()):
            module, wrapped, names, plain = match.groups()
            names = wrapped or names
            if plain:
                targets = [_module_file(plain)]
            else:
                # Names imported from a package may be modules; from a module, never.
                origin = _module_file(module)
                package = origin is not None and origin.name == "__init__.py"
                names = names.split(",") if package else []
                targets = [origin] + [_module_file(f"{module}.{n.strip()}") for n in names]
            pending.extend(f for f in targets if f is not None)
    return sorted(found)


def _numba_version() -> bytes:
    """numba's version file (its version and revision), read without importing numba or
    importlib.metadata (a thirtieth of a second, a twentieth of a compiled run's start)."""
    try:
        spec = importlib.util.find_spec("numba")
        return Path(spec.origin).with_name("_version.py").read_bytes()
    except (AttributeError, TypeError, ValueError, OSError):
        return b"numba unknown"


@functools.cache
def cache_key() -> str:
    """A hash of the kernels' sources and of the numba and Python versions."""
    digest = hashlib.sha256(f"python {sys.version}".encode())
    digest.update(_numba_version())
    for path in engine_sources():
        digest.update(path.relative_to(_PACKAGE_ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def cache_root() -> Path:
    """Where the compiled caches live: NUMBA_CACHE_DIR, or beside the engine's source."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    return Path(root) if root else _ENGINE / "__pycache__"


def cache_dir() -> Path:
    """This source's compiled cache (numba's files, the lock, the status and the log)."""
    return cache_root() / f"collide-{cache_key()}"


def _ready_file() -> Path:
    return cache_dir() / "ready.json"


def _status_file() -> Path:
    return cache_dir() / "status.json"


def compile_lock() -> Path:
    """The file a compiling process holds locked while it lives."""
    return cache_dir() / "compile.lock"


def compile_log() -> Path:
    return cache_dir() / "compile.log"


# ---------------------------------------------------------------- the compile's state


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def write_status(**status) -> None:
    """Record the compile's state for other processes (written whole: a reader never sees half)."""
    path = _status_file()
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".status.{os.getpid()}.json")
    partial.write_text(json.dumps(status))
    partial.replace(path)


def mark_compiled(seconds: float, functions: int, curve: list[list[float]]) -> None:
    """Mark the cache ready, with the compile's time and its curve (functions done against the
    fraction of its time) that later compiles measure their progress by."""
    _ready_file().write_text(json.dumps({"key": cache_key(), "seconds": seconds, "functions": functions,
                                         "curve": curve}))


def compiled_ready() -> bool:
    """Whether a compile finished for this exact source."""
    return _read_json(_ready_file()).get("key") == cache_key()


def _lock_held() -> bool:
    """Whether a live process holds the compile lock."""
    try:
        fd = os.open(compile_lock(), os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def compiling_elsewhere() -> bool:
    """Whether a compile is running (in another process, or in this one's child)."""
    return _lock_held()


@dataclass(frozen=True)
class EngineState:
    """The compiled engine's state, as `collide engine` shows it.

    state: "ready", "compiling", "failed", "interrupted" (a compile that died without a word:
    killed, or the machine stopped) or "absent" (never compiled for this source)."""

    state: str
    cache: Path
    seconds: float = 0.0  # the compile's time: so far while compiling, in all when ready or failed
    done: int = 0  # functions compiled so far
    reason: str = ""  # why a compile failed
    # A whole compile's progress to measure by (the last one here, or warm's estimate): pairs of
    # functions done and the fraction of its time, and its time in seconds.
    curve: tuple[tuple[float, float], ...] = ()
    reference_seconds: float = 0.0

    def fraction(self) -> float:
        """How far a running compile is: the reference compile's share of time at this many
        functions, moved on by the time spent since, up to its share at the next function (numba
        spends minutes on a few large functions). At most 0.99 until it is done."""
        if self.state == "ready":
            return 1.0
        lo, hi = 0.0, 1.0
        for count, share in self.curve:
            if count <= self.done:
                lo = share
            else:
                hi = share
                break
        by_time = self.seconds / self.reference_seconds if self.reference_seconds > 0 else lo
        return min(max(lo, min(by_time, hi)), 0.99)

    def describe(self) -> str:
        """One line for people."""
        if self.state == "ready":
            return f"compiled (in {self.seconds:.0f} s); cache {self.cache}"
        if self.state == "compiling":
            functions = f"{self.done} function{'' if self.done == 1 else 's'}"
            return f"compiling: about {self.fraction():.0%} ({functions}), {self.seconds:.0f} s so far"
        if self.state == "failed":
            return f"the compile failed: {self.reason} (log: {compile_log()})"
        if self.state == "interrupted":
            return "a compile was interrupted before it finished"
        return "not compiled yet"


def engine_state() -> EngineState:
    """The compiled engine's state now."""
    ready = _read_json(_ready_file())
    if ready.get("key") == cache_key():
        return EngineState("ready", cache_dir(), float(ready.get("seconds", 0.0)), int(ready.get("functions", 0)))
    status = _read_json(_status_file())
    done = int(status.get("done", 0))
    progress = {"curve": tuple(tuple(point) for point in status.get("curve", ())),
                "reference_seconds": float(status.get("reference_seconds", 0.0))}
    if _lock_held():
        started = float(status.get("started", time.time()))
        return EngineState("compiling", cache_dir(), time.time() - started, done, **progress)
    if status.get("state") == "failed":
        return EngineState("failed", cache_dir(), float(status.get("seconds", 0.0)), done,
                           str(status.get("reason", "unknown")))
    if status.get("state") == "compiling":
        return EngineState("interrupted", cache_dir(), 0.0, done)
    return EngineState("absent", cache_dir())


def start_compile(force: bool = False) -> bool:
    """Compile the kernels in a detached process (`python -m collide.warmup`), unless one
    is running, they are ready, or the last compile failed (unless `force`). Returns whether it
    started one. The lock is taken here and handed to the child, so that no second compile can
    start between the two."""
    state = engine_state()
    if state.state in ("ready", "compiling") or (state.state == "failed" and not force):
        return False
    try:
        compile_lock().parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(compile_lock(), os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        return False  # a read-only install: runs stay interpreted; `collide engine --compile` says why
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return False  # another process started one just now
        write_status(state="compiling", started=time.time(), done=0)
        env = dict(os.environ, COLLIDE_JIT="1", **{LOCK_FD_VARIABLE: str(fd)})
        env.pop(HINT_VARIABLE, None)
        with open(compile_log(), "w") as log:
            subprocess.Popen([sys.executable, "-m", "collide.warmup"], stdout=log, stderr=subprocess.STDOUT,
                             stdin=subprocess.DEVNULL, env=env, start_new_session=True, pass_fds=(fd,))
        return True
    finally:
        os.close(fd)  # the child holds the lock from here


def wait_compiled(report: Callable[[EngineState], None] | None = None, every: float = 1.0) -> EngineState:
    """Wait while a compile runs, calling `report` with its state every `every` seconds."""
    while True:
        state = engine_state()
        if state.state != "compiling":
            return state
        if report is not None:
            report(state)
        time.sleep(every)


def _report_to_stderr(state: EngineState, _last: list[float] = [0.0]) -> None:  # noqa: B006 - a clock
    if time.time() - _last[0] >= 15.0:
        _last[0] = time.time()
        print(f"collide: waiting for the engine's compile ({state.describe()})", file=sys.stderr, flush=True)


def require_compiled(report: Callable[[EngineState], None] | None = _report_to_stderr) -> None:
    """Make sure the compiled kernels are ready: wait for a running compile, or start one and
    wait for it. Raises EngineUnavailable (one line) when the compile failed."""
    state = engine_state()
    if state.state == "ready":
        return
    if state.state == "failed":
        raise EngineUnavailable(f"the compiled engine is not available: {state.reason} "
                                "(`collide engine --compile` tries again; COLLIDE_JIT=0 runs interpreted)")
    start_compile()
    state = wait_compiled(report)
    if state.state != "ready":
        raise EngineUnavailable(f"the compiled engine is not available: {state.describe()} "
                                "(`collide engine --compile` tries again; COLLIDE_JIT=0 runs interpreted)")


# ---------------------------------------------------------------- this process's choice

# Set by a command for a run that is quicker interpreted (collide.hint); read once and
# removed, so that no child process (a background compile, a viewer) inherits it.
_HINT = os.environ.pop(HINT_VARIABLE, "")
_SELF_COMPILING = os.environ.pop(COMPILING_VARIABLE, "") == "1" or LOCK_FD_VARIABLE in os.environ


def _choose() -> tuple[bool, bool]:
    """(compiled, compiling in the background while this process interprets)."""
    setting = jit_setting()
    if setting == "interpreted":
        return False, False
    if _SELF_COMPILING:
        return True, False
    if setting == "compiled":
        require_compiled()
        return True, False
    state = engine_state()
    if state.state == "ready":
        return _HINT != "interpreted", False
    if state.state != "failed":
        start_compile()
        return False, True
    return False, False


COMPILED, BACKGROUND = _choose()

# numba imports importlib.metadata (with email, socket and more) when it is imported, to find its
# extensions when its compiler is set up; a process that loads cached kernels never sets it up.
# The module is loaded when first used instead (importlib's LazyLoader; numba takes it by
# `from importlib import metadata`, which does not load it): 0.03 s of a compiled run's start.
NUMBA_UNUSED = ("importlib.metadata",)


def _load_when_used(name: str) -> None:
    """Put `name` in sys.modules as a module that loads itself at its first attribute access."""
    if name in sys.modules:
        return
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return
    if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
        return
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    parent, _, child = name.rpartition(".")
    if parent:
        setattr(sys.modules[parent], child, module)


if COMPILED and not _SELF_COMPILING:
    for _name in NUMBA_UNUSED:
        _load_when_used(_name)

# Seconds this process spent loading compiled kernels from numba's cache (once per kernel): a
# batch reports its runs' cost apart from this one-time cost.
_loading = [0.0]


# A kernel the warm-up leaves out (a sphere alone's, the seed's) compiles at its first run, for
# seconds: a user at a terminal is told why the run waits.
SLOW_LOAD_NOTICE_S = 1.0


@contextmanager
def loading() -> Iterator[None]:
    """Time a kernel's loading (add it to `load_seconds`); at a terminal, say so when it takes
    long enough to be a compile."""
    started = time.perf_counter()
    notice = threading.Timer(SLOW_LOAD_NOTICE_S, _say_compiling)
    notice.daemon = True
    if sys.stderr.isatty():
        notice.start()
    try:
        yield
    finally:
        notice.cancel()
        _loading[0] += time.perf_counter() - started


def _say_compiling() -> None:
    print("collide: compiling the kernels this scene needs, once (about 10 s; cached after)",
          file=sys.stderr, flush=True)


def load_seconds() -> float:
    """Seconds this process has spent loading compiled kernels."""
    return _loading[0]
