"""Issue 14: extreme and careless input as a user types it. Each case is one line `error: ...`
on stderr and exit 2 (never a traceback, a numpy warning or a box of usage text), and a
result is never printed with a non-finite number in it."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
import warnings
from pathlib import Path

import numpy as np
import pytest

from collide import recording as rec
from collide.recording import writer as rec_writer
from collide.run import check_finite, run_scene
from collide.scene import MAX_MAGNITUDE, SceneError, load_scene
from collide.stepper import RunError
from collide.summary import run_summary

DATA = Path(__file__).parent / "data"


def _main(args: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
          cwd: Path) -> tuple[int, str, str]:
    """`collide ARGS` in this process, as the console script runs it."""
    from cli.main import main

    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", ["collide", *args])
    # pytest would capture a warning before it reached stderr: record every one, and fail on it.
    with warnings.catch_warnings(record=True) as caught, pytest.raises(SystemExit) as info:
        warnings.simplefilter("always")
        main()
    out, err = capsys.readouterr()
    assert not caught, f"warnings: {[str(w.message) for w in caught]}"
    return int(info.value.code or 0), out, err


def _one_line_error(code: int, out: str, err: str, needle: str) -> None:
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert needle in lines[0], lines[0]
    assert "Traceback" not in err and "Warning" not in err and out == ""


def _write(folder: Path, name: str, text: str) -> str:
    path = folder / name
    path.write_text(text)
    return str(path)


def _deep(folder: Path) -> str:
    return _write(folder, "deep.toml", "x = " + "[" * 1000 + "]" * 1000 + "\n")


def _huge_mass(folder: Path) -> str:
    text = load_scene("demo-bonus").to_toml().replace("mass = 0.0254", "mass = " + "9" * 400, 1)
    return _write(folder, "huge.toml", text)


def _one_body(folder: Path) -> str:
    return _write(folder, "one.toml", 'dim = 2\n[[body]]\nname = "a"\nmass = 1.0\nradius = 0.1\n'
                                      "position = [0.0, 0.0]\nvelocity = [1.0, 0.0]\n")


@pytest.mark.parametrize("args, needle", [
    (["run", "demo-bonus", "--set", "body.ball1.radius=1e200", "--no-record"], "body.ball1.radius"),
    (["run", "demo-bonus", "--set", "body.ball1.mass=1e-200", "--no-record"], "body.ball1.mass"),
    (["run", _huge_mass, "--no-record"], "body.ball1.mass"),
    (["run", _deep, "--no-record"], "nested"),
    (["run", "demo-bonus", "--set", "x=" + "[" * 1200 + "]" * 1200, "--no-record"], "nested"),
    (["run", "demo-bonus", "--set", "dim=2.0", "--no-record"], "dim"),
    (["run", "demo-bonus", "--out", "/proc/x.rrd"], "/proc/x.rrd"),
    (["run", "demo-bonus", "--out", "."], "folder"),
    (["run", "demo-bonus", "--set", "contact.k=1e300", "--no-record"], "contact.k"),
    (["run", "demo-bonus", "--set", "duration=1e308", "--no-record"], "duration"),
    (["run", _one_body, "--no-record"], "one sphere and no walls"),
    (["run", "textbook-1d", "--set", "tail=1e15", "--out", "x.rrd"], "time axis holds"),  # past Rerun's int64 ns
    (["run", "missing\nfile.toml", "--no-record"], "does not exist"),  # a message holding a newline
    (["run", "demo-bonus", "--stride", "1e3"], "--stride"),
    (["run", "demo-bonus", "--bogus"], "--bogus"),
    (["run"], "scene"),
    (["batch", "demo-bonus", "--chunk", "x"], "--chunk"),
])
def test_extreme_input_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
                                   args: list, needle: str) -> None:
    args = [a(tmp_path) if callable(a) else a for a in args]
    code, out, err = _main(args, monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, needle)
    if args[0] == "run" and "--stride" in args or "--bogus" in args:
        assert "--help" in err  # usage errors point to the help, in the same one line


@pytest.mark.parametrize("variable, value", [("COLLIDE_THREADS", "abc"), ("COLLIDE_THREADS", "0"),
                                             ("COLLIDE_FRAME_STEPS", "-3"), ("COLLIDE_FRAME_STEPS", "1.5")])
def test_a_malformed_count_in_the_environment_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture, variable: str,
                                                          value: str) -> None:
    """COLLIDE_THREADS and COLLIDE_FRAME_STEPS are checked before any command runs: a typo is
    refused naming the variable, never run with the default."""
    monkeypatch.setenv(variable, value)
    code, out, err = _main(["run", "demo-bonus", "--no-record"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, f"{variable}: a whole number >= 1, got '{value}'")


def test_range_limits_name_the_key() -> None:
    assert load_scene("demo-bonus", [f"contact.k={MAX_MAGNITUDE}"]).contact.k == MAX_MAGNITUDE
    for override in (f"contact.k={MAX_MAGNITUDE * 10}", "body.ball2.velocity.x=-1e31", "gravity=[0, 1e40]"):
        with pytest.raises(SceneError, match=override.split("=")[0].split(".x")[0].replace("[", r"\[")):
            load_scene("demo-bonus", [override])


def test_one_body_with_a_given_step_runs_without_warnings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture) -> None:
    # No contact is possible: the stability limit divides by a zero frequency (numpy warned).
    scene = _one_body(tmp_path)
    code, out, err = _main(["run", scene, "--set", "dt=1e-4", "--set", "duration=0.5", "--no-record", "--json"],
                           monkeypatch, capsys, tmp_path)
    assert (code, err) == (0, "")
    summary = json.loads(out)
    assert summary["bodies"][0]["position"] == pytest.approx([0.5, 0.0])


def test_a_non_finite_final_state_is_refused() -> None:
    run = run_scene(load_scene("demo-bonus"))
    run.result.final.s[0, 1, 0] = -np.inf  # what an overflowing free flight ends with
    with pytest.raises(RunError, match="body.ball2's final position is not finite"):
        check_finite(run.result, run.scenes)
    with pytest.raises(RunError, match=r"bodies\[1\]\.position\[0\] is -inf"):
        run_summary(run)


def test_a_damaged_recording_on_the_command_line_is_one_line(tmp_path: Path) -> None:
    # In-process, this file makes Rerun's reader abort Python (exit 134): `collide view` reads
    # it in a child first, so the command gets one line and exit 2 instead.
    out = subprocess.run([sys.executable, "-m", "cli.main", "view", str(DATA / "bitflip-aborts-reader.rrd"),
                          "--port", "0"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    _one_line_error(out.returncode, out.stdout, out.stderr, "crashed")


def test_a_foreign_recording_with_collide_metadata_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture) -> None:
    import pyarrow as pa
    import rerun as rr

    path = tmp_path / "foreign.rrd"
    stream = rr.RecordingStream("someone-else", recording_id=uuid.uuid4())
    stream.save(path)
    stream.log("/collide/meta", rr.AnyValues(format="collide-recording", format_version=3,
                                             created=pa.array([2**62], type=pa.timestamp("s"))), static=True)
    stream.flush()
    stream.disconnect()
    code, out, err = _main(["view", str(path), "--port", "0"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, "not a valid collide recording")


def test_a_long_free_flight_records_a_bounded_number_of_frames(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture) -> None:
    # demo-1d for 1e6 s would be 1.2e8 frames at 120 fps: the rate drops to fit the cap, and says so.
    monkeypatch.setattr(rec_writer, "MAX_FREE_FRAMES", 2000)
    code, out, err = _main(["run", "demo-1d", "--set", "duration=100", "--out", "long.rrd"], monkeypatch, capsys,
                           tmp_path)
    assert (code, err) == (0, "")
    assert rec.last_write.fps == pytest.approx(20.0, rel=0.01)
    assert rec.last_write.exact_frames < 2000 + 200
    assert "warning: the recording draws free flight at 20 frames per simulated second" in out
    back = rec.read_recording(tmp_path / "long.rrd")
    assert back.result.final.t[0] == pytest.approx(100.0)


def test_no_record_keeps_no_steps_in_memory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture) -> None:
    # 1.3 million Verlet steps: kept, the knots would take about 2 KB each (2.6 GB); not kept, the
    # run's own arrays are a few kilobytes whatever the step count.
    import tracemalloc

    tracemalloc.start()
    try:
        code, out, err = _main(["run", "demo-bonus", "--integrator", "verlet", "--dt", "1e-8", "--no-record",
                                "--json"], monkeypatch, capsys, tmp_path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert (code, err) == (0, "")
    assert json.loads(out)["steps"] > 1_000_000
    assert peak < 40e6, f"peak {peak / 1e6:.0f} MB"
    assert not (tmp_path / "recordings").exists()


def test_a_scene_name_never_leaves_recordings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture) -> None:
    code, _, err = _main(["run", "demo-1d", "--set", 'name="../../escaped"'], monkeypatch, capsys, tmp_path)
    assert (code, err) == (0, "")
    assert [p.name for p in (tmp_path / "recordings").iterdir()] == ["escaped.rrd"]
    assert not (tmp_path.parent / "escaped.rrd").exists()


def test_one_d_vectors_take_an_x_component() -> None:
    assert load_scene("demo-1d", ["body.ball1.velocity.x=0.75"]).bodies[0].velocity == (0.75,)
    with pytest.raises(SceneError, match="velocity"):
        load_scene("demo-1d", ["body.ball1.velocity.y=0.75"])
