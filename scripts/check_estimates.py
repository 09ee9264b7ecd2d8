"""Issue 10's large check of the error estimate: random frictional scenes (2-6 balls, 2D and 3D,
with and without a floor under gravity), each run at --tol and at a 1000 times tighter one.

    python scripts/check_estimates.py [--scenes 200] [--seed 0] [--tol 1e-6] [--model-only]
                                      [--k 1e4] [--mu 0.3]

--k sets every scene's spring (default 1e4 N/m), --mu every scene's friction (0: none; default
drawn, 0.1-0.6); the scenes drawn are the same.

Printed: how many scenes had their error (against the tighter run) within the reported
error_estimate, within 10 times it, or beyond; how many measured their error; the energy balance
residuals; the worst cases. Exits 1 if any scene was beyond 10 times its estimate or had an
energy residual of 1e-4 or more.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from collide import diagnostics as dg  # noqa: E402
from collide.accuracy import outcome, speed_scale  # noqa: E402
from collide.run import run_scene  # noqa: E402
from collide.scene import SceneError  # noqa: E402
from collide.stepper import RunError  # noqa: E402
from tests.random_scenes import random_scene  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--model-only", action="store_true",
                        help="quote the error model alone (no run measures its error): how far the model holds")
    parser.add_argument("--k", type=float, default=1e4, help="every scene's spring constant, N/m")
    parser.add_argument("--mu", type=float, default=None, help="every scene's friction coefficient (0: none)")
    args = parser.parse_args()
    if not (args.k > 0 and args.tol > 0 and args.scenes > 0 and (args.mu is None or args.mu >= 0)):
        parser.error("--k, --tol and --scenes must be positive and --mu at least 0")
    rng = np.random.default_rng(args.seed)
    counts: collections.Counter[str] = collections.Counter()
    worst: list[tuple] = []
    started = time.perf_counter()
    for index in range(args.scenes):
        scene = random_scene(rng, index, k=args.k, mu=args.mu)
        try:
            run = run_scene(scene, tol=args.tol, record=False, measure=not args.model_only)
            reference = run_scene(scene, tol=args.tol / 1000, record=False, measure=not args.model_only)
        except (RunError, SceneError) as exc:
            counts["refused"] += 1
            print(f"  refused: {scene.name}: {exc}")
            continue
        error = float(np.abs(outcome(run.result) - outcome(reference.result)).max() / speed_scale(scene))
        estimate = float(run.error_estimate[0])
        energy = float(dg.residuals(run.result).energy[0])
        counts[f"error_method {run.error_method[0]}"] += 1
        counts["within the estimate" if error <= estimate else
               "within 10x the estimate" if error <= 10 * estimate else "beyond 10x the estimate"] += 1
        counts["energy residual < 1e-4" if energy < 1e-4 else "energy residual >= 1e-4"] += 1
        counts["warned"] += bool(run.result.warnings)
        worst.append((error / estimate, scene.name, scene.dim, len(scene.bodies), bool(scene.walls), error,
                      estimate, energy))
    kind = "frictional" if args.mu is None else f"mu = {args.mu:g}"
    print(f"{args.scenes} random {kind} scenes (seed {args.seed}, k = {args.k:g} N/m), tol {args.tol:g} against "
          f"{args.tol / 1000:g}, {time.perf_counter() - started:.0f} s")
    for what in sorted(counts):
        print(f"  {what}: {counts[what]}")
    print("  worst error / estimate:")
    for ratio, name, dim, n, floor, error, estimate, energy in sorted(worst, reverse=True)[:5]:
        print(f"    {ratio:8.3g}  {name} ({dim}D, {n} balls{', floor' if floor else ''}): error {error:.2g}, "
              f"estimate {estimate:.2g}, energy residual {energy:.2g}")
    bad = counts["beyond 10x the estimate"] + counts["energy residual >= 1e-4"]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
