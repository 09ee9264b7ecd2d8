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
from collide.engine import layout
from collide.recording import RecordingError, read_recording, write_recording
from collide.recording import reader as rec_reader
from collide.recording import writer as rec_writer
from collide.run import run_scene
from collide.scene import load_scene


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    run = run_scene(load_scene("demo-bonus"))
    return run, write_recording(run, tmp_path_factory.mktemp("rrd") / "bonus.rrd")


def _flip_a_stored_position(run: object, data: bytes) -> bytes:
    """Flip the lowest bit of a trajectory position stored verbatim (an LZ4 literal) in the file:
    the file stays well-formed and the position changes by one unit in the last place."""
    traj = run.result.trajectory
    values = traj.knots[:, layout.K_S:layout.K_S + traj.model.dim].reshape(-1)
    unique = [x for x in values if data.count(np.float64(x).tobytes()) == 1]
    assert unique, "no position stored verbatim"
    pos = data.index(np.float64(unique[len(unique) // 2]).tobytes())
    damaged = bytearray(data)
    damaged[pos] ^= 1
    return bytes(damaged)


def test_checksum_is_stored_and_matches(written: tuple) -> None:
    run, path = written
    back = read_recording(path)
    for table in ("knots", "records", "intervals"):
        np.testing.assert_array_equal(getattr(back.result.trajectory, table),
                                      getattr(run.result.trajectory, table))
    chunks = rec_reader._load_chunks(path)
    meta = rec_reader._meta(path, chunks)
    assert meta["format_version"] == 4 and len(meta["checksum"]) == 64
    assert meta["records"] > 0 and meta["intervals"] > 0  # the checksum covers non-empty tables


@pytest.mark.parametrize("table", ["knots", "records", "intervals"])
def test_each_table_is_covered(written: tuple, table: str) -> None:
    run, _ = written
    traj = run.result.trajectory
    tables = {"knots": traj.knots, "records": traj.records, "intervals": traj.intervals}
    meta = {"format": rec.FORMAT, "dt": 1e-5}
    before = rec.checksum(tables, meta)
    changed = dict(tables)
    changed[table] = tables[table].copy()
    changed[table][len(changed[table]) // 2, -1] = np.nextafter(changed[table][len(changed[table]) // 2, -1], np.inf)
    assert rec.checksum(changed, meta) != before
    if len(tables[table]) > 1:
        reordered = dict(tables)
        reordered[table] = tables[table][::-1]
        assert rec.checksum(reordered, meta) != before
    reshaped = dict(tables)  # the same values in another shape
    reshaped[table] = tables[table].reshape(-1, 1)
    assert rec.checksum(reshaped, meta) != before


def test_format_2_without_checksum_is_read(written: tuple, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    # Main's format 2 (the same tables, no checksum) is still read; with the version lowered but
    # a checksum present, the checksum is still checked.
    run, _ = written
    monkeypatch.setattr(rec_writer._Writer, "seal", False)  # no integrity record, as format 2 had none
    monkeypatch.setattr(rec_writer, "FORMAT_VERSION", 2)
    any_values = rr.AnyValues
    monkeypatch.setattr(rec_writer.rr, "AnyValues", lambda **values: any_values(
        **{k: v for k, v in values.items() if k != "checksum"}))
    path = write_recording(run, tmp_path / "v2.rrd")
    monkeypatch.undo()
    assert "checksum" not in rec_reader._meta(path, rec_reader._load_chunks(path))
    back = read_recording(path)
    np.testing.assert_array_equal(back.result.trajectory.knots, run.result.trajectory.knots)
    flipped = tmp_path / "v2-flipped.rrd"  # without a checksum a change goes unseen: why format 3 has one
    flipped.write_bytes(_flip_a_stored_position(run, path.read_bytes()))
    assert not np.array_equal(read_recording(flipped).result.trajectory.knots, run.result.trajectory.knots)

    monkeypatch.setattr(rec_writer._Writer, "seal", False)
    monkeypatch.setattr(rec_writer, "FORMAT_VERSION", 2)
    path = write_recording(run, tmp_path / "v2-with-checksum.rrd")
    monkeypatch.undo()
    flipped.write_bytes(_flip_a_stored_position(run, path.read_bytes()))
    with pytest.raises(RecordingError, match="checksum mismatch"):
        read_recording(flipped)


def test_a_changed_position_is_refused(written: tuple, tmp_path: Path) -> None:
    # Refused twice over: the seal (every byte) and the trajectory's own checksum.
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

    monkeypatch.setattr(rec_writer, "checksum", stale)
    monkeypatch.setattr(rec_writer._Writer, "seal", False)  # else the seal, over every byte, hides this check
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
    ({"format": "collide-recording", "format_version": 3,
      "created": pa.array([2**62], type=pa.timestamp("s"))}, "not a valid collide recording"),
    ({"format": "collide-recording", "format_version": pa.array(["two"])}, "format version"),
    ({"format": "collide-recording", "format_version": 1}, "older collide"),
    ({"format": "collide-recording", "format_version": 3, "scene_toml": "x"}, "checksum is missing"),
    ({"format": "collide-recording", "format_version": 2, "knots": -4}, "row count"),
    ({"format": "collide-recording", "format_version": 2, "knots": 0, "records": 0, "intervals": 0,
      "scene_toml": pa.array([3]), "scene_name": "x"}, "not a valid collide recording"),
])
def test_foreign_metadata_is_one_line(tmp_path: Path, meta: dict, words: str) -> None:
    path = _foreign(tmp_path / "foreign.rrd", **meta)
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert words in message and str(path) in message and "\n" not in message


def test_a_run_without_warnings_recorded_after_one_with_them_reads_back(tmp_path) -> None:
    """In one process, a recording whose run warned and then one whose run did not: the second's
    settings hold no warnings at all (Rerun wrote a None it had seen as a list as an empty list,
    outside the checksum, and the good file was refused as damaged)."""
    from collide.run import run_scene
    from collide.scene import load_scene

    warned = run_scene(load_scene("newtons-cradle"), record=True, dt=1e-5)
    assert warned.result.warnings
    write_recording(warned, tmp_path / "warned.rrd")
    quiet = run_scene(load_scene("demo-1d"), record=True)
    assert not quiet.result.warnings
    write_recording(quiet, tmp_path / "quiet.rrd")
    assert read_recording(tmp_path / "warned.rrd").result.warnings == warned.result.warnings
    assert read_recording(tmp_path / "quiet.rrd").result.warnings == []
