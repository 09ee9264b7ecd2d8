"""Recordings carry a checksum of what `read_recording` restores; damaged or foreign files are
one `RecordingError`, whatever they hold."""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from collide import recording as rec
from collide.recording import RecordingError, read_recording, write_recording
from collide.run import run_scene
from collide.scene import load_scene


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    run = run_scene(load_scene("demo-bonus"))
    return run, write_recording(run, tmp_path_factory.mktemp("rrd") / "bonus.rrd")


def _flip_a_stored_position(run: object, data: bytes) -> bytes:
    """Flip the lowest bit of a trajectory position stored verbatim (an LZ4 literal) in the file:
    the file stays well-formed and the position changes by one unit in the last place."""
    values = run.result.trajectory.s[:, 0].reshape(-1)
    unique = [x for x in values if data.count(np.float64(x).tobytes()) == 1]
    assert unique, "no position stored verbatim"
    pos = data.index(np.float64(unique[len(unique) // 2]).tobytes())
    damaged = bytearray(data)
    damaged[pos] ^= 1
    return bytes(damaged)


def test_checksum_is_stored_and_matches(written: tuple) -> None:
    run, path = written
    back = read_recording(path)
    np.testing.assert_array_equal(back.result.trajectory.s, run.result.trajectory.s)
    chunks = rec._load_chunks(path)
    meta = rec._meta(path, chunks)
    assert meta["format_version"] == 2 and len(meta["checksum"]) == 64


def test_a_changed_position_is_refused(written: tuple, tmp_path: Path) -> None:
    run, path = written
    damaged = tmp_path / "flipped.rrd"
    damaged.write_bytes(_flip_a_stored_position(run, path.read_bytes()))
    with pytest.raises(RecordingError, match="checksum mismatch") as info:
        read_recording(damaged)
    assert str(damaged) in str(info.value) and "\n" not in str(info.value)


def test_a_changed_setting_is_refused(written: tuple, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A writer whose meta differs from what it checksummed (e.g. dt changed afterwards).
    run, _ = written
    real = rec.checksum

    def stale(columns: dict, meta: dict) -> str:
        value = real(columns, meta)
        meta["dt"] = meta["dt"] * (1 + 1e-15)
        return value

    monkeypatch.setattr(rec, "checksum", stale)
    path = write_recording(run, tmp_path / "stale.rrd")
    monkeypatch.undo()
    with pytest.raises(RecordingError, match="checksum mismatch"):
        read_recording(path)


def _foreign(path: Path, **meta: object) -> Path:
    stream = rr.RecordingStream("someone-else", recording_id=uuid.uuid4())
    stream.save(path)
    stream.log("/collide/meta", rr.AnyValues(**meta), static=True)
    stream.flush()
    stream.disconnect()
    return path


@pytest.mark.parametrize("meta, words", [
    # Another program's file with collide-like metadata: a timestamp that Python cannot hold.
    ({"format": "collide-recording", "format_version": 1,
      "created": pa.array([2**62], type=pa.timestamp("s"))}, "not a valid collide recording"),
    ({"format": "collide-recording", "format_version": pa.array(["two"])}, "format version"),
    ({"format": "collide-recording", "format_version": 2, "scene_toml": "x"}, "checksum is missing"),
    ({"format": "collide-recording", "format_version": 1, "scene_toml": pa.array([3]), "scene_name": "x"},
     "not a valid collide recording"),
])
def test_foreign_metadata_is_one_line(tmp_path: Path, meta: dict, words: str) -> None:
    path = _foreign(tmp_path / "foreign.rrd", **meta)
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert words in message and str(path) in message and "\n" not in message
