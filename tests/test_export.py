"""`collide export`: VTK series, long-form CSV, MP4 and scene TOML from recordings, checked against
the runs they came from (initial and final states, contact geometry), and refusals that write nothing."""

from __future__ import annotations

import base64
import csv
import json
import struct
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from collide.export import contacts_path, export_run, frames_folder
from collide.recording import read_recording, write_recording
from collide.run import run_scene
from collide.scene import load_scene, parse_scene

COLLIDE = Path(sys.executable).parent / "collide"
# pair-3d last: its run has a warning, and a recording without warnings written after one with
# them in the same process reads back as damaged (a recording bug outside export, reported).
SCENES = ["demo-bonus", "bounce", "demo-1d", "pair-3d"]
# Two spheres in 3D, with spin and friction, meeting each other and a wall (small: quick interpreted).
PAIR_3D = {
    "name": "pair-3d", "dim": 3, "dt": 1e-4,
    "contact": {"k": 5000.0, "mu": 0.3},
    "body": [{"name": "a", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.2, 0.0],
              "velocity": [0.5, -1.0, 0.2], "spin": [0.0, 0.0, 4.0]},
             {"name": "b", "mass": 0.1, "radius": 0.05, "position": [0.3, 0.2, 0.05],
              "velocity": [-0.5, -1.0, 0.0]}],
    "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}],
}


def _scene(name: str):
    return parse_scene(PAIR_3D, name) if name == "pair-3d" else load_scene(name)
_NUMPY = {"Float64": "<f8", "Int32": "<i4", "Int64": "<i8"}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple]:
    """Each scene's run, its recording, and the run read back from the recording."""
    folder = tmp_path_factory.mktemp("rrd")
    out = {}
    for name in SCENES:
        run = run_scene(_scene(name))
        path = write_recording(run, folder / f"{name}.rrd")
        out[name] = (run, path, read_recording(path, trusted=True))
    return out


def _array(node: ET.Element) -> np.ndarray:
    """A VTK XML DataArray as numpy (binary: base64 of a UInt32 byte count and the data; or ascii)."""
    kind, width = _NUMPY[node.get("type")], int(node.get("NumberOfComponents", "1"))
    if node.get("format") == "ascii":
        values = np.array((node.text or "").split(), dtype=kind)
    else:
        raw = base64.b64decode(node.text or "")
        (count,) = struct.unpack("<I", raw[:4])
        assert count == len(raw) - 4
        values = np.frombuffer(raw[4:], dtype=kind)
    return values.reshape(-1, width) if width > 1 else values


def _polydata(path: Path) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Point data, cell data, points and the lines' point pairs of one .vtp file."""
    piece = ET.parse(path).getroot().find("PolyData/Piece")
    point = {a.get("Name"): _array(a) for a in piece.find("PointData")}
    cell = {a.get("Name"): _array(a) for a in piece.find("CellData")}
    points = _array(piece.find("Points/DataArray"))
    lines = {a.get("Name"): _array(a) for a in piece.find("Lines")}
    assert len(points) == int(piece.get("NumberOfPoints"))
    assert len(lines["offsets"]) == int(piece.get("NumberOfLines"))
    np.testing.assert_array_equal(lines["offsets"], 2 * np.arange(1, len(lines["offsets"]) + 1))
    return point, cell, points, lines["connectivity"].reshape(-1, 2)


def _pad(x: np.ndarray) -> np.ndarray:
    return np.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, 3 - x.shape[-1])])


def _series(pvd: Path) -> list[tuple[float, Path]]:
    root = ET.parse(pvd).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), pvd.parent / d.get("file")) for d in root.find("Collection")]


@pytest.mark.parametrize("name", SCENES)
def test_vtk_series_holds_the_run(recorded: dict, name: str, tmp_path: Path) -> None:
    run, _, back = recorded[name]
    pvd = tmp_path / f"{name}.pvd"
    export_run(back, "vtk", pvd)
    series = _series(pvd)
    times = np.array([t for t, _ in series])
    assert len(series) > 2 and np.all(np.diff(times) > 0)
    assert times[0] == run.result.initial.t[0] and times[-1] == run.result.final.t[0]
    model, n = run.result.model, run.result.model.n_bodies
    lines = 0
    for k, (_, vtp) in enumerate(series):
        point, cell, points, pairs = _polydata(vtp)
        np.testing.assert_array_equal(point["radius"][:n], model.radius[0])
        np.testing.assert_array_equal(point["id"][:n], np.arange(n))
        if k in (0, len(series) - 1):  # the run's own states at its start and end
            state = run.result.initial if k == 0 else run.result.final
            np.testing.assert_allclose(points[:n], _pad(state.s[0]), rtol=0, atol=1e-12)
            np.testing.assert_allclose(point["velocity"][:n], _pad(state.v[0]), rtol=0, atol=1e-12)
        lines += len(pairs)
        _check_contacts(model, point, cell, points, pairs)
    assert lines > 0, "every scene here has contacts"


def _check_contacts(model, point: dict, cell: dict, points: np.ndarray, pairs: np.ndarray) -> None:
    """Each line joins two spheres that overlap by its `overlap`, or a sphere and a point on a wall
    at the sphere's radius less the overlap; its force's magnitude is `normal_force`."""
    n = model.n_bodies
    np.testing.assert_array_equal(pairs[:, 0], cell["i"])
    np.testing.assert_allclose(cell["normal_force"], np.linalg.norm(cell["normal_force_vector"], axis=1))
    assert np.all(cell["overlap"] > 0) and np.all(cell["normal_force"] > 0)
    radius = model.radius[0]
    for (a, b), j, overlap in zip(pairs, cell["j"], cell["overlap"]):
        gap = np.linalg.norm(points[a] - points[b])
        if j >= 0:
            assert b == j
            np.testing.assert_allclose(radius[a] + radius[b] - gap, overlap, rtol=1e-9, atol=1e-15)
        else:
            assert b >= n and point["id"][b] == j and point["radius"][b] == 0.0
            wall = -1 - j
            normal, on = _pad(model.wall_normal[wall]), _pad(model.wall_point[wall])
            np.testing.assert_allclose(np.dot(points[b] - on, normal), 0.0, atol=1e-12)
            np.testing.assert_allclose(gap, radius[a] - overlap, rtol=1e-9)


def test_vtk_ascii_equals_binary(recorded: dict, tmp_path: Path) -> None:
    _, _, back = recorded["demo-bonus"]
    export_run(back, "vtk", tmp_path / "b.pvd")
    export_run(back, "vtk", tmp_path / "a.pvd", ascii=True)
    for (_, fb), (_, fa) in zip(_series(tmp_path / "b.pvd"), _series(tmp_path / "a.pvd"), strict=True):
        for x, y in zip(_polydata(fb), _polydata(fa), strict=True):
            if isinstance(x, dict):
                assert x.keys() == y.keys()
                for key in x:
                    np.testing.assert_array_equal(x[key], y[key])
            else:
                np.testing.assert_array_equal(x, y)


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        table = list(csv.reader(f))
    return table[0], table[1:]


@pytest.mark.parametrize("name", SCENES)
def test_long_csv(recorded: dict, name: str, tmp_path: Path) -> None:
    run, _, back = recorded[name]
    model = run.result.model
    export_run(back, "csv", tmp_path / "x.csv")
    export_run(back, "vtk", tmp_path / "x.pvd")
    header, rows = _rows(tmp_path / "x.csv")
    axes = "xyz"[:model.dim]
    spin = {0: "", 1: "z", 3: "xyz"}[model.spin_dim]
    assert header == ["t", "body", *axes, *(f"v{a}" for a in axes), *(f"w{a}" for a in spin)]
    n, frames = model.n_bodies, len(_series(tmp_path / "x.pvd"))
    assert len(rows) == n * frames
    assert [r[1] for r in rows[:n]] == list(model.body_names)
    for state, chunk in ((run.result.initial, rows[:n]), (run.result.final, rows[-n:])):
        values = np.array([[float(x) for x in r[2:]] for r in chunk])
        assert {float(r[0]) for r in chunk} == {float(state.t[0])}
        d = model.dim
        np.testing.assert_allclose(values[:, :d], state.s[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(values[:, d:2 * d], state.v[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(values[:, 2 * d:], state.w[0].reshape(n, -1), rtol=0, atol=1e-12)
    header, contacts = _rows(contacts_path(tmp_path / "x.csv"))
    friction = [f"friction_{a}" for a in axes] if back.scene.has_friction else []
    assert header == ["t", "i", "j", "overlap", "normal_force", *friction]
    lines = sum(len(_polydata(f)[3]) for _, f in _series(tmp_path / "x.pvd"))
    assert len(contacts) == lines > 0
    names = set(model.body_names) | {f"wall{k}" for k in range(model.n_walls)}
    assert all(r[1] in names and r[2] in names and float(r[3]) > 0 and float(r[4]) > 0 for r in contacts)


@pytest.mark.parametrize("name", ["demo-bonus", "bounce", "pair-3d"])
def test_scene_toml_runs_the_same_run(recorded: dict, name: str, tmp_path: Path) -> None:
    run, _, back = recorded[name]
    path = tmp_path / "again.toml"
    export_run(back, "toml", path)
    tomllib.loads(path.read_text())
    again = run_scene(load_scene(str(path)))
    a, b = run.result, again.result
    assert b.integrator == a.integrator and b.steps[0] == a.steps[0]
    np.testing.assert_array_equal(b.dt, a.dt)
    for field in ("t", "s", "v", "w"):
        np.testing.assert_array_equal(getattr(b.final, field), getattr(a.final, field), err_msg=field)


def test_scene_toml_keeps_the_runs_settings(tmp_path: Path) -> None:
    """A run with another integrator and step than its scene's, by the CLI: the exported TOML
    holds the run's, and `collide run` on it gives the same summary."""
    first = _cli("run", "demo-bonus", "--integrator", "seed", "--dt", "1e-5", "--out", "seed.rrd", "--json",
                 cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    done = _cli("export", "seed.rrd", "--format", "toml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    scene = tomllib.loads((tmp_path / "seed.toml").read_text())
    assert scene["integrator"] == "seed" and scene["dt"] == 1e-5
    again = _cli("run", "seed.toml", "--no-record", "--json", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    a, b = json.loads(first.stdout), json.loads(again.stdout)
    assert b["steps"] == a["steps"] and b["bodies"] == a["bodies"] and b["integrator"] == "seed"


def test_mp4_plays(recorded: dict, tmp_path: Path) -> None:
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    _, _, back = recorded["pair-3d"]
    path = tmp_path / "break.mp4"
    export_run(back, "mp4", path, max_frames=24)
    count, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert count == 24
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["size"] == (960, 720) and meta["codec"] == "h264"
    first = np.frombuffer(next(reader), np.uint8).reshape(720, 960, 3)
    assert first.std() > 5  # a picture, not a blank frame
    reader.close()


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(COLLIDE), *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_damaged_recording_is_refused_and_nothing_written(recorded: dict, tmp_path: Path) -> None:
    data = bytearray(recorded["demo-bonus"][1].read_bytes())
    data[len(data) // 2] ^= 0xFF
    (tmp_path / "bad.rrd").write_bytes(bytes(data))
    for fmt in ("vtk", "csv", "toml"):
        done = _cli("export", "bad.rrd", "--format", fmt, cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        assert done.stdout == "" and len(done.stderr.strip().splitlines()) == 1
        assert done.stderr.startswith("error: ") and "bad.rrd" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.rrd"]


def test_cli_writes_and_refuses_usage(recorded: dict, tmp_path: Path) -> None:
    _, source, _ = recorded["bounce"]
    done = _cli("export", str(source), "--format", "vtk", "--out", "out/b.pvd", "--max-frames", "5", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert len(_series(tmp_path / "out/b.pvd")) == 5
    assert len(list(frames_folder(tmp_path / "out/b.pvd").iterdir())) == 5
    # Again with fewer frames: the folder is replaced, not added to.
    done = _cli("export", str(source), "--out", "out/b.pvd", "--max-frames", "3", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert len(list((tmp_path / "out/b").iterdir())) == 3 and len(_series(tmp_path / "out/b.pvd")) == 3
    for args in (["--format", "gif"], ["--out", "x.vtp"], ["--fps", "0"]):
        done = _cli("export", str(source), *args, cwd=tmp_path)
        assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, (args, done.stderr)
    frames = [f"frame_0000{k}.vtp" for k in range(3)]
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["b", "b.pvd", *frames, "out"]


@pytest.mark.parametrize("name", ["demo-bonus", "pair-3d"])
def test_friction_is_the_contact_series_own(recorded: dict, name: str) -> None:
    """The export's friction lookup (pressed contacts only) gives diagnostics.contact_series's forces."""
    from collide import diagnostics as dg
    from collide.export.frames import export_frames, export_times

    run = recorded[name][2]
    times = export_times(run)
    frames = export_frames(run, times)
    series = dg.contact_series(run.result.model, run.result.trajectory, times)
    index = {tuple(p): c for c, p in enumerate(series.pairs.tolist())}
    which = [index[tuple(p)] for p in frames.pairs.tolist()]
    want = series.friction_force[frames.contact_frame, 0, which]
    d = run.result.model.dim
    assert len(want) > 0 and np.abs(want).max() > 0
    np.testing.assert_array_equal(frames.friction[:, :d], want)
    np.testing.assert_array_equal(frames.normal_force[:, :d], series.normal_force[frames.contact_frame, 0, which])


def test_download_bundles(recorded: dict) -> None:
    """What the viewer sends: a zip of the VTK series or of both CSV tables, the TOML itself."""
    import io
    import zipfile

    from collide.export import export_download

    run = recorded["demo-bonus"][2]
    name, data = export_download(run, "vtk", "bonus", max_frames=4)
    names = zipfile.ZipFile(io.BytesIO(data)).namelist()
    assert name == "bonus-vtk.zip" and sorted(names) == ["bonus.pvd", *(f"bonus/frame_0000{k}.vtp" for k in range(4))]
    name, data = export_download(run, "csv", "bonus")
    assert name == "bonus-csv.zip" and sorted(zipfile.ZipFile(io.BytesIO(data)).namelist()) == \
        ["bonus-contacts.csv", "bonus.csv"]
    name, data = export_download(run, "toml", "bonus")
    assert name == "bonus.toml" and tomllib.loads(data.decode())["name"] == "demo-bonus"


def test_viewer_download_buttons(recorded: dict) -> None:
    """The viewer's VTK, CSV long, MP4 and TOML buttons send what `export_download` makes (no
    browser: the download goes to a stand-in client)."""
    import io
    import zipfile

    from viewer.file_actions import EXPORTS, FileActions
    from viewer.state import ViewRun

    sent, said = [], []
    actions = FileActions.__new__(FileActions)
    send = lambda self, name, data, **kw: sent.append((name, data))  # noqa: E731
    actions._client = type("Client", (), {"send_file_download": send})()
    actions._shown = lambda: (ViewRun(recorded["demo-bonus"][2]), 0.0)
    actions._say = lambda message, error=False: said.append((message, error))
    actions.downloads = []
    formats = {"vtk": "demo-bonus-vtk.zip", "csv": "demo-bonus-csv.zip", "toml": "demo-bonus.toml"}
    assert set(formats) < set(EXPORTS.values())
    for fmt, name in formats.items():
        assert actions.export_file(fmt) == name
    assert [n for n, _ in sent] == list(formats.values()) and not any(error for _, error in said)
    assert "demo-bonus.pvd" in zipfile.ZipFile(io.BytesIO(sent[0][1])).namelist()
    actions._shown = lambda: (None, 0.0)
    assert actions.export_file("toml") is None and said[-1] == ("No run to export.", True)
