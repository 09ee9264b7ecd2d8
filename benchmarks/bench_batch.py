"""Per-scene cost of one batched call against single calls (issue 2, item 8).

Runs B copies of a scene with different parameters (a sweep of the friction coefficient and of
ball1's offset) through `run_scenes` in one vectorised call, and the same scenes one at a time.
Single calls are timed on a sample and their median per-scene cost is used for the ratio
(1000 single runs would take minutes); the figures are medians of repeats. Prints, never asserts.

    python benchmarks/bench_batch.py [--scene demo-bonus] [--batch 1000] [--singles 40]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import statistics
import time

import numpy as np

from collide.run import run_scene, run_scenes
from collide.scene import load_scene


def sweep(scene: str, b: int) -> list:
    mus = np.linspace(0.0, 1.0, b)
    offsets = np.linspace(-0.02, 0.02, b)
    base = load_scene(scene)
    keyed = "body.ball1.position.y" if base.dim > 1 else "body.ball1.velocity"
    scenes = []
    for mu, y in zip(mus, offsets):
        value = y if base.dim > 1 else 1.0 + y
        overrides = [f"{keyed}={value}"] + ([f"contact.mu={mu}"] if base.dim > 1 else [])
        scenes.append(load_scene(scene, overrides))
    return scenes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="demo-bonus")
    parser.add_argument("--batch", type=int, default=1000)
    parser.add_argument("--singles", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenes = sweep(args.scene, args.batch)
    batched = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        result = run_scenes(scenes, record=False).result
        batched.append((time.perf_counter() - start) / args.batch)
    sample = scenes[:: max(1, args.batch // args.singles)][: args.singles]
    singles = []
    for scene in sample:
        start = time.perf_counter()
        run_scene(scene, record=False)
        singles.append(time.perf_counter() - start)
    per_batched = statistics.median(batched)
    per_single = statistics.median(singles)
    print(f"scene {args.scene}: B = {args.batch} (friction coefficient and offset swept)")
    print(f"  steps per run: median {int(np.median(result.steps))}, max {int(result.steps.max())}")
    print(f"  batched: {per_batched * 1e3:.3f} ms per scene (median of {args.repeats} calls of "
          f"{per_batched * args.batch:.2f} s)")
    print(f"  single:  {per_single * 1e3:.3f} ms per scene (median of {len(sample)} single calls)")
    print(f"  ratio single / batched: {per_single / per_batched:.1f}x")


if __name__ == "__main__":
    main()
