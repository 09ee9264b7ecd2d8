"""Cost of whole-or-absent recordings (issue 53): a recording's write without the seal and the
check (as collide wrote it before) against the full write (sealed: SHA-256 of every byte, the
file read back and checked, fsync, rename), and the safe reader (a child process) against the
in-process one (`trusted=True`).

Run: python scripts/bench_writes.py [SCENE ...] [--set KEY=VALUE ...] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("COLLIDE_JIT", "1")

from collide import recording as rec  # noqa: E402
from collide.recording import sandbox as rec_sandbox  # noqa: E402
from collide.recording import writer as rec_writer  # noqa: E402
from collide.run import run_scene  # noqa: E402
from collide.scene import load_scene  # noqa: E402


def timed(fn, repeats: int) -> float:  # noqa: ANN001 - any callable
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        fn()
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def bench(name: str, sets: list[str], repeats: int, folder: Path) -> None:
    began = time.perf_counter()
    run = run_scene(load_scene(name, sets))
    print(f"{name}: {run.result.model.n_bodies} bodies, run {time.perf_counter() - began:.1f} s")
    path = folder / f"{name}.rrd"

    def unsealed() -> None:
        writer = rec_writer._Writer(run, 1, rec.DEFAULT_FPS, rec.CONTACT_FRAMES)
        writer.seal = False
        writer.write(folder / "plain.rrd")  # frames and Rerun's writer: what collide did before

    before = timed(unsealed, repeats)
    after = timed(lambda: rec.write_recording(run, path), repeats)
    size = path.stat().st_size / 2**20
    print(f"  write: {before:.3f} s before, {after:.3f} s sealed and checked (+{after - before:.3f} s, "
          f"{100 * (after - before) / before:+.0f} %), {size:.1f} MB")
    trusted = timed(lambda: rec.read_recording(path, trusted=True), repeats)
    rec_sandbox._stop_idle_readers()
    cold = timed(lambda: (rec_sandbox._stop_idle_readers(), rec.read_recording(path)), 1)
    warm = timed(lambda: rec.read_recording(path), repeats)
    verify = timed(lambda: rec.verify_recording(path), repeats)
    print(f"  read: in process (trusted) {trusted:.3f} s; safe {warm:.3f} s with a warm reader, "
          f"{cold:.3f} s starting one; verify only (safe, warm) {verify:.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("scenes", nargs="*", default=["demo-bonus"])
    parser.add_argument("--set", action="append", default=[])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            bench(name, args.set, args.repeats, Path(tmp))


if __name__ == "__main__":
    main()
