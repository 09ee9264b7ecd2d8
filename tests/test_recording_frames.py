"""Recordings of many bodies (docs/design.md section 5): a DEM run of 1 000 bodies or more takes a
frame at most once each `dem.FRAME_STEPS` steps, says how many in its JSON summary and its
recording, and the frames it keeps are the run's own states, read back exactly."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from collide import dem
from collide.engine import layout
from collide.recording import read_recording, write_recording
from collide.run import run_scene
from collide.scene import load_scene
from collide.summary import run_summary

SIDE = 0.05  # m: the pour cut to a box a tenth of its width, 1 000 spheres (as tests/test_pour.py)
POUR = ["fill.0.count=1000", f"fill.0.upper.x={SIDE}", f"fill.0.upper.y={SIDE}", f"wall.1.point.x={SIDE}",
        f"wall.3.point.y={SIDE}", "duration=0.012"]


def _run(monkeypatch: pytest.MonkeyPatch, frame_steps: int | None):
    monkeypatch.setenv("COLLIDE_THREADS", "1")
    if frame_steps is None:
        monkeypatch.delenv(dem.FRAME_STEPS_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(dem.FRAME_STEPS_VARIABLE, str(frame_steps))
    return run_scene(load_scene("pour", POUR), record=True)


@pytest.fixture(scope="module")
def runs() -> dict:
    with pytest.MonkeyPatch.context() as mp:
        return {"default": _run(mp, None), "every": _run(mp, 1)}


def _frames(run) -> np.ndarray:
    return run.result.trajectory.knot_times


def test_many_bodies_take_a_frame_at_most_once_each_k_steps(runs: dict) -> None:
    """Frames on a grid k steps apart, plus the ends of coasts (free flight where nothing
    touches, flown in one go) that end at least the grid's spacing after the last frame: at most
    one frame per k steps of simulated time on the grid, two per spacing at coasts, the start and
    the end."""
    run = runs["default"]
    r = run.result
    k = dem.FRAME_STEPS
    assert r.model.n_bodies >= dem.FRAME_STEPS_FROM and r.frame_steps == k
    dt, steps, jumps = float(r.dt[0]), int(r.steps[0]), int(r.jumps[0])
    assert steps > 3 * k  # the rule binds: the scene's own budget (1 500 frames) would take every step
    frames = _frames(run)
    assert jumps > 5  # the fill falls: coasts between contacts
    assert len(frames) <= 3 * float(r.final.t[0]) / (k * dt) + 4
    assert len(frames) < 3 * len(_frames(runs["every"])) / k
    # Every frame holds every body once.
    knots = r.trajectory.knots
    assert len(knots) == len(frames) * r.model.n_bodies
    summary = run_summary(run)
    assert summary["frames"] == {"recorded": len(frames), "every_steps": k}


def test_asked_frame_steps_record_every_step_and_the_run_is_the_same(runs: dict) -> None:
    """--frame-steps 1 records every step; the frames kept by default are those steps' states to
    the bit, and the run itself does not depend on what it records."""
    every, default = runs["every"].result, runs["default"].result
    assert every.frame_steps == 1 and run_summary(runs["every"])["frames"]["every_steps"] == 1
    assert len(_frames(runs["every"])) >= int(every.steps[0]) + 1 - 2 * int(every.jumps[0])
    for key in ("s", "v", "w", "q"):
        assert np.array_equal(getattr(every.final, key), getattr(default.final, key)), key
    kept = default.trajectory.knots
    all_ = every.trajectory.knots
    times = _frames(runs["default"])
    assert np.isin(times, _frames(runs["every"])).all()
    for t in times[:: max(1, len(times) // 5)]:
        a, b = kept[kept[:, layout.K_T] == t], all_[all_[:, layout.K_T] == t]
        assert np.array_equal(a[:, layout.K_S:layout.K_W], b[:, layout.K_S:layout.K_W])


def test_recording_of_many_bodies_round_trips_with_its_frames(runs: dict, tmp_path: Path) -> None:
    """Written and read back (the reader's own process): the frames exactly, float64, and the
    frame rule in the settings."""
    run = runs["default"]
    path = write_recording(run, tmp_path / "pour.rrd")
    back = read_recording(path)
    assert np.array_equal(back.result.trajectory.knots, run.result.trajectory.knots)
    assert back.result.frame_steps == dem.FRAME_STEPS
    assert run_summary(back)["frames"] == run_summary(run)["frames"]


def test_collide_run_says_the_frames(tmp_path: Path) -> None:
    """The command line's output names the frames and the option that asks for more."""
    args = [a for o in POUR for a in ("--set", o)]
    out = tmp_path / "pour.rrd"
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", "pour", *args, "--threads", "1", "--out",
                           str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"frames, one each {dem.FRAME_STEPS} steps (--frame-steps K for one each K)" in done.stdout
    asked = subprocess.run([sys.executable, "-m", "cli.main", "run", "pour", *args, "--threads", "1",
                            "--frame-steps", "7", "--json", "--out", str(out)], capture_output=True, text=True,
                           timeout=600)
    assert asked.returncode == 0, asked.stderr[-2000:]
    assert json.loads(asked.stdout)["frames"]["every_steps"] == 7


def test_tables_hashed_in_place_give_the_canonical_checksum() -> None:
    """The checksum hashes float tables from their own memory: the same digest as over the bytes
    `_canonical` makes of them (what files written before hold), empty tables and a table of
    another float width or order included."""
    import hashlib

    from collide.recording.spec import _canonical, checksum

    def by_bytes(tables: dict, meta: dict) -> str:
        digest = hashlib.sha256()
        for label, table in ((b"tables", tables), (b"meta", meta)):
            digest.update(label)
            for key in sorted(table):
                digest.update(len(key).to_bytes(4, "little") + key.encode())
                data = _canonical(table[key])
                digest.update(len(data).to_bytes(8, "little") + data)
        return digest.hexdigest()

    rng = np.random.default_rng(1)
    tables = {"knots": rng.random((50, layout.NK)), "records": np.zeros((0, layout.NR)),
              "intervals": np.asfortranarray(rng.random((7, 4))).astype(np.float32)}
    meta = {"n": 3, "initial_s": rng.random((4, 3)), "initial_w": np.zeros((4, 0)), "x": [1.0, 2.5], "name": "a"}
    before = checksum(tables, meta)
    assert before == by_bytes(tables, meta)
    tables["knots"][3, 4] = np.nextafter(tables["knots"][3, 4], 2.0)  # one bit
    assert checksum(tables, meta) != before


def _contents(path: Path) -> dict:
    """Every entity's rows as (time, value) pairs per component, sorted: what a file holds, however
    its calls cut it into chunks (the seal left out: it hashes the bytes)."""
    from rerun.chunk import RrdReader

    out: dict = {}
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == "/collide/integrity":
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        times = (batch.column("sim_time").cast("int64").to_pylist() if "sim_time" in names
                 else [None] * batch.num_rows)
        for name in names:
            if name.startswith("rerun.") or name in ("sim_time", "log_tick", "log_time") or "row_id" in name:
                continue
            rows = zip(map(str, times), map(repr, batch.column(name).to_pylist()))
            out.setdefault((chunk.entity_path, name), []).extend(rows)
    return {key: sorted(rows) for key, rows in out.items()}


def test_many_contacts_drawn_a_block_at_a_time_are_the_frames_drawn_at_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A recording of many contacts draws them a block of frames at a time (one frame a block
    here): every entity holds the same rows as when all frames are drawn in one block."""
    from collide.recording import writer

    monkeypatch.setenv("COLLIDE_THREADS", "1")
    # 200 spheres in a fill 3 cm deep: they land on the floor and on each other within the run.
    low = ["fill.0.count=200", "fill.0.upper.z=0.03", "duration=0.06"]
    run = run_scene(load_scene("pour", [*POUR[1:-1], *low]), record=True)
    monkeypatch.setattr(writer, "BLOCK_ENTRIES", 1 << 40)
    whole = _contents(write_recording(run, tmp_path / "whole.rrd"))
    calls = writer.last_write.calls
    monkeypatch.setattr(writer, "BLOCK_ENTRIES", 1)
    blocks = _contents(write_recording(run, tmp_path / "blocks.rrd"))
    points = whole[("/world/contacts/points", "Points3D:positions")]
    frames = len(whole[("/world/bodies", "Points3D:positions")])
    assert sum(p[1] != "[]" for p in points) > 3  # frames with contacts drawn
    # One frame a block: three more calls a frame (points, normal and friction arrows).
    assert writer.last_write.calls == calls + 3 * (frames - 1)
    assert blocks.keys() == whole.keys()
    for key in whole:
        assert blocks[key] == whole[key], key
