"""The forces the viewer draws are the engine's (issue 54, items 1 and 2), and whole runs are drawn.

Without a browser: the legend's peak, the arrows' lengths and the frames' forces read from
`ViewRun`; the browser test that reads the legend off the page is in test_viewer_browser_forces.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.contact_forces import RecordedForces
from collide.engine import layout
from collide.run import run_scene
from collide.scene import load_scene, parse_scene
from viewer.params import add_ball, for_viewing
from viewer.state import ViewRun


def _drawn(view: ViewRun, times: np.ndarray) -> np.ndarray:
    """The normal force (N) of every contact the frames at `times` draw."""
    out = [np.linalg.norm(c.normal_force) for t in times for c in view.frame(float(t)).contacts]
    return np.array(out)


def _record_times(view: ViewRun) -> np.ndarray:
    return np.unique(view.traj.records[:, layout.R_T])


@pytest.mark.parametrize("name", ["textbook-1d", "demo-bonus", "newtons-cradle", "textbook-glancing"])
def test_event_engine_legend_is_the_runs_peak_and_the_frames_reach_it(name):
    """The legend's peak is the run's max_normal_force (the JSON summary's number); the frames at
    the engine's step ends draw the forces it recorded, the strongest of them that peak, and
    each is the linear law's k_eff delta at the exact knots there (closed form)."""
    run = run_scene(load_scene(name))
    view = ViewRun(run)
    peak = float(run.result.contacts.max_normal_force[0])
    assert view.max_normal_force == pytest.approx(peak, rel=1e-12)
    drawn = _drawn(view, _record_times(view))
    assert drawn.max() == pytest.approx(peak, rel=1e-9)
    # Between the records too, nothing is drawn longer than the legend.
    between = np.linspace(view.t0, view.t1, 301)
    assert _drawn(view, between).max(initial=0.0) <= peak * (1 + 1e-12)
    rec = view.traj.records
    k = int(np.argmax(rec[:, layout.R_FN]))
    pair = rec[k, [layout.R_I, layout.R_J]].astype(np.int64)[None]
    stiff = float(dg.stiffness(view.model, pair)[0, 0])
    assert rec[k, layout.R_FN] == pytest.approx(stiff * rec[k, layout.R_DELTA], rel=1e-12)


def _hertz_drop() -> object:
    """A glass bead (r = 5 mm, E = 5 MPa) dropped on a floor with restitution 0.3: it settles and
    rests, its weight carried by the Hertz contact."""
    return parse_scene({"name": "bead", "dim": 3, "integrator": "dem", "dt": "auto", "tol": 4e-2,
                        "duration": 0.4, "gravity": [0.0, 0.0, -9.81],
                        "contact": {"model": "hertz", "youngs_modulus": 5e6, "poisson_ratio": 0.25},
                        "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6,
                                      "poisson_ratio": 0.25, "restitution": 0.3}],
                        "body": [{"name": "bead", "material": "glass", "radius": 0.005,
                                  "position": [0.0, 0.0, 0.008]}],
                        "wall": [{"point": [0, 0, 0], "normal": [0, 0, 1]}]}, "bead")


@pytest.mark.parametrize("name", ["bounce", "break-3d", "bead"])
def test_dem_hertz_legend_is_the_runs_peak_and_the_engine_records_it(name):
    """Hertz with dashpots, tangential springs and rolling resistance (the DEM kernel): the
    legend's peak is the run's max_normal_force; the engine records each contact phase's peak
    as it ends, so a frame there draws it (a billiard collision lasts less than a frame); no
    frame draws more."""
    scene = _hertz_drop() if name == "bead" else load_scene(name)
    run = run_scene(scene)
    view = ViewRun(run)
    peak = float(run.result.contacts.max_normal_force[0])
    assert view.max_normal_force == pytest.approx(peak, rel=1e-12)
    drawn = _drawn(view, _record_times(view))
    assert drawn.max() == pytest.approx(peak, rel=1e-9)
    assert _drawn(view, np.linspace(view.t0, view.t1, 301)).max(initial=0.0) <= peak * (1 + 1e-12)


def test_a_resting_hertz_bead_is_drawn_carrying_its_weight():
    """Closed form: a bead at rest on a floor presses with m g, whatever the law (the viewer
    drew a linear spring's k delta for every law)."""
    view = ViewRun(run_scene(_hertz_drop()))
    contacts = view.frame(view.t1).contacts
    weight = float(view.mass[0]) * 9.81
    assert len(contacts) == 1
    assert np.linalg.norm(contacts[0].normal_force) == pytest.approx(weight, rel=1e-3)
    assert contacts[0].normal_force[2] > 0  # on the bead (body i), pushed up by the floor


def test_recorded_forces_are_zero_outside_a_phase_and_straight_between_records():
    run = run_scene(load_scene("textbook-1d"))
    traj = run.result.trajectory
    pairs = traj.contacts_touched()
    forces = RecordedForces(traj, pairs, 2, 0, 1, False)
    start, end = traj.intervals[0, layout.V_START], traj.intervals[0, layout.V_END]
    rec = traj.records
    assert forces.normal(np.zeros(2, int), np.array([start - 1e-3, end + 1e-3])).tolist() == [0.0, 0.0]
    mid = 0.5 * (rec[3, layout.R_T] + rec[4, layout.R_T])
    got = forces.normal(np.zeros(1, int), np.array([mid]))[0]
    assert got == pytest.approx(0.5 * (rec[3, layout.R_FN] + rec[4, layout.R_FN]), rel=1e-12)


def test_the_recordings_contact_series_draws_the_engines_forces():
    """The Rerun recording's arrows and plots come from `contact_series`: the recorded force."""
    run = run_scene(load_scene("bounce"))
    traj = run.result.trajectory
    rec = traj.records
    times = rec[:, layout.R_T]
    series = dg.contact_series(run.result.model, traj, times)
    drawn = np.linalg.norm(series.normal_force[:, 0, 0], axis=-1)
    assert np.allclose(drawn, np.abs(rec[:, layout.R_FN]), rtol=1e-12, atol=0)


def test_textbook_1d_at_half_restitution_is_viewed_to_the_runs_end():
    """e = 0.5 in the DEM kernel (asked for); its tail of free flight after the separation is part of the
    run (199 ms), and the view reaches it with the bodies where the run left them."""
    raw = dict(load_scene("textbook-1d").source)
    raw.update(contact={"k": 1500.0, "mu": 0.0, "restitution": 0.5}, integrator="dem", tol=1e-3)
    run = run_scene(for_viewing(parse_scene(raw, "textbook-1d")))
    view = ViewRun(run)
    final = run.result.final
    assert view.t1 == pytest.approx(float(final.t[0]), rel=1e-15)
    assert view.t1 > 1.5 * view.contact_windows[-1][1]  # well past the separation
    end = view.frame(view.t1)
    assert np.allclose(end.positions[:, 0], final.s[0, :, 0], rtol=0, atol=1e-12)
    assert np.allclose(end.velocities[:, 0], final.v[0, :, 0], rtol=0, atol=1e-12)
    # Free flight from the kernel's last frame (closed form): the gap grows at the relative speed.
    last = float(np.unique(view.traj.knots[:, layout.K_T])[-2])
    assert last <= 1.01 * view.contact_windows[-1][1]
    gap = end.positions[1, 0] - end.positions[0, 0] - 2 * 0.05
    before = view.frame(last).positions
    grown = (final.v[0, 1, 0] - final.v[0, 0, 0]) * (view.t1 - last)
    assert gap == pytest.approx(before[1, 0] - before[0, 0] - 2 * 0.05 + grown, rel=1e-12)
    assert gap > 0.04 and not end.contacts
    # Momentum (closed form: conserved) and the restitution (closed form: e = 0.5).
    mass = view.mass
    assert mass @ final.v[0, :, 0] == pytest.approx(0.34 * 1.2, rel=1e-9)
    assert (final.v[0, 1, 0] - final.v[0, 0, 0]) / 1.2 == pytest.approx(0.5, rel=2e-3)


@pytest.mark.parametrize("name", ["demo-2d-moving", "textbook-glancing", "demo-bonus"])
def test_added_balls_take_part(name):
    """"more balls" aims each new ball so that it touches another in the run."""
    scene = load_scene(name)
    for _ in range(2):
        scene = add_ball(scene)
        iv = run_scene(for_viewing(scene)).result.trajectory.intervals
        new = len(scene.bodies) - 1
        assert np.any((iv[:, layout.V_I] == new) | (iv[:, layout.V_J] == new)), f"{scene.bodies[-1].name} never touched"


def test_walls_are_drawn_under_every_path():
    """2D: the floor reaches under every bounce (it was drawn from the wall's own point, 1.6
    extents wide, and a ball thrown sideways bounced off its end in mid-air)."""
    import viser

    from viewer.scene3d import SceneDrawer

    scene = parse_scene({"name": "throw", "dim": 2, "gravity": [0.0, -9.81], "duration": 1.5,
                         "contact": {"k": 1e4},
                         "body": [{"name": "ball", "mass": 0.05, "radius": 0.02, "position": [0.0, 0.3],
                                   "velocity": [1.5, 0.0]}],
                         "wall": [{"point": [-0.5, 0.0], "normal": [0.0, 1.0]}]}, "throw")
    view = ViewRun(run_scene(scene))
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(view)
        floor = server.scene.get_handle_by_name("/world/walls/0")
        half = 0.5 * floor.dimensions[1]
        x = view.paths[0][:, 0]
        assert floor.position[0] - half <= x.min() - view.radius[0]
        assert floor.position[0] + half >= x.max() + view.radius[0]
    finally:
        server.stop()


@pytest.mark.parametrize("name", ["bounce", "break-3d", "demo-bonus"])
def test_the_rerun_recordings_normal_force_plot_peaks_at_the_runs_max(name, tmp_path):
    """The recording's per-contact normal-force plot (Scalars) reaches the run's
    max_normal_force, Hertz collisions shorter than a frame included."""
    from rerun.chunk import RrdReader

    from collide.recording import write_recording

    run = run_scene(load_scene(name))
    path = write_recording(run, tmp_path / f"{name}.rrd")
    top = 0.0
    for chunk in RrdReader(path).stream():
        if chunk.entity_path.startswith("/contacts/") and chunk.entity_path.endswith("/normal_force") \
                and not chunk.is_static:
            values = [row[0] for row in chunk.to_record_batch().column("Scalars:scalars").to_pylist()]
            top = max(top, max(values, default=0.0))
    assert top == pytest.approx(float(run.result.contacts.max_normal_force[0]), rel=1e-9)
