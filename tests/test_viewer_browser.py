"""The viewer in a real browser: Debian's chromium driven by Playwright (headless, software GL).

One server and one browser for the module. The server runs in-process on 127.0.0.1, port 0,
so the tests can also look at each tab's `Session` (its state model) next to what the page
shows. Skipped, with the reason, when /usr/bin/chromium or the playwright package is missing.
"""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import BROWSER_MARKS
from viewer.testing import screenshot_dir

DOCS = screenshot_dir()

try:
    from playwright.sync_api import Page
except ImportError:  # pragma: no cover - depends on the machine
    pass

pytestmark = BROWSER_MARKS


def dom_id(handle) -> str:
    """The DOM id viser gives a GUI element (its uuid)."""
    return handle._impl.uuid


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Path:
    from collide.recording import write_recording
    from collide.run import run_scene
    from collide.scene import load_scene

    folder = tmp_path_factory.mktemp("recordings")
    write_recording(run_scene(load_scene("demo-2d-moving")), folder / "moving.rrd")
    (folder / "broken.rrd").write_bytes(b"RRF2 but not really a recording")
    return folder


@pytest.fixture(scope="module")
def app(recordings):
    from viewer.app import ViewerApp

    app = ViewerApp("demo-bonus", host="127.0.0.1", port=0, recordings_dir=recordings)
    app.start()
    yield app
    app.stop()



@pytest.fixture(scope="module")
def page(browser, app):
    page = browser.new_page(viewport={"width": 1600, "height": 900})
    page.goto(app.url)
    page.wait_for_selector("canvas", timeout=30_000)
    session = app.wait_for_session(1)[0]
    assert session.worker.wait_idle(60)
    page.wait_for_function("() => document.body.innerText.includes('simulated in')", timeout=30_000)
    page.add_style_tag(content=".mantine-Notifications-root{display:none !important}")
    page.session = session  # type: ignore[attr-defined]
    yield page
    page.close()


def session_of(page: Page):
    return page.session  # type: ignore[attr-defined]


def status_text(page: Page) -> str:
    return page.evaluate("""() => [...document.querySelectorAll('p')].map(p => p.innerText)
                            .find(t => t.includes('simulated in') || t.includes('Not run')) || ''""")


def plot_data(page: Page, title: str) -> list[list[float]]:
    """The data of the uPlot chart with this title, as the browser holds it."""
    return page.evaluate("""(title) => {
        const charts = Object.values(window.__viserTestpoints?.uplots || {}).map(u => u.chart);
        const c = charts.find(c => (c.root.innerText || '').startsWith(title));
        return c ? c.data.map(a => Array.from(a)) : null;
    }""", title)


def canvas_shot(page: Page) -> bytes:
    """A screenshot of the 3D canvas (the largest canvas on the page)."""
    page.evaluate("""() => {
        const cs = [...document.querySelectorAll('canvas')];
        cs.sort((a, b) => b.clientWidth * b.clientHeight - a.clientWidth * a.clientHeight);
        cs[0].setAttribute('data-test', 'scene');
    }""")
    return page.locator("canvas[data-test=scene]").screenshot()


def click_slider(page: Page, handle, fraction: float) -> None:
    """Click a slider's track at `fraction` of its width, as a user would."""
    slider = page.locator(f'[id="{dom_id(handle)}"]')
    slider.scroll_into_view_if_needed()
    box = slider.bounding_box()
    page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)


def text_input(page: Page, handle):
    """The text box of a parameter or of the time (what a user types into)."""
    from viewer.testing import text_box

    return text_box(page, handle)


def choose(page: Page, handle, option: str) -> None:
    """Pick an option of a viser dropdown (a Mantine Select)."""
    box = page.locator(f'[id="{dom_id(handle)}"]')
    box.scroll_into_view_if_needed()
    box.click()
    page.get_by_role("option", name=option, exact=True).click()


def wait_until(predicate, timeout: float = 30.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def colour_fraction(png: bytes, rgb: tuple[int, int, int], tol: int = 40) -> float:
    """Share of pixels within `tol` of a colour (per channel)."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float(np.mean(np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1)))


# ---------------------------------------------------------------------------------------------


def test_page_shows_scene_controls_and_plots(page):
    session = session_of(page)
    assert page.locator("canvas").count() >= 1
    text = status_text(page)
    assert "demo-bonus" in text and "residuals: energy" in text and "ms wall" in text
    for title in ("energy", "momentum", "angular momentum", "compression"):
        data = plot_data(page, title)
        assert data is not None and len(data[0]) > 100, title
    # Controls of a 2D scene with friction: spin and mu are there.
    assert {"body.ball1.spin", "contact.mu", "contact.k"} <= set(session._param_handles)
    assert page.get_by_text("spin (rad/s)").count() == 2


def test_screenshot_of_demo_bonus_mid_contact(page):
    """docs/viewer-demo-bonus.png: both spheres, their spin markers, the friction arrow."""
    session = session_of(page)
    view = session.view
    a, b = view.contact_windows[0]
    # The sliding phase: friction at its Coulomb limit, compression well under way.
    session.seek(a + 0.12 * (b - a))
    frame = view.frame(session.t)
    assert frame.contacts and np.linalg.norm(frame.contacts[0].friction_force) > 1.0
    session.fit_camera("contact")
    page.wait_for_timeout(2500)
    png = page.screenshot(path=str(DOCS / "viewer-demo-bonus.png"))
    scene = canvas_shot(page)
    # ball1 blue, ball2 orange, the friction arrow green, the normal arrow red.
    assert colour_fraction(scene, (90, 150, 240), 45) > 0.01
    assert colour_fraction(scene, (250, 170, 90), 45) > 0.01
    assert colour_fraction(scene, (110, 220, 170), 50) > 0.0005
    assert len(png) > 50_000


def test_slider_resimulates_and_redraws(page):
    session = session_of(page)
    before_text = status_text(page)
    before_plot = plot_data(page, "compression")
    before_shot = canvas_shot(page)
    drawn = session.runs_drawn
    click_slider(page, session._param_handles["contact.k"], 0.8)
    wait_until(lambda: session.controls is not None and session.runs_drawn > drawn and session.worker.idle()
               and not session.view.preview, 60, "the new run")
    k = session._param_handles["contact.k"].value
    assert k > 5000
    assert session.view.scene.contact.k == pytest.approx(k)
    page.wait_for_function("(old) => { const t = [...document.querySelectorAll('p')].map(p => p.innerText)"
                           ".find(t => t.includes('simulated in')); return t && t !== old; }", arg=before_text,
                           timeout=20_000)
    # A stiffer spring: a shorter, shallower contact in the compression plot.
    wait_until(lambda: plot_data(page, "compression") != before_plot, 20, "new plot data")
    after = plot_data(page, "compression")
    assert max(after[1]) < 0.8 * max(before_plot[1])
    page.wait_for_timeout(800)
    assert canvas_shot(page) != before_shot
    assert session.last_latency is not None


def test_unstable_combination_shows_message(page):
    session = session_of(page)
    good = session.view
    box = text_input(page, session._param_boxes["body.ball1.position.x"])
    box.scroll_into_view_if_needed()
    box.fill("480")  # ball1's centre 20 mm from ball2's: they overlap at the start
    page.wait_for_function("() => document.body.innerText.includes('Not run')", timeout=30_000)
    assert "overlaps" in status_text(page)
    assert session.view is good  # the last good run stays on screen
    # Back to the scene's own values: the message goes away.
    page.get_by_role("button", name="Reset parameters").click()
    page.wait_for_function("() => !document.body.innerText.includes('Not run')", timeout=60_000)
    assert session.worker.wait_idle(60)


def test_replay_recording_from_the_list_and_play(page, recordings):
    session = session_of(page)
    choose(page, session.recording, "moving.rrd")
    wait_until(lambda: session.view is not None and "moving.rrd" in session.view.origin, 30, "the replay")
    page.wait_for_function("() => document.body.innerText.includes('Replaying')", timeout=20_000)
    view = session.view
    assert view.scene.name == "demo-2d-moving"
    # The state the viewer draws is the recorded one.
    from collide.recording import read_recording
    from viewer.state import ViewRun

    reference = ViewRun(read_recording(recordings / "moving.rrd"))
    for t in np.linspace(view.t0, view.t1, 7):
        assert np.array_equal(view.frame(t).positions, reference.frame(t).positions)
    # Play it with the same controls: the time moves on, then pause.
    t0 = session.t
    page.get_by_role("button", name="Play").click()
    wait_until(lambda: session.playing, 10, "play")
    # The clock moves on while playing (its first frame can take seconds under load).
    wait_until(lambda: session.t != t0, 30, "the replay's time to move on")
    page.get_by_role("button", name="Pause").click()
    wait_until(lambda: not session.playing, 10, "pause")
    assert session.t != t0, (session.error, session.view.t0, session.view.t1)
    # The paused time reaches the box a moment later under load: wait for it, then compare.
    wait_until(lambda: abs(float(text_input(page, session.time_box).input_value()) - session.t * 1e3)
               <= 2 * session.time_slider.step, 15, "the time box to show the paused time")


def test_unreadable_recordings_show_a_message(page):
    session = session_of(page)
    good = session.view
    choose(page, session.recording, "broken.rrd")
    page.wait_for_function("() => document.body.innerText.includes('Cannot open broken.rrd')", timeout=20_000)
    upload = f'[id="file_upload_{dom_id(session.upload)}"]'
    page.set_input_files(upload, files=[{"name": "junk.rrd", "mimeType": "application/octet-stream",
                                         "buffer": b"\x00garbage" * 100}])
    page.wait_for_function("() => document.body.innerText.includes('Cannot open junk.rrd')", timeout=20_000)
    page.set_input_files(upload, files=[{"name": "notes.txt", "mimeType": "text/plain", "buffer": b"hello"}])
    page.wait_for_function("() => document.body.innerText.includes('is not a .rrd recording')", timeout=20_000)
    assert session.view is good
    assert not any(p.name.startswith(("junk", "notes", ".upload")) for p in session.config.recordings_dir.iterdir())


def test_upload_a_recording_and_save_a_run(page, recordings):
    session = session_of(page)
    content = (recordings / "moving.rrd").read_bytes()
    upload = f'[id="file_upload_{dom_id(session.upload)}"]'
    page.set_input_files(upload, files=[{"name": "../../my upload!.rrd", "mimeType": "application/octet-stream",
                                         "buffer": content}])
    wait_until(lambda: session.view is not None and "my-upload.rrd" in session.view.origin, 30, "the upload")
    assert (recordings / "my-upload.rrd").read_bytes() == content
    page.get_by_role("button", name="Save this run (.rrd)").click()
    page.wait_for_function("() => document.body.innerText.includes('Saved')", timeout=30_000)
    saved = [p for p in recordings.glob("demo-2d-moving-*.rrd")]
    assert len(saved) == 1
    from collide.recording import read_recording

    assert read_recording(saved[0]).scene.name == "demo-2d-moving"


def test_ensemble_draws_ghost_paths(page):
    session = session_of(page)
    choose(page, session.picker, "demo-bonus")
    wait_until(lambda: session.view is not None and session.view.scene.name == "demo-bonus"
               and session.worker.idle(), 60, "demo-bonus")
    page.get_by_text("Ensemble", exact=True).click()
    page.get_by_text("show ensemble").click()
    page.wait_for_function("() => document.body.innerText.includes('7 runs')", timeout=60_000)
    assert session._ensemble_paths is not None and len(session._ensemble_paths) == 7


def test_two_tabs_and_a_closed_tab_leave_the_server_healthy(page, browser, app):
    first = session_of(page)
    other = browser.new_page(viewport={"width": 1000, "height": 700})
    other.goto(app.url + "/?fixedDpr=0.5")
    wait_until(lambda: len(app.sessions) == 2, 30, "a second session")
    second = next(s for s in app.sessions.values() if s is not first)
    other.wait_for_function("() => document.body.innerText.includes('simulated in')", timeout=30_000)
    # Each tab has its own timeline.
    second.seek(second.view.t1)
    assert first.t != second.t
    other.close()
    wait_until(lambda: len(app.sessions) == 1, 30, "the closed tab's session to end")
    wait_until(lambda: not second._player.is_alive(), 10, "the closed tab's player thread to stop")
    # The first tab still works.
    drawn = first.runs_drawn
    click_slider(page, first._param_handles["contact.mu"], 0.1)
    wait_until(lambda: first.runs_drawn > drawn, 60, "a run after the other tab closed")
    assert first.view.scene.contact.mu == pytest.approx(first._param_handles["contact.mu"].value)
    status = json.dumps(status_text(page))
    assert "Not run" not in status
