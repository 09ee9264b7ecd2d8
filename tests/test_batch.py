"""Batches: sweep syntax, sweeps equal single runs, interrupt and resume, the CLI's errors."""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from collide import batch as lib
from collide.batch import BatchError, parse_sweep, parse_vary, plan_batch, read_summary, run_batch
from collide.run import run_scene
from collide.scene import SceneError, load_scene

COLLIDE = Path(sys.executable).parent / "collide"


# ---------------------------------------------------------------------------------------------
# Syntax


def test_parse_sweep() -> None:
    sweep = parse_sweep("contact.mu=0:1:11")
    assert (sweep.key, sweep.num) == ("contact.mu", 11)
    np.testing.assert_array_equal(sweep.values, np.linspace(0, 1, 11))
    assert parse_sweep(" body.ball1.velocity.y = -0.5:0.5:101 ").values[50] == 0.0
    assert list(parse_sweep("contact.k=1e3:2e3:1").values) == [1000.0]


@pytest.mark.parametrize("text, words", [
    ("contact.mu", "key=value"),
    ("contact.mu=0:1", "start:stop:num"),
    ("contact.mu=0:1:2:3", "start:stop:num"),
    ("contact.mu=a:1:3", "numbers"),
    ("contact.mu=0:1:0", "at least 1"),
    ("contact.mu=0:1:-2", "whole number"),
    ("contact.mu=0:1:2.5", "whole number"),
    ("=0:1:3", "bad key"),
    ("contact.mu=0:inf:3", "finite"),
])
def test_bad_sweeps_say_why(text: str, words: str) -> None:
    with pytest.raises(BatchError, match=words):
        parse_sweep(text)


def test_parse_vary() -> None:
    assert parse_vary("contact.k=1500+-30") == lib.Vary("contact.k", 1500.0, 30.0)
    assert parse_vary("contact.mu=0.5±0.1") == lib.Vary("contact.mu", 0.5, 0.1)
    for bad in ("contact.k=1500", "contact.k=1500+-x", "contact.k=1500+--3"):
        with pytest.raises(BatchError):
            parse_vary(bad)


def test_grid_order_and_ids() -> None:
    plan = plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.mu=0:1:3"),
                                              parse_sweep("body.ball1.velocity.y=-0.5:0.5:2")])
    assert [s.run_id for s in plan.specs] == ["0000", "0001", "0002", "0003", "0004", "0005"]
    assert [tuple(s.params.values()) for s in plan.specs] == [
        (0.0, -0.5), (0.0, 0.5), (0.5, -0.5), (0.5, 0.5), (1.0, -0.5), (1.0, 0.5)]
    assert plan.specs[3].scene.contact.mu == 0.5
    assert plan.specs[3].scene.bodies[0].velocity == (1.0, 0.5)


def test_unknown_keys_and_invalid_values_fail_before_running(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="nonsense"):
        plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.nonsense=0:1:3")])
    with pytest.raises(SceneError, match="contact.k"):
        plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.k=-10:10:3")])
    with pytest.raises(BatchError, match="no .toml"):
        plan_batch([str(tmp_path)])
    with pytest.raises(BatchError, match="not both"):
        plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.mu=0:1:3")],
                   varies=[parse_vary("contact.k=1+-1")])


def test_folder_of_scenes(tmp_path: Path) -> None:
    from collide.scene import builtin_text

    (tmp_path / "b.toml").write_text(builtin_text("demo-1d").replace('name = "demo-1d"', 'name = "second"'))
    (tmp_path / "a.toml").write_text(builtin_text("demo-1d"))
    (tmp_path / "notes.txt").write_text("ignored")
    plan = plan_batch([str(tmp_path), "demo-bonus"])
    assert [s.scene.name for s in plan.specs] == ["demo-1d", "second", "demo-bonus"]


def test_vary_redraws_invalid_draws_and_is_reproducible() -> None:
    varies = [parse_vary("contact.mu=0.05+-0.1")]
    a = plan_batch(["demo-bonus"], varies=varies, samples=40, seed=3)
    b = plan_batch(["demo-bonus"], varies=varies, samples=40, seed=3)
    assert len(a.specs) == 40
    assert [s.params for s in a.specs] == [s.params for s in b.specs]
    assert all(s.scene.contact.mu >= 0 for s in a.specs)
    assert a.notes and "again" in a.notes[0] and "contact.mu" in a.notes[0]


# ---------------------------------------------------------------------------------------------
# Runs


def _floats(row: dict[str, str], columns: list[str]) -> np.ndarray:
    return np.array([float(row[c]) for c in columns])


def test_sweep_rows_equal_single_runs(tmp_path: Path) -> None:
    plan = plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.mu=0:0.6:2"),
                                              parse_sweep("body.ball1.velocity.y=-0.2:0.2:2")])
    result = run_batch(plan, summary=tmp_path / "s.csv")
    assert result.failed == 0 and len(result.rows) == 4
    outcome = lib.outcome_columns(plan.specs[0].scene)
    for spec, row in zip(plan.specs, read_summary(tmp_path / "s.csv")[1]):
        overrides = [f"{k}={v!r}" for k, v in spec.params.items()]
        single = run_scene(load_scene("demo-bonus", overrides), record=False).result
        expected = []
        for n in range(2):
            expected += list(single.final.v[0, n]) + [single.final.w[0, n, 0]]
            expected.append(float(lib.deflection_deg(single.initial.v[0, n], single.final.v[0, n])))
        np.testing.assert_allclose(_floats(row, outcome), expected, rtol=0, atol=1e-12)
        assert int(row["steps"]) == int(single.steps[0])
        assert float(row["contact.mu"]) == spec.params["contact.mu"]


def test_a_sweep_of_a_wall_runs_each_member_with_its_own_wall(tmp_path: Path) -> None:
    """Walls are the batch model's, not a member's: a sweep of a wall's normal ran the members of
    each vectorised call against the first one's wall (8 of 11 rows repeated others, silently).
    Members with walls elsewhere are run apart, each equal to its single run."""
    scene = tmp_path / "wall-ball.toml"
    scene.write_text('name = "wall-ball"\ndim = 2\n[contact]\nk = 1e5\nmu = 0.3\n'
                     '[[body]]\nname = "ball"\nmass = 0.1\nradius = 0.05\nposition = [0.0, 0.0]\n'
                     'velocity = [1.0, 0.0]\n[[wall]]\npoint = [0.5, 0.0]\nnormal = [-1.0, 0.0]\n')
    plan = plan_batch([str(scene)], sweeps=[parse_sweep("wall.0.normal.y=-0.5:0.5:7")])
    result = run_batch(plan, summary=tmp_path / "s.csv")
    assert result.failed == 0
    rows = read_summary(tmp_path / "s.csv")[1]
    for spec, row in zip(plan.specs, rows):
        single = run_scene(load_scene(str(scene), [f"wall.0.normal.y={spec.params['wall.0.normal.y']!r}"]),
                           record=False).result
        np.testing.assert_allclose(_floats(row, ["ball.velocity.x", "ball.velocity.y"]), single.final.v[0, 0],
                                   rtol=0, atol=1e-12)
    # Mirror images: the walls tilted either way turn the ball either way.
    vy = [float(row["ball.velocity.y"]) for row in rows]
    np.testing.assert_allclose(vy, [-y for y in vy[::-1]], atol=1e-9)


def test_mixed_shapes_are_grouped(tmp_path: Path) -> None:
    # mu = 0 with no spin is another shape than mu > 0: they run in separate vectorised calls.
    plan = plan_batch(["demo-2d-moving"], sweeps=[parse_sweep("contact.mu=0:0.4:3")])
    result = run_batch(plan, dt=1e-4, summary=tmp_path / "s.csv")
    assert result.failed == 0
    assert [r["contact.mu"] for r in result.rows] == ["0.0", "0.2", "0.4"]
    assert "ball1.spin" in result.header and result.rows[0]["ball1.spin"] == "0.0"


def test_failed_runs_are_rows_not_crashes(tmp_path: Path) -> None:
    # The stiffest k makes dt = 1e-3 unstable: that run fails with a message, the others run.
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.k=100:1e9:3")])
    result = run_batch(plan, dt=1e-4, summary=tmp_path / "s.csv")
    errors = [r["error"] for r in result.rows]
    assert result.failed >= 1 and errors[0] == "" and "dt" in errors[-1]


def _without_wall_time(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k != "wall_time_s"} for r in rows]


def test_interrupt_then_resume_equals_uninterrupted(tmp_path: Path) -> None:
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep("body.ball1.velocity=0.5:1.5:9")])
    full = tmp_path / "full.csv"
    run_batch(plan, dt=1e-4, summary=full, chunk_size=2)

    part = tmp_path / "part.csv"
    records = tmp_path / "rrd"
    calls = []

    def stop_after_two_chunks(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == 3:  # the initial call, then two chunks
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(plan, dt=1e-4, summary=part, record_dir=records, chunk_size=2,
                  progress=stop_after_two_chunks)
    header, rows = read_summary(part)
    finished = calls[-1]
    assert 2 <= finished <= 4 and len(rows) == finished  # sub-chunks of 1, then up to 2 runs
    assert sorted(p.name for p in records.iterdir()) == [lib.recording_name(s) for s in plan.specs[:finished]]
    assert not [p for p in tmp_path.rglob("*.tmp")]

    result = run_batch(plan, dt=1e-4, summary=part, record_dir=records, chunk_size=2, resume=True)
    assert (result.ran, result.skipped) == (9 - finished, finished)
    assert len(list(records.glob("*.rrd"))) == 9
    full_header, full_rows = read_summary(full)
    header, rows = read_summary(part)
    assert header == full_header
    assert _without_wall_time(rows) == _without_wall_time(full_rows)


def test_resume_refuses_another_batch(tmp_path: Path) -> None:
    summary = tmp_path / "s.csv"
    first = plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.k=1000:2000:2")])
    run_batch(first, dt=1e-4, summary=summary)
    other = plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.k=1000:3000:2")])
    with pytest.raises(BatchError, match="other parameters"):
        run_batch(other, summary=summary, resume=True)
    with pytest.raises(BatchError, match="other columns"):
        run_batch(plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.mu=0:1:2")]), summary=summary,
                  resume=True)


def test_ensemble_stats() -> None:
    rows = [{"a": "1.0"}, {"a": "3.0"}, {"a": ""}]
    (stat,) = lib.ensemble_stats(rows, ["a", "missing"])
    assert (stat.mean, stat.std, stat.count) == (2.0, pytest.approx(np.sqrt(2.0)), 2)


def test_safe_recording_names() -> None:
    params = {"body.ball1.velocity.y": -0.25, "contact.mu": 1 / 3}
    spec = lib.RunSpec("0007", load_scene("demo-bonus"), params)
    name = lib.recording_name(spec)
    assert name == "0007_demo-bonus_body.ball1.velocity.y=-0.25_contact.mu=0.333333.rrd"
    assert lib.safe_name("a/b c:*?") == "a_b_c"


# ---------------------------------------------------------------------------------------------
# The command line


def _collide(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(COLLIDE), *args], capture_output=True, text=True, cwd=cwd, timeout=120)



@pytest.mark.parametrize("args, words", [
    (["demo-bonus", "--sweep", "contact.mu=0:1"], "start:stop:num"),
    (["demo-bonus", "--sweep", "contact.mu=0:1:0"], "at least 1"),
    (["demo-bonus", "--sweep", "contact.bogus=0:1:2"], "bogus"),
    (["demo-bonus", "--vary", "contact.k=1500"], "mean+-std"),
    (["emptydir"], "no .toml"),
    ([], "no scenes"),
    (["demo-bonus", "--samples", "5"], "go with --vary"),
])
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture, args: list[str],
                                              words: str) -> None:
    from cli.main import main

    (tmp_path / "emptydir").mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["collide", "batch", *args, "--no-progress"])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0]
    assert not (tmp_path / "recordings").exists()


def test_cli_sweep_prints_paths_and_writes_rows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture) -> None:
    from cli.main import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["collide", "batch", "demo-1d", "--sweep", "contact.k=1000:2000:3",
                                      "--dt", "1e-4", "--record", "rrd"])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code in (0, None)
    out, err = capsys.readouterr()
    assert "summary: recordings/batch-summary.csv" in out and "recordings: rrd/ (3 written)" in out
    assert "runs: 3/3" in err  # progress on stderr
    # One sentence a reader can take in: "3 runs in 0.1 s (33 ms each), 0 failed" (issue 12:
    # it read "3 runs: 3 run in").
    assert re.search(r"^3 runs in [0-9.e+-]+ s \([0-9.e+-]+ ms each(, after [0-9.e+-]+ s loading the compiled "
                     r"engine)?\), 0 failed$", out, re.M), out
    header, rows = read_summary(tmp_path / "recordings" / "batch-summary.csv")
    assert header[:3] == ["run_id", "scene", "contact.k"] and "ball1.velocity.x" in header
    assert [r["contact.k"] for r in rows] == ["1000.0", "1500.0", "2000.0"]


def test_cli_sigint_then_resume(tmp_path: Path) -> None:
    if not COLLIDE.exists():
        pytest.skip("collide is not installed next to python")
    args = ["batch", "demo-1d", "--sweep", "body.ball1.velocity=0.5:1.5:40", "--chunk", "1",
            "--summary", "s.csv"]
    proc = subprocess.Popen([str(COLLIDE), *args], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    seen = 0
    deadline = time.monotonic() + 60
    while seen < 3 and time.monotonic() < deadline:  # wait for a few chunks to finish
        ready, _, _ = select.select([proc.stderr], [], [], max(deadline - time.monotonic(), 0.0))
        line = proc.stderr.readline() if ready else ""
        if not line and proc.poll() is not None:
            break
        seen += line.startswith("runs: ")
    os.kill(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 130)
    if proc.returncode == 130:
        assert "--resume" in err
        _, rows = read_summary(tmp_path / "s.csv")
        assert 2 <= len(rows) < 40
    out = _collide(*args, "--resume", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "summary: s.csv" in out.stdout
    assert _collide(*args[:-1], "full.csv", cwd=tmp_path).returncode == 0
    assert _without_wall_time(read_summary(tmp_path / "s.csv")[1]) == \
        _without_wall_time(read_summary(tmp_path / "full.csv")[1])


# ---------------------------------------------------------------------------------------------
# Durability: finished runs survive a kill; a resume trusts only complete rows


def _rows_on_disk(path: Path) -> dict[str, list[str]]:
    """Run id -> fields of every complete row of a summary (a line ending in a newline, with
    as many fields as the header), read without the library's own parser."""
    import csv

    lines = path.read_text().split("\n")[:-1]
    header = next(csv.reader([lines[0]]))
    rows = [next(csv.reader([line]), []) for line in lines[1:]]
    return {r[0]: r for r in rows if len(r) == len(header)}


def test_resume_reruns_a_row_cut_short(tmp_path: Path) -> None:
    # The recipe: five runs, the last 280 bytes cut off, then --resume.
    plan = plan_batch(["demo-bonus"], sweeps=[parse_sweep("contact.mu=0:1:5")])
    summary = tmp_path / "S.csv"
    run_batch(plan, summary=summary)
    full = read_summary(summary)[1]
    with open(summary, "r+b") as f:
        f.truncate(summary.stat().st_size - 280)
    result = run_batch(plan, summary=summary, resume=True)
    assert (result.ran, result.skipped) == (1, 4)
    assert any("cut short" in note for note in result.notes)
    assert _without_wall_time(read_summary(summary)[1])[:4] == _without_wall_time(full)[:4]
    assert _without_wall_time(read_summary(summary)[1]) == _without_wall_time(full)


@pytest.mark.parametrize("damage", ["fields missing", "number garbled", "steps garbled"])
def test_resume_reruns_a_malformed_row(tmp_path: Path, damage: str) -> None:
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.k=1000:2000:3")])
    summary = tmp_path / "S.csv"
    run_batch(plan, dt=1e-4, summary=summary)
    full = read_summary(summary)[1]
    header, *lines = summary.read_text().splitlines()
    fields = lines[1].split(",")
    column = header.split(",")
    if damage == "fields missing":
        fields = fields[:6]
    elif damage == "number garbled":
        fields[column.index("ball1.velocity.x")] = "-1.87e"
    else:
        fields[column.index("steps")] = "12.5"
    lines[1] = ",".join(fields)
    summary.write_text("\n".join([header, *lines]) + "\n")
    result = run_batch(plan, dt=1e-4, summary=summary, resume=True)
    assert (result.ran, result.skipped) == (1, 2)
    assert _without_wall_time(read_summary(summary)[1]) == _without_wall_time(full)


def test_resume_reruns_a_run_whose_recording_is_missing_and_removes_temporaries(tmp_path: Path) -> None:
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep("contact.k=1000:2000:3")])
    summary, records = tmp_path / "S.csv", tmp_path / "rrd"
    run_batch(plan, dt=1e-4, summary=summary, record_dir=records)
    (records / lib.recording_name(plan.specs[2])).unlink()
    name = lib.recording_name(plan.specs[2])
    stale = [records / f".{name}.0123abcd.tmp", tmp_path / ".S.csv.89abcdef.tmp"]
    foreign = records / ".someone-else.rrd.0123abcd.tmp"
    for path in [*stale, foreign]:
        path.write_bytes(b"half a file")
    result = run_batch(plan, dt=1e-4, summary=summary, record_dir=records, resume=True)
    assert (result.ran, result.skipped) == (1, 2)
    assert (records / name).is_file()
    assert not any(p.exists() for p in stale) and foreign.exists()  # only this batch's leftovers


_KILL_INSIDE_A_CHUNK = """
import os, signal, sys
from pathlib import Path
from collide import batch as lib
from collide.engine import seed
from collide.engine.event import run

started = 0


class Counted:  # a kernel that kills the process, as the OOM killer would, when it starts the n-th run

    def __init__(self, real):
        self.real = real

    def __getattr__(self, name):
        return getattr(self.real, name)

    def __call__(self, *args):
        global started
        started += 1
        if started == int(sys.argv[2]):
            os.kill(os.getpid(), signal.SIGKILL)
        return self.real(*args)


run.simulate, seed.seed_run = Counted(run.simulate), Counted(seed.seed_run)
plan = lib.plan_batch(["demo-1d"], sweeps=[lib.parse_sweep("body.ball1.velocity=0.5:1.5:12")])
lib.run_batch(plan, dt=1e-4, summary=Path(sys.argv[1]))  # the default chunk of 1000 runs
"""


def test_finished_runs_survive_sigkill_inside_a_chunk(tmp_path: Path) -> None:
    summary = tmp_path / "S.csv"
    proc = subprocess.run([sys.executable, "-c", _KILL_INSIDE_A_CHUNK, str(summary), "11"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    rows = _rows_on_disk(summary)
    # Ten runs had finished; the stepper takes them in sub-chunks of 1, 2, 4, ... runs (each
    # about a second at most), so at most the sub-chunk being run is lost.
    assert len(rows) >= 5 and set(rows) == {f"{i:04d}" for i in range(len(rows))}
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep("body.ball1.velocity=0.5:1.5:12")])
    result = run_batch(plan, dt=1e-4, summary=summary, resume=True)
    assert (result.ran, result.skipped) == (12 - len(rows), len(rows))
    full = tmp_path / "full.csv"
    run_batch(plan, dt=1e-4, summary=full)
    assert _without_wall_time(read_summary(summary)[1]) == _without_wall_time(read_summary(full)[1])


@pytest.mark.slow
def test_sigkill_at_random_moments_then_resume_equals_uninterrupted(tmp_path: Path) -> None:
    """A real `collide batch` killed with SIGKILL ten times at random moments (seeded), each time
    resumed: after every kill each complete recording has its row; a last --resume then
    finishes the batch exactly as an uninterrupted one, with no temporary file left."""
    import random

    if not COLLIDE.exists():
        pytest.skip("collide is not installed next to python")
    sweep = "body.ball1.velocity=0.5:1.5:400"
    args = ["batch", "demo-1d", "--sweep", sweep, "--dt", "1e-4", "--summary", "s.csv", "--record", "rrd",
            "--chunk", "20", "--resume"]
    rng = random.Random(14)
    kills = 0
    for attempt in range(10):
        proc = subprocess.Popen([str(COLLIDE), *args], cwd=tmp_path, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # the batch is running once it reports progress
            ready, _, _ = select.select([proc.stderr], [], [], 1.0)
            line = proc.stderr.readline() if ready else ""
            if line.startswith("runs: ") or (not line and proc.poll() is not None):
                break
        # Under load a run can take longer than every random moment below: the last kill waits
        # for a first finished row, so the batch is killed part way, not before it began.
        summary = tmp_path / "s.csv"
        while attempt == 9 and not (summary.exists() and summary.read_text().count("\n") > 1) \
                and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        # Ten moments of 0.5 s on average: half the batch's work on this machine (400 runs, 9 s).
        time.sleep(rng.uniform(0.0, 1.0))
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            kills += 1
        proc.wait(timeout=60)
        proc.stderr.close()
        rows = _rows_on_disk(tmp_path / "s.csv")
        complete = {p.name.split("_")[0] for p in (tmp_path / "rrd").glob("*.rrd")}
        assert complete <= set(rows), f"complete recordings without their row: {sorted(complete - set(rows))}"
    assert kills == 10
    assert 0 < len(_rows_on_disk(tmp_path / "s.csv")) < 400  # killed part way
    out = _collide(*args, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    plan = plan_batch(["demo-1d"], sweeps=[parse_sweep(sweep)])
    full = run_batch(plan, dt=1e-4, summary=tmp_path / "full.csv")  # rows do not depend on recording
    assert _without_wall_time(read_summary(tmp_path / "s.csv")[1]) == _without_wall_time(full.rows)
    assert sorted(p.name for p in (tmp_path / "rrd").iterdir()) == sorted(lib.recording_name(s) for s in plan.specs)


def test_batch_says_the_engine_loading_apart_from_the_runs(tmp_path: Path) -> None:
    """Loading the compiled engine (a process's one-time cost: 0.02-0.05 s now that kernels load
    when first called, more on a slow disk) is measured and not spread over the runs: the 20 runs
    of demo-bonus add up to well under the total less half the loading (spread, they would add up
    to the total). Not a closer comparison: the runs' sum against the total less loading moved by
    70 % with two test suites on the machine's two cores."""
    from collide.engine import tier

    if not COLLIDE.exists() or not tier.compiled_ready():
        pytest.skip("needs the compiled engine (python -m collide.warmup) and the collide command")
    env = {**os.environ, "COLLIDE_JIT": "1"}
    out = subprocess.run([str(COLLIDE), "batch", "demo-bonus", "--sweep", "contact.mu=0.1:0.3:20", "--summary",
                          "s.csv"], capture_output=True, text=True, cwd=tmp_path, timeout=300, env=env)
    assert out.returncode == 0, out.stderr
    found = re.search(r"^20 runs in ([0-9.e+-]+) s \(([0-9.e+-]+) ms each, after ([0-9.e+-]+) s loading the "
                      r"compiled engine\), 0 failed$", out.stdout, re.M)
    assert found, out.stdout
    total, each, load = (float(x) for x in found.groups())
    assert load > 0 and each * 1e-3 * 20 < total - 0.5 * load


def test_a_sweep_too_large_for_memory_is_refused_before_it_is_built() -> None:
    sweeps = [parse_sweep("contact.mu=0:1:10000"), parse_sweep("contact.k=1000:2000:10000")]
    with pytest.raises(BatchError, match="1e\\+08 runs"):
        plan_batch(["demo-bonus"], sweeps=sweeps)


def test_batch_members_run_side_by_side_unless_capped(monkeypatch):
    """Compiled members go one thread per core, every member's outcome in its place;
    COLLIDE_THREADS=1 (set in Dask workers) and a progress display keep them on one thread."""
    import threading

    from collide.engine import tier
    from collide.stepper import run_members

    monkeypatch.setattr(tier, "COMPILED", True)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    seen: list[int] = []

    def member(b: int) -> tuple:
        seen.append(threading.get_ident())
        time.sleep(0.02)  # long enough that both threads take members
        return (b,)

    watched = [(np.zeros(8), 6, 1.0, -1)] * 6
    assert run_members(6, member, None, watched) == [(b,) for b in range(6)]
    assert len(set(seen)) == 2
    seen.clear()
    monkeypatch.setenv("COLLIDE_THREADS", "1")
    assert run_members(6, member, None, watched) == [(b,) for b in range(6)]
    assert len(set(seen)) == 1
    seen.clear()
    monkeypatch.delenv("COLLIDE_THREADS")
    assert run_members(6, member, lambda *args: None, watched) == [(b,) for b in range(6)]
    assert len(set(seen)) == 1
