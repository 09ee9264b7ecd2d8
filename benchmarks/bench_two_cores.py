"""What two cores of this machine give to work that shares nothing: the ceiling of any two-thread
speed-up here, measured beside the DEM kernel's own.

    python benchmarks/bench_two_cores.py [--repeats 5] [--spheres 10000] [--steps 3000]

Three jobs, each run alone and then as two copies at once, repeats alternated; a copy's time
at once against its time alone is the machine's two-way efficiency for that kind of work (1.00:
two cores do twice one core's work; a virtual machine whose two processors are one physical
core's two hyper-threads, or a memory bus the copies share, give less):

1. compute: a numba loop of arithmetic in registers (no memory touched), one copy a thread;
2. stream: a numba loop summing an array of 64 MB (larger than the caches), one a thread;
3. DEM: the box of bench_dem.py --threads (bench_liggghts' box, N spheres) on one thread, one
   copy a process (two processes: nothing in common but the machine).

Prints wall and CPU seconds a copy (medians, every run's wall), the efficiency (alone / at once;
2 x it is the two copies' speed-up) by each, and the load average at each run: on a loaded
machine the other processor is busy in both cases, and only CPU time, steadier, says anything.
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")

import argparse
import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parents[1]


@njit(nogil=True, cache=True)
def _compute(rounds: int) -> float:
    x, y = 1.0, 0.5
    for _ in range(rounds):
        x = x * 0.999999 + y * 1e-7
        y = y * 0.999998 + x * 1e-7
    return x + y


@njit(nogil=True, cache=True, fastmath=True)  # (vectorised: the loop waits on memory, not on its adds)
def _stream(a: np.ndarray, rounds: int) -> float:
    total = 0.0
    for _ in range(rounds):
        for k in range(a.shape[0]):
            total += a[k]
    return total


def _threads(job, copies: int) -> tuple[float, float]:
    """job() on `copies` threads at once: the means of their wall and CPU times."""
    spent = [(0.0, 0.0)] * copies

    def one(r: int) -> None:
        start, cpu = time.perf_counter(), time.thread_time()
        job()
        spent[r] = (time.perf_counter() - start, time.thread_time() - cpu)

    workers = [threading.Thread(target=one, args=(r,)) for r in range(copies)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    return sum(w for w, _ in spent) / copies, sum(c for _, c in spent) / copies


_DEM = """
import json, os, sys, time, tomllib, resource
sys.path.insert(0, {bench!r})
from bench_liggghts import box_case, scene_toml
from collide.run import run_scene
from collide.scene import parse_scene
scene = parse_scene(tomllib.loads(scene_toml(box_case({steps}, spheres={spheres}))))
run_scene(scene, record=False)
print("ready", flush=True)
sys.stdin.readline()
cpu = time.process_time()
result = run_scene(scene, record=False).result
print(json.dumps({{"wall": float(result.wall_time_s), "cpu": time.process_time() - cpu}}), flush=True)
"""


def _dem(copies: int, spheres: int, steps: int) -> tuple[float, float]:
    """The box on one thread in `copies` processes, started together once each has loaded its
    kernels: the means of their kernels' wall times and their runs' CPU times."""
    env = {**os.environ, "COLLIDE_THREADS": "1", "PYTHONPATH": str(ROOT)}
    code = _DEM.format(bench=str(ROOT / "benchmarks"), steps=steps, spheres=spheres)
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env=env) for _ in range(copies)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    out = [json.loads(p.stdout.readline()) for p in procs]
    for p in procs:
        p.wait()
    return sum(o["wall"] for o in out) / copies, sum(o["cpu"] for o in out) / copies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--spheres", type=int, default=10000)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--only", choices=["compute", "stream", "dem"], action="append")
    args = parser.parse_args()
    a = np.ones(8 << 20)
    jobs = {"compute": lambda copies: _threads(lambda: _compute(200_000_000), copies),
            "stream": lambda copies: _threads(lambda: _stream(a, 100), copies),
            "dem": lambda copies: _dem(copies, args.spheres, args.steps)}
    chosen = args.only or list(jobs)
    _compute(10), _stream(a[:10], 1)
    times = {(name, c): [] for name in chosen for c in (1, 2)}
    loads = {(name, c): [] for name in chosen for c in (1, 2)}
    for _ in range(args.repeats):
        for name in chosen:
            for copies in (1, 2):
                loads[name, copies].append(os.getloadavg()[0])
                times[name, copies].append(jobs[name](copies))
    print(f"\n{os.cpu_count()} cores, {args.repeats} runs each alternated (dem: {args.spheres} spheres, one thread "
          "a process)\n")
    print("| job | alone: wall s (median; runs) | CPU s | two at once, each: wall s (median; runs) | CPU s | "
          "efficiency, wall | CPU | load (1 min) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in chosen:
        alone, both = ([statistics.median(x[m] for x in times[name, c]) for m in (0, 1)] for c in (1, 2))
        runs = [", ".join(f"{x[0]:.2f}" for x in times[name, c]) for c in (1, 2)]
        load = ", ".join(f"{x:.1f}" for x in loads[name, 1] + loads[name, 2])
        print(f"| {name} | {alone[0]:.3f} ({runs[0]}) | {alone[1]:.3f} | {both[0]:.3f} ({runs[1]}) | {both[1]:.3f} | "
              f"{alone[0] / both[0]:.2f} | {alone[1] / both[1]:.2f} | {load} |")


if __name__ == "__main__":
    main()
