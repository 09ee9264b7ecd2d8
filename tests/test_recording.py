"""Recordings: lossless round trip, the leave-out rule, valid files, refusal of bad files."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from collide import diagnostics as dg
from collide import recording as rec
from collide.recording import RecordingError, entity_paths, read_recording, write_recording
from collide.recording import writer as rec_writer
from collide.run import run_scene, run_scenes
from collide.scene import load_scene, parse_scene
from collide.summary import run_summary

RERUN = Path(sys.executable).parent / "rerun"

WALL_3D = {
    "name": "wall-3d", "dim": 3, "dt": 1e-4,
    "contact": {"k": 5000.0, "mu": 0.3},
    "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.2, 0.0],
              "velocity": [0.5, -1.0, 0.2], "spin": [0.0, 0.0, 4.0]}],
    "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}],
}


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple]:
    """Runs of demo-bonus (2D, friction, spin), demo-1d and a 3D wall scene, and their files."""
    folder = tmp_path_factory.mktemp("rrd")
    out = {}
    scenes = {"demo-bonus": load_scene("demo-bonus"), "demo-1d": load_scene("demo-1d"),
              "wall-3d": parse_scene(WALL_3D, "wall-3d"), "bounce": load_scene("bounce"),
              "break-3d": load_scene("break-3d")}
    for name, scene in scenes.items():
        run = run_scene(scene)
        path = write_recording(run, folder / "sub" / f"{name}.rrd")
        out[name] = (run, path)
    return out


@pytest.mark.parametrize("name", ["demo-bonus", "demo-1d", "wall-3d", "bounce", "break-3d"])
def test_round_trip_is_exact(written: dict, name: str) -> None:
    run, path = written[name]
    back = read_recording(path)
    a, b = run.result, back.result
    assert back.scene == run.scene
    assert back.scene.to_toml() == run.scene.to_toml()
    for field in ("t", "s", "v", "w", "q", "work", "free"):
        x, y = getattr(a.trajectory, field), getattr(b.trajectory, field)
        assert x.shape == y.shape, field
        np.testing.assert_allclose(y, x, rtol=0, atol=1e-12, err_msg=field)
    for field in ("knots", "records", "intervals"):  # the trajectory itself, bit for bit
        np.testing.assert_array_equal(getattr(b.trajectory, field), getattr(a.trajectory, field), err_msg=field)
    for state in ("initial", "final"):
        for field in ("t", "s", "v", "w", "q", "work"):
            np.testing.assert_allclose(getattr(getattr(b, state), field), getattr(getattr(a, state), field),
                                       rtol=0, atol=1e-12)
    ca, cb = dg.trajectory_conserved(a.model, a.trajectory), dg.trajectory_conserved(b.model, b.trajectory)
    for field in ("kinetic", "rotational", "spring", "gravitational", "dissipated", "momentum",
                  "angular_momentum", "com"):
        x, y = getattr(ca, field), getattr(cb, field)
        assert (x is None) == (y is None), field
        if x is not None:
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-12, err_msg=field)
    assert b.integrator == a.integrator and b.wall_time_s == a.wall_time_s
    np.testing.assert_array_equal(b.dt, a.dt)
    np.testing.assert_array_equal(b.steps, a.steps)
    np.testing.assert_array_equal(b.jumps, a.jumps)
    np.testing.assert_array_equal(b.contacts.max_overlap, a.contacts.max_overlap)
    res_a, res_b = dg.residuals(a), dg.residuals(b)
    np.testing.assert_array_equal(res_a.energy, res_b.energy)
    assert run_summary(back) == run_summary(run)  # the JSON summary of the file equals the run's


def test_member_of_a_batch_is_recorded_alone(tmp_path: Path) -> None:
    scenes = [load_scene("demo-bonus", [f"contact.mu={mu}"]) for mu in (0.2, 0.5)]
    batch = run_scenes(scenes)
    path = write_recording(batch.member(1), tmp_path / "m1.rrd")
    back = read_recording(path)
    assert back.scene.contact.mu == 0.5
    np.testing.assert_array_equal(back.result.final.v, batch.result.final.v[1:2])


def test_leave_out_rule(written: dict) -> None:
    paths_1d = entity_paths(written["demo-1d"][1])
    assert not [p for p in paths_1d if any(w in p for w in ("friction", "spin", "wall", "angular_momentum"))]
    assert "/energy/rotational" not in paths_1d
    for word in ("compression", "energy", "momentum"):
        assert any(word in p for p in paths_1d), word

    paths_bonus = entity_paths(written["demo-bonus"][1])
    assert "/world/contacts/ball1-ball2/friction_force" in paths_bonus
    assert "/world/contacts/ball1-ball2/normal_force" in paths_bonus
    assert {"/world/ball1/spin", "/world/ball2/spin", "/energy/rotational", "/energy/dissipated",
            "/angular_momentum", "/contacts/ball1-ball2/compression"} <= set(paths_bonus)
    assert not [p for p in paths_bonus if "wall" in p or "gravitational" in p]

    paths_wall = entity_paths(written["wall-3d"][1])
    assert "/world/walls/wall0" in paths_wall
    assert "/contacts/ball-wall0/compression" in paths_wall
    assert "/residuals/momentum" not in paths_wall  # not conserved against a wall


def _readme_entity_patterns() -> list[re.Pattern]:
    """The entity paths of the design's table (docs/design.md section 5), `<b>`, `<c>` and `<k>` as any name."""
    readme = (Path(__file__).resolve().parent.parent / "docs" / "design.md").read_text()
    patterns = []
    for line in readme.splitlines():
        first = line.split("|")[1] if line.startswith("| `/") else ""
        for path in re.findall(r"`(/[^`]*)`", first):
            parts = re.split(r"(<[a-z]>)", path)
            patterns.append(re.compile("".join("[^/]+" if re.fullmatch(r"<[a-z]>", x) else re.escape(x)
                                               for x in parts)))
    return patterns


def test_readme_lists_every_entity(written: dict, tmp_path: Path) -> None:
    """Every entity of a few-body recording and of a many-body, many-contact one (a row of 30
    balls in 2D with friction: one instanced entity, 29 touching pairs) is in docs/design.md's table."""
    bodies = [{"name": f"b{i}", "mass": 0.1, "radius": 0.01, "position": [0.0201 * i + (0.01 if i else 0.0), 0.0],
               "velocity": [1.0 if i == 0 else 0.0, 0.0]} for i in range(30)]
    row = parse_scene({"name": "row", "dim": 2, "contact": {"k": 1e5, "mu": 0.2}, "body": bodies}, "row")
    many = entity_paths(write_recording(run_scene(row), tmp_path / "row.rrd"))
    assert "/world/bodies" in many and "/contacts/count" in many
    patterns = _readme_entity_patterns()
    for name, (_, path) in written.items():
        for entity in entity_paths(path):
            assert any(p.fullmatch(entity) for p in patterns), f"{name}: {entity} is not in docs/design.md"
    for entity in many:
        assert any(p.fullmatch(entity) for p in patterns), f"row: {entity} is not in docs/design.md"


def test_frames_include_contact_start_and_end_and_free_flight_is_sparse(written: dict) -> None:
    from rerun.chunk import RrdReader

    run, path = written["demo-bonus"]
    chunks = [c for c in RrdReader(path).stream() if c.entity_path == "/world/ball1" and not c.is_static]
    assert len(chunks) == 1  # one send_columns call
    ns = np.array(chunks[0].to_record_batch().column("sim_time").cast("int64").to_numpy())
    log = run.result.contacts
    for t in (log.first_start[0], log.last_end[0]):
        assert np.min(np.abs(ns - t * 1e9)) <= 1.0
    steps = int(run.result.steps[0])
    assert len(ns) >= steps + rec.CONTACT_FRAMES  # every step, and at least 100 frames per contact


def test_2d_scene_lives_in_z0_plane(written: dict) -> None:
    from rerun.chunk import RrdReader

    _, path = written["demo-bonus"]
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == "/world/ball2" and not chunk.is_static:
            centres = np.array(chunk.to_record_batch().column("Ellipsoids3D:centers").to_pylist())
            assert np.all(centres[:, 0, 2] == 0.0)
            return
    raise AssertionError("no ball2 centres")


def _series(path: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) of a recorded scalar series."""
    from rerun.chunk import RrdReader

    for chunk in RrdReader(path).stream():
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            times = np.array(batch.column("sim_time").cast("int64").to_numpy()) * 1e-9
            return times, np.array([row[0] for row in batch.column("Scalars:scalars").to_pylist()], float)
    raise AssertionError(f"no {entity}")


def test_a_rack_in_a_tilted_plane_records_no_round_off(tmp_path: Path) -> None:
    """The billiards break turned into a tilted plane: its tight rack touches with round-off
    overlaps (1e-17 m), which pressed nothing but were counted as 12 contacts before the cue
    arrived; and the cue ball, moving through the origin, has s x v of round-off, which made the
    angular momentum's relative residual 0.5 before the break. Neither any more."""
    from collide.scene import turned_source

    run = run_scene(parse_scene(turned_source(load_scene("billiards-break").source)))
    path = write_recording(run, tmp_path / "tilted.rrd")
    start = float(run.result.contacts.first_start[0])
    times, count = _series(path, "/contacts/count")
    assert count[times < start].max() == 0 and count.max() >= 15
    times, angular = _series(path, "/residuals/angular_momentum")
    assert len(times) > 10 and angular.max() < 1e-12


def test_residuals_are_drawn_at_exact_states_only(tmp_path: Path) -> None:
    """Two balls sliding on a floor, far apart: two islands, each stepping at its own times, so
    every step end of one falls inside a step of the other, whose ball is interpolated there (spin
    and dissipated work straight across the step). Drawn at those frames the energy residual was
    1.3e-5 while the run balances to round-off; now only states where every body is at a knot or
    in free flight are drawn (`diagnostics.settled`)."""
    scene = parse_scene({
        "name": "two-sliding", "dim": 3, "dt": "auto", "integrator": "kahan6", "tol": 1e-6, "duration": 0.3,
        "gravity": [0.0, 0.0, -9.81], "contact": {"k": 1e7, "mu": 0.3},
        "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
        "body": [{"name": "a", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.0, 0.05], "velocity": [1.0, 0.0, 0.0]},
                 {"name": "b", "mass": 0.2, "radius": 0.07, "position": [0.0, 1.0, 0.07],
                  "velocity": [0.6, 0.0, 0.0]}]})
    run = run_scene(scene)
    traj = run.result.trajectory
    times = traj.knot_times
    exact = dg.settled(traj, times)
    assert 10 < exact.sum() < 0.5 * len(times)  # most step ends are inside the other ball's step
    path = write_recording(run, tmp_path / "two.rrd")
    drawn, energy = _series(path, "/residuals/energy")
    nearest = np.abs(drawn[:, None] - times[exact][None, :]).min(axis=1)
    assert len(drawn) > 10 and (nearest <= 1e-9).all()  # the file keeps times to the nanosecond
    assert np.abs(energy).max() < 1e-12


def test_rrd_verify_accepts_the_file(written: dict) -> None:
    if not RERUN.exists():
        pytest.skip("no rerun executable next to python")
    _, path = written["demo-bonus"]
    out = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    assert "1 file verified" in out.stdout + out.stderr


def test_bad_files_raise_recording_error(written: dict, tmp_path: Path) -> None:
    import rerun as rr

    text = tmp_path / "notes.rrd"
    text.write_text("this is not a recording\n")
    data = written["demo-bonus"][1].read_bytes()
    truncated = tmp_path / "truncated.rrd"
    truncated.write_bytes(data[: len(data) // 2])
    foreign = tmp_path / "foreign.rrd"
    stream = rr.RecordingStream("someone-else")
    stream.save(foreign)
    stream.log("/points", rr.Points3D([[0.0, 0.0, 0.0]]))
    stream.flush()
    stream.disconnect()
    for path, words in ((text, "not a Rerun recording"), (truncated, "truncated"),
                        (foreign, "not a collide recording"), (tmp_path / "missing.rrd", "no such file")):
        with pytest.raises(RecordingError) as info:
            read_recording(path)
        message = str(info.value)
        assert str(path) in message and words in message and "\n" not in message
    assert issubclass(RecordingError, ValueError)


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = run_scene(load_scene("demo-1d"))
    target = tmp_path / "new" / "folder" / "run.rrd"

    def boom(self: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(rec_writer._Writer, "_write_meta", boom)
    with pytest.raises(KeyboardInterrupt):
        write_recording(run, target)
    assert not target.exists()
    assert list(target.parent.iterdir()) == []  # no temporary file left behind
    monkeypatch.undo()
    assert write_recording(run, target) == target
    assert [p.name for p in target.parent.iterdir()] == ["run.rrd"]


def test_stride_thins_contact_frames(tmp_path: Path) -> None:
    run = run_scene(load_scene("demo-1d"), integrator="verlet", dt=1e-5)
    write_recording(run, tmp_path / "a.rrd", stride=1)
    dense = rec.last_write.exact_frames
    assert dense >= int(run.result.steps[0])
    write_recording(run, tmp_path / "b.rrd", stride=10)
    assert rec.last_write.exact_frames < dense / 5
    assert rec.last_write.frames >= rec.last_write.exact_frames + rec.CONTACT_FRAMES - 2
    back = read_recording(tmp_path / "b.rrd")
    np.testing.assert_array_equal(back.result.trajectory.s, run.result.trajectory.s)


def test_few_long_steps_still_animate_smoothly(written: dict) -> None:
    run, _ = written["demo-bonus"]
    exact, view = rec.frame_times(run.result.trajectory, 120.0, 1, 100)
    log = run.result.contacts
    inside = (view >= log.first_start[0]) & (view <= log.last_end[0])
    assert inside.sum() >= 100
    steps = run.result.trajectory.t[:, 0]
    assert np.isin(steps, exact).all()  # every step is an exact frame
