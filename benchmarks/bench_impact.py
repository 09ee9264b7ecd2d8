"""The normal laws at full order, one contact at a time (collide/engine/event/impact.py): for a
ball dropped from 1 m on a rigid floor (linear dashpot, Hertz with its damping), the compiled
kernel's time for ten bounces, the steps per contact, and the rebound speeds' largest error
against the same chain at a 100 times finer tolerance, per tol. Prints a Markdown table.

    .venv/bin/python benchmarks/bench_impact.py [--repeat 20]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time the compiled kernel

import argparse
import math
import statistics
import time

import numpy as np

from collide.dem import damping_ratio
from collide.engine.event import impact as im


def ball(hertz: bool, e: float, young: float) -> np.ndarray:
    """The built-in bounce's ball (r 0.03 m, 1100 kg/m^3) on a rigid floor under gravity."""
    r, rho, nu = 0.03, 1100.0, 0.45
    mass = 4.0 / 3.0 * math.pi * r**3 * rho
    zeta = float(damping_ratio(np.array(e), hertz))
    return im.impact_params(hertz=hertz, mstar=mass, k=1e6, estar=young / (1 - nu * nu), rstar=r, zeta=zeta,
                            accel=9.81)


def bounces(params: np.ndarray, tol: float, count: int = 10) -> tuple[list[float], float]:
    """The rebound speeds of `count` bounces from 1 m, and the most steps one contact took."""
    n_end, n_mid = im.steps_for(tol, params)
    out = np.zeros(im.NOUT)
    v, speeds, steps = math.sqrt(2 * 9.81), [], 0.0
    for _ in range(count):
        im.impact(params, v, n_end, n_mid, out)
        if out[im.O_OK] != 1.0:
            raise SystemExit("a bounce did not separate: choose a stiffer ball or a higher restitution")
        v = out[im.O_VOUT]
        speeds.append(v)
        steps = max(steps, out[im.O_STEPS])
    return speeds, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    bounces(ball(True, 0.8, 1e9), 1e-6)  # compile (or load) the kernel before timing
    print("| law | e | tol | steps per contact (most) | ten bounces (median) | largest error of the speeds |")
    print("|---|---|---|---|---|---|")
    for hertz, young in ((False, 0.0), (True, 1e9)):
        for e in (0.6, 0.8):
            params = ball(hertz, e, young)
            for tol in (1e-6, 1e-8, 1e-9, 1e-10):
                speeds, steps = bounces(params, tol)
                finer, _ = bounces(params, tol / 100)
                error = max(abs(a / b - 1) for a, b in zip(speeds, finer))
                times = []
                for _ in range(args.repeat):
                    start = time.perf_counter()
                    bounces(params, tol)
                    times.append(time.perf_counter() - start)
                law = "hertz" if hertz else "linear"
                print(f"| {law} | {e} | {tol:.0e} | {steps:.0f} | {statistics.median(times) * 1e3:.3f} ms | "
                      f"{error:.1e} |", flush=True)


if __name__ == "__main__":
    main()
