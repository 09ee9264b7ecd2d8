"""Start-up cost of a compiled run: the process's CPU time (user + sys) before its first step.

The bar (issue 50): a process that runs a compiled scene (`collide run billiards-break
--no-record`) spends at most 0.6 s of CPU before its first step. Each run is the real command in
a fresh process; COLLIDE_STARTUP_PROBE makes the engine write the process's CPU time when its
first kernel step starts (`collide.stepper`). With --baseline DIR (another checkout of collide
that has the probe, e.g. `git worktree add --detach ../startup-base <commit>`) the runs alternate
between the two trees, so that the machine's load falls on both alike; medians are printed with
the load average before and after. Both trees run on this script's Python (PYTHONPATH=tree), so
the baseline needs no environment of its own, only its compiled kernels: `cd DIR &&
PYTHONPATH=DIR /path/to/.venv/bin/python -m collide.warmup`.

Then a breakdown of each tree's start (medians of a few runs of a driver that calls the CLI's
`main()` as the `collide` script does, with `-X importtime`): the imports by top-level package
(the CPU of each module's own import, from a hook on `__import__`, beside importtime's wall
time, which a loaded machine inflates), and the CPU of each phase: the interpreter, importing
the CLI, importing what the run needs (imported ahead by the driver), option parsing, scene
loading, loading the compiled kernels from numba's cache, and the rest up to the first step.

    .venv/bin/python benchmarks/bench_startup.py                      # this tree, 15 runs
    .venv/bin/python benchmarks/bench_startup.py --baseline /work/wt/startup-base --runs 21
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BAR = 0.6  # s of CPU before the first step (issue 50)
COMMAND = ["run", "billiards-break", "--no-record"]

# Runs the CLI as the `collide` script does, timing its phases in CPU seconds.
DRIVER = r"""
import builtins, contextlib, functools, json, sys, time
marks = {"interpreter": time.process_time()}
# CPU of each module's own import (its imports' excluded), by top-level package
own_cpu, stack, original_import = {}, [], builtins.__import__
def timed_import(name, globals=None, locals=None, fromlist=(), level=0):
    if level or name in sys.modules:
        return original_import(name, globals, locals, fromlist, level)
    stack.append(0.0)
    started = time.process_time()
    try:
        return original_import(name, globals, locals, fromlist, level)
    finally:
        spent = time.process_time() - started
        inner = stack.pop()
        top = name.partition(".")[0]
        own_cpu[top] = own_cpu.get(top, 0.0) + spent - inner
        if stack:
            stack[-1] += spent
builtins.__import__ = timed_import
import cli.main
marks["import cli.main"] = time.process_time()
import collide.engine.tier as tier, collide.run, collide.scene, collide.summary
marks["import the run's modules"] = time.process_time()
phases = {"scene loading": 0.0, "cache loading": 0.0}
load_scene = collide.scene.load_scene
@functools.wraps(load_scene)
def timed_load(*args, **kwargs):
    started = time.process_time()
    try:
        return load_scene(*args, **kwargs)
    finally:
        phases["scene loading"] += time.process_time() - started
collide.scene.load_scene = timed_load
loading = tier.loading
@contextlib.contextmanager
def timed_loading():
    started = time.process_time()
    with loading():
        yield
    phases["cache loading"] += time.process_time() - started
tier.loading = timed_loading
app = cli.main.__dict__.get("_app") or cli.main.app
for info in app.registered_commands:
    if info.callback is not None and info.callback.__name__ == "run":
        callback = info.callback
        @functools.wraps(callback)
        def entered(*args, **kwargs):
            marks.setdefault("options parsed", time.process_time())
            return callback(*args, **kwargs)
        info.callback = entered
marks["main() called"] = time.process_time()
sys.argv = ["collide", *sys.argv[1:]]
try:
    cli.main.main()
except SystemExit:
    pass
builtins.__import__ = original_import
print("PHASES " + json.dumps({"marks": marks, "phases": phases, "imports": own_cpu}), file=sys.stderr)
"""


def bytecode(tree: Path) -> str:
    """How many of the tree's collide and cli modules have an up-to-date bytecode cache (without
    one, where PYTHONDONTWRITEBYTECODE is set, every process compiles them from source;
    `python -m collide.warmup` writes it)."""
    import importlib.util

    sources = [p for package in ("collide", "cli") for p in (tree / package).rglob("*.py")]
    fresh = 0
    for source in sources:
        cached = Path(importlib.util.cache_from_source(str(source)))
        fresh += cached.exists() and cached.read_bytes()[8:12] == int(source.stat().st_mtime).to_bytes(4, "little")
    return f"bytecode cached for {fresh} of {len(sources)} modules"


def load_average() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def collide_run(tree: Path, probe: Path) -> dict:
    """One `collide run` in a fresh process started from `tree`: the probe's line."""
    script = Path(sys.executable).parent / "collide"
    env = dict(os.environ, COLLIDE_STARTUP_PROBE=str(probe), PYTHONPATH=str(tree))
    env.pop("COLLIDE_JIT", None)
    probe.unlink(missing_ok=True)
    done = subprocess.run([sys.executable, str(script), *COMMAND], cwd=tree, env=env, capture_output=True,
                          text=True, timeout=300)
    if done.returncode != 0 or not probe.exists():
        raise SystemExit(f"{tree}: the run failed or has no probe (exit {done.returncode}): {done.stderr.strip()}")
    line = json.loads(probe.read_text().splitlines()[0])
    if not line["compiled"]:
        raise SystemExit(f"{tree}: the run was interpreted; compile first: python -m collide.warmup")
    return line


def alternated(trees: list[Path], runs: int) -> dict[Path, list[float]]:
    """CPU at the first step for `runs` runs of each tree, the trees taking turns (order reversed
    every round)."""
    cpu: dict[Path, list[float]] = {tree: [] for tree in trees}
    with tempfile.TemporaryDirectory() as tmp:
        probe = Path(tmp) / "probe.jsonl"
        for tree in trees:  # a first run each, not counted: the files into the page cache
            collide_run(tree, probe)
        for i in range(runs):
            for tree in trees if i % 2 == 0 else trees[::-1]:
                cpu[tree].append(collide_run(tree, probe)["cpu"])
    return cpu


def _package(name: str) -> str:
    top = name.strip().split(".")[0]
    if top in sys.stdlib_module_names or top.startswith("_"):
        return "(standard library)" if not top.startswith("__editable") else "(site, editable finder)"
    return top


def breakdown(tree: Path, runs: int) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    """Medians over `runs` driver runs: per package, (CPU, importtime's wall) of its modules' own
    imports, in s; and CPU per phase."""
    wall: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}
    phases: dict[str, list[float]] = {}
    probe = Path(tempfile.mkdtemp()) / "probe.jsonl"
    env = dict(os.environ, PYTHONPATH=str(tree), COLLIDE_STARTUP_PROBE=str(probe))
    env.pop("COLLIDE_JIT", None)
    for _ in range(runs):
        probe.unlink(missing_ok=True)
        done = subprocess.run([sys.executable, "-X", "importtime", "-c", DRIVER, *COMMAND], cwd=tree, env=env,
                              capture_output=True, text=True, timeout=300)
        found = re.search(r"^PHASES (.+)$", done.stderr, re.M)
        if found is None or not probe.exists():
            raise SystemExit(f"{tree}: the driver failed: {done.stderr[-2000:]}")
        own: dict[str, float] = {}
        for match in re.finditer(r"^import time:\s+(\d+) \|\s+\d+ \| (.+)$", done.stderr, re.M):
            own[_package(match[2])] = own.get(_package(match[2]), 0.0) + int(match[1]) * 1e-6
        _gather(wall, own)
        found = json.loads(found[1])
        own = {}
        for name, seconds in found["imports"].items():
            own[_package(name)] = own.get(_package(name), 0.0) + seconds
        _gather(cpu, own)
        first_step = json.loads(probe.read_text().splitlines()[0])["cpu"]
        _gather(phases, _phases(found, first_step))
    median = {k: statistics.median(v + [0.0] * (runs - len(v))) for k, v in cpu.items()}
    packages = {k: (median.get(k, 0.0), statistics.median(v + [0.0] * (runs - len(v)))) for k, v in wall.items()}
    return packages, {k: statistics.median(v) for k, v in phases.items()}


def _gather(into: dict[str, list[float]], values: dict[str, float]) -> None:
    for name, value in values.items():
        into.setdefault(name, []).append(value)


def _phases(found: dict, first_step: float) -> dict[str, float]:
    marks, timed = found["marks"], found["phases"]
    parsed = marks.get("options parsed", marks["main() called"])
    phases = {
        "interpreter and site": marks["interpreter"],
        "import cli.main (typer, the commands)": marks["import cli.main"] - marks["interpreter"],
        "import the run's modules (numpy, numba, engine)": marks["import the run's modules"] - marks["import cli.main"],
        "main() to the run command (option parsing)": parsed - marks["main() called"],
        "scene loading": timed["scene loading"],
        "cache loading (compiled kernels)": timed["cache loading"],
    }
    phases["the rest (the run's set-up: model, step, checks)"] = first_step - sum(phases.values())
    phases["at the first step (with importtime's own cost)"] = first_step
    return phases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=15, help="runs of each tree (default 15)")
    parser.add_argument("--baseline", type=Path, help="another collide checkout, compiled, to alternate with")
    parser.add_argument("--breakdown-runs", type=int, default=5, help="driver runs for the breakdown (default 5)")
    args = parser.parse_args()
    trees = [ROOT] if args.baseline is None else [args.baseline.resolve(), ROOT]
    print(f"collide {' '.join(COMMAND)}: process CPU (user + sys) at the first step, {args.runs} runs each, "
          f"alternated; load average {load_average()}")
    cpu = alternated(trees, args.runs)
    for tree, values in cpu.items():
        print(f"  {tree}: median {statistics.median(values):.3f} s (min {min(values):.3f}, max {max(values):.3f})"
              f"{'' if statistics.median(values) <= BAR else f'  over the bar of {BAR} s'}; {bytecode(tree)}")
    print(f"load average after: {load_average()}")
    for tree in trees:
        packages, phases = breakdown(tree, args.breakdown_runs)
        print(f"\n{tree}: breakdown, medians of {args.breakdown_runs} runs")
        print("  CPU by phase (s):")
        for name, seconds in phases.items():
            print(f"    {name:<50} {seconds:.3f}")
        title = "  imports by package (s; each module's own import)"
        print(f"{title:<54} {'CPU':>7} {'importtime (wall)':>18}")
        for name, (cpu, wall) in sorted(packages.items(), key=lambda kv: -kv[1][0])[:12]:
            print(f"    {name:<50} {cpu:7.3f} {wall:18.3f}")
        print(f"    {'all':<50} {sum(c for c, _ in packages.values()):7.3f} "
              f"{sum(w for _, w in packages.values()):18.3f}")


if __name__ == "__main__":
    main()
