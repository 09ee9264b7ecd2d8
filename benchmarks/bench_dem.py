"""The DEM kernel: error against steps per contact, and throughput in particle-steps per second.

    python benchmarks/bench_dem.py [--repeats 3] [--spheres 1000] [--steps 4000]
    python benchmarks/bench_dem.py --threads 1,2 --spheres 10000 --steps 400 --repeats 5

1. Error model (`collide.dem.ERROR_CONSTANT`): for impacts on a wall (linear and Hertz, damped,
   with friction: slide and spring), the outcome's error (final velocity and spin times radius,
   relative to the impact speed) against a run at 64 times more steps per contact, for 25 to
   3200 steps per contact. Contacts switch at steps, so the error falls as 1 / steps.
2. Throughput: a granular box (Hertz, e = 0.5, tangential springs, mu = 0.5, gravity) of N
   spheres dropped from a loose lattice, run for a fixed number of steps at a fixed dt;
   particle-steps per second of the kernel's own time (`wall_time_s`), median of repeats.
3. With `--threads 1,2`: benchmarks/bench_liggghts.py's box (1 mm spheres from a lattice, in
   contact within the first steps) run on each number of threads in turn (COLLIDE_THREADS),
   repeats alternated, the kernel's wall time and the process's CPU time over it (every thread),
   medians, the speed-up of wall time and the CPU efficiency (the first count's CPU time over
   this one's) against the first, the load average at each run, and for the threaded runs the
   time on one thread in the driver, the time each thread waited at the barrier and at the other
   threads' flags, the meetings and flag waits a step and the stretches taken on one thread
   (`--no-pace`: none, whatever the load). `--spin 100000,1000000` runs each threaded count once
   with each spin of the barrier before a waiting thread sleeps (`barrier.SPIN_CYCLES`), alternated.
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import math
import statistics
import time

import numpy as np

from collide.dem import contact_time
from collide.model import compile_scenes
from collide.run import run_scene
from collide.scene import parse_scene

CASES = {
    "linear, e=0.5, coulomb": {"model": "linear", "k": 1e7, "restitution": 0.5, "mu": 0.3},
    "hertz, e=0.5, coulomb": {"model": "hertz", "restitution": 0.5, "mu": 0.3},
    "hertz, e=0.9, spring": {"model": "hertz", "restitution": 0.9, "mu": 0.3, "tangential": "spring"},
    "linear, e=0.9, spring": {"model": "linear", "k": 1e7, "restitution": 0.9, "mu": 0.3, "tangential": "spring"},
}


def impact(law: dict, per_contact: float) -> tuple[np.ndarray, float]:
    contact = {"youngs_modulus": 7e10, "poisson_ratio": 0.3, **law}
    raw = {"dim": 3, "integrator": "dem", "dt": 1.0, "contact": contact,
           "body": [{"name": "a", "radius": 0.1, "mass": 10.0, "position": [0.0, 0.0, 0.1],
                     "velocity": [0.1, 0.0, -0.2]}],
           "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]}
    scene = parse_scene(raw)
    model, state = compile_scenes([scene])
    t_c = float(contact_time(model, state)[0][0])
    raw["dt"] = t_c / per_contact
    result = run_scene(parse_scene(raw), record=False).result
    return np.concatenate((result.final.v[0, 0], 0.1 * result.final.w[0, 0])), t_c


def error_table() -> None:
    print("steps per contact | " + " | ".join(CASES))
    print("---|" + "---|" * len(CASES))
    refs = {name: impact(law, 204800)[0] for name, law in CASES.items()}
    worst = 0.0
    for n in (25, 50, 100, 200, 400, 800, 1600, 3200):
        row = []
        for name, law in CASES.items():
            out, _ = impact(law, n)
            err = float(np.abs(out - refs[name]).max() / np.hypot(0.1, 0.2))
            worst = max(worst, err * n)
            row.append(f"{err:.2e}")
        print(f"{n} | " + " | ".join(row))
    print(f"\nlargest error x steps per contact: {worst:.3g} (collide.dem.ERROR_CONSTANT should be about 2x that)")


def granular_box(n: int, steps: int) -> dict:
    r, spacing = 0.005, 0.012
    per = max(1, int(round(n ** (1 / 3))))
    rng = np.random.default_rng(1)
    bodies = []
    side = per * spacing
    while len(bodies) < n:
        k = len(bodies) // (per * per)
        i, j = divmod(len(bodies) % (per * per), per)
        pos = [(i + 0.5) * spacing + rng.uniform(-1e-4, 1e-4), (j + 0.5) * spacing + rng.uniform(-1e-4, 1e-4),
               r + 0.002 + k * spacing]
        bodies.append({"name": f"g{len(bodies)}", "material": "glass", "radius": r, "position": pos,
                       "velocity": [0.0, 0.0, 0.0]})
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    for axis in range(2):
        for value, sign in ((0.0, 1.0), (side, -1.0)):
            point, normal = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            point[axis], normal[axis] = value, sign
            walls.append({"point": point, "normal": normal})
    dt = 1e-5
    return {"dim": 3, "integrator": "dem", "dt": dt, "duration": steps * dt, "gravity": [0.0, 0.0, -9.81],
            "contact": {"model": "hertz", "restitution": 0.5, "tangential": "spring", "mu": 0.5},
            "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6, "poisson_ratio": 0.25}],
            "body": bodies, "wall": walls}


def _cycle_rate() -> float:
    """The barrier's cycle counter's ticks per second (`collide.engine.dem.barrier.cycles`)."""
    from collide.engine.dem.barrier import cycles

    c0, t0 = cycles(), time.perf_counter()
    time.sleep(0.05)
    return (cycles() - c0) / (time.perf_counter() - t0)


def thread_scan(scene, counts: list[int], repeats: int, spheres: int, spins: list[int]) -> None:
    """The box on each thread count in turn (a threaded count once for each of the barrier's
    spins, `barrier.SPIN_CYCLES`), repeats alternated: wall and CPU medians, the CPU efficiency
    (one thread's CPU over this count's: 1.0 when the threads waste nothing), the load average at
    each run, and where the threaded runs' time went (`dem_threads.LAST_RUN`)."""
    import resource

    import collide.dem
    from collide.dem_threads import LAST_RUN
    from collide.engine.dem import barrier

    spent: list[tuple[float, float]] = []
    real = collide.dem.run_members

    def timed(*args, **kwargs):
        before, start = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        out = real(*args, **kwargs)
        after = resource.getrusage(resource.RUSAGE_SELF)
        spent.append((time.perf_counter() - start,
                      after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime))
        return out

    rate = _cycle_rate()
    collide.dem.run_members = timed
    # (threads, spin): the runs' configurations; a spin counts only on several threads
    configs = [(c, s) for c in counts for s in (spins if c > 1 else spins[:1])]
    times: dict[tuple, list[tuple[float, float]]] = {c: [] for c in configs}
    loads: dict[tuple, list[float]] = {c: [] for c in configs}
    where: dict[tuple, list[tuple]] = {c: [] for c in configs}
    steps = 0
    kept = barrier.SPIN_CYCLES
    for _ in range(repeats):
        for config in configs:
            count, barrier.SPIN_CYCLES = config  # (read as each run's barrier is made)
            os.environ["COLLIDE_THREADS"] = str(count)
            loads[config].append(os.getloadavg()[0])
            LAST_RUN.clear()
            result = run_scene(scene, record=False).result
            assert result.threads == count
            times[config].append(spent[-1])
            steps = int(result.steps[0])
            if LAST_RUN:  # (a run on one thread takes the one-thread kernel)
                waited = LAST_RUN["waited"] / rate
                waits = int(LAST_RUN["meets"][0]) + float(LAST_RUN["flags"].mean())
                where[config].append((LAST_RUN["seconds"] - LAST_RUN["parallel"], float(waited.mean()),
                                     float(LAST_RUN["sleeps"].mean()) / max(1.0, waits),
                                     LAST_RUN.get("alone", 0), int(LAST_RUN["meets"][0]) / max(1, steps),
                                     float(LAST_RUN["flags"].sum()) / max(1, steps),
                                     ", ".join(f"{w:.3f}" for w in waited)))
    collide.dem.run_members = real
    barrier.SPIN_CYCLES = kept
    print(f"\n{spheres} spheres, {steps} steps, {repeats} runs each alternated, on {os.cpu_count()} cores\n")
    label = {c: f"{c[0]}" if len(spins) == 1 or c[0] == 1 else f"{c[0]}, spin {c[1]:,}" for c in configs}
    print("| threads | wall s (median; runs) | CPU s (median; runs) | load (1 min) at each run | "
          "particle-steps/s wall | per CPU s | speedup wall | CPU efficiency |")
    print("|---|---|---|---|---|---|---|---|")
    base = None
    for config in configs:
        wall = statistics.median(w for w, _ in times[config])
        cpu = statistics.median(c for _, c in times[config])
        base = base or (wall, cpu)
        walls = ", ".join(f"{w:.2f}" for w, _ in times[config])
        cpus = ", ".join(f"{c:.2f}" for _, c in times[config])
        load = ", ".join(f"{x:.1f}" for x in loads[config])
        print(f"| {label[config]} | {wall:.3f} ({walls}) | {cpu:.3f} ({cpus}) | {load} | "
              f"{spheres * steps / wall:.3g} | {spheres * steps / cpu:.3g} | {base[0] / wall:.2f} | "
              f"{base[1] / cpu:.2f} |")
    if any(where.values()):
        print("\nThreaded runs (medians): seconds on one thread in the driver (the rebuilds' cell grid, coasting, "
              "hand-offs), seconds a thread waited at the barrier and at other threads' flags (mean of the threads; "
              "each thread's, of the run with the median mean), share of waits at which it slept, barrier meetings a "
              "step, flags waited for a step (all threads), stretches of steps taken on one thread as the threads "
              "waited too long (`dem_threads._Pace`)\n")
        print("| threads | driver s | waited s | each thread's | slept | meetings a step | flag waits a step | "
              "stretches on one thread |")
        print("|---|---|---|---|---|---|---|---|")
        for config in configs:
            if where[config]:
                serial, waited, slept, alone, meets, flags = (statistics.median(x[c] for x in where[config])
                                                              for c in range(6))
                each = sorted(where[config], key=lambda x: x[1])[len(where[config]) // 2][6]
                print(f"| {label[config]} | {serial:.3f} | {waited:.3f} | {each} | {slept:.1%} | {meets:.2f} | "
                      f"{flags:.2f} | {alone:g} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--spheres", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--skip-errors", action="store_true")
    parser.add_argument("--threads", help="thread counts to compare, e.g. 1,2 (skips the error table)")
    parser.add_argument("--spin", default=None,
                        help="with --threads: the barrier's spins before a waiting thread sleeps, in cycles, e.g. "
                             "100000,1000000 (each threaded count runs once with each, alternated; default "
                             "`barrier.SPIN_CYCLES`)")
    parser.add_argument("--no-pace", action="store_true",
                        help="with --threads: every stretch of steps on all the threads, however long they wait "
                             "(`dem_threads._Pace` off), for the threaded kernel's own CPU cost on a loaded machine")
    args = parser.parse_args()
    if args.threads:
        import sys
        import tomllib

        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from bench_liggghts import box_case, scene_toml  # the box LIGGGHTS runs too

        scene = parse_scene(tomllib.loads(scene_toml(box_case(args.steps, spheres=args.spheres))))
        if args.no_pace:
            from collide.dem_threads import _Pace

            _Pace.WAITED = math.inf
        run_scene(scene, record=False)  # load (or compile) the kernels
        from collide.engine.dem.barrier import SPIN_CYCLES

        spins = [int(c) for c in args.spin.split(",")] if args.spin else [SPIN_CYCLES]
        thread_scan(scene, [int(c) for c in args.threads.split(",")], args.repeats, args.spheres, spins)
        return
    if not args.skip_errors:
        error_table()
    scene = parse_scene(granular_box(args.spheres, args.steps))
    run_scene(scene, record=False)  # load the compiled kernel
    times, steps = [], 0
    for _ in range(args.repeats):
        result = run_scene(scene, record=False).result
        times.append(result.wall_time_s)
        steps = int(result.steps[0])
    median = statistics.median(times)
    print(f"\ngranular box: {args.spheres} spheres, {steps} steps at dt = 1e-5 s: median {median:.3f} s "
          f"({min(times):.3f}-{max(times):.3f}), {args.spheres * steps / median:.3g} particle-steps/s")


if __name__ == "__main__":
    main()
