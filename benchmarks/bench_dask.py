"""Runs per second of a large sweep in process and on a local Dask cluster, and the scheduler's
cost per chunk (issue 13). Prints a table, never asserts.

A sweep of demo-bonus (contact.mu over [0, 1]) is planned once, then run with `run_batch`
(summary CSV written and synced as in real use) in process and through `DaskExecutor` on a
LocalCluster of `--workers` single-threaded processes on 127.0.0.1 (started once, warmed up by
a small batch so that each worker has loaded the compiled engine). The per-chunk cost is the
time per chunk of a stream of empty chunks through the same executor (nothing to compute:
what is left is submitting, scheduling, pickling and the round trips). Medians of `--repeats`.

    python benchmarks/bench_dask.py [--runs 100000] [--chunk 1000] [--workers 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

from collide import batch as lib


def _empty_chunk(specs: list, settings: lib.ChunkSettings) -> lib.ChunkResult:
    """A chunk with nothing to compute (defined in __main__: pickled by value to the workers)."""
    return lib.ChunkResult([], [])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--chunk", type=int, default=lib.DEFAULT_CHUNK)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--empty-chunks", type=int, default=400)
    args = parser.parse_args()

    from collide.distributed import DaskExecutor, connect

    began = time.perf_counter()
    plan = lib.plan_batch(["demo-bonus"], sweeps=[lib.parse_sweep(f"contact.mu=0:1:{args.runs}")])
    planning = time.perf_counter() - began

    began = time.perf_counter()
    cluster = connect("local", workers=args.workers, threads=1)  # as `--scheduler local` makes it
    executor = DaskExecutor(cluster)
    warm = lib.Plan(plan.specs[:4 * args.workers], plan.param_keys)
    lib.run_batch(warm, chunk_size=1, executor=executor)  # each worker loads the compiled engine
    startup = time.perf_counter() - began

    lib.run_batch(warm, chunk_size=1)  # this process too
    seconds: dict[str, list[float]] = {"in process": [], f"LocalCluster {args.workers}x1": []}
    cpu: dict[str, list[float]] = {label: [] for label in seconds}

    def cpu_seconds(label: str) -> float:
        """CPU time so far of the processes that compute (this one; or it and the workers)."""
        mine = time.process_time()
        if label == "in process":
            return mine
        return mine + sum(cluster.client.run(time.process_time).values())
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeats):
            for label in seconds:
                summary = Path(tmp) / f"{repeat}-{len(label)}.csv"
                began, cpu_began = time.perf_counter(), cpu_seconds(label)
                result = lib.run_batch(plan, summary=summary, chunk_size=args.chunk,
                                       executor=None if label == "in process" else executor)
                seconds[label].append(time.perf_counter() - began)
                cpu[label].append(cpu_seconds(label) - cpu_began)
                assert result.failed == 0 and len(result.rows) == args.runs

        empty = [[spec] for spec in plan.specs[:args.empty_chunks]]
        per_chunk = []
        for _ in range(args.repeats):
            began = time.perf_counter()
            for _ in DaskExecutor(cluster, task=_empty_chunk).run(empty, lib.ChunkSettings()):
                pass
            per_chunk.append((time.perf_counter() - began) / len(empty))
    cluster.close()

    print(f"demo-bonus sweep of {args.runs} runs, chunks of {args.chunk}, medians of {args.repeats}")
    print(f"planning the sweep (not in the figures below): {planning:.1f} s; "
          f"starting and warming the cluster: {startup:.1f} s")
    print(f"load average while measuring (2 cores shared with other work): {os.getloadavg()[0]:.1f}")
    print(f"{'where':<20} {'wall time (s)':>14} {'runs/s':>10} {'CPU time (s)':>13} {'runs per CPU s':>15}")
    for label, times in seconds.items():
        t, c = statistics.median(times), statistics.median(cpu[label])
        print(f"{label:<20} {t:>14.1f} {args.runs / t:>10.0f} {c:>13.1f} {args.runs / c:>15.0f}")
    cost = statistics.median(per_chunk)
    print(f"scheduler cost per chunk (stream of {len(empty)} empty chunks, {args.workers} workers): "
          f"{cost * 1e3:.1f} ms; at {args.chunk} runs per chunk that is "
          f"{cost / args.chunk * 1e6:.1f} us per run")


if __name__ == "__main__":
    main()
