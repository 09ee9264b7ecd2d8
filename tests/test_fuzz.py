"""Fuzzing in the suite (issue 14): seeded, generated command lines and damaged recordings, each
held to the contract. The larger run is `python scripts/fuzz.py` (counts in the README)."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from collide.recording import RecordingError, read_recording_safely, write_recording
from collide.run import run_scene
from collide.scene import load_scene
from tests.fuzz_cases import cases, check_outcome, run_case

CASES = 300
SEED = 2024


def test_generated_command_lines_keep_the_contract(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Exit 0 with a finite JSON summary and a quiet stderr, or exit 2 with one line
    `error: ...`: never a traceback, a warning, an internal error or a hang."""
    monkeypatch.chdir(tmp_path)  # a run without --out writes into ./recordings
    problems, ran, refused = [], 0, 0
    for case in cases(SEED, CASES, tmp_path):
        outcome = run_case(case, tmp_path)
        problem = check_outcome(case, outcome)
        if problem:
            problems.append(f"case {case.number}: {problem}\n  collide {' '.join(case.argv)[:300]}")
        elif outcome.code == 0:
            ran += 1
        else:
            refused += 1
    assert not problems, "\n".join(problems[:10])
    # The generator reaches both sides of the contract, not only one of them.
    assert ran >= CASES // 10 and refused >= CASES // 2


def test_checks_catch_what_they_are_for() -> None:
    """The judge itself: each kind of broken outcome is caught."""
    from tests.fuzz_cases import Case, Outcome

    run = Case(0, ["run", "demo-1d", "--json"])
    good = '{"a": [1.0, 2]}'
    assert check_outcome(run, Outcome(0, good, "")) is None
    assert check_outcome(run, Outcome(2, "", "error: contact.k: must be positive\n")) is None
    assert "non-finite" in check_outcome(run, Outcome(0, '{"a": Infinity}', ""))
    assert "warning" in check_outcome(run, Outcome(0, good, "x.py:1: RuntimeWarning: overflow\n"))
    assert "traceback" in check_outcome(run, Outcome(1, "", "Traceback (most recent call last):\n"))
    assert "2 lines" in check_outcome(run, Outcome(2, "", "Usage: collide run\nError: bad\n"))
    assert "internal error" in check_outcome(run, Outcome(1, "", "error: internal error (KeyError: 1)\n"))
    assert "hung" in check_outcome(run, Outcome(-1, "", "", hung=True))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    run = run_scene(load_scene("demo-bonus"))
    return run, write_recording(run, tmp_path_factory.mktemp("rrd") / "bonus.rrd").read_bytes()


def test_damaged_recordings_are_refused_or_read_unchanged(recording: tuple, tmp_path: Path) -> None:
    """Truncated and bit-flipped copies: each is one `RecordingError` line, or (the damage hit
    only what is drawn) reads back exactly the original trajectory; never a crash or a change."""
    run, data = recording
    rng = random.Random(SEED)
    traj = run.result.trajectory
    refused = 0
    for n in range(24):
        damaged = bytearray(data)
        if n % 4 == 0:
            damaged = damaged[:rng.randrange(len(data))]
        else:
            for _ in range(rng.choice([1, 2, 5])):
                damaged[rng.randrange(len(damaged))] ^= 1 << rng.randrange(8)
        path = tmp_path / f"damaged{n}.rrd"
        path.write_bytes(bytes(damaged))
        try:
            back = read_recording_safely(path, timeout_s=60)
        except RecordingError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)
            refused += 1
            continue
        for table in ("knots", "records", "intervals"):
            np.testing.assert_array_equal(getattr(back.result.trajectory, table), getattr(traj, table))
    assert refused >= 12
