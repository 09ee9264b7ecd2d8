"""`collide view FILE.rrd` in a real browser (issue 52, item 6): the server listens before the
recording is read, the page shows the recording's first frame (its scene's start) with a status
saying the rest is still loading, then its run. Functional, not timed: the seconds are
benchmarks/bench_large_recording.py's (`open`).

A pile of 1 000 spheres recorded for a few milliseconds stands in for the built-in pile's
recording (the same bodies; its run only shorter). The run is held back while the page is
checked (the server's preparation of it waits on an event), so "still loading" is seen whatever
the machine's speed.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from collide.recording import write_recording
from collide.run import run_scene
from collide.scene import load_scene
from tests.conftest import BROWSER_MARKS
from tests.test_viewer_browser_lod import POINTS_JS
from viewer.testing import launch, screenshot_dir, wait_for_text, wait_until

pytestmark = BROWSER_MARKS


@pytest.fixture(scope="module")
def pile_recording(tmp_path_factory):
    run = run_scene(load_scene("pile", ["duration=0.004"]))
    return run, write_recording(run, tmp_path_factory.mktemp("rec") / "pile.rrd")


def _points(page) -> np.ndarray | None:
    values = page.evaluate(POINTS_JS)
    return None if values is None else np.asarray(values, float).reshape(-1, 3)


def test_the_page_shows_the_start_while_the_run_loads_then_the_run(pile_recording, monkeypatch, tmp_path):
    from playwright.sync_api import sync_playwright

    import viewer.state
    from viewer.app import ViewerApp

    run, path = pile_recording
    release, held = threading.Event(), threading.Event()
    prepare = viewer.state.ViewRun

    def held_back(*args, **kwargs):  # the reader's run is in: its display waits for the test
        held.set()
        assert release.wait(300)
        return prepare(*args, **kwargs)

    monkeypatch.setattr(viewer.state, "ViewRun", held_back)
    # Points (not spheres) above 100 bodies: the page's positions are then read back exactly.
    app = ViewerApp(str(path), host="127.0.0.1", port=0, recordings_dir=tmp_path, point_bodies=100)
    app.begin_reading()
    app.prepare()
    app.start()
    start = np.array([b.position for b in run.scene.bodies], float)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1100, "height": 760})
            page.goto(app.url + "/?fixedDpr=0.6")
            text = wait_for_text(page, "is still loading", timeout=300)
            assert f"1000 bodies at the start (t = 0 s): {path.name} is still loading" in text
            assert f"Reading {path.name}" in text and "Replaying" not in text
            wait_until(lambda: (got := _points(page)) is not None and got.shape == start.shape, 120,
                       "the start's points in the page")
            np.testing.assert_allclose(_points(page), start, rtol=0, atol=1e-6)  # float32 in the page
            assert wait_until(held.is_set, 300, "the run read back")
            assert app.opening.view is None and not app.opening.done.is_set()
            page.screenshot(path=str(screenshot_dir() / "open-recording-loading.png"))

            release.set()
            text = wait_for_text(page, f"Replaying {path.name}", timeout=300)
            assert "is still loading" not in text and f"Reading {path.name}" not in text
            app.wait_for_recording(60)
            view = app.opening.view
            assert view.n_bodies == 1000 and view.t1 == pytest.approx(float(run.result.final.t[0]))
            # The run's first frame is its start: the same points, now the run's.
            wait_until(lambda: (got := _points(page)) is not None and got.shape == start.shape, 120, "the run's points")
            np.testing.assert_allclose(_points(page), view.frame(view.t0).positions, rtol=0, atol=1e-6)
            page.screenshot(path=str(screenshot_dir() / "open-recording-loaded.png"))
            browser.close()
    finally:
        release.set()
        app.stop()


def test_a_recording_that_cannot_be_read_is_said_in_the_page_and_by_wait(tmp_path):
    """The server listens before the file is read: a file that is not a recording is refused
    by `wait_for_recording` (the CLI's one line, exit code 2) and in the tab's status."""
    from playwright.sync_api import sync_playwright

    from collide.recording import RecordingError
    from viewer.app import ViewerApp

    path = tmp_path / "notes.rrd"
    path.write_text("not a recording")
    app = ViewerApp(str(path), host="127.0.0.1", port=0, recordings_dir=tmp_path)
    app.begin_reading()
    app.prepare()
    app.start()
    try:
        with pytest.raises(RecordingError, match="not a Rerun recording"):
            app.wait_for_recording(120)
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1100, "height": 760})
            page.goto(app.url)
            text = wait_for_text(page, "Cannot open notes.rrd", timeout=120)
            assert "not a Rerun recording" in text
            browser.close()
    finally:
        app.stop()
