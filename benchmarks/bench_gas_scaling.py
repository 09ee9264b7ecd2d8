"""Cost against the number of bodies: a dilute gas of N spheres in a closed box at the same
density and speeds (the built-in gas-box's: 1 cm spheres, one per 5 cm cube, 1 m/s scale),
elastic, kahan6 at tol 1e-7 for 0.1 s. Prints steps, collisions, wall time (median of repeats)
and the ratio to the smallest N; issue 9 asks 512 spheres at most 16 times the cost of 64.

    .venv/bin/python benchmarks/bench_gas_scaling.py [--sizes 64 512 4096] [--repeat 3]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import math
import statistics

import numpy as np

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import parse_scene

SPACING = 0.05  # m between sphere centres at the start: the built-in gas-box's density


def gas(n: int, seed: int = 1, duration: float = 0.1) -> dict:
    rng = np.random.default_rng(seed)
    per = math.ceil(n ** (1 / 3))
    side = per * SPACING
    cells = [(i, j, k) for i in range(per) for j in range(per) for k in range(per)][:n]
    jitter = 0.2 * (SPACING - 0.02)
    bodies = []
    for index, cell in enumerate(cells):
        position = [(c + 0.5) * SPACING + rng.uniform(-jitter, jitter) for c in cell]
        bodies.append({"name": f"p{index + 1}", "mass": 0.01, "radius": 0.01, "position": position,
                       "velocity": list(rng.normal(0.0, 1.0, 3))})
    walls = []
    for axis in range(3):
        for value, sign in ((0.0, 1.0), (side, -1.0)):
            point, normal = [0.0] * 3, [0.0] * 3
            point[axis], normal[axis] = value, sign
            walls.append({"point": point, "normal": normal})
    return {"name": f"gas-{n}", "dim": 3, "dt": "auto", "integrator": "kahan6", "tol": 1e-7,
            "duration": duration, "contact": {"k": 1e5}, "body": bodies, "wall": walls}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 512, 4096])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--duration", type=float, default=0.1)
    args = parser.parse_args()
    run_scene(parse_scene(gas(8, duration=0.01)), record=False)  # load the compiled kernels first
    print("| spheres | steps | contacts | wall time (median) | ratio to the first | energy residual |")
    print("|---|---|---|---|---|---|")
    first = None
    for n in args.sizes:
        scene = parse_scene(gas(n, duration=args.duration))
        walls = []
        for _ in range(args.repeat):
            result = run_scene(scene, record=False).result
            walls.append(result.wall_time_s)
        median = statistics.median(walls)
        first = first or median
        contacts = int(result.contacts.count[0])
        print(f"| {n} | {int(result.steps[0])} | {contacts} | {median:.3f} s | {median / first:.1f} | "
              f"{dg.residuals(result).energy[0]:.1e} |", flush=True)


if __name__ == "__main__":
    main()
