"""Issue 51's bar for two spheres: random sphere-sphere oblique impacts with friction and a
tangential spring (angle, both spins, k_t / k_n, mu, linear or Hertz, damped or not, radii and
materials: tests/engine/event/test_pair.py's `rub_case`), each run at --tol 1e-6 and 1e-9.

    python scripts/pair_oblique.py [--cases 120] [--seed 100]

Printed: how many ran in the event engine at both tolerances and how many were handed on (with
their causes), the worst difference of the outcomes (both velocities, both spins times their
radii, over the speed) and the worst ratio of that difference to the 1e-6 run's reported
estimate, the steps and wall times. Exits 1 if a difference exceeds 1e-6 or 10 times its
estimate, or fewer than 100 cases ran.
"""

from __future__ import annotations

import argparse
import collections
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from collide.errors import RunError  # noqa: E402
from tests.engine.event.test_pair import rub_case, rub_run  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=120)
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args()
    worst, worst_ratio, counted, bad = 0.0, 0.0, 0, 0
    handed = collections.Counter()
    steps, walls = [], []
    started = time.perf_counter()
    for seed in range(args.seed, args.seed + args.cases):
        case = rub_case(seed)
        try:
            (coarse, estimate, res6), (fine, _, res9) = rub_run(case, 1e-6), rub_run(case, 1e-9)
        except (RunError, AssertionError) as exc:
            handed[re.sub(r"at t = \S+ s ", "", str(exc).split(";")[0])] += 1
            continue
        counted += 1
        diff = float(np.abs(coarse - fine).max())
        ratio = diff / estimate
        worst, worst_ratio = max(worst, diff), max(worst_ratio, ratio)
        steps.append((int(res6.steps[0]), int(res9.steps[0])))
        walls.append((res6.wall_time_s, res9.wall_time_s))
        if diff > 1e-6 or ratio > 10.0:
            bad += 1
            print(f"seed {seed}: difference {diff:.2e}, {ratio:.2f} times the estimate {estimate:.2e}")
    print(f"{counted} of {args.cases} cases in the event engine at both tolerances, {sum(handed.values())} handed on")
    for cause, n in handed.most_common():
        print(f"  {n} x {cause}")
    if counted:
        s, w = np.array(steps), np.array(walls)
        print(f"worst difference {worst:.2e} of the speed, worst ratio to the estimate {worst_ratio:.3f}")
        print(f"steps per run: median {np.median(s[:, 0]):.0f} at 1e-6, {np.median(s[:, 1]):.0f} at 1e-9; "
              f"wall_time_s median {1e3 * np.median(w[:, 0]):.3f} ms at 1e-6, {1e3 * np.median(w[:, 1]):.3f} ms at "
              f"1e-9 (each run once, not its measurement)")
    print(f"total {time.perf_counter() - started:.0f} s")
    return 1 if bad or counted < 100 else 0


if __name__ == "__main__":
    sys.exit(main())
