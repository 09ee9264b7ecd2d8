"""Inside the pile (issue 54, item 5) in a real browser, on a small settled DEM pile: the clip
plane's slider hides the spheres beyond it (on the server and on the canvas), a click on a
sphere in the canvas picks it and the panel reads its values and contacts, and the Histograms
tab shows speed, contact count and normal force at the time shown.

One server and browser for the module (Debian's chromium through Playwright, headless).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BROWSER_MARKS
from tests.test_viewer_inside import small_pile
from viewer.testing import (
    canvas_box,
    canvas_shot,
    click,
    click_slider,
    hide_notifications,
    image,
    open_page,
    plots,
    project,
    screenshot_dir,
    settle,
    visible_text,
    wait_until,
)

pytestmark = BROWSER_MARKS

BACKGROUND_TOL = 12


@pytest.fixture(scope="module")
def page(browser, app):
    page = open_page(browser, app, width=1100, height=760, query="fixedDpr=0.6")
    hide_notifications(page)
    session = page.session
    scene = small_pile(27)
    session.load_scene(scene)
    wait_until(lambda: session.view is not None and session.view.scene.name == scene.name
               and not session.view.preview and session.worker.idle(), 600, "the small pile")
    session.set_show(chains=False, shadows=False)
    session.seek(session.view.t1)  # settled
    settle(page)
    yield page
    page.close()


def _sphere_pixels(png: bytes) -> int:
    """Pixels that are neither the page's background nor the grid's greys."""
    img = image(png)
    corner = img[2, 2]
    grey = (np.ptp(img, axis=-1) < 14) & (img.mean(axis=-1) > 150)
    return int(np.sum(~grey & (np.abs(img - corner).max(axis=-1) > BACKGROUND_TOL)))


def test_the_clip_slider_hides_the_spheres_beyond_the_plane(page):
    session = page.session
    inside = session.inside
    before = _sphere_pixels(canvas_shot(page))
    click(page, inside.clip_on)
    wait_until(lambda: session.drawer.look.clip.on, 30, "the clip plane on")
    click_slider(page, inside.clip_offset, 0.35)
    offset = {}

    def hidden_as_the_slider_says() -> bool:
        frame = session.drawer.frame
        offset["mm"] = float(inside.clip_offset.value)
        want = frame.positions[:, 0] > offset["mm"] * 1e-3
        return 0 < want.sum() < len(want) and np.array_equal(session.drawer._hidden, want)

    wait_until(hidden_as_the_slider_says, 30, "the spheres beyond the plane hidden")
    hidden = session.drawer._hidden
    scales = np.asarray(session.drawer._batch["spheres"].batched_scales, float).reshape(len(hidden), -1)[:, 0]
    assert np.array_equal(scales == 0, hidden)
    settle(page)
    after = _sphere_pixels(canvas_shot(page))
    assert after < 0.85 * before, (before, after)
    click(page, inside.clip_on)
    wait_until(lambda: not session.drawer._hidden.any(), 30, "every sphere shown again")


def test_a_click_on_a_sphere_reads_its_values_in_the_panel(page):
    session = page.session
    inside = session.inside
    inside.set_clip(True, "y", keep="below")  # a cut through the middle: the inner spheres face the camera
    settle(page)
    camera = session.client.camera
    frame, view = session.drawer.frame, session.view
    shown = np.flatnonzero(~session.drawer._hidden)
    eye = np.asarray(camera.position, float)
    # The shown sphere nearest the eye: nothing can hide its centre (equal spheres).
    k = int(shown[np.argmin(np.linalg.norm(frame.positions[shown] - eye, axis=-1))])
    box = canvas_box(page)
    x, y = project(camera, frame.positions[k][None], box["width"], box["height"])[0]
    assert 0 < x < box["width"] and 0 < y < box["height"]
    page.mouse.click(box["x"] + x, box["y"] + y)
    wait_until(lambda: session.drawer.look.picked == k, 30, f"body {k} picked")
    name = view.names[k]
    page.wait_for_function("(t) => document.body.innerText.includes(t)", arg=f"{name} (body {k})", timeout=30_000)
    text = visible_text(page)
    assert "sum of contact forces (N)" in text and "contact with" in text
    assert "(230, 0, 180)" not in text  # colours are drawn, not printed
    assert tuple(session.drawer.body_colours()[k]) == (230, 0, 180)
    settle(page)
    png = canvas_shot(page)
    (screenshot_dir() / "inside-small-pile-picked.png").write_bytes(png)
    magenta = np.all(np.abs(image(png) - np.array([230, 0, 180])) < 70, axis=-1)
    assert magenta.sum() > 20  # the picked sphere is drawn in its colour
    click(page, inside.clear_button)
    wait_until(lambda: session.drawer.look.picked is None, 30, "the pick cleared")
    inside.set_clip(False)


def test_the_histograms_tab_shows_speed_contacts_and_normal_force(page):
    session = page.session
    page.get_by_role("tab", name="Histograms").click()
    wait_until(lambda: {t.split(":")[0] for t in plots(page)} >= {"speed", "contacts per sphere", "normal force"},
               60, "the three histograms")
    charts = {t.split(":")[0]: p for t, p in plots(page).items()}
    frame = session.drawer.frame
    counts = frame.contact_links().counts(len(frame.positions))
    y = np.asarray(charts["contacts per sphere"]["data"][1])
    assert y.sum() == 2 * len(frame.positions)  # the outline counts each bin twice
    assert int(y.max()) == int(np.bincount(counts).max())
    t_before = frame.t
    session.seek(session.view.t0 + 0.3 * session.view.duration)
    wait_until(lambda: session.drawer.frame.t != t_before and f"{session.drawer.frame.t * 1e3:.4g} ms"
               in visible_text(page), 30, "the histograms at the new time")
