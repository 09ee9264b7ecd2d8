"""A robustness sweep of random billiards breaks, in and out of the plane: each run as `collide
run` makes it (its error measured), every failure printed, the warnings counted. Not a test
(minutes of runs); the README's Known limits quote it.

    python scripts/sweep_breaks.py [--seed 1] [--count 200]

Each break: the cue 0, 1, 3, 5, 10 or 20 mm above the rack's plane (0 two times in seven), up to
3 cm off its line, mu 0.05-0.5, the friction band's half-width eps 1e-7 to 1e-4 m/s
(log-uniform), tol 1e-4, 1e-6 or 1e-8, and the rack turned, scaled and the cue's speed changed
as `benchmarks/bench_friction_cost.py --scan` does.
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # compiled kernels (waited for): hundreds of breaks

import argparse
import collections
import random
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from bench_friction_cost import in_plane  # noqa: E402

from collide.errors import RunError  # noqa: E402
from collide.run import run_scene  # noqa: E402
from collide.scene import load_scene, parse_scene  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--count", type=int, default=200)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    failed = 0
    warnings: collections.Counter[tuple[str, str, str]] = collections.Counter()
    runs: collections.Counter[tuple[str, str]] = collections.Counter()
    started = time.perf_counter()
    for _ in range(args.count):
        lift = rng.choice([0, 0, 0.001, 0.003, 0.005, 0.01, 0.02])
        tol = rng.choice([1e-4, 1e-6, 1e-8])
        sets = [f"tol={tol}", f"body.cue.position.y={rng.uniform(-0.03, 0.03):.4f}",
                f"contact.mu={rng.uniform(0.05, 0.5):.3f}", f"contact.eps={10 ** rng.uniform(-7, -4):.2e}"]
        change = {"angle": rng.uniform(0, 3.14), "size": rng.choice([0.7, 1.0, 1.4]),
                  "speed": rng.choice([0.5, 1.0, 2.0]), "lift": lift}
        kind = "out of the plane" if lift else "in the plane"
        runs[kind, f"{tol:g}"] += 1
        try:
            scene = parse_scene(in_plane(load_scene("billiards-break", sets).source, **change))
            for warning in run_scene(scene, record=False, measure=True).result.warnings:
                warnings[kind, f"{tol:g}", re.sub(r"\d[\d.e+-]*", "#", warning)[:40]] += 1
        except RunError as error:
            failed += 1
            print(f"failed: {' '.join(sets)} {change}: {error}", flush=True)
    print(f"{args.count} breaks (seed {args.seed}), {failed} failed, {time.perf_counter() - started:.0f} s")
    for (kind, tol), count in sorted(runs.items()):
        print(f"  {kind}, tol {tol}: {count} runs")
    for (kind, tol, text), count in sorted(warnings.items()):
        print(f"  {count} warned ({kind}, tol {tol}): {text}...")


if __name__ == "__main__":
    main()
