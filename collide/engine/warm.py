"""Compile the engine's kernels into numba's on-disk cache: `python -m collide.engine.warm`.

Runs every entry point once on a tiny scene of each kind it can be called for, so that every
signature a run uses is compiled; then marks the cache ready (`tier.compiled_ready`). The
first `collide` command after install starts this in the background by itself; run it by hand
to compile in the foreground (the test script does): it first waits for a background compile
that is running, rather than compile beside it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def warm() -> float:
    """Compile every kernel entry point; returns the seconds it took."""
    os.environ["COLLIDE_JIT"] = "1"
    started = time.perf_counter()
    from collide.engine import tier

    if not tier.COMPILED:
        raise RuntimeError("the engine was imported interpreted before COLLIDE_JIT=1 could apply")
    from collide.run import run_scene
    from collide.scene import parse_scene

    bodies = [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0], "velocity": [1.0, 0.0], "spin": 1.0},
              {"name": "b", "mass": 1.0, "radius": 0.1, "position": [0.3, 0.05], "velocity": [0.0, 0.0]}]
    scene = parse_scene({"dim": 2, "contact": {"k": 1e4, "mu": 0.3}, "body": bodies})
    run_scene(scene, record=True)
    run_scene(scene, integrator="seed", dt=1e-4, record=True)
    dem = parse_scene({"dim": 3, "dt": 1e-6, "duration": 2e-3,
                       "contact": {"model": "hertz", "youngs_modulus": 1e8, "restitution": 0.5, "mu": 0.3,
                                   "tangential": "spring", "rolling_friction": 0.01},
                       "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0, 0.1],
                                 "velocity": [1.0, 0.0, -1.0]}],
                       "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]})
    run_scene(dem, record=True)
    tier.mark_compiled()
    return time.perf_counter() - started


def wait_for_background(poll: float = 1.0) -> float:
    """Wait while a background compile runs (the first `collide` command after install starts
    one): compiling beside it doubles the work on the same cache. Returns the seconds waited."""
    os.environ["COLLIDE_JIT"] = "1"  # before the engine is imported: no compile of its own starts
    from collide.engine import tier

    started = time.perf_counter()
    if tier.compiling_elsewhere():
        print("waiting for the background compile of the engine to finish", flush=True)
    while tier.compiling_elsewhere() and not tier.compiled_ready():
        time.sleep(poll)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lock", help="a lock file to remove when done (set by the background start)")
    args = parser.parse_args()
    try:
        if not args.lock:
            wait_for_background()
        seconds = warm()
        print(f"collide engine compiled in {seconds:.1f} s")
    finally:
        if args.lock:
            Path(args.lock).unlink(missing_ok=True)


if __name__ == "__main__":
    sys.exit(main())
