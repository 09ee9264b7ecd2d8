"""Engine figures for the built-in scenes: steps, contacts, wall time (median of repeats, the
compiled kernels loaded before timing), energy residual. Prints a Markdown table.

    .venv/bin/python benchmarks/bench_engine.py [--repeat 5] [SCENE ...]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import statistics
import time

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import builtin_names, load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=builtin_names(heavy=False))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    run_scene(load_scene("demo-1d"), record=False)  # load the compiled kernels once
    print("| scene | bodies | steps | wall time (median) | energy residual |")
    print("|---|---|---|---|---|")
    for name in args.scenes:
        scene = load_scene(name)
        walls = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            result = run_scene(scene, record=False).result
            walls.append(time.perf_counter() - start)
        energy = dg.residuals(result).energy[0]
        print(f"| {name} | {len(scene.bodies)} | {int(result.steps[0])} | "
              f"{statistics.median(walls) * 1e3:.1f} ms | {energy:.1e} |", flush=True)


if __name__ == "__main__":
    main()
