"""Compile the engine's kernels into numba's on-disk cache: `python -m collide.warmup`.

Runs every entry point once on a tiny scene of each kind it can be called for, so that every
signature a run uses is compiled, but for the kernels of runs that are rare and cheap to compile
on their own: the seed integrator's (`seed_run`, about 5 s of CPU) and a sphere alone's
(`alone_run`, about 18 s), compiled and cached by their first compiled run; then marks the cache
ready (`tier.compiled_ready`). It also writes the bytecode cache of collide's Python modules
(`write_bytecode`). The first `collide` command after install starts this in the background by
itself (`tier.start_compile`, which hands it the compile lock); run by hand (`collide engine
--compile`, the test script) it takes the lock itself, waiting for a compile that is
running rather than compile beside it.

While it runs it records how many functions it has compiled (`collide engine` shows that as a
fraction of the last compile's count); a failure is recorded with its cause in one line.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import shutil
import sys
import time
import traceback
from pathlib import Path

# How a whole compile progresses, for the first compile on a machine (later ones measure by the
# last compile there): pairs of functions compiled and the fraction of the compile's time, and
# that time in seconds, as measured here.
REFERENCE_CURVE = [[0, 0.0], [8, 0.0141], [23, 0.0232], [38, 0.0321], [53, 0.0406], [67, 0.0584],
                   [82, 0.0729], [97, 0.1239], [111, 0.1459], [126, 0.1864], [141, 0.2612], [156, 0.3507],
                   [170, 0.4195], [185, 0.4758], [200, 0.5346], [214, 0.5808], [229, 0.6139], [244, 0.8309],
                   [259, 0.8856], [273, 0.9306], [288, 1.0]]
REFERENCE_SECONDS = 85.0  # on a quiet machine; three to five times that at a load of 10


def warm() -> float:
    """Compile every kernel entry point; returns the seconds it took."""
    os.environ["COLLIDE_JIT"] = "1"
    started = time.perf_counter()
    from collide.engine import tier

    if not tier.COMPILED:
        raise RuntimeError("the engine was imported interpreted before COLLIDE_JIT=1 could apply")
    from collide.settings import COUNT_VARIABLES

    for name in COUNT_VARIABLES:  # the same kernels whatever the user's threads and frames
        os.environ.pop(name, None)
    from collide.run import run_scene
    from collide.scene import parse_scene

    bodies = [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0], "velocity": [1.0, 0.0], "spin": 1.0},
              {"name": "b", "mass": 1.0, "radius": 0.1, "position": [0.3, 0.05], "velocity": [0.0, 0.0]}]
    scene = parse_scene({"dim": 2, "contact": {"k": 1e4, "mu": 0.3}, "body": bodies})
    run_scene(scene, record=True)
    dem = parse_scene({"dim": 3, "dt": 1e-6, "duration": 2e-3,
                       "contact": {"model": "hertz", "youngs_modulus": 1e8, "restitution": 0.5, "mu": 0.3,
                                   "tangential": "spring", "rolling_friction": 0.01},
                       "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0, 0.1],
                                 "velocity": [1.0, 0.0, -1.0]}],
                       "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]})
    run_scene(dem, record=True)
    return time.perf_counter() - started


class _Progress:
    """Counts the functions numba compiles and records the count for `collide engine`."""

    def __init__(self, started: float, curve: list, seconds: float) -> None:
        self.started, self.written, self.ends = started, 0.0, []
        self.reference = {"curve": curve, "reference_seconds": seconds}

    def compiled(self) -> None:
        self.ends.append(time.time() - self.started)
        if time.time() - self.written >= 1.0:
            self.written = time.time()
            self.write()

    def write(self) -> None:
        from collide.engine import tier

        tier.write_status(state="compiling", started=self.started, done=len(self.ends), pid=os.getpid(),
                          **self.reference)

    def curve(self, points: int = 40) -> list[list[float]]:
        """This compile's progress (functions done, fraction of its time), at most `points` long."""
        total = max(self.ends[-1], 1e-9) if self.ends else 1.0
        picked = sorted({round(i * (len(self.ends) - 1) / (points - 1)) for i in range(points)}) if self.ends else []
        return [[0, 0.0]] + [[i + 1, round(self.ends[i] / total, 4)] for i in picked]


def _listen(progress: _Progress) -> None:
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, ev) -> None:
            pass

        def on_end(self, ev) -> None:
            progress.compiled()

    event.register("numba:compile", Listener())


def _reference(root: Path) -> tuple[list, float]:
    """The last whole compile's progress curve and time here (any source), or the estimate above."""
    from collide.engine.tier import _read_json

    done = [_read_json(p) for p in root.glob("collide-*/ready.json")]
    done = [d for d in done if d.get("curve") and d.get("seconds")]
    if not done:
        return REFERENCE_CURVE, REFERENCE_SECONDS
    last = max(done, key=lambda d: d["functions"])
    return last["curve"], float(last["seconds"])


def _remove_stale(root: Path, keep: Path) -> None:
    """Caches of other sources or versions are never read again: remove them (only from the
    cache beside the source; a NUMBA_CACHE_DIR may be shared by installs of other versions)."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    for old in root.glob("collide-*"):
        if not old.is_dir() or old == keep:
            continue
        try:
            fd = os.open(old / "compile.lock", os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # not while a compile of that source runs
            shutil.rmtree(old, ignore_errors=True)
        except OSError:
            pass
        finally:
            os.close(fd)


def compile_now() -> float:
    """Compile with the lock held by this process; record the outcome. Returns the seconds."""
    from collide.engine import tier

    started = time.time()
    progress = _Progress(started, *_reference(tier.cache_root()))
    progress.write()
    try:
        _listen(progress)
        seconds = warm()
    except BaseException as exc:
        reason = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}".rstrip(": ")
        tier.write_status(state="failed", started=started, seconds=time.time() - started, reason=reason,
                          done=len(progress.ends))
        raise
    tier.mark_compiled(seconds, len(progress.ends), progress.curve())
    tier.write_status(state="ready", started=started, seconds=seconds, done=len(progress.ends))
    _remove_stale(tier.cache_root(), tier.cache_dir())
    return seconds


def _take_lock(report) -> int | None:
    """Take the compile lock, waiting for a compile that holds it. Returns the descriptor, or
    None when the kernels turned out ready (the other compile did the work)."""
    from collide.engine import tier

    tier.compile_lock().parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(tier.compile_lock(), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        tier.wait_compiled(report)
        fcntl.flock(fd, fcntl.LOCK_EX)
    if tier.compiled_ready():
        os.close(fd)
        return None
    return fd


def write_bytecode() -> None:
    """Write Python's bytecode cache of collide's own packages, as pip does when it installs
    one: an editable install where Python does not write it (PYTHONDONTWRITEBYTECODE) compiled
    their source again in every process, about 0.1 s of CPU of a compiled run's start
    (docs/performance.md).
    A file Python finds out of date is compiled from source as before; one that cannot be
    written costs only that time."""
    import compileall

    root = Path(__file__).resolve().parent.parent
    for package in ("collide", "cli", "viewer"):
        if (root / package / "__init__.py").is_file():
            compileall.compile_dir(root / package, quiet=2)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    write_bytecode()
    handed = os.environ.pop("COLLIDE_COMPILE_LOCK_FD", None)
    os.environ["COLLIDE_COMPILING"] = "1"  # this process compiles: the engine must not wait for the lock
    from collide.engine import tier

    if handed is None and _take_lock(lambda s: print(f"waiting: {s.describe()}", flush=True)) is None:
        print(f"collide engine: {tier.engine_state().describe()}")
        return 0
    try:
        seconds = compile_now()
    except BaseException:
        traceback.print_exc()
        print(f"collide engine: {tier.engine_state().describe()}", file=sys.stderr)
        return 1
    print(f"collide engine compiled in {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
