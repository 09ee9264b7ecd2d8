"""The larger fuzz runs: random physical scenes held to the invariants (issue 53), or thousands of
generated command lines and hundreds of damaged recordings (issue 14), with the counts printed.

    python scripts/fuzz.py --count 5000 [--seed 53] [--first 0] [--found fuzz-found] [--cli-every 50]
    python scripts/fuzz.py [--cases 2000] [--recordings 200] [--seed 14]

Scenes (`--count N`) come from tests/scene_fuzz.py (the generator of tests/test_scene_fuzz.py)
and run in this process as `collide run FILE --json --no-record` runs them; every `--cli-every`
th also runs through the CLI in a child process (its one-line contract). Each must exit 0 with
the invariants kept (finite numbers, no pass-through, energy kept where nothing dissipates,
under 60 s) or be refused in one line. One line of counts per outcome is printed, then each
violation, whose scene is written to `--found` (replay: `collide run FILE`).

Command lines come from tests/fuzz_cases.py (the same generator as the test suite's fuzz, more
cases) and run in this process, as the console script runs them. Each must exit 0 with a finite
JSON summary and nothing on stderr, or exit non-zero with one line `error: ...`: no traceback,
warning, internal error or hang. Damaged recordings are truncated and bit-flipped copies of a
real one, read with `read_recording_safely`: each must read back equal to the original or be
refused with one `RecordingError` line. Exits 1 if anything broke the contract.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.fuzz_cases import cases, check_outcome, run_case  # noqa: E402


def fuzz_command_lines(seed: int, count: int) -> int:
    outcomes: collections.Counter[str] = collections.Counter()
    broken: list[str] = []
    slowest = (0.0, "")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for case in cases(seed, count, folder):
            began = time.perf_counter()
            outcome = run_case(case, folder)
            took = time.perf_counter() - began
            slowest = max(slowest, (took, " ".join(case.argv)[:160]))
            problem = check_outcome(case, outcome)
            if problem:
                outcomes["broke the contract"] += 1
                broken.append(f"case {case.number}: {problem}\n    collide {' '.join(case.argv)[:400]}")
            elif outcome.code == 0:
                outcomes["ran (exit 0, finite JSON)"] += 1
            else:
                outcomes[f"refused in one line (exit {outcome.code})"] += 1
    print(f"command lines: {count} cases (seed {seed}) in {time.perf_counter() - started:.0f} s")
    for what, n in outcomes.items():
        print(f"  {what}: {n}")
    print(f"  slowest case: {slowest[0]:.1f} s ({slowest[1]})")
    for line in broken[:40]:
        print("  " + line)
    return len(broken)


def fuzz_recordings(seed: int, count: int) -> int:
    import random

    import numpy as np

    from collide.recording import RecordingError, read_recording_safely, write_recording
    from collide.run import run_scene
    from collide.scene import load_scene

    rng = random.Random(seed)
    outcomes: collections.Counter[str] = collections.Counter()
    for what in ("refused (one RecordingError line)", "  of which Rerun's reader crashed (in the child process)",
                 "read back unchanged (the damage hit what is only drawn)"):
        outcomes[what] = 0
    broken: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        run = run_scene(load_scene("demo-bonus"))
        data = write_recording(run, folder / "original.rrd").read_bytes()
        traj = run.result.trajectory
        for n in range(count):
            damaged = bytearray(data)
            if n % 4 == 0:
                damaged = damaged[:rng.randrange(len(data))]
                how = "truncated"
            else:
                flips = rng.choice([1, 1, 2, 5, 20])
                for _ in range(flips):
                    damaged[rng.randrange(len(damaged))] ^= 1 << rng.randrange(8)
                how = f"{flips} bit flip(s)"
            path = folder / f"damaged{n}.rrd"
            path.write_bytes(bytes(damaged))
            try:
                back = read_recording_safely(path, timeout_s=30)
            except RecordingError as exc:
                text = str(exc)
                if "\n" in text or "Traceback" in text:
                    broken.append(f"{how}: a RecordingError of several lines")
                outcomes["refused (one RecordingError line)"] += 1
                outcomes["  of which Rerun's reader crashed (in the child process)"] += "crashed" in text
                continue
            except Exception as exc:  # anything else escaping is a broken contract
                broken.append(f"{how}: {type(exc).__name__}: {exc}")
                continue
            same = all(np.array_equal(getattr(back.result.trajectory, f), getattr(traj, f), equal_nan=True)
                       for f in ("knots", "records", "intervals"))
            if same:
                outcomes["read back unchanged (the damage hit what is only drawn)"] += 1
            else:
                broken.append(f"{how}: read back with changed data and no error")
    print(f"recordings: {count} damaged copies of demo-bonus (seed {seed})")
    for what, n in outcomes.items():
        print(f"  {what}: {n}")
    for line in broken[:20]:
        print("  " + line)
    return len(broken)


def _worker(conn, seed: int, max_bodies: int) -> None:
    """Runs the scenes it is sent (their numbers) and answers each verdict."""
    import random

    from tests.scene_fuzz import random_raw, run_in_process

    while True:
        i = conn.recv()
        if i is None:
            return
        verdict, _ = run_in_process(random_raw(random.Random(seed * 1_000_003 + i), max_bodies))
        conn.send(verdict)


class Runner:
    """Scenes run in a child process (this process stays the judge): a run past the time limit,
    in compiled code no alarm interrupts, is ended from here and the child replaced."""

    def __init__(self, seed: int, max_bodies: int, limit_s: float) -> None:
        self.seed, self.max_bodies, self.limit_s = seed, max_bodies, limit_s
        self.child = None

    def _start(self) -> None:
        import multiprocessing

        context = multiprocessing.get_context("fork")
        self.conn, theirs = context.Pipe()
        self.child = context.Process(target=_worker, args=(theirs, self.seed, self.max_bodies), daemon=True)
        self.child.start()

    def run(self, i: int):
        from tests.scene_fuzz import Verdict

        if self.child is None or not self.child.is_alive():
            self._start()
        began = time.perf_counter()
        self.conn.send(i)
        if self.conn.poll(self.limit_s):
            try:
                return self.conn.recv()
            except EOFError:
                pass
        crashed = self.child.is_alive() is False
        self.child.kill()
        self.child.join()
        self.child = None
        took = time.perf_counter() - began
        if crashed:
            return Verdict("violation", "crash", "the run killed its process", took)
        return Verdict("violation", "too slow", f"still running after {took:.0f} s (ended)", took)

    def close(self) -> None:
        if self.child is not None:
            self.conn.send(None)
            self.child.join(5)


def fuzz_scenes(seed: int, count: int, found: Path, cli_every: int, max_bodies: int, first: int = 0) -> int:
    """Scene i of seed S is drawn from random.Random(S * 1_000_003 + i)."""
    import random

    from collide.scene import dump_toml
    from tests.scene_fuzz import TIME_LIMIT_S, Verdict, random_raw, run_cli

    outcomes: collections.Counter[str] = collections.Counter()
    broken: list[str] = []
    slowest, worst_energy = (0.0, -1), (0.0, -1)
    started = time.perf_counter()
    runner = Runner(seed, max_bodies, 1.5 * TIME_LIMIT_S)
    for i in range(first, first + count):
        raw = random_raw(random.Random(seed * 1_000_003 + i), max_bodies)
        verdict = runner.run(i)
        slowest = max(slowest, (verdict.seconds, i))
        path = found / f"scene-{seed}-{i}.toml"
        if cli_every and i % cli_every == 0 and verdict.outcome != "violation":
            with tempfile.TemporaryDirectory() as tmp:
                text = Path(tmp) / "scene.toml"
                text.write_text(dump_toml(raw))
                by_cli = run_cli(str(text))
            outcomes["checked through the CLI"] += 1
            if by_cli.outcome == "violation":
                verdict = by_cli
            elif by_cli.outcome != verdict.outcome:
                verdict = Verdict("violation", "CLI differs",
                                  f"in process: {verdict.outcome}, CLI: {by_cli.outcome} {by_cli.message}")
        key = verdict.outcome if verdict.outcome == "ran" else f"{verdict.outcome}: {verdict.kind}"
        outcomes[key] += 1
        if verdict.energy_residual is not None:
            outcomes["ran with nothing dissipating (energy checked)"] += 1
            worst_energy = max(worst_energy, (verdict.energy_residual, i))
        if verdict.outcome == "violation":
            found.mkdir(parents=True, exist_ok=True)
            path.write_text(dump_toml(raw))
            broken.append(f"{verdict.kind}: {verdict.message[:300]}\n    collide run {path}")
            print(f"  scene {i}: {broken[-1]}", file=sys.stderr, flush=True)
        if (i + 1 - first) % 100 == 0:
            so_far = ", ".join(f"{what} {n}" for what, n in sorted(outcomes.items()))
            print(f"  ... {i + 1 - first} scenes in {time.perf_counter() - started:.0f} s: {so_far}", file=sys.stderr,
                  flush=True)
    runner.close()
    took = time.perf_counter() - started
    counts = ", ".join(f"{what} {n}" for what, n in sorted(outcomes.items()))
    print(f"scenes: {count} (seed {seed}) in {took:.0f} s: {counts}; slowest {slowest[0]:.1f} s (scene {slowest[1]}); "
          f"largest energy residual where nothing dissipates {worst_energy[0]:.2g} (scene {worst_energy[1]})")
    for line in broken:
        print("  " + line)
    return len(broken)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=None, help="random physical scenes to run")
    parser.add_argument("--found", type=Path, default=Path("fuzz-found"), help="where violating scenes go")
    parser.add_argument("--cli-every", type=int, default=50, help="run every n-th scene through the CLI too")
    parser.add_argument("--max-bodies", type=int, default=30)
    parser.add_argument("--first", type=int, default=0, help="the first scene's number (replay a stretch of a seed)")
    parser.add_argument("--cases", type=int, default=None)
    parser.add_argument("--recordings", type=int, default=None)
    parser.add_argument("--seed", type=int, default=None)
    args = parser.parse_args()
    scenes = args.count is not None
    cases = args.cases if args.cases is not None else (0 if scenes else 2000)
    recordings = args.recordings if args.recordings is not None else (0 if scenes else 200)
    broken = 0
    if scenes:
        broken += fuzz_scenes(53 if args.seed is None else args.seed, args.count, args.found, args.cli_every,
                              args.max_bodies, args.first)
    seed = 14 if args.seed is None else args.seed
    if cases:
        broken += fuzz_command_lines(seed, cases)
    if recordings:
        broken += fuzz_recordings(seed, recordings)
    print(f"broke the contract: {broken}")
    sys.exit(1 if broken else 0)


if __name__ == "__main__":
    main()
