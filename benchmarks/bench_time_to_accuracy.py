"""Time to accuracy (issue 4's headline): `dt = auto` at several tolerances on the report's demos.

For each demo and tolerance: the chosen step, steps, the run's own wall_time_s (median of
repeats after a warm-up; simulation only, as in the JSON summary) and the error of the final
velocities and spins against a converged reference (kahan6 at omega dt = 0.005), in m/s and
rad/s. Prints, never asserts. The report's own program (rebuilt, -O2) needs dt = 1e-8 and about
0.34 s to get within 2.7e-6 on demo-bonus, and about 1 s for 1e-6 (issue 4).

    python benchmarks/bench_time_to_accuracy.py [--repeats 7]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import statistics

import numpy as np

from collide.model import compile_scenes, reference_frequency
from collide.run import run_scene
from collide.scene import load_scene

DEMOS = ("demo-1d", "demo-2d-stationary", "demo-2d-moving", "demo-bonus")
TOLS = (1e-6, 1e-7, 1e-9)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--integrator", default="kahan6")
    args = parser.parse_args()
    print(f"{'scene':<20} {'tol':>7} {'dt (s)':>10} {'steps':>6} {'wall (ms)':>10} {'err v (m/s)':>12} "
          f"{'err w (rad/s)':>13}")
    for name in DEMOS:
        scene = load_scene(name)
        model, _ = compile_scenes([scene])
        omega = float(reference_frequency(model)[0])
        ref = run_scene(scene, integrator="kahan6", dt=0.005 / omega, record=False).result
        for tol in TOLS:
            run_scene(scene, integrator=args.integrator, dt="auto", tol=tol, record=False)  # warm-up
            times = []
            for _ in range(args.repeats):
                r = run_scene(scene, integrator=args.integrator, dt="auto", tol=tol, record=False).result
                times.append(r.wall_time_s)
            err_v = float(np.abs(r.final.v - ref.final.v).max())
            err_w = float(np.abs(r.final.w - ref.final.w).max()) if r.final.w.size else 0.0
            print(f"{name:<20} {tol:>7.0e} {r.dt[0]:>10.3g} {int(r.steps[0]):>6} "
                  f"{statistics.median(times) * 1e3:>10.2f} {err_v:>12.2e} {err_w:>13.2e}")


if __name__ == "__main__":
    main()
