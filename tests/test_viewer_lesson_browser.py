"""Drag to set up and the lesson's pictures in a real browser (Debian's chromium, headless).

The handles are dragged with the mouse on the 3D canvas: the point grabbed is a handle's plane
square, projected through the tab's camera (`viewer.testing.project`). What the test checks is
that the run then starts where the drag left the ball, with the velocity the arrow's tip says.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.conftest import BROWSER_MARKS
from viewer.testing import (
    canvas_box,
    canvas_shot,
    choose,
    click,
    hide_notifications,
    open_page,
    project,
    screenshot_dir,
    settle,
    wait_for_text,
    wait_until,
)

pytestmark = BROWSER_MARKS
SHOTS = screenshot_dir()


@pytest.fixture(scope="module")
def page(browser, app):
    page = open_page(browser, app, width=1400, height=850)
    hide_notifications(page)
    yield page
    page.close()


def _drag(page, world: np.ndarray, pixels: tuple[float, float]) -> None:
    """Press at a world point's pixel on the canvas, move by `pixels` in small steps, release."""
    session = page.session
    box = canvas_box(page)
    x, y = project(session.client.camera, world[None, :], box["width"], box["height"])[0]
    page.mouse.move(box["x"] + x, box["y"] + y)
    page.mouse.down()
    for k in range(1, 13):
        page.mouse.move(box["x"] + x + pixels[0] * k / 12, box["y"] + y + pixels[1] * k / 12)
        time.sleep(0.05)
    page.mouse.up()


def _grab_point(centre: np.ndarray, scale: float) -> np.ndarray:
    """A gizmo's xy plane square: a third of its size out along x and y from its centre."""
    return centre + np.array([0.3 * scale, 0.3 * scale, 0.0])


def _run_start(session) -> tuple[np.ndarray, np.ndarray]:
    """The shown run's start positions and velocities (N, D), from the run's own initial state."""
    initial = session.view.run.result.initial
    return initial.s[0].copy(), initial.v[0].copy()


def _settled(page, drawn: int) -> None:
    session = page.session
    wait_until(lambda: session.runs_drawn > drawn and session.worker.wait_idle(0.1), 60, "the run after the drag")
    assert session.worker.wait_idle(60)


def test_drag_ball_and_arrow_change_the_run(page):
    session = page.session
    drag = session.drag
    click(page, drag.start_button)  # "Set up (go to t = 0)": the handles show
    wait_until(lambda: session.t == session.view.t0 and all(b.ball.visible for b in drag._balls.values()), 30,
               "the handles at t = 0")
    settle(page)
    before_s, before_v = _run_start(session)
    ball = drag._balls["ball1"]
    r = session.view.radius[0]
    start = np.array(ball.ball.position, float)
    drawn = session.runs_drawn
    _drag(page, _grab_point(start, 1.4 * r), (40.0, 50.0))  # right and down on the screen
    _settled(page, drawn)
    moved = np.array(ball.ball.position, float)
    s, v = _run_start(session)
    # The run starts where the drag left the ball: x larger, y smaller (the camera looks from -y,
    # above), the other ball and both velocities as they were.
    assert moved[0] > start[0] + 0.2 * r and moved[1] < start[1] - 0.2 * r
    np.testing.assert_allclose(s[0], moved[:2], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(s[1], before_s[1])
    np.testing.assert_array_equal(v, before_v)
    assert session.values["body.ball1.position.x"] == pytest.approx(moved[0] * 1e3, abs=1e-9)
    # The arrow's tip: the velocity is the tip's offset over the arrow's scale.
    tip = np.array(ball.tip.position, float)
    drawn = session.runs_drawn
    _drag(page, _grab_point(moved + tip, 1.2 * r), (0.0, -60.0))  # up on the screen: +y
    _settled(page, drawn)
    new_tip = np.array(ball.tip.position, float)
    s2, v2 = _run_start(session)
    assert new_tip[1] > tip[1] + 0.2 * r
    np.testing.assert_allclose(v2[0], new_tip[:2] / drag._arrow_scale, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(s2, s)
    assert v2[0, 1] > 0.1  # aimed upwards
    settle(page)
    (SHOTS / "viewer-drag.png").write_bytes(canvas_shot(page))


def test_overlap_refused_on_the_spot(page):
    session = page.session
    drag = session.drag
    ball = drag._balls["ball1"]
    good = np.array(ball.ball.position, float)
    s_before, _ = _run_start(session)
    other = np.array(drag._balls["ball2"].ball.position, float)
    # Where the handle's drag ends on top of ball2 (the callback the gizmo's drag calls).
    assert not drag.move_ball("ball1", other + [0.01, 0.0, 0.0], end=True)
    text = wait_for_text(page, "ball1 not moved there")
    assert "overlap" in text
    np.testing.assert_array_equal(np.array(ball.ball.position, float), good)  # back where it was
    assert session.worker.wait_idle(30)
    np.testing.assert_array_equal(_run_start(session)[0], s_before)


def test_snap_rounds_to_the_grid(page):
    session = page.session
    drag = session.drag
    drag.snap.value = True
    try:
        ball = drag._balls["ball1"]
        drawn = session.runs_drawn
        assert drag.move_ball("ball1", np.array([-0.01234, 0.02871, 0.0]))
        _settled(page, drawn)
        s, _ = _run_start(session)
        np.testing.assert_allclose(s[0], [-0.012, 0.029], rtol=0, atol=1e-15)
        drawn = session.runs_drawn
        assert drag.aim_ball("ball1", np.array([1.2345, -0.3333, 0.0]) * drag._arrow_scale)
        _settled(page, drawn)
        _, v = _run_start(session)
        np.testing.assert_allclose(v[0], [1.23, -0.33], rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.array(ball.tip.position)[:2], v[0] * drag._arrow_scale, rtol=1e-12)
    finally:
        drag.snap.value = False


def test_momentum_diagram_totals_agree_to_the_residual(page):
    from viewer.lesson import moment

    session = page.session
    view = session.view
    before, after = moment(view, view.t0), moment(view, view.t1)
    run = view.run.result
    # The residual's scale: sum m|v| at the start or the end (collide.diagnostics.residuals).
    p_scale = max(float(np.sum(view.mass * np.linalg.norm(run.initial.v[0], axis=-1))),
                  float(np.sum(view.mass * np.linalg.norm(run.final.v[0], axis=-1))))
    change = float(np.linalg.norm(after.total_momentum - before.total_momentum))
    assert change <= (view.residuals["momentum"] + 4 * np.finfo(float).eps) * p_scale
    # ...and what the tab shows are those totals, at the time shown.
    session.seek(view.t1)
    settle(page)
    assert not any(b.ball.visible for b in session.drag._balls.values())  # the handles: at t = 0 only
    page.get_by_role("tab", name="Momentum & energy").click()
    text = wait_for_text(page, "before (t = 0)", "energy at")
    total = " ".join(f"{c:.4g}" for c in before.total_momentum)
    assert f"({total})" in text
    assert f"({' '.join(f'{c:.4g}' for c in after.total_momentum)})" in text
    page.screenshot(path=str(SHOTS / "viewer-lesson-tab.png"))
    name = session.lesson.export_csv()
    assert name is not None and session.downloads[-1][0] == name


def test_line_switch_and_perfectly_inelastic(page):
    session = page.session
    drawn = session.runs_drawn
    choose(page, session.lesson.motion, "line (1D)")
    _settled(page, drawn)
    assert session.view.scene.dim == 1
    drawn = session.runs_drawn
    click(page, session.lesson.sticky)
    wait_until(lambda: session.view.scene.contact.restitution == 0.0, 120, "the sticky run")
    assert session.worker.wait_idle(120)
    view = session.view
    final = view.run.result.final.v[0, :, 0]
    initial = view.run.result.initial.v[0, :, 0]
    common = float(view.mass @ initial / view.mass.sum())
    scale = float(np.max(np.abs(initial - common)))  # the relative speed the dashpot takes away
    np.testing.assert_allclose(final, common, rtol=0, atol=1e-9 * scale)
    session.seek(view.t1)
    page.mouse.move(5, 5)  # no tooltip over the panel
    settle(page)
    page.screenshot(path=str(SHOTS / "viewer-lesson-sticky.png"))


def test_3d_drag_in_the_chosen_plane(page):
    from collide.scene import parse_scene

    session = page.session
    raw = {"dim": 3, "contact": {"k": 1500.0, "mu": 0.0},
           "body": [{"name": "a", "mass": 0.03, "radius": 0.03, "position": [0.0, 0.0, 0.0], "velocity": [1.0, 0, 0]},
                    {"name": "b", "mass": 0.03, "radius": 0.03, "position": [0.2, 0.0, 0.01], "velocity": [0, 0, 0]}]}
    drawn = session.runs_drawn
    session.load_scene(parse_scene(raw, "two-3d"))
    _settled(page, drawn)
    drag = session.drag
    assert drag.plane.visible
    drawn = session.runs_drawn
    choose(page, drag.plane, "xz")
    wait_until(lambda: drag._made_for[1] == "xz", 30, "the handles in the xz plane")
    ball = drag._balls["a"]
    assert tuple(ball.ball.active_axes) == (True, False, True)
    assert tuple(ball.tip.active_axes) == (True, False, True)
    assert drag.move_ball("a", np.array([-0.01, 0.05, 0.02]))  # y is off the plane: kept
    _settled(page, drawn)
    s, _ = _run_start(session)
    np.testing.assert_allclose(s[0], [-0.01, 0.0, 0.02], rtol=0, atol=1e-15)
