"""Many bodies stay live: a scene of many bodies shows its start at once while its run goes in the
background, a colour mode sends the spheres' colours only, and a recording of many bodies keeps
every k-th frame of its 3D view and says so (the viewer's drawing and loading paths)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from collide.recording import read_recording, write_recording
from collide.recording import writer as rec_writer
from collide.recording.reader import _columns, _load_chunks, _meta
from collide.run import run_scene
from collide.scene import load_scene, parse_scene
from tests.conftest import BROWSER_MARKS
from tests.test_viewer_background import _pile
from viewer.frames import StartFrames, start_frames
from viewer.testing import ServerClient, wait_for_text, wait_until

# The spheres' colours as the page holds them (viser's scene tree, exposed for tests).
COLOURS_JS = """() => {
    const node = window.__viserSceneTree?.getState()['/bodies/spheres'];
    const c = node?.message?.props?.batched_colors;
    return c ? Array.from(c) : null;
}"""


def _drifting(n: int) -> object:
    """n spheres in free flight, far apart (no contact): a many-body recording in milliseconds."""
    side = int(np.ceil(n ** (1 / 3)))
    bodies = [{"name": f"b{k}", "mass": 0.01, "radius": 0.01,
               "position": [0.1 * (k % side), 0.1 * (k // side % side), 0.1 * (k // side // side)],
               "velocity": [0.01 * (k % 3), -0.02, 0.005 * (k % 5)]} for k in range(n)]
    return parse_scene({"name": "drift", "dim": 3, "dt": 1e-4, "duration": 0.5, "contact": {"k": 1000.0},
                        "body": bodies}, "drift")


def test_start_frames_are_the_scene_where_it_starts():
    scene = load_scene("pile")
    start = start_frames(scene)
    assert isinstance(start, StartFrames) and start.n_bodies == len(scene.bodies) == 1000
    assert start.scene is scene and start.preview and start.run is None  # nothing to save or export yet
    assert start.t0 == start.t1 == 0.0
    frame = start.frame(0.0)
    assert np.array_equal(frame.positions, np.array([b.position for b in scene.bodies]))
    assert np.array_equal(frame.velocities, np.array([b.velocity for b in scene.bodies]))
    assert np.allclose(start.radius, [b.radius for b in scene.bodies])
    # The floor and the box's sides, for the drawer's floor and shadows.
    assert len(start.walls) == len(scene.walls) and any(n[2] == 1.0 for _, n in start.walls)
    assert "at the start" in start.status_lines()[0]


def test_a_many_body_scene_is_not_run_before_the_server_starts(tmp_path):
    from viewer.app import ViewerApp
    from viewer.live import MANY_BODIES

    path = tmp_path / "small-pile.toml"
    path.write_text(_pile(MANY_BODIES + 16, 0.03).to_toml())
    app = ViewerApp(str(path), port=0, recordings_dir=tmp_path)
    app.prepare()
    assert app.initial_run is None and app.initial_scene is not None and app.initial_cost is None


def test_a_colour_mode_sends_the_colours_only(tmp_path):
    """Server side: the spheres' batch gets new colours, and no position is sent again."""
    from viewer.app import ViewerApp
    from viewer.session import Session

    app = ViewerApp("demo-1d", port=0, recordings_dir=tmp_path)
    app.start()
    session = Session(app.session_config(), ServerClient(app.server))  # type: ignore[arg-type]
    session.fit_camera = lambda *a, **k: None
    try:
        start = start_frames(load_scene("pile"))
        session.show_frames(start)
        spheres = session.drawer._batch["spheres"]
        socket = session.client.scene._websock_interface
        sent: list = []
        real = socket.queue_message
        socket.queue_message = lambda message: (sent.append(message), real(message))[1]
        try:
            session.set_show(colour_by="speed")
        finally:
            socket.queue_message = real
        scene = [(m.name, sorted(m.updates)) for m in sent if type(m).__name__ == "SceneNodeUpdateMessage"]
        assert scene == [("/bodies/spheres", ["batched_colors"])]
        speed = np.linalg.norm(start.velocities[0], axis=-1)
        colours = session.drawer.body_colours()
        assert np.array_equal(spheres.batched_colors, colours)
        assert colours[np.argmax(speed)].sum() > colours[np.argmin(speed)].sum()  # viridis: brighter is faster
    finally:
        session.close()
        app.stop()


def test_a_recording_of_many_bodies_keeps_every_kth_frame_and_says_so(tmp_path, monkeypatch):
    scene = _drifting(27)
    run = run_scene(scene)
    whole = write_recording(run, tmp_path / "whole.rrd")
    assert rec_writer.last_write.frame_every == 1
    frames_whole = rec_writer.last_write.frames
    # 0.5 s at 120 frames a second for 27 bodies is 1 620 positions; allow 600.
    monkeypatch.setattr(rec_writer, "MAX_BODY_FRAMES", 600)
    kept = write_recording(run, tmp_path / "kept.rrd")
    k = rec_writer.last_write.frame_every
    assert k == int(np.ceil(0.5 * 120 * 27 / 600)) == 3
    assert rec_writer.last_write.fps == pytest.approx(120 / k)
    assert rec_writer.last_write.frames * 27 <= 600 + 2 * 27 < frames_whole * 27
    chunks = _load_chunks(kept)
    assert _meta(kept, chunks)["frame_every"] == k
    settings = " ".join(str(a.to_pylist()) for arrays in _columns(chunks, "/settings").values() for a in arrays)
    assert re.search(rf"every k-th frame, k = {k}, of 120 per second \(27 bodies\)", settings)
    # The trajectory is stored whole: the run read back is the same either way.
    a, b = read_recording(whole, trusted=True), read_recording(kept, trusted=True)
    assert np.array_equal(a.result.trajectory.knots, b.result.trajectory.knots)
    assert np.array_equal(a.result.final.v, b.result.final.v)


# ---------------------------------------------------------------------------------------------
# In a browser


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    from viewer.app import ViewerApp

    folder = tmp_path_factory.mktemp("live")
    app = ViewerApp("demo-1d", port=0, recordings_dir=folder)
    app.start()
    yield app
    app.stop()


def _in_browser(test):
    for mark in BROWSER_MARKS:
        test = mark(test)
    return test


@_in_browser
def test_browser_colour_mode_on_a_thousand_spheres_updates_their_colours(browser, app):
    """The page holds the new colours for all 1 000 spheres, and the positions it holds are the
    same object as before: only colours were sent."""
    from viewer.testing import open_page

    page = open_page(browser, app, query="fixedDpr=0.5")
    session = page.session
    start = start_frames(load_scene("pile"))
    session.show_frames(start)
    wait_for_text(page, "1000 bodies at the start", timeout=120)
    page.wait_for_function(f"() => {{ const c = ({COLOURS_JS})(); return c && c.length === {3 * 1000}; }}",
                           timeout=120_000)
    page.evaluate("() => { window.__positionsBefore = window.__viserSceneTree.getState()['/bodies/spheres']"
                  ".message.props.batched_positions; }")
    session.set_show(colour_by="speed")
    want = session.drawer.body_colours().reshape(-1).tolist()
    page.wait_for_function(f"(want) => {{ const c = ({COLOURS_JS})(); return c && c.every((x, i) => x === want[i]); }}",
                           arg=want, timeout=120_000)
    same = page.evaluate("() => window.__viserSceneTree.getState()['/bodies/spheres'].message.props.batched_positions"
                         " === window.__positionsBefore")
    assert same, "the positions were sent again with the colours"
    assert len({tuple(c) for c in session.drawer.body_colours()}) > 20
    page.close()


@_in_browser
def test_browser_a_many_body_scene_shows_its_start_then_its_run(browser, tmp_path):
    from viewer.app import ViewerApp
    from viewer.live import MANY_BODIES

    path = tmp_path / "small-pile.toml"
    path.write_text(_pile(MANY_BODIES + 16, 0.02).to_toml())
    app = ViewerApp(str(path), port=0, recordings_dir=tmp_path)
    app.prepare()
    app.start()
    try:
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(app.url + "/?fixedDpr=0.5")
        session = app.wait_for_session(1, timeout=120)[0]
        wait_until(lambda: len(session.timings) >= 1, 120, "the start drawn")  # counted once drawn
        assert session.timings[0]["preview"]  # the start, before any run
        wait_for_text(page, "small-pile", "simulated in", timeout=300)
        assert session.view.run is not None and session.view.n_bodies == MANY_BODIES + 16
        page.close()
    finally:
        app.stop()
