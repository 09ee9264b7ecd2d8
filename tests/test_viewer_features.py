"""What the viewer shows beyond the report, in a real browser: PhET-style vectors, centre of mass,
values table, step buttons, more and fewer balls, the plot readout; many bodies (instanced
spheres, colour modes with a legend, force chains, floor shadows); exports (CSV, PNG, save).

Headless Chromium at 1280x800; one server and browser for the module, a fresh tab per test.
The screenshots in docs/ are taken here (and looked at).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import BROWSER_MARKS
from viewer.testing import (
    canvas_box,
    canvas_shot,
    choose,
    click,
    click_slider,
    colour_mask,
    group_button,
    hide_notifications,
    image,
    open_page,
    plot,
    project,
    screenshot_dir,
    scroll_to_text,
    settle,
    text_box,
    visible_text,
    wait_for_text,
    wait_until,
)

pytestmark = BROWSER_MARKS
DOCS = screenshot_dir()
CHAIN = (190, 60, 60)  # the force chains' red as lit (the axes gizmo's red also matches: compare counts)


@pytest.fixture
def half_page(browser, app):
    """A tab at half the pixels: hundreds of see-through spheres take seconds a frame under
    software GL. Closed even when the test fails, so it never slows the next ones."""
    page = open_page(browser, app, width=1280, height=800, query="fixedDpr=0.5")
    hide_notifications(page)
    yield page
    page.close()
    wait_until(lambda: page.session.client.client_id not in app.sessions, 30, "the tab to close")


def load(page, source):
    session = page.session
    name = source if isinstance(source, str) else source.name
    session.load_scene(source)
    wait_until(lambda: session.view is not None and session.view.name == name and session.worker.idle(), 120, name)
    settle(page)  # a new scene's first frames compile its shaders
    return session


def pixels_changed(a: bytes, b: bytes, where: np.ndarray) -> int:
    return int((np.abs(image(a) - image(b)).sum(axis=-1) > 60)[where].sum())


def changed_shot(page, before: bytes, where: np.ndarray, pixels: int, timeout: float = 20.0) -> bytes:
    """The canvas once at least `pixels` pixels in `where` differ from `before` (software GL
    on a busy machine can take seconds per frame)."""
    shots = []

    def changed():
        shots.append(canvas_shot(page))
        return pixels_changed(before, shots[-1], where) >= pixels

    wait_until(changed, timeout, f"{pixels} pixels of the 3D view to change")
    return shots[-1]


def disc(shape, centre, radius) -> np.ndarray:
    ys, xs = np.mgrid[: shape[0], : shape[1]]
    return (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2 <= radius**2


# ---------------------------------------------------------------------------------------------
# PhET's Collision Lab, and more


def test_velocity_momentum_vectors_and_centre_of_mass(page):
    session = load(page, "demo-2d-moving")
    view = session.view
    session.seek(view.t0 + 0.3 * (view.contact_windows[0][0] - view.t0))  # both balls on their way in
    page.wait_for_timeout(1200)
    box = canvas_box(page)
    frame = view.frame(session.t)
    centres = project(session.client.camera, frame.positions, box["width"], box["height"])
    r_px = abs(project(session.client.camera, frame.positions[:1] + [view.radius[0], 0, 0], box["width"],
                       box["height"])[0, 0] - centres[0, 0])
    before = canvas_shot(page)
    shape = image(before).shape
    around = disc(shape, centres[0], 4 * r_px) | disc(shape, centres[1], 4 * r_px)
    click(page, session.show_velocity)
    wait_until(lambda: session.drawer._vectors["velocity"].count == 2, 10, "two velocity arrows")
    page.wait_for_timeout(1200)
    with_velocity = changed_shot(page, before, around, 40)
    click(page, session.show_momentum)
    wait_until(lambda: session.drawer._vectors["momentum"].count == 2, 10, "two momentum arrows")
    click(page, session.show_com)
    wait_until(lambda: session.drawer._com is not None, 10, "the centre of mass marker")
    page.wait_for_timeout(1200)
    com_px = project(session.client.camera, frame.com[None], box["width"], box["height"])[0]
    changed_shot(page, with_velocity, disc(shape, com_px, 0.4 * r_px), 10)
    legend = visible_text(page)
    assert "velocity:" in legend and "momentum:" in legend and "centre of mass" in legend
    # The arrows' lengths follow the state: ball1 at 1 m/s, ball2 at -2 m/s (scale: 3 r for 2 m/s).
    arrows = session.drawer._vectors["velocity"].handle.points
    lengths = np.linalg.norm(arrows[:, 1] - arrows[:, 0], axis=-1)
    assert lengths[1] / lengths[0] == pytest.approx(2.0, rel=1e-4)
    click(page, session.show_velocity)
    wait_until(lambda: session.drawer._vectors["velocity"].count == 0, 10, "velocity arrows gone")


def test_values_table_before_now_after(page):
    """textbook-1d: exactly 0.66 and 1.86 m/s after, for any k (report section II)."""
    session = load(page, "textbook-1d")
    view = session.view
    page.get_by_role("tab", name="Values").click()
    session.seek(view.t0)
    # The numbers the table must show, waited for (not a fixed pause: under load the page takes
    # its time to draw the tab).
    after = view.body_values(view.t1)["velocity"][:, 0]
    assert after == pytest.approx([0.66, 1.86], abs=1e-7)
    wait_for_text(page, "1.2", "0.66", "1.86", "momentum (kg m/s)", "kinetic energy (J)")
    table = page.locator("table").filter(has_text="before").filter(has_text="ball2").first
    assert "after" in table.inner_text()
    # "now" follows the timeline: mid-contact, the balls share the momentum differently.
    a, b = view.contact_windows[0]
    session.seek(0.5 * (a + b))
    now = view.body_values(session.t)["velocity"][:, 0]
    wait_for_text(page, f"{now[0]:.4g}")


def test_step_buttons_move_by_a_frame_and_by_a_contact_step(page):
    session = load(page, "demo-bonus")
    view = session.view
    a, _ = view.contact_windows[0]
    session.seek(a - 1e-4)
    group_button(page, session.step_buttons, "▶").click()
    wait_until(lambda: session.t == pytest.approx(view.step_times[0]), 10, "the contact's first step")
    group_button(page, session.step_buttons, "▶").click()
    wait_until(lambda: session.t == pytest.approx(view.step_times[1]), 10, "the next step")
    assert view.step_times[1] > view.step_times[0] and view.in_contact(session.t)
    group_button(page, session.step_buttons, "◀").click()
    wait_until(lambda: session.t == pytest.approx(view.step_times[0]), 10, "back one step")
    t = session.t
    group_button(page, session.frame_buttons, "▶").click()
    wait_until(lambda: session.t > t, 10, "a frame forward")
    expected = session._speed(view) * (0.1 if session.slowmo.value else 1.0) / 30.0
    assert session.t - t == pytest.approx(expected, rel=1e-6)
    box = text_box(page, session.time_box)
    wait_until(lambda: abs(float(box.input_value()) - session.t * 1e3) <= session.time_slider.step, 10,
               "the time box to show the new time")


def test_more_and_fewer_balls(page):
    session = load(page, "demo-2d-moving")
    assert session.balls.visible
    group_button(page, session.balls, "more balls").click()
    wait_until(lambda: session.view.n_bodies == 3 and session.worker.idle(), 60, "a third ball")
    # The page shows the new ball's controls a moment after the server has them (seconds under load).
    page.wait_for_function("() => document.body.innerText.includes('ball3')", timeout=30_000)
    assert "ball3" in visible_text(page)
    iv = session.view.traj.intervals  # the new ball takes part: it touches another in the run
    assert np.any((iv[:, 0] == 2) | (iv[:, 1] == 2))
    group_button(page, session.balls, "fewer balls").click()
    wait_until(lambda: session.view.n_bodies == 2 and session.worker.idle(), 60, "back to two")
    group_button(page, session.balls, "fewer balls").click()
    page.wait_for_function("() => document.body.innerText.includes('at least two')", timeout=10_000)
    load(page, "demo-1d")
    assert not session.balls.visible


def _bounce_height(view) -> float:
    """The ball's highest point (its bottom above the floor) after its first bounce."""
    _, end = view.contact_windows[0]
    times = np.linspace(end, view.t1, 600)
    return max(float(view.frame(t).positions[0, 1]) for t in times) - float(view.radius[0])


def test_restitution_slider_takes_height_out_of_a_bounce(page):
    """Every scene gets an elasticity slider; moved to about 0.5 on a ball dropped from 0.2 m
    (linear spring: a sphere alone on a wall runs the restitution's dashpot in the event engine
    at full order), the ball comes back up to about e^2 of the drop instead of all of it."""
    from collide.scene import parse_scene

    scene = parse_scene({"name": "drop-ball", "dim": 2, "gravity": [0.0, -9.81], "duration": 0.6,
                         "contact": {"k": 1e4},
                         "body": [{"name": "ball", "mass": 0.05, "radius": 0.02, "position": [0.0, 0.22]}],
                         "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}, "drop-ball")
    session = load(page, scene)
    assert "contact.restitution" in session._param_handles
    elastic = _bounce_height(session.view)
    assert elastic == pytest.approx(0.2, rel=1e-3)  # e = 1: back to where it fell from
    before = session.view
    click_slider(page, session._param_handles["contact.restitution"], 0.5)
    wait_until(lambda: session.view is not before and session.worker.idle(), 120, "the run with the new restitution")
    e = float(session.values["contact.restitution"])
    assert 0.3 < e < 0.7 and session.view.result.engine == "event"
    assert _bounce_height(session.view) == pytest.approx(e**2 * 0.2, rel=0.05)


def test_plot_readout_at_the_cursor(page):
    load(page, "demo-bonus")
    wait_until(lambda: plot(page, "energy") is not None, 30, "the energy plot")

    def hover() -> bool:
        try:
            chart = page.locator(".uplot").filter(has_text="energy").first
            chart.scroll_into_view_if_needed(timeout=10_000)
            box = chart.locator(".u-over").bounding_box(timeout=10_000)
        except Exception:  # noqa: BLE001 - the chart was rebuilt meanwhile: try again
            return False
        page.mouse.move(box["x"] + 0.5 * box["width"], box["y"] + 0.5 * box["height"])
        page.wait_for_timeout(500)
        return bool(plot(page, "energy")["legend"][:1] != ["--"])

    wait_until(hover, 60, "a readout under the pointer")
    values = plot(page, "energy")["legend"]
    assert values and all(v not in ("--", "") for v in values[:3]), values
    assert any(c.isdigit() for c in values[1])


# ---------------------------------------------------------------------------------------------
# Many bodies


def test_many_spheres_instanced_colour_modes_chains_and_shadows(half_page):
    from viewer.frames import settling_pile

    page = half_page
    session = page.session
    run = settling_pile(300, duration=1.0, fps=30)
    session.show_frames(run)
    wait_until(lambda: session.view is run, 30, "the pile")
    session.seek(0.8)
    drawer = session.drawer
    assert drawer.many and set(drawer._batch) >= {"spheres", "shadows", "chains"}
    assert drawer._batch["spheres"].batched_positions.shape == (300, 3)
    assert session.show_chains.visible and session.show_shadows.visible
    # The count from the screenshot that showed them (a second shot under load may catch a redraw).
    with_chains = wait_until(lambda: (n := int(colour_mask(canvas_shot(page), CHAIN, 60).sum())) > 300 and n, 60,
                             "the force chains")
    # Colour by speed: a viridis legend, and the colours follow each body's speed. (Set from the
    # server: with 400 spheres under software GL the page draws about one frame a second, too
    # slow for a dropdown click; the dropdown itself is clicked in the next test.)
    session.set_show(colour_by="speed")
    page.wait_for_function("() => document.body.innerText.includes('colour: speed')", timeout=30_000)
    frame = run.frame(session.t)
    speed = np.linalg.norm(frame.velocities, axis=-1)
    colours = drawer.body_colours()
    assert len({tuple(c) for c in colours}) > 20
    fast, slow = int(np.argmax(speed)), int(np.argmin(speed))
    assert colours[fast].sum() > colours[slow].sum()  # viridis: brighter is faster
    session.set_show(colour_by="contacts")
    page.wait_for_function("() => document.body.innerText.includes('colour: contacts')", timeout=30_000)
    counts = frame.contact_links().counts(run.n_bodies)
    colours = drawer.body_colours()
    assert len({tuple(c) for c in colours[counts == counts.max()]}) == 1
    session.set_show(chains=False)
    assert not drawer._batch["chains"].visible and not session.show_chains.value
    # Software GL on a loaded machine (two browser tests at once) draws 300 spheres slowly: a
    # generous wait, and the red pixels left in the message if the chains stay.
    left = [with_chains]

    def chains_gone() -> bool:
        left[0] = int(colour_mask(canvas_shot(page), CHAIN, 60).sum())
        return left[0] < 0.3 * with_chains

    try:
        wait_until(chains_gone, 180, "the chains to go")
    except AssertionError:
        raise AssertionError(f"the chains stayed: {left[0]} red pixels, {with_chains} with them") from None

    def coloured() -> int:
        shot = image(canvas_shot(page))
        return int(((shot.max(axis=-1) - shot.min(axis=-1)) > 25).sum())  # spheres; floor and grid are grey

    wait_until(lambda: coloured() > 5000, 60, "the spheres, still drawn once the chains are off")


def test_colour_by_speed_from_the_dropdown(page):
    session = load(page, "demo-bonus")
    choose(page, session.colour_by, "speed")
    wait_until(lambda: session.drawer.options.colour_by == "speed", 30, "colour by speed")
    page.wait_for_function("() => document.body.innerText.includes('colour: speed')", timeout=30_000)
    view = session.view
    frame = view.frame(session.t)
    speed = np.linalg.norm(frame.velocities, axis=-1)
    colours = session.drawer.body_colours()
    assert (colours[int(np.argmax(speed))].sum() > colours[int(np.argmin(speed))].sum()) or np.ptp(speed) < 1e-9


def test_engine_run_of_dozens_of_spheres_on_a_floor(page):
    """A real run (32 spheres dropped on a floor, 3D, the current engine): drawn instanced, the
    floor where the wall is, camera on the bodies."""
    from collide.scene import parse_scene

    rng = np.random.default_rng(1)
    bodies = []
    for layer in range(2):
        for i in range(4):
            for j in range(4):
                bodies.append({"name": f"s{len(bodies) + 1}", "mass": 0.004, "radius": 0.01,
                               "position": [(i - 1.5) * 0.022, (j - 1.5) * 0.022, 0.0105 + layer * 0.023],
                               "velocity": [*rng.uniform(-0.2, 0.2, 2), -0.5]})
    scene = parse_scene({"name": "drop", "dim": 3, "gravity": [0, 0, -9.81], "duration": 0.04, "tol": 1e-3,
                         "integrator": "verlet", "contact": {"k": 2e4}, "body": bodies,
                         "wall": [{"point": [0, 0, 0], "normal": [0, 0, 1]}]}, "drop")
    session = load(page, scene)
    assert session.drawer.many and session.view.n_bodies == 32
    floor = session.drawer._floor
    assert floor is not None and floor[0][2] == 0.0
    lo, hi = session.view.bounds()
    session.seek(0.02)
    page.wait_for_timeout(1500)
    box = canvas_box(page)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    px = project(session.client.camera, corners, box["width"], box["height"])
    assert px[:, 0].min() > -5 and px[:, 0].max() < box["width"] + 5  # framed on the bodies
    assert px[:, 0].max() - px[:, 0].min() > 0.35 * box["width"]  # and not lost in the distance
    page.screenshot(path=str(DOCS / "viewer-drop-32.png"), timeout=120_000)


def test_screenshot_many_spheres_on_a_floor(page, tmp_path):
    """docs/viewer-many-spheres.png and docs/viewer-force-chains.png: a real engine run, recorded
    and replayed. drop-pile (tests/data: 125 beads dropped into a bin, friction and restitution,
    DEM kernel) mid-landing coloured by speed, then nearly settled with its force chains coloured
    by number of contacts."""
    from collide.recording import write_recording
    from collide.run import run_scene
    from collide.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parent / "data" / "drop-pile.toml")
    path = write_recording(run_scene(scene), tmp_path / "drop-pile.rrd")
    session = page.session
    assert session.open_recording(path)
    wait_until(lambda: session.view is not None and session.view.n_bodies == 125, 60, "the drop-pile recording")
    assert session.drawer.many and session.drawer._floor is not None
    session.seek(0.08)
    frame = session.view.frame(session.t)
    assert len(frame.contacts) > 20 and np.linalg.norm(frame.velocities, axis=-1).max() > 0.1  # landing
    session.set_show(colour_by="speed", chains=False)
    page.wait_for_function("() => document.body.innerText.includes('colour: speed')", timeout=30_000)
    scroll_to_text(page, "colour: speed")
    page.wait_for_timeout(6000)
    png = page.screenshot(path=str(DOCS / "viewer-many-spheres.png"), timeout=180_000)
    assert len(png) > 50_000
    session.seek(session.view.t1)
    session.set_show(colour_by="contacts", chains=True)
    scroll_to_text(page, "colour: contacts")
    end = session.view.frame(session.t)
    assert len(end.contacts) > 125  # resting on each other and the floor: more contacts than beads
    wait_until(lambda: colour_mask(canvas_shot(page), CHAIN, 60).sum() > 300, 60, "the force chains")
    page.wait_for_timeout(3000)
    png = page.screenshot(path=str(DOCS / "viewer-force-chains.png"), timeout=180_000)
    assert len(png) > 50_000


# ---------------------------------------------------------------------------------------------
# Exports


def test_download_csv_and_png(page):
    from collide.summary import csv_columns

    session = load(page, "demo-bonus")
    with page.expect_download(timeout=30_000) as info:
        group_button(page, session.export_buttons, "CSV").click()
    download = info.value
    assert download.suggested_filename == "demo-bonus.csv"
    rows = list(csv.reader(io.StringIO(Path(download.path()).read_text())))
    assert rows[0] == csv_columns(session.view.model)
    assert len(rows) - 1 >= 200
    times = np.array([float(r[0]) for r in rows[1:]])
    assert times[0] == 0.0 and times[-1] <= session.view.t1 + 1e-12 and np.all(np.diff(times) > 0)
    with page.expect_download(timeout=60_000) as info:
        group_button(page, session.export_buttons, "PNG").click()
    download = info.value
    assert download.suggested_filename.endswith(".png")
    png = Path(download.path()).read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    img = image(png)
    box = canvas_box(page)
    assert img.shape[1] == pytest.approx(box["width"], abs=2) and img.shape[0] == pytest.approx(box["height"], abs=2)
    # The two spheres are in it (blue ball1, orange ball2).
    assert colour_mask(img, (66, 133, 244), 70).sum() > 100 and colour_mask(img, (244, 132, 36), 70).sum() > 100


def test_screenshot_textbook_glancing_after_separation(page):
    """docs/viewer-textbook-glancing.png: the 37 degree split, with the values table."""
    session = load(page, "textbook-glancing")
    view = session.view
    click(page, session.show_velocity)
    session.seek(view.t1)
    page.get_by_role("tab", name="Values").click()
    page.wait_for_timeout(2500)
    text = visible_text(page)
    assert "deflected by" in text and "after" in text
    png = page.screenshot(path=str(DOCS / "viewer-textbook-glancing.png"))
    assert len(png) > 50_000
