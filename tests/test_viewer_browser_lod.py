"""Level of detail in a real browser (issue 52, item 6): a recording of more bodies than the
viewer's point threshold opens drawn as points, one per body at its centre in the page, and the
time slider moves them. The threshold is lowered through `ViewerApp(point_bodies=...)`, so a
small pile stands in for 100 000 spheres (benchmarks/bench_viewer_latency.py --only lod and
docs/performance.md measure those).

One server and browser for the module (Debian's chromium through Playwright, headless).
"""

from __future__ import annotations

import numpy as np
import pytest

from collide.recording import write_recording
from collide.run import run_scene
from tests.conftest import BROWSER_MARKS
from tests.test_viewer_inside import small_pile
from viewer.testing import canvas_shot, click_slider, hide_notifications, image, open_page, settle, wait_until

pytestmark = BROWSER_MARKS

BODIES, THRESHOLD = 36, 20

# The point cloud's centres as the page holds them (sent as float32 bytes).
POINTS_JS = """() => {
    const p = window.__viserSceneTree?.getState()['/bodies/points']?.message?.props?.points;
    if (!p) return null;
    return Array.from(new Float32Array(p.buffer.slice(p.byteOffset, p.byteOffset + p.byteLength)));
}"""


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    from viewer.app import ViewerApp

    folder = tmp_path_factory.mktemp("recordings")
    app = ViewerApp("demo-1d", host="127.0.0.1", port=0, recordings_dir=folder, point_bodies=THRESHOLD)
    app.start()
    yield app
    app.stop()


@pytest.fixture(scope="module")
def page(browser, app):
    page = open_page(browser, app, width=1100, height=760, query="fixedDpr=0.6")
    hide_notifications(page)
    yield page
    page.close()


def _page_points(page) -> np.ndarray | None:
    values = page.evaluate(POINTS_JS)
    return None if values is None else np.asarray(values, float).reshape(-1, 3)


def _shown_in_page(page, positions: np.ndarray) -> bool:
    held = _page_points(page)
    return held is not None and held.shape == positions.shape and np.allclose(held, positions, atol=1e-6)


def test_a_recording_above_the_threshold_is_drawn_as_points_and_the_time_slider_moves_them(page, app):
    session = page.session
    run = run_scene(small_pile(BODIES, duration=0.3, rest=None))
    path = write_recording(run, app.recordings_dir / "pile36.rrd")
    assert session.open_recording(path)
    wait_until(lambda: session.view is not None and session.view.n_bodies == BODIES and session.drawer.frame
               is not None, 120, "the recording shown")
    drawer = session.drawer
    assert drawer.points and set(drawer._batch) == {"points"}
    assert f"{BODIES} bodies drawn as points" in drawer.legend()
    # Every body, at its centre, in the page.
    first = drawer.frame.positions.copy()
    assert first.shape == (BODIES, 3)
    wait_until(lambda: _shown_in_page(page, first), 60, "every body's point in the page")
    settle(page)
    img = image(canvas_shot(page))
    grey = (np.ptp(img, axis=-1) < 14)
    assert (~grey).sum() > 0, "no coloured point on the canvas"
    # The time slider moves them: the page holds the new frame's centres, which fell.
    click_slider(page, session.panel.time_slider, 0.95)
    wait_until(lambda: drawer.frame is not None and drawer.frame.t > session.view.t0 + 0.5 * session.view.duration,
               60, "the time slider's frame")
    later = drawer.frame.positions.copy()
    assert np.max(np.abs(later - first)) > 1e-3  # metres: the pile fell and settled
    np.testing.assert_allclose(later, session.view.frame(drawer.frame.t).positions, atol=1e-12)
    wait_until(lambda: _shown_in_page(page, later), 60, "the later frame's points in the page")
