"""Peak memory of a DEM settling box, collide against LIGGGHTS on the same scene.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_dem_memory.py [--spheres 100000] [--steps 200]
        [--threads N] [--np N] [--no-liggghts]

The box of benchmarks/bench_liggghts.py (spheres dropped from a lattice into a box of five
walls under gravity) with `--spheres` spheres, run for `--steps` steps by `collide run FILE
--no-record --json` and by LIGGGHTS (`liggghts -in`, or `mpirun -np N`), each under
`/usr/bin/time -v`. The figure is the peak resident memory above the same program's running
the same box with one sphere (its baseline: the interpreter, numba and the compiled kernels for
collide; the binary and its MPI for LIGGGHTS), so that what is compared is what the spheres
cost. collide reads its spheres from a body table (`[bodies] file = "spheres.npz"`), LIGGGHTS
from its data file.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_liggghts import LIGGGHTS, PROCESSES, box_case, liggghts_input, scene_toml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def collide_scene(case, workdir: Path) -> Path:
    """The case as a scene whose spheres are a body table (.npz), its walls and laws as TOML."""
    text = scene_toml(case)
    head = text.split("[[body]]")[0]
    walls = text[text.index("[[wall]]"):] if "[[wall]]" in text else ""
    pos = np.array([s.position for s in case.spheres])
    vel = np.array([s.velocity for s in case.spheres])
    table = {"name": np.array([f"s{i + 1}" for i in range(len(pos))]), "radius": np.full(len(pos), case.radius),
             "material": np.array([case.material.name] * len(pos))}
    for d, axis in enumerate("xyz"):
        table[f"position_{axis}"] = pos[:, d]
        table[f"velocity_{axis}"] = vel[:, d]
    np.savez(workdir / "spheres.npz", **table)
    path = workdir / "box.toml"
    path.write_text(head + '[bodies]\nfile = "spheres.npz"\n\n' + walls)
    return path


def peak_rss(argv: list[str], cwd: Path, env: dict | None = None) -> tuple[float, float]:
    """(peak resident memory in MB, wall seconds) of a command under /usr/bin/time -v; a collide
    summary's steps and threads are printed."""
    start = time.perf_counter()
    proc = subprocess.run(["/usr/bin/time", "-v", *argv], cwd=cwd, capture_output=True, text=True, env=env,
                          check=False)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{argv[0]} failed (exit {proc.returncode}):\n{proc.stdout[-1000:]}\n{proc.stderr[-2000:]}")
    found = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    assert found is not None
    if proc.stdout.startswith("{"):
        summary = json.loads(proc.stdout)
        print(f"collide: {summary['steps']} steps + {summary['jumps']} jumps to t = {summary['sim_time']:.4g} s on "
              f"{summary.get('threads')} threads, kernel {summary['wall_time_s']:.1f} s, process {wall:.1f} s",
              flush=True)
    return int(found.group(1)) / 1024.0, wall


def measure(spheres: int, steps: int, workdir: Path, liggghts: bool) -> dict[str, tuple[float, float]]:
    out = {}
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLLIDE_JIT="1")
    for label, n in (("baseline", 1), ("box", spheres)):
        case = box_case(steps, spheres=n)
        where = workdir / f"{label}-collide"
        where.mkdir(parents=True)
        scene = collide_scene(case, where)
        code = "import sys; from cli.main import main; sys.argv[0] = 'collide'; main()"
        out[f"collide {label}"] = peak_rss([sys.executable, "-c", code, "run", str(scene), "--no-record", "--json"],
                                           where, env)
        if liggghts:
            where = workdir / f"{label}-liggghts"
            where.mkdir(parents=True)
            inp = liggghts_input(case, where)
            mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(PROCESSES[0])] \
                if PROCESSES[0] > 1 else []
            out[f"LIGGGHTS {label}"] = peak_rss([*mpi, LIGGGHTS, "-echo", "none", "-log", "none", "-in", inp.name],
                                                where)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=100_000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--threads", type=int, help="collide's threads (COLLIDE_THREADS)")
    parser.add_argument("--np", type=int, default=1, help="LIGGGHTS processes")
    parser.add_argument("--no-liggghts", action="store_true")
    args = parser.parse_args()
    PROCESSES[0] = args.np
    if args.threads is not None:
        os.environ["COLLIDE_THREADS"] = str(args.threads)
    with tempfile.TemporaryDirectory(prefix="bench_dem_memory_") as tmp:
        got = measure(args.spheres, args.steps, Path(tmp), not args.no_liggghts)
    print(f"{args.spheres} spheres, {args.steps} steps; load average {os.getloadavg()[0]:.1f}\n")
    print("| | peak RSS, 1 sphere (MB) | peak RSS, box (MB) | above baseline (MB) | wall (s) |")
    print("|---|---|---|---|---|")
    for code in ("collide", "LIGGGHTS"):
        if f"{code} box" in got:
            base, box = got[f"{code} baseline"], got[f"{code} box"]
            print(f"| {code} | {base[0]:.0f} | {box[0]:.0f} | {box[0] - base[0]:.0f} | {box[1]:.1f} |")


if __name__ == "__main__":
    main()
