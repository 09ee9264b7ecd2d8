"""Cost against simulated time: a run twice as long should cost twice as much. Runs a scene
(by default 12 spheres stacked on a floor in 1D, elastic, bouncing for hours; found by the scene
fuzzer) at growing durations, unmeasured, and prints steps, CPU time and CPU time per step.

    .venv/bin/python benchmarks/bench_long_run.py [SCENE] [--durations 500 1000 2000 4000]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import dataclasses
import time
from pathlib import Path

from collide.run import run_scenes
from collide.scene import load_scene

STACK = Path(__file__).parent / "data" / "stack-1d-hours.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default=str(STACK))
    parser.add_argument("--durations", type=float, nargs="+", default=[500.0, 1000.0, 2000.0, 4000.0])
    args = parser.parse_args()
    scene = load_scene(args.scene)
    run_scenes([dataclasses.replace(scene, duration=1.0)], record=False, measure=False)  # load the kernels
    print(f"load average {os.getloadavg()[0]:.1f}")
    print("| duration (s) | steps | contacts | CPU time | CPU per step |")
    print("|---|---|---|---|---|")
    for duration in args.durations:
        started = time.process_time()
        result = run_scenes([dataclasses.replace(scene, duration=duration)], record=False, measure=False).result
        cpu = time.process_time() - started
        steps = int(result.steps[0])
        print(f"| {duration:g} | {steps} | {int(result.contacts.count[0])} | {cpu:.2f} s | "
              f"{cpu / steps * 1e6:.2f} us |", flush=True)


if __name__ == "__main__":
    main()
