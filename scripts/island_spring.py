"""Issue 51's bar for islands with a tangential spring: random cases (tests/engine/event/test_spring.py's
`spring_case`: three spheres in a row or two on a floor, angles, spins, k_t / k_n 0.1-1.5, mu
0.02-0.9, linear or Hertz, damped or not; with --dim 3 tests/spring3d_reference.py's `case3d`:
three spheres out of a plane or two on a floor, spun about all axes, undamped), each run at --tol
1e-6, 1e-8 and 1e-10 as the CLI runs it (its error measured), and again at a hundredth of the
tolerance.

    python scripts/island_spring.py [--cases 26] [--seed 0] [--tols 1e-6,1e-8,1e-10] [--dim 2]

Printed per case and tolerance: the engine, the difference from the tighter run (over the speed),
the reported estimate and their ratio, or the cause it was handed on (or refused) with. Exits 1 if
a difference exceeds 10 times its estimate.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from collide.accuracy import outcome, speed_scale  # noqa: E402
from collide.errors import RunError  # noqa: E402
from collide.run import run_scene  # noqa: E402
from collide.scene import parse_scene  # noqa: E402
from tests.engine.event.test_spring import spring_case  # noqa: E402
from tests.spring3d_reference import case3d  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=26)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tols", default="1e-6,1e-8,1e-10")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    args = parser.parse_args()
    tols = [float(x) for x in args.tols.split(",")]
    worst, answered, handed, bad = 0.0, 0, 0, 0
    for seed in range(args.seed, args.seed + args.cases):
        raw = spring_case(seed) if args.dim == 2 else case3d(seed)
        scene = parse_scene(raw)
        law = raw["contact"]
        tag = (f"{seed:3d} {law['model']:6s} ratio {law['tangential_stiffness_ratio']:.2f} mu {law['mu']:.2f} "
               f"e {law.get('restitution', 1.0):.2f} {'floor' if 'wall' in raw else 'row'}")
        for tol in tols:
            started = time.perf_counter()
            try:
                run = run_scene(scene, tol=tol, record=False)
            except RunError as exc:
                handed += 1
                print(f"{tag} tol {tol:.0e}: refused: {str(exc)[:160]}", flush=True)
                continue
            if run.result.engine != "event":
                handed += 1
                print(f"{tag} tol {tol:.0e}: {run.result.engine}: {run.result.engine_reason[-120:]}", flush=True)
                continue
            fine = outcome(run_scene(scene, tol=tol / 100, record=False, measure=False).result)
            diff = float(np.abs(outcome(run.result) - fine).max()) / speed_scale(scene)
            estimate = float(run.error_estimate[0])
            ratio = diff / estimate
            answered += 1
            worst = max(worst, ratio)
            bad += ratio > 10.0
            print(f"{tag} tol {tol:.0e}: difference {diff:.2e} estimate {estimate:.2e} ratio {ratio:.2f} "
                  f"({time.perf_counter() - started:.1f} s)", flush=True)
    print(f"answered {answered}, handed on or refused {handed}; worst difference / estimate {worst:.2f}; "
          f"over 10: {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
