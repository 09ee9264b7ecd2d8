"""`read_recording_safely`: a recording that crashes, hangs or floods Rerun's reader costs a
child process, never the caller, and becomes one `RecordingError` line."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from collide.recording import RecordingError, read_recording, read_recording_safely, write_recording
from collide.run import run_scene
from collide.scene import load_scene

DATA = Path(__file__).parent / "data"
# demo-bonus written by collide, then one bit flipped (byte 142732, 0x00 -> 0x01): rerun-sdk
# 0.41's reader panics on it ("Type <UNKNOWN ..> not supported") and aborts the process.
ABORTS = DATA / "bitflip-aborts-reader.rrd"


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_recording(run_scene(load_scene("demo-bonus")), tmp_path_factory.mktemp("rrd") / "bonus.rrd")


def test_plain_reader_aborts_on_the_damaged_file() -> None:
    # The reason for the child process: in-process, this file kills Python (SIGABRT).
    code = f"from collide.recording import read_recording; read_recording({str(ABORTS)!r}, trusted=True)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == -6, out.stderr[-500:]


def test_damaged_file_is_one_line_recording_error() -> None:
    with pytest.raises(RecordingError) as info:
        read_recording_safely(ABORTS)
    message = str(info.value)
    assert "\n" not in message and str(ABORTS) in message
    assert "crashed" in message and "SIGABRT" in message
    assert isinstance(info.value, ValueError)


def test_good_file_reads_as_read_recording(good: Path) -> None:
    safe, plain = read_recording_safely(good), read_recording(good)
    assert safe.scene == plain.scene
    np.testing.assert_array_equal(safe.result.trajectory.s, plain.result.trajectory.s)
    np.testing.assert_array_equal(safe.result.final.v, plain.result.final.v)
    # The reader survives a crash on another file and reads again.
    with pytest.raises(RecordingError):
        read_recording_safely(ABORTS)
    assert read_recording_safely(good).scene == plain.scene


def test_the_scene_comes_first_and_the_run_is_read_as_before(good: Path) -> None:
    """`on_scene` (what `collide view FILE` shows while the rest is read) gets the file's scene
    once, before the run, and the run read with it is the one read without it, bit for bit."""
    plain = read_recording(good, trusted=True)
    got: list = []
    safe = read_recording_safely(good, on_scene=lambda scene: got.append(scene))
    assert len(got) == 1 and got[0] == plain.scene and got[0].to_toml() == plain.scene.to_toml()
    for field in ("knots", "records", "intervals"):
        np.testing.assert_array_equal(getattr(safe.result.trajectory, field), getattr(plain.result.trajectory, field))
    np.testing.assert_array_equal(safe.result.final.s, plain.result.final.s)
    assert safe.result.wall_time_s == plain.result.wall_time_s and safe.scene == plain.scene
    # A file the reader refuses gives no scene, and the same one line as without `on_scene`.
    with pytest.raises(RecordingError, match="crashed"):
        read_recording_safely(ABORTS, on_scene=got.append)
    assert len(got) == 1
    # What the caller does with the scene cannot break the read.
    assert read_recording_safely(good, on_scene=lambda scene: 1 / 0).scene == plain.scene


def test_errors_of_the_plain_reader_pass_through(tmp_path: Path) -> None:
    text = tmp_path / "notes.rrd"
    text.write_text("not a recording")
    with pytest.raises(RecordingError, match="not a Rerun recording"):
        read_recording_safely(text)
    with pytest.raises(RecordingError, match="no such file"):
        read_recording_safely(tmp_path / "missing.rrd")
    with pytest.raises(RecordingError, match="not a file"):
        read_recording_safely(tmp_path)


def test_time_and_memory_limits_stop_the_child(good: Path) -> None:
    with pytest.raises(RecordingError, match="longer than 1e-06 s"):
        read_recording_safely(good, timeout_s=1e-6)
    # Any reader needs more than 1 MB (Python alone is about 10): stopped, one line.
    with pytest.raises(RecordingError, match="more than 1 MB"):
        read_recording_safely(good, memory_mb=1)
    assert read_recording_safely(good).scene.name == "demo-bonus"


def test_reads_from_several_threads(good: Path) -> None:
    results: list[object] = []

    def read(path: Path) -> None:
        try:
            results.append(read_recording_safely(path).scene.name)
        except RecordingError as exc:
            results.append(exc)

    threads = [threading.Thread(target=read, args=(p,)) for p in (good, ABORTS, good)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert sorted(map(str, results))[-2:] == ["demo-bonus", "demo-bonus"]
    assert sum(isinstance(r, RecordingError) for r in results) == 1


def test_a_grown_reader_is_replaced_by_a_fresh_one(good: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A reader grown past _IDLE_MAX_MB is stopped (its memory is not held), and a fresh process
    # takes its place at once, so the next read does not wait for Rerun's import.
    from collide.recording import sandbox

    sandbox.warm_reader()
    with sandbox._idle_lock:
        first = sandbox._idle[-1]
    monkeypatch.setattr(sandbox, "_IDLE_MAX_MB", 0)  # every reader counts as grown
    read_recording_safely(good)
    assert first.proc.poll() is not None  # the one that read was stopped
    with sandbox._idle_lock:
        fresh = list(sandbox._idle)
    assert len(fresh) == 1 and fresh[0] is not first and fresh[0].proc.poll() is None
    monkeypatch.undo()
    run = read_recording_safely(good)  # the fresh one reads
    assert run.scene.name == "demo-bonus"


def test_a_grown_reader_is_replaced_when_the_caller_says(good: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # rewarm=False (the viewer opening a file): the grown reader is stopped and no fresh one
    # starts until `warm_reader()`, called once the run is shown.
    from collide.recording import sandbox

    sandbox.warm_reader()
    with sandbox._idle_lock:
        first = sandbox._idle[-1]
    monkeypatch.setattr(sandbox, "_IDLE_MAX_MB", 0)
    run = read_recording_safely(good, rewarm=False)
    assert run.scene.name == "demo-bonus"
    assert first.proc.poll() is not None
    with sandbox._idle_lock:
        assert sandbox._idle == []
    sandbox.warm_reader()
    with sandbox._idle_lock:
        assert len(sandbox._idle) == 1 and sandbox._idle[0].proc.poll() is None
