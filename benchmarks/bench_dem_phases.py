"""Where a threaded DEM run's CPU time goes: the built-in pour, scaled down, run to rest.

    python benchmarks/bench_dem_phases.py [--spheres 10000] [--threads 2] [--duration 2.0]

The pour (collide/scenes/pour.toml: radii 2-3 mm, Hertz e = 0.3, tangential springs, mu = 0.5,
rolling 0.05, a loose fill 11 cm deep settling to rest) with its fill's count set to --spheres and
its box narrowed to keep the fill's packing and depth (side 0.5 m x sqrt(N / 100 000)): the same
bed, so the same contacts a sphere, at a size that runs in minutes. It runs on the threaded
driver (`collide.dem_threads`; with --threads 1, on one thread of it) and prints the process's
CPU time (every thread, `getrusage`) in each of the driver's phases: the stretches of steps on the
threads (force pass, kicks, barrier), the neighbour rebuilds (the cell grid on one thread, the rest
on all), the threads' shares of each new list, coasting, and what is left (set-up, the first force
pass, the run's end), with the load average before and after. CPU time holds under load where
wall time does not; the wall time is printed beside it.
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels

import argparse
import math
import resource
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def pour(spheres: int, duration: float) -> dict:
    """The built-in pour with `spheres` spheres in a box narrowed to keep its fill's packing."""
    raw = tomllib.loads((ROOT / "collide" / "scenes" / "pour.toml").read_text())
    side = 0.5 * math.sqrt(spheres / raw["fill"][0]["count"])
    raw["fill"][0]["count"] = spheres
    raw["fill"][0]["upper"][:2] = [side, side]
    raw["wall"][1]["point"][0] = side
    raw["wall"][3]["point"][1] = side
    raw["duration"] = duration
    return raw


def instrument(spent: dict) -> None:
    """Time the threaded driver's phases into spent[name] = [CPU, wall, calls], each phase's own
    time (a rebuild inside coasting counts as a rebuild, not as coasting)."""
    import collide.dem_threads as driver

    inside: list[list[float]] = []  # (CPU, wall) of the phases within the running one

    def timed(name, function):
        def run(*args, **kwargs):
            c0, w0 = _cpu(), time.perf_counter()
            inside.append([0.0, 0.0])
            try:
                return function(*args, **kwargs)
            finally:
                c, w = _cpu() - c0, time.perf_counter() - w0
                nested = inside.pop()
                entry = spent.setdefault(name, [0.0, 0.0, 0])
                entry[0] += c - nested[0]
                entry[1] += w - nested[1]
                entry[2] += 1
                if inside:
                    inside[-1][0] += c
                    inside[-1][1] += w
        return run

    driver._rebuild = timed("neighbour rebuilds: the threads' passes (search, carry-over, wall list)",
                            driver._rebuild)
    driver.grid = timed("neighbour rebuilds: the cell grid (one thread)", driver.grid)
    driver._Shares.__init__ = timed("threads' shares of each list", driver._Shares.__init__)
    driver._Pace.run = timed("stretches of steps on the threads", driver._Pace.run)
    driver._coast = timed("coasting (free flight)", driver._coast)
    driver._recorded_step = timed("recorded steps", driver._recorded_step)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=10000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--duration", type=float, default=2.0, help="the most it runs (it ends at rest)")
    args = parser.parse_args()
    import collide.dem
    import collide.dem_threads as driver
    from collide.run import run_scene
    from collide.scene import parse_scene

    scene = parse_scene(pour(args.spheres, args.duration))
    spent: dict = {}
    instrument(spent)
    collide.dem.run_threads = lambda n: 2  # every run on the threaded driver, with the threads asked:
    threaded = driver.dem_run_threaded
    driver.dem_run_threaded = lambda *kernel: threaded(*kernel[:-1], args.threads)
    load = os.getloadavg()[0]
    c0, w0 = _cpu(), time.perf_counter()
    result = run_scene(scene, record=False).result
    cpu, wall = _cpu() - c0, time.perf_counter() - w0
    steps = int(result.steps[0])
    print(f"\npour of {args.spheres} spheres on {args.threads} thread(s): {steps} steps to "
          f"{float(result.final.t[0]):.4f} s simulated; {cpu:.1f} s CPU, {wall:.1f} s wall; load (1 min) "
          f"{load:.1f} before, {os.getloadavg()[0]:.1f} after; {args.spheres * steps / cpu:.3g} sphere-steps a CPU "
          f"second\n")
    print("| phase | CPU s | share of CPU | wall s | calls |")
    print("|---|---|---|---|---|")
    named = 0.0
    for name, (c, w, calls) in sorted(spent.items(), key=lambda item: -item[1][0]):
        named += c
        print(f"| {name} | {c:.2f} | {c / cpu:.1%} | {w:.2f} | {calls} |")
    print(f"| the rest (set-up, the first force pass, the end) | {cpu - named:.2f} | {(cpu - named) / cpu:.1%} | | |")
    if driver.LAST_RUN.get("alone"):
        print(f"\n{driver.LAST_RUN['alone']} stretches went on one thread while the threads waited for each other "
              "(`dem_threads._Pace`: other work held the cores)")


if __name__ == "__main__":
    main()
