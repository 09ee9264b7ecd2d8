"""Benchmark: what recording costs against stepping, and what the batch stepper saves.

Prints figures (medians of repeats); asserts nothing. Two parts:

1. A contact-heavy run of about 100 000 steps (demo-bonus, verlet at dt = 1.3e-7 s): time to step it,
   time to record it (`write_recording`, one `send_columns` call per entity), their ratio
   (target: recording at most 2x stepping), rows written per second, and the same data logged
   with one `rr.log` per row instead. The per-row variant is timed on the first `--log-rows`
   rows of every entity and extrapolated to all rows (it is slow); its rows are ready Arrow
   slices, so it is a lower bound on what per-frame logging costs.
2. A sweep of demo-bonus (`--sweep-runs`, default 10 000: contact.mu x ball1's velocity.y)
   through the batch stepper in chunks, against a loop of single runs timed on `--single-runs`
   of the same scenes and extrapolated.

3. `--many`: scenes of many bodies (the pile; the pour cut to 10 000 spheres for 0.03 s), each run
   in fresh processes, alternately with and without its recording: the run's CPU and wall, the
   recording's write CPU and wall, frames, size, and the process's peak RSS either way (what
   `collide.dem.FRAME_STEPS` is chosen from: writing at most the run's own cost).

Run: python benchmarks/bench_recording.py [--repeats 3] [--dt 1.3e-7] [--sweep-runs 10000]
     python benchmarks/bench_recording.py --many [--repeats 3] [--threads 1]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr

from collide import batch as lib
from collide import recording as rec
from collide.recording import writer as rec_writer
from collide.run import run_scene
from collide.scene import load_scene


def _median(xs: list[float]) -> float:
    return statistics.median(xs)


def bench_recording(dt: float, integrator: str, repeats: int, log_rows: int, folder: Path) -> None:
    scene = load_scene("demo-bonus")
    step_times, record_times = [], []
    run = None
    for _ in range(repeats):
        start = time.perf_counter()
        run = run_scene(scene, dt=dt, integrator=integrator)
        step_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        rec.write_recording(run, folder / "big.rrd")
        record_times.append(time.perf_counter() - start)
    stats = rec.last_write
    t_step, t_rec = _median(step_times), _median(record_times)
    size = (folder / "big.rrd").stat().st_size
    steps = int(run.result.steps[0])
    print(f"contact-heavy run: demo-bonus, {integrator}, dt = {dt:g} s, {steps} contact steps, "
          f"{stats.frames} frames, {stats.calls} send_columns calls, {stats.rows} rows, {size / 1e6:.1f} MB")
    print(f"  step:   {t_step:8.3f} s  (median of {repeats}: {', '.join(f'{x:.3g}' for x in step_times)})")
    print(f"  record: {t_rec:8.3f} s  (median of {repeats}: {', '.join(f'{x:.3g}' for x in record_times)})")
    print(f"  record / step = {t_rec / t_step:.3f}  (target <= 2)")
    print(f"  rows written per second: {stats.rows / t_rec:,.0f}")

    # The same entities and rows, one rr.log per row: capture what the writer sends.
    captured: list[tuple[str, list, rr.TimeColumn]] = []
    original = rec_writer._Writer._send

    def capture(self: rec_writer._Writer, entity: str, columns: object, index: rr.TimeColumn | None = None) -> None:
        cols = list(columns)
        captured.append((entity, cols, index or self.tc))
        original(self, entity, cols, index)

    rec_writer._Writer._send = capture
    try:
        rec.write_recording(run, folder / "capture.rrd")
    finally:
        rec_writer._Writer._send = original
    per_row_times = []
    for _ in range(repeats):
        per_row_times.append(_per_row_log(captured, log_rows, folder / "per-row.rrd"))
    per_row = _median(per_row_times)
    total_rows = sum(len(index.as_arrow_array()) for _, _, index in captured)
    t_log = per_row * total_rows
    print(f"  rr.log per row: {per_row * 1e6:.1f} us per row (median of {repeats}, timed on the first "
          f"{log_rows} rows of each of {len(captured)} entities), extrapolated to {total_rows} rows: "
          f"{t_log:.1f} s")
    print(f"  rr.log per row / send_columns = {t_log / t_rec:.1f}x slower")


def _per_row_log(captured: list, rows: int, path: Path) -> float:
    """Seconds per row to log the first `rows` rows of each entity with one rr.log each."""
    stream = rr.RecordingStream("collide-bench")
    stream.save(path)
    prepared = []
    for entity, cols, index in captured:
        seconds = index.as_arrow_array().cast(pa.int64()).to_numpy()[:rows] * 1e-9
        arrays = [(c.component_descriptor(), c.as_arrow_array()) for c in cols]
        prepared.append((entity, seconds, arrays))
    count = 0
    start = time.perf_counter()
    for k in range(rows):
        for entity, seconds, arrays in prepared:
            if k >= len(seconds):
                continue
            stream.set_time(rec.TIMELINE, duration=float(seconds[k]))
            stream.log(entity, [rr.DescribedComponentBatch(_Row(a[k].values), d) for d, a in arrays])
            count += 1
    stream.flush()
    elapsed = time.perf_counter() - start
    stream.disconnect()
    return elapsed / count


class _Row:
    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def bench_sweep(runs: int, single_runs: int, chunk: int, folder: Path) -> None:
    side = int(round(np.sqrt(runs)))
    sweeps = [lib.parse_sweep(f"contact.mu=0.1:1:{side}"),
              lib.parse_sweep(f"body.ball1.velocity.y=-0.2:0.2:{runs // side}")]
    plan = lib.plan_batch(["demo-bonus"], sweeps=sweeps)
    n = len(plan.specs)
    marks: list[tuple[float, int]] = []

    def progress(done: int, total: int) -> None:
        marks.append((time.perf_counter(), done))

    start = time.perf_counter()
    result = lib.run_batch(plan, summary=folder / "sweep.csv", chunk_size=chunk, progress=progress)
    total = time.perf_counter() - start
    per_chunk = [(t1 - t0) / (d1 - d0) for (t0, d0), (t1, d1) in zip(marks, marks[1:]) if d1 > d0]
    batch_per_run = _median(per_chunk)
    print(f"sweep: demo-bonus, {n} runs (contact.mu x ball1 velocity.y), chunks of {chunk}, "
          f"{result.failed} failed")
    print(f"  batch stepper: {total:.1f} s in all, {batch_per_run * 1e3:.2f} ms per run "
          f"(median over {len(per_chunk)} chunks)")
    pick = plan.specs[:: max(n // single_runs, 1)][:single_runs]
    single = []
    for spec in pick:
        t0 = time.perf_counter()
        one = run_scene(spec.scene, record=False)
        lib.outcome_rows([spec], one, one.result.wall_time_s)
        single.append(time.perf_counter() - t0)
    single_per_run = _median(single)
    print(f"  single runs:   {single_per_run * 1e3:.2f} ms per run (median of {len(pick)} spread over the "
          "grid); "
          f"extrapolated to {n} runs: {single_per_run * n:.0f} s")
    print(f"  per-run cost, single / batch = {single_per_run / batch_per_run:.1f}x")


MANY = {"pile": [], "pour-10k": ["fill.0.count=10000", "duration=0.03"]}


def _child(name: str, record: bool, out: Path) -> dict:
    """One fresh process: load, run (recorded or not), write; its figures as a dict."""
    import resource

    def cpu() -> float:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return usage.ru_utime + usage.ru_stime

    scene = load_scene(name.split("-")[0], MANY[name])
    wall, used = time.perf_counter(), cpu()
    run = run_scene(scene, record=record)
    figures = {"run_wall": time.perf_counter() - wall, "run_cpu": cpu() - used, "steps": int(run.result.steps[0]),
               "load": os.getloadavg()[0]}
    if record:
        wall, used = time.perf_counter(), cpu()
        rec.write_recording(run, out)
        figures.update(write_wall=time.perf_counter() - wall, write_cpu=cpu() - used,
                       frames=len(run.result.trajectory.knot_times), every=run.result.frame_steps,
                       mb=out.stat().st_size / 1e6)
    figures["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return figures


def bench_many(repeats: int, threads: int, folder: Path) -> None:
    import json
    import subprocess
    import sys

    env = dict(os.environ, COLLIDE_THREADS=str(threads))
    for name in MANY:
        rows: dict[bool, list[dict]] = {False: [], True: []}
        for _ in range(repeats):
            for record in (False, True):
                done = subprocess.run([sys.executable, __file__, "--child", name, str(int(record)),
                                       str(folder / "many.rrd")], capture_output=True, text=True, env=env, check=True)
                rows[record].append(json.loads(done.stdout.splitlines()[-1]))
        bare, rec_ = rows[False], rows[True]

        def med(rows: list[dict], key: str) -> float:
            return _median([r[key] for r in rows])

        loads = [r["load"] for r in bare + rec_]
        print(f"{name}: {rec_[0]['steps']} steps, {threads} thread(s), medians of {repeats} (load "
              f"{min(loads):.1f}-{max(loads):.1f})")
        print(f"  run:    {med(rec_, 'run_cpu'):.2f} s CPU, {med(rec_, 'run_wall'):.2f} s wall (recorded); "
              f"{med(bare, 'run_cpu'):.2f} s CPU unrecorded")
        print(f"  write:  {med(rec_, 'write_cpu'):.2f} s CPU, {med(rec_, 'write_wall'):.2f} s wall, "
              f"{rec_[0]['frames']} frames at least {rec_[0]['every']} steps apart, {rec_[0]['mb']:.1f} MB")
        print(f"  write / run (CPU) = {med(rec_, 'write_cpu') / med(rec_, 'run_cpu'):.2f}  (target <= 1)")
        print(f"  peak RSS: {med(bare, 'peak_mb'):.0f} MB unrecorded, {med(rec_, 'peak_mb'):.0f} MB recorded")


def main() -> None:
    import sys

    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        import json

        print(json.dumps(_child(sys.argv[2], sys.argv[3] == "1", Path(sys.argv[4]))))
        return
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dt", type=float, default=1.3e-7)
    parser.add_argument("--integrator", default="verlet")
    parser.add_argument("--log-rows", type=int, default=2000)
    parser.add_argument("--sweep-runs", type=int, default=10_000)
    parser.add_argument("--single-runs", type=int, default=200)
    parser.add_argument("--chunk", type=int, default=1000)
    parser.add_argument("--skip-recording", action="store_true")
    parser.add_argument("--skip-sweep", action="store_true")
    parser.add_argument("--many", action="store_true", help="only part 3: recordings of many bodies")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if args.many:
            bench_many(args.repeats, args.threads, folder)
            return
        if not args.skip_recording:
            bench_recording(args.dt, args.integrator, args.repeats, args.log_rows, folder)
        if not args.skip_sweep:
            bench_sweep(args.sweep_runs, args.single_runs, args.chunk, folder)


if __name__ == "__main__":
    main()
