"""The viewer's pure-Python layer: controls, clamping, frames, plots, files, worker, replay."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import Scene, SceneError, builtin_names, load_scene, parse_scene
from collide.stepper import RunError
from viewer import ensemble as ens
from viewer import files
from viewer.geometry import compressed_sphere, fit_camera, orientation_wxyz, quat_from_to
from viewer.params import (
    AUTO,
    CONTACT_PARAMS,
    DEM_TOL,
    Settings,
    TypedValueError,
    add_ball,
    approach_time,
    build_scene,
    check_settings,
    for_viewing,
    format_value,
    parse_dt_choice,
    read_typed,
    remove_ball,
    scene_controls,
    values_of,
)
from viewer.plots import CURSOR_OFF, display_scale, with_cursor, y_range
from viewer.state import ViewRun
from viewer.worker import LatestWorker


@pytest.fixture(scope="module")
def bonus_view() -> ViewRun:
    return ViewRun(run_scene(load_scene("demo-bonus"), integrator="verlet", dt="auto", tol=1e-5))


def _scene_3d():
    raw = {"dim": 3, "contact": {"k": 2000.0, "mu": 0.3},
           "body": [{"name": "a", "mass": 0.1, "radius": 0.02, "position": [0, 0, 0], "velocity": [1, 0, 0],
                     "spin": [0, 0, 5]},
                    {"name": "b", "mass": 0.1, "radius": 0.02, "position": [0.2, 0.01, 0.005]}]}
    return parse_scene(raw, "three-d")


# ---------------------------------------------------------------------------------------------
# Controls


def test_controls_1d_have_no_spin_or_friction():
    controls = scene_controls(load_scene("demo-1d"))
    idents = {p.ident for p in controls.params}
    assert "contact.k" in idents and "body.ball1.mass" in idents and "body.ball1.velocity.x" in idents
    assert not any("spin" in i or "mu" in i or "eps" in i for i in idents)


def test_controls_2d_bonus_have_everything():
    controls = scene_controls(load_scene("demo-bonus"))
    idents = [p.ident for p in controls.params]
    for body in ("ball1", "ball2"):
        for key in ("mass", "radius", "position.x", "position.y", "velocity.x", "velocity.y", "spin"):
            assert f"body.{body}.{key}" in idents
    assert {"contact.k", "contact.mu", "contact.eps"} <= set(idents)
    for p in controls.params:
        assert p.lo <= p.value <= p.hi, p
        assert p.step > 0


def test_controls_3d_spin_is_a_vector():
    idents = {p.ident for p in scene_controls(_scene_3d()).params}
    assert {"body.a.spin.x", "body.a.spin.y", "body.a.spin.z", "body.b.position.z"} <= idents


def test_defaults_rebuild_the_same_scene():
    scene = load_scene("demo-bonus")
    controls = scene_controls(scene)
    rebuilt = build_scene(controls, controls.defaults(), controls.settings)
    assert rebuilt.bodies == scene.bodies and rebuilt.contact == scene.contact
    assert values_of(rebuilt, controls) == pytest.approx(controls.defaults())


@pytest.mark.parametrize("name", builtin_names(heavy=False))
def test_a_recordings_scene_shows_the_values_its_controls_show(name):
    """Opening a recording sets the controls from its scene (`values_of`): for every built-in
    they are the values the scene's own controls start at (a [contact] key left to the law, like
    the pile's tangential ratio, shows the law's value, not nothing)."""
    scene = load_scene(name)
    controls = scene_controls(scene)
    assert values_of(scene, controls) == pytest.approx(controls.defaults())


def test_viewed_runs_go_on_as_long_after_the_contact_as_before_it():
    """The viewer's tail: as long as the approach (textbook-glancing: 28 ms, not 2.8)."""
    scene = load_scene("textbook-glancing")
    assert scene.tail is None and scene.duration is None
    approach = approach_time(scene)
    gap = scene.bodies[1].position[0] - scene.bodies[0].position[0]
    # Straight-line motion to the first touch: |d + u t| = r1 + r2.
    assert approach == pytest.approx((gap - np.sqrt(0.1**2 - scene.bodies[0].position[1] ** 2)) / 5.0)
    viewed = for_viewing(scene)
    assert viewed.tail == pytest.approx(approach) and viewed.bodies == scene.bodies
    view = ViewRun(run_scene(viewed))
    a, b = view.contact_windows[0]
    assert view.t1 - b == pytest.approx(approach, rel=1e-9)
    assert for_viewing(load_scene("demo-bonus", ["duration=0.3"])).tail is None  # a set duration is kept


def test_slider_values_reach_the_scene_in_si_units():
    controls = scene_controls(load_scene("demo-bonus"))
    values = controls.defaults() | {"contact.k": 3000.0, "body.ball1.mass": 30.0, "body.ball1.position.y": 5.0,
                                    "body.ball2.spin": -2.0}
    scene = build_scene(controls, values, controls.settings)
    assert scene.contact.k == 3000.0
    assert scene.bodies[0].mass == pytest.approx(0.030)
    assert scene.bodies[0].position[1] == pytest.approx(0.005)
    assert scene.bodies[1].spin == (-2.0,)


def test_the_rolling_resistance_slider_moves_a_full_order_run():
    """A ball thrown along a floor with a tangential spring and rolling resistance: the mu_r slider
    moved, the scene still runs in the event engine (rolling and held located), not DEM, and the
    ball rolls farther under a smaller mu_r."""
    from tests.engine.event.test_alone import _rolling

    raw = _rolling(tol=1e-6)
    controls = scene_controls(parse_scene(raw))
    assert "contact.rolling_friction" in {p.ident for p in controls.params}
    way = []
    for mu_r in (0.2, 0.1):
        scene = build_scene(controls, controls.defaults() | {"contact.rolling_friction": mu_r}, controls.settings)
        assert scene.contact.rolling_friction == mu_r and scene.integrator != "dem"
        res = run_scene(scene, record=False).result
        assert res.engine == "event" and "between rolling and held located" in res.engine_reason
        way.append(float(res.final.s[0, 0, 0]))
    assert way[1] > way[0]


@pytest.mark.parametrize("text, value", [("1e-7", 1e-7), ("2.5E9", 2.5e9), (" -0.02 ", -0.02), ("\u22123", -3.0),
                                         ("1500", 1500.0), (".5", 0.5)])
def test_typed_values_are_read_exactly(text, value):
    assert read_typed(text, "x") == value


@pytest.mark.parametrize("text, reason", [("1e", "not a number"), ("15OO", "not a number"), ("", "empty"),
                                          ("1,5", "comma"), ("inf", "not finite"), ("nan", "not finite"),
                                          ("1_000", "not a plain number"), ("e-7", "not a number")])
def test_typed_values_that_do_not_read_are_refused(text, reason):
    with pytest.raises(TypedValueError, match=reason) as info:
        read_typed(text, "eps (m/s)")
    assert str(info.value).startswith("eps (m/s)") and str(info.value).endswith("not applied")


def test_typed_values_beyond_the_slider_widen_it_and_invalid_ones_are_refused():
    controls = scene_controls(load_scene("demo-bonus"))
    k = controls.by_ident()["contact.k"]
    assert k.problem(1e9) is None
    wider = k.widened(1e9)
    assert wider.lo <= 1e9 <= wider.hi and wider.step > 0 and k.widened(k.value) is k
    assert k.problem(-5.0) == "must be positive" and k.problem(float("nan")) == "must be finite"
    eps = controls.by_ident()["contact.eps"]
    assert eps.problem(0.0) is None and eps.problem(-1e-7) == "must not be negative"
    assert eps.widened(1.0).hi >= 1.0 and eps.widened(1.0).lo == 0.0
    x = controls.by_ident()["body.ball1.position.x"]
    assert x.widened(-5000.0).lo <= -5000.0
    with pytest.raises(SceneError, match="k .N/m. = -5: must be positive"):
        build_scene(controls, controls.defaults() | {"contact.k": -5.0}, controls.settings)
    # A value beyond the slider is used exactly as typed, not clamped.
    assert build_scene(controls, controls.defaults() | {"contact.k": 1e9}, controls.settings).contact.k == 1e9
    assert format_value(1e-7) == "1e-07" and read_typed(format_value(0.1 + 0.2), "x") == 0.1 + 0.2


def test_contact_parameters_come_from_one_table():
    """A contact law parameter (restitution, once the engine has it) is one row: shown only for a
    scene whose contact has it."""
    names = [row.name for row in CONTACT_PARAMS]
    assert names[:3] == ["k", "mu", "eps"] and "restitution" in names
    idents = {p.ident for p in scene_controls(load_scene("demo-bonus")).params}
    assert {"contact.k", "contact.mu", "contact.eps"} <= idents
    assert ("contact.restitution" in idents) == hasattr(load_scene("demo-bonus").contact, "restitution")


def test_law_sliders_show_where_the_scene_uses_the_law():
    """E for Hertz (the materials' own where they give it), the tangential ratio for the spring,
    rolling resistance where a contact has it; none of them on the report's law."""
    bonus = {p.ident for p in scene_controls(load_scene("demo-bonus")).params}
    assert not {"contact.youngs_modulus", "contact.tangential_stiffness_ratio", "contact.rolling_friction"} & bonus
    bounce = {p.ident for p in scene_controls(load_scene("bounce")).params}
    assert "material.rubber.youngs_modulus" in bounce and "contact.youngs_modulus" not in bounce
    pile = {p.ident for p in scene_controls(load_scene("pile")).params}
    assert {"material.glass.youngs_modulus", "contact.tangential_stiffness_ratio", "contact.rolling_friction"} <= pile


def test_unmoved_law_sliders_leave_the_law_as_it_was():
    """The tangential ratio's slider shows [contact]'s default; unmoved, each pair keeps the
    Mindlin ratio of its own materials (glass: nu = 0.25, not [contact]'s 0.3), and moved, every
    pair takes the value."""
    from collide.model import TABLE_KTR, compile_scenes

    scene = load_scene("pile")
    controls = scene_controls(scene)
    same = build_scene(controls, controls.defaults(), controls.settings)
    nu = 0.25  # (index 0 is "no material")
    assert compile_scenes([same])[0].pair_table[0, 1, 1, TABLE_KTR] == pytest.approx(2 * (1 - nu) / (2 - nu))
    moved = build_scene(controls, controls.defaults() | {"contact.tangential_stiffness_ratio": 0.5},
                        controls.settings)
    assert compile_scenes([moved])[0].pair_table[0, 1, 1, TABLE_KTR] == 0.5


def test_the_youngs_modulus_slider_moves_a_full_order_hertz_run():
    """E four times stiffer on the bouncing ball: still the event engine at the scene's tolerance,
    and the first impact's peak force grows as Hertz's E*^(2/5) (F_max = (4/3 E* sqrt r)^(2/5)
    (5/4 m v^2)^(3/5) for the undamped law; Hertz's damping at fixed e scales both runs alike)."""
    scene = load_scene("bounce")
    controls = scene_controls(scene)
    values = values_of(scene, controls)
    runs = []
    for factor in (1.0, 4.0):
        values["material.rubber.youngs_modulus"] = 5e6 * factor
        moved = build_scene(controls, values, controls.settings)
        assert moved.materials[0].youngs_modulus == 5e6 * factor
        runs.append(run_scene(moved, record=False))
    assert all(run.result.engine == "event" for run in runs)
    assert all(float(run.error_estimate[0]) <= scene.tol for run in runs)
    peaks = [float(run.result.contacts.max_normal_force[0]) for run in runs]
    # Gravity's pull during the contact breaks the self-similarity, by at most its share of the peak.
    weight = scene.bodies[0].mass * 9.81
    assert peaks[1] / peaks[0] == pytest.approx(4.0 ** 0.4, rel=2 * weight / peaks[0])


def test_more_and_fewer_balls():
    scene = load_scene("demo-bonus")
    more = add_ball(scene)
    assert [b.name for b in more.bodies] == ["ball1", "ball2", "ball3"]
    new = more.bodies[2]
    assert new.mass == scene.bodies[1].mass and new.radius == scene.bodies[1].radius
    run = run_scene(more, dt="auto", tol=1e-3)
    iv = run.result.trajectory.intervals  # the new ball takes part: it touches another
    assert np.any((iv[:, 0] == 2) | (iv[:, 1] == 2))
    assert [b.name for b in remove_ball(more).bodies] == ["ball1", "ball2"]
    with pytest.raises(SceneError, match="at least two"):
        remove_ball(scene)
    with pytest.raises(SceneError, match="2D"):
        add_ball(load_scene("demo-1d"))
    many = scene
    for _ in range(8):
        many = add_ball(many)
    with pytest.raises(SceneError, match="at most"):
        add_ball(many)


def test_overlap_at_start_is_a_scene_error():
    controls = scene_controls(load_scene("demo-bonus"))
    with pytest.raises(SceneError, match="overlaps"):
        build_scene(controls, controls.defaults() | {"body.ball1.position.x": 480.0}, controls.settings)


def test_too_soft_contact_is_a_run_error():
    scene = load_scene("demo-bonus", ["contact.k=10", "body.ball1.velocity=[5,0]"])
    with pytest.raises(RunError, match="too soft"):
        run_scene(scene)


def test_settings_are_checked():
    assert parse_dt_choice("auto") == "auto"
    assert parse_dt_choice("2e-5 s") == 2e-5
    assert check_settings("seed", 1e-5, 1e-6) == Settings("seed", 1e-5, 1e-6)
    with pytest.raises(SceneError):
        check_settings("euler", 1e-5, 1e-6)
    with pytest.raises(SceneError):
        check_settings("verlet", 1.0, 1e-6)


# ---------------------------------------------------------------------------------------------
# What to draw at time t


def test_frame_positions_follow_the_trajectory(bonus_view):
    v = bonus_view
    # At every step: the step's own state.
    for k in range(0, v.traj.t.shape[0], 7):
        f = v.frame(float(v.traj.t[k, 0]))
        assert np.allclose(f.positions[:, :2], v.traj.s[k, 0], rtol=0, atol=1e-15)
        assert np.allclose(f.positions[:, 2], 0.0)
    # In free flight: the closed form (diagnostics.sample).
    a, b = v.contact_windows[0]
    for t in np.concatenate((np.linspace(v.t0, a, 5), np.linspace(b, v.t1, 5))):
        expected = dg.sample(v.model, v.traj, np.array([t])).s[0, 0]
        assert np.allclose(v.frame(t).positions[:, :2], expected, rtol=0, atol=1e-15)


def test_between_steps_the_energy_stays_balanced():
    """Inside a contact step, positions and velocities come from a quintic Hermite: the energy
    plotted between steps keeps the balance the steps keep (a cubic-and-linear one wobbles)."""
    v = ViewRun(run_scene(load_scene("demo-1d"), integrator="verlet", dt="auto", tol=1e-6))
    total = v.plots.energy.lines["total"]
    assert np.ptp(total) < 1e-4 * total[0]
    a, b = v.contact_windows[0]
    inside = (v.times > a) & (v.times < b)
    assert inside.sum() > 50 and v.plots.energy.lines["spring"][inside].max() > 0.5 * total[0]


def test_frame_in_contact_has_forces_and_compression(bonus_view):
    v = bonus_view
    a, b = v.contact_windows[0]
    f = v.frame(a + 0.1 * (b - a))
    assert len(f.contacts) == 1
    c = f.contacts[0]
    assert c.name == "ball1-ball2" and c.overlap > 0 and c.compression[0] == pytest.approx(c.overlap / 2)
    assert np.linalg.norm(c.friction_force) > 0
    # The normal force on ball1 points away from ball2; friction is tangential.
    assert np.dot(c.normal_force, c.normal) < 0
    # (the friction of the step containing t, against the normal at t: equal to the step's rotation)
    assert abs(np.dot(c.friction_force, c.normal)) < 1e-3 * np.linalg.norm(c.friction_force)
    assert v.frame(v.t0).contacts == [] and v.frame(v.t1).contacts == []


def test_spin_turns_the_marker(bonus_view):
    v = bonus_view
    q0, q1 = v.frame(v.t0).wxyz, v.frame(v.t0 + 0.1).wxyz
    assert np.allclose(np.linalg.norm(q1, axis=1), 1.0)
    # ball1 spins at +3 rad/s about z: 0.3 rad in 0.1 s of free flight.
    angle = 2 * np.arctan2(q1[0, 3], q1[0, 0]) - 2 * np.arctan2(q0[0, 3], q0[0, 0])
    assert angle == pytest.approx(0.3, rel=1e-9)


def test_1d_scene_has_no_spin_or_friction():
    v = ViewRun(run_scene(load_scene("demo-1d"), dt="auto", tol=1e-3))
    a, b = v.contact_windows[0]
    c = v.frame(0.5 * (a + b)).contacts[0]
    assert c.friction_force is None
    assert np.allclose(v.frame(a).wxyz, [1, 0, 0, 0])
    assert v.plots.angular_momentum is None
    assert "rotational" not in v.plots.energy.lines and "dissipated" not in v.plots.energy.lines
    assert v.status_lines()[1].endswith("angular momentum n/a")


def test_plots_hold_the_conserved_quantities(bonus_view):
    p = bonus_view.plots
    assert list(p.energy.lines) == ["kinetic", "rotational", "spring", "total", "dissipated",
                                    "total + dissipated"]
    balance = p.energy.lines["total + dissipated"]
    assert np.ptp(balance) < 2e-3 * balance[0]
    assert list(p.momentum.lines) == ["px", "py"] and list(p.angular_momentum.lines) == ["Lz"]
    assert list(p.compression.lines) == ["ball1-ball2"]
    assert p.compression.lines["ball1-ball2"].max() == pytest.approx(6.05, rel=0.02)  # mm
    assert np.all(np.diff(p.times) > 0)
    # Half the plot points resolve the 13 ms contact.
    a, b = bonus_view.contact_windows[0]
    assert np.sum((p.times >= a) & (p.times <= b)) > 100


def test_conserved_quantities_stay_flat_between_coarse_steps():
    """At the scene's own settings (few, large steps) the plots show no interpolation spikes."""
    v = ViewRun(run_scene(load_scene("demo-bonus")))
    lz = v.plots.angular_momentum.lines["Lz"]
    assert np.ptp(lz) < 1e-9 * abs(lz[0])
    p = v.plots.momentum.lines
    assert np.ptp(p["px"]) < 1e-9 * abs(p["px"][0]) and np.ptp(p["py"]) < 1e-12
    balance = v.plots.energy.lines["total + dissipated"]
    assert np.ptp(balance) < 5e-3 * balance[0]


def test_3d_scene_frames():
    v = ViewRun(run_scene(_scene_3d(), dt="auto", tol=1e-3))
    assert v.frame(v.t1).wxyz.shape == (2, 4)
    assert list(v.plots.angular_momentum.lines) == ["Lx", "Ly", "Lz"]
    lo, hi = v.bounds()
    assert hi[2] > lo[2]


# ---------------------------------------------------------------------------------------------
# Replay


def test_replay_shows_the_same_positions_at_the_same_times(tmp_path):
    from collide.recording import read_recording, write_recording

    run = run_scene(load_scene("demo-bonus"))
    path = write_recording(run, tmp_path / "bonus.rrd")
    live, replay = ViewRun(run), ViewRun(read_recording(path))
    assert (replay.t0, replay.t1) == (live.t0, live.t1)
    a, b = live.contact_windows[0]
    for t in np.concatenate((np.linspace(live.t0, live.t1, 25), np.linspace(a, b, 25))):
        f, g = live.frame(t), replay.frame(t)
        assert np.array_equal(f.positions, g.positions)
        assert np.array_equal(f.wxyz, g.wxyz)
        assert len(f.contacts) == len(g.contacts)
        for c, d in zip(f.contacts, g.contacts):
            assert np.array_equal(c.friction_force, d.friction_force)
    assert replay.residuals == pytest.approx(live.residuals, nan_ok=True)


def test_unreadable_recording_raises_recording_error(tmp_path):
    from collide.recording import RecordingError, read_recording

    bad = tmp_path / "bad.rrd"
    bad.write_bytes(b"this is not a recording")
    with pytest.raises(RecordingError):
        read_recording(bad)


# ---------------------------------------------------------------------------------------------
# Files


def test_safe_names_stay_inside_the_folder(tmp_path):
    assert files.safe_stem("../../etc/passwd.rrd") == "passwd"
    assert files.safe_stem("my run (1).rrd") == "my-run-1"
    assert files.safe_stem("..rrd") == "run"
    assert files.safe_stem("C:\\evil\\x.rrd") == "x"
    p = files.unique_path(tmp_path, "../up")
    assert p.parent == tmp_path.resolve() and p.name == "up.rrd"
    p.write_bytes(b"x")
    assert files.unique_path(tmp_path, "up").name == "up-2.rrd"
    with pytest.raises(files.UploadError):
        files.recording_path(tmp_path, "notes.txt")
    assert files.recording_path(tmp_path, "../../x.rrd").parent == tmp_path.resolve()


def test_uploads_are_checked():
    files.check_upload("a.rrd", 10)
    files.check_upload("A.RRD", 10)
    for name, size, match in (("a.txt", 10, "not a .rrd"), ("a.rrd", 0, "empty"), ("a.rrd", 11, "limit")):
        with pytest.raises(files.UploadError, match=match):
            files.check_upload(name, size, limit=10)


def test_recordings_list_and_scene_choices(tmp_path):
    (tmp_path / "a.rrd").write_bytes(b"x")
    (tmp_path / ".hidden.rrd").write_bytes(b"x")
    (tmp_path / "b.txt").write_bytes(b"x")
    assert files.list_recordings(tmp_path) == ["a.rrd"]
    assert files.list_recordings(tmp_path / "missing") == []
    (tmp_path / "mine.toml").write_text(load_scene("demo-1d").to_toml())
    labels = [c.label for c in files.scene_choices(tmp_path)]
    assert labels[0] == "demo-1d" and labels[-1] == "mine.toml"


# ---------------------------------------------------------------------------------------------
# Worker: the latest request wins, a preview is followed by a final pass


def test_worker_drops_stale_requests():
    seen: list[tuple[int, bool]] = []

    def job(item: int, final: bool) -> bool:
        time.sleep(0.05)
        seen.append((item, final))
        return False

    worker = LatestWorker(job, settle=0.05)
    for i in range(20):
        worker.submit(i)
        time.sleep(0.005)
    assert worker.wait_idle(5)
    worker.close()
    items = [i for i, _ in seen]
    assert items[-1] == 19 and len(items) < 8
    assert items == sorted(items)


def test_worker_runs_the_final_pass_after_the_user_stops():
    seen: list[tuple[int, bool]] = []

    def job(item: int, final: bool) -> bool:
        seen.append((item, final))
        return not final  # every first pass is a preview

    worker = LatestWorker(job, settle=0.15)
    worker.submit(1)
    time.sleep(0.05)
    worker.submit(2)  # arrives during the settle time: no final pass for 1
    assert worker.wait_idle(5)
    worker.close()
    assert seen == [(1, False), (2, False), (2, True)]


def test_worker_survives_errors():
    errors: list[BaseException] = []
    done = threading.Event()

    def job(item: int, final: bool) -> bool:
        if item == 0:
            raise RuntimeError("boom")
        done.set()
        return False

    worker = LatestWorker(job, on_error=errors.append)
    worker.submit(0)
    assert worker.wait_idle(5)
    worker.submit(1)
    assert done.wait(5)
    worker.close()
    assert str(errors[0]) == "boom"


# ---------------------------------------------------------------------------------------------
# Plots, geometry, ensembles


def test_cursor_rows_in_plot_data():
    times = np.linspace(0, 1, 11)
    data = with_cursor(times, {"a": times * 2}, 0.35)
    x, a, cursor = data
    assert len(x) == 13 and np.all(np.diff(x) >= 0)
    k = int(np.argmax(cursor > CURSOR_OFF))
    assert x[k] == x[k + 1] == 0.35 and cursor[k] == 0 and cursor[k + 1] == 1
    assert a[k] == pytest.approx(0.7)
    assert np.all(np.isfinite(np.concatenate(data)))


def test_plot_scales():
    assert display_scale({"L": np.array([-2.7e-4, -2.7e-4])}, "kg m²/s") == (1e6, "1e-6 kg m²/s")
    # Round-off around zero keeps the quantity's own scale, not 1e-21.
    assert display_scale({"L": np.array([0.0, 3e-21, -2e-21])}, "kg m²/s", scale=2.5e-3) == (1e3, "1e-3 kg m²/s")
    assert display_scale({"E": np.array([0.0, 0.063])}, "J") == pytest.approx((1e3, "mJ"))
    lo, hi = y_range({"p": np.array([-0.0254, -0.0254 + 1e-17])})
    assert hi - lo > 1e-3  # round-off is not magnified into a spike


def test_compressed_sphere_is_flat_at_the_contact():
    n = np.array([1.0, 0.0, 0.0])
    v = compressed_sphere(0.03, [(n, 0.005)])
    assert (v @ n).max() == pytest.approx(0.025)
    assert (v @ -n).max() == pytest.approx(0.03, rel=1e-3)


def test_orientations_and_camera():
    assert np.allclose(orientation_wxyz(np.zeros((2, 0))), [[1, 0, 0, 0]] * 2)
    q = orientation_wxyz(np.array([np.pi]))
    assert np.allclose(q, [0, 0, 0, 1], atol=1e-12)
    r = quat_from_to(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    assert np.allclose(r, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)])
    fit = fit_camera(np.array([0, -0.1, -0.03]), np.array([0.5, 0.1, 0.03]), planar=True, aspect=1.0)
    pos, look = np.array(fit.position), np.array(fit.look_at)
    assert look == pytest.approx([0.25, 0, 0]) and pos[2] > 0.5  # looking down from above


def test_ensemble_spreads_k_and_offset():
    scene = load_scene("demo-bonus")
    ks = [s.contact.k for s in ens.ensemble_scenes(scene, "k", 2.0, 5)]
    assert ks == pytest.approx([1470, 1485, 1500, 1515, 1530])
    ys = [s.bodies[0].position[1] for s in ens.ensemble_scenes(scene, "offset", 1.0, 3)]
    assert ys == pytest.approx([0.009, 0.010, 0.011])
    assert ens.kinds_for(load_scene("demo-1d")) == ["k", "speed"]
    paths, wall = ens.ensemble_paths(ens.ensemble_scenes(scene, "offset", 2.0, 3), dt="auto", tol=1e-3)
    assert len(paths) == 3 and paths[0].shape[0] == 2 and wall > 0
    # Different impact parameters send ball2 off at different angles.
    assert abs(paths[0][1, -1, 1] - paths[2][1, -1, 1]) > 1e-3


# ---------------------------------------------------------------------------------------------
# Command line: a file or scene that cannot be read is one line and a non-zero exit


@pytest.mark.parametrize("make, expected", [
    (lambda d: d / "bad.rrd", "Rerun recording"),
    (lambda d: d / "missing.rrd", "does not exist"),
    (lambda d: "no-such-scene", "unknown scene"),
])
def test_view_refuses_unreadable_input(tmp_path, make, expected):
    import subprocess
    import sys

    (tmp_path / "bad.rrd").write_bytes(b"garbage")
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run([sys.executable, "-m", "cli.main", "view", str(make(tmp_path)), "--port", "0"],
                          cwd=root, capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expected in lines[0]
    assert proc.stdout == ""


# ---------------------------------------------------------------------------------------------
# Preview, many bodies, colours, exports, reading untrusted recordings


def _break_3d(tol: float):
    """Issue 12's 3D break: a cue ball with top spin into three balls on a floor, friction."""
    bodies = [{"name": "cue", "mass": 0.17, "radius": 0.028, "position": [0.0, 0.0, 0.028], "velocity": [2.0, 0, 0],
               "spin": [0.0, 40.0, 0.0]}]
    for k, (x, y) in enumerate([(0.3, 0.0), (0.35, 0.03), (0.35, -0.03)]):
        bodies.append({"name": f"b{k + 1}", "mass": 0.17, "radius": 0.028, "position": [x, y, 0.028]})
    return parse_scene({"name": "break", "dim": 3, "tol": tol, "gravity": [0, 0, -9.81], "duration": 0.2,
                        "contact": {"k": 1e5, "mu": 0.2}, "body": bodies,
                        "wall": [{"point": [0, 0, 0], "normal": [0, 0, 1]}]}, "break")


@pytest.mark.parametrize("integrator, tol", [("verlet", 1e-2), ("kahan6", 1e-2), ("kahan6", 1e-3)])
def test_a_preview_never_costs_more_than_the_run(integrator, tol):
    """The coarse preview ran Verlet at tol 1e-3 whatever the scene asked: for a scene that asks
    less than that it cost more than the real run (issue 12, item 3: a 3D break took 41-54 s a
    slider change). Now a preview is used only when it costs less than half the run."""
    from collide.run import auto_dt
    from viewer.live import STAGES, preview_settings

    scene = replace(_break_3d(tol), integrator=integrator)

    def cost(name: str, t: float) -> float:
        return STAGES[name] / float(auto_dt([scene], name, np.array([t]))[0][0])

    full = cost(scene.integrator, scene.tol)
    if integrator == "verlet":
        assert cost("verlet", 1e-3) > full  # the old preview
    preview = preview_settings(scene)
    assert preview is None or (preview.tol >= scene.tol and cost(preview.integrator, preview.tol) < 0.5 * full)


def test_frames_run_answers_like_a_view():
    from viewer.frames import settling_pile

    run = settling_pile(200, duration=0.5, fps=20)
    assert run.positions.shape == (len(run.times), 200, 3) and run.n_bodies == 200
    f = run.frame(0.33)
    k = int(np.searchsorted(run.times, 0.33)) - 1
    x = (0.33 - run.times[k]) / (run.times[k + 1] - run.times[k])
    assert np.allclose(f.positions, (1 - x) * run.positions[k] + x * run.positions[k + 1])
    links = f.contact_links()
    assert len(links.i) and np.all(links.force > 0) and links.counts(200).sum() == 2 * np.sum(links.j >= 0) + np.sum(
        links.j < 0)
    # Floor contacts touch the floor; pair contacts lie between the two centres.
    floor = links.j < 0
    assert np.allclose(links.point[floor, 2], 0.0)
    lo, hi = run.bounds()
    assert lo[2] >= -1e-9 and np.all(hi > lo)
    assert [s.title for s in run.plots.all] == ["energy", "momentum", "contacts"]
    assert run.next_step(0.33, 1) == run.times[k + 1] and run.next_step(0.33, -1) == run.times[k]
    assert run.body_values(0.33)["speed"].shape == (200,)


def test_every_body_has_its_own_colour():
    from viewer.colours import body_colours, colour_map

    colours = body_colours(1000)
    assert len({tuple(c) for c in colours}) == 1000
    assert len({tuple(c) for c in colours[:16]}) == 16
    ramp = colour_map(np.linspace(0, 1, 5), 0.0, 1.0)
    assert np.all(np.diff(ramp.astype(int).sum(axis=1)) > 0)  # viridis brightens with the value
    assert np.array_equal(colour_map(np.array([-1.0, 2.0]), 0.0, 1.0), colour_map(np.array([0.0, 1.0]), 0.0, 1.0))


def _recorded_body_colours(path: Path) -> np.ndarray:
    """The colour of each body as the Rerun recording stores it: (N, 3), bodies in scene order."""
    from rerun.chunk import RrdReader

    packed: dict[str, list[int]] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        for column in ("Ellipsoids3D:colors", "Points3D:colors"):
            if chunk.is_static and column in batch.schema.names:
                packed[chunk.entity_path] = batch.column(column).to_pylist()[-1]
    if "/world/bodies" in packed:
        rgba = packed["/world/bodies"]
    else:
        names = sorted((p for p in packed if p.startswith("/world/ball")), key=lambda p: int(p[len("/world/ball"):]))
        rgba = [packed[p][0] for p in names]
    rgba = np.array(rgba, dtype=np.uint64)
    return np.stack([(rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255], axis=1).astype(np.uint8)


@pytest.mark.parametrize("n, dim", [(16, 2), (40, 3)])
def test_recording_and_viewer_give_each_body_the_same_colour(tmp_path, n, dim):
    """16 bodies (one entity each in the recording) and 40 (one instanced entity): the recording's
    colour of every body is the one the viewer draws it in, and no two bodies share one."""
    import viser

    from collide.recording import read_recording, write_recording
    from viewer.scene3d import SceneDrawer

    bodies = [{"name": f"ball{i + 1}", "mass": 0.1, "radius": 0.01,
               "position": [0.05 * (i % 8), 0.05 * (i // 8), 0.0][:dim], "velocity": [0.0, 0.1, 0.0][:dim]}
              for i in range(n)]
    scene = parse_scene({"name": f"colours-{n}", "dim": dim, "duration": 0.01, "body": bodies}, f"colours-{n}")
    path = write_recording(run_scene(scene), tmp_path / f"colours-{n}.rrd")
    recorded = _recorded_body_colours(path)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        view = ViewRun(read_recording(path))
        drawer.show_run(view)
        drawer.show_frame(view.frame(view.t0))
        drawn = drawer.body_colours()
    finally:
        server.stop()
    assert recorded.shape == drawn.shape == (n, 3)
    assert np.array_equal(recorded, drawn)
    assert len({tuple(c) for c in recorded}) == n


def test_csv_export_is_the_cli_layout():
    from collide.summary import csv_columns, report_csv
    from viewer.exports import csv_every, png_bytes, run_csv

    run = run_scene(load_scene("demo-bonus"))
    content, every = run_csv(run)
    assert every == csv_every(run) and every <= 100 * float(run.result.dt[0])
    lines = content.decode().splitlines()
    assert lines[0].split(",") == csv_columns(run.result.model) and len(lines) - 1 >= 200
    assert content.decode() == report_csv(run, every, "aligned")
    png = png_bytes(np.zeros((4, 6, 4), np.uint8))
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_untrusted_recordings_are_read_in_a_child(tmp_path):
    from collide.recording import RecordingError, write_recording
    from viewer.reading import read_untrusted

    good = write_recording(run_scene(load_scene("demo-1d")), tmp_path / "good.rrd")
    run = read_untrusted(good)
    assert run.scene.name == "demo-1d" and run.result.trajectory is not None
    crash = Path(__file__).parent / "data" / "viewer-reader-crash.rrd"
    with pytest.raises(RecordingError, match=r"^upload\.rrd: damaged recording: Rerun.s reader crashed"):
        read_untrusted(crash, name="upload.rrd")
    (tmp_path / "junk.rrd").write_bytes(b"junk" * 10)
    with pytest.raises(RecordingError) as info:
        read_untrusted(tmp_path / "junk.rrd", name="mine.rrd")
    assert str(info.value).startswith("mine.rrd: ") and str(tmp_path) not in str(info.value)


# ---------------------------------------------------------------------------------------------
# Many bodies: what viewing a large run costs (issue 12: gas-box and pile were OOM-killed)


def _gas(n: int, duration: float, seed: int = 1) -> Scene:
    """n spheres with random velocities in a closed box (gas-box's recipe, smaller)."""
    rng = np.random.default_rng(seed)
    per = int(np.ceil(n ** (1 / 3)))
    side = per * 0.05
    cells = np.stack(np.meshgrid(*[np.arange(per)] * 3, indexing="ij"), -1).reshape(-1, 3)[:n]
    pos = (cells + 0.5) * 0.05 + rng.uniform(-0.005, 0.005, (n, 3))
    bodies = [{"name": f"p{k + 1}", "mass": 0.01, "radius": 0.01, "position": list(pos[k]),
               "velocity": list(rng.normal(0.0, 1.0, 3))} for k in range(n)]
    walls = [{"point": [side * (s < 0) if a == c else 0.0 for c in range(3)],
              "normal": [float(s) if a == c else 0.0 for c in range(3)]} for a in range(3) for s in (1, -1)]
    return parse_scene({"name": "gas", "dim": 3, "dt": "auto", "integrator": "kahan6", "tol": 1e-7,
                        "duration": duration, "contact": {"k": 1e5}, "body": bodies, "wall": walls}, "gas")


def _pile(n: int, duration: float, seed: int = 2) -> Scene:
    """n spheres dropped from a loose lattice into an open box (the built-in pile's recipe, DEM)."""
    rng = np.random.default_rng(seed)
    per = 6
    cells = [(i, j, k) for k in range(n // per**2 + 1) for i in range(per) for j in range(per)][:n]
    bodies = [{"name": f"g{m + 1}", "material": "glass", "radius": 0.005,
               "position": [(i + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4), (j + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4),
                            0.007 + k * 0.011],
               "velocity": [*rng.normal(0.0, 0.05, 2), 0.0]} for m, (i, j, k) in enumerate(cells)]
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    walls += [{"point": [0.066 * (s < 0) if a == c else 0.0 for c in range(3)],
               "normal": [float(s) if a == c else 0.0 for c in range(3)]} for a in range(2) for s in (1, -1)]
    return parse_scene({"name": "pile", "dim": 3, "dt": "auto", "integrator": "dem", "tol": 4e-2,
                        "duration": duration, "gravity": [0.0, 0.0, -9.81],
                        "contact": {"model": "hertz", "restitution": 0.3, "tangential": "spring", "mu": 0.5,
                                    "rolling_friction": 0.05},
                        "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6,
                                      "poisson_ratio": 0.25}],
                        "body": bodies, "wall": walls}, "pile")


def _held_elements(view: ViewRun) -> int:
    """Elements of the numpy arrays a ViewRun holds beyond the run it was given."""
    run_arrays = {id(a) for a in (view.traj.knots, view.traj.records, view.traj.intervals)}
    seen: set[int] = set()

    def count(x, depth: int = 0) -> int:
        if id(x) in seen or depth > 6 or x is view.run or x is view.result or x is view.model or x is view.traj:
            return 0
        seen.add(id(x))
        if isinstance(x, np.ndarray):
            return 0 if id(x) in run_arrays else x.size
        if isinstance(x, dict):
            return sum(count(v, depth + 1) for v in x.values())
        if isinstance(x, (list, tuple)):
            return sum(count(v, depth + 1) for v in x)
        if hasattr(x, "__dict__") and type(x).__module__.startswith(("viewer", "collide")):
            return sum(count(v, depth + 1) for v in vars(x).values())
        return 0

    return count(view)


@pytest.mark.parametrize("make", [lambda: _gas(200, 0.5), lambda: _pile(150, 0.1)], ids=["gas", "pile"])
def test_a_many_body_run_is_viewed_in_memory_bounded_by_its_frames_and_contacts(make):
    """Preparing the view of a run costs O(bodies x plot points + the run's own tables), not
    bodies x knot times (gas-box: 70 000 knot times x 1 000 bodies) or contacts x plot times:
    both the peak while preparing (tracemalloc sees numpy's buffers) and what the view holds."""
    import tracemalloc

    from viewer.state import MAX_PLOT_POINTS

    run = run_scene(make())
    traj = run.result.trajectory
    n = run.result.model.n_bodies
    tables = traj.knots.nbytes + traj.records.nbytes + traj.intervals.nbytes
    # The gas has thousands of knot times: dense sampling would be bodies x knots.
    assert traj.n_steps * n > 20 * n * MAX_PLOT_POINTS or len(traj.records) > 100_000
    sampled = 8 * n * MAX_PLOT_POINTS  # bytes of one float per body and plot point
    tracemalloc.start()
    try:
        view = ViewRun(run)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 40 * sampled + 2 * tables + 32e6, (peak, sampled, tables)
    assert _held_elements(view) * 8 < 20 * sampled + tables
    # Still the run: frames, contacts and plots are there.
    frame = view.frame(0.5 * (view.t0 + view.t1))
    assert frame.positions.shape == (n, 3) and len(frame.links.i) > 0
    assert len(view.plots.times) <= MAX_PLOT_POINTS + 1 and view.plots.compression is not None


def test_sampling_is_exact_at_every_knot_and_free_rows_follow_the_knots():
    """Sampling every body at once gives each body's knot state exactly at its knot times, in
    1D, 2D and 3D, event engine and DEM; and the rows Trajectory.free marks as free flight are
    those no body's step crosses."""
    from collide.engine import layout
    from collide.trajectory import Knots, body_knots

    for scene in (load_scene("demo-1d"), load_scene("demo-bonus"), _scene_3d(), load_scene("break-3d"),
                  _gas(30, 0.2)):
        run = run_scene(scene)
        traj, model = run.result.trajectory, run.result.model
        d = model.dim
        knots = Knots(model, traj)
        t = traj.knot_times
        stepped_rows = np.zeros(len(t), bool)
        for body, mine in enumerate(body_knots(traj)):
            kt = mine[:, layout.K_T]
            # A body's state after its last knot at each time; its final knot is reached from
            # the segment before it, so it is left out.
            last = np.r_[kt[1:] != kt[:-1], False]
            st = knots.sample(kt[last])
            assert np.array_equal(st.s[:, 0, body], mine[last][:, layout.K_S:layout.K_S + d]), scene.name
            # Inside a step the velocity is (h v) / h: exact to an ulp.
            np.testing.assert_allclose(st.v[:, 0, body], mine[last][:, layout.K_V:layout.K_V + d],
                                       rtol=1e-15, atol=0, err_msg=scene.name)
            for a, b in zip(mine[:-1], mine[1:]):
                if a[layout.K_FREE] == 0.0:
                    inside = (t > a[layout.K_T]) & (t <= b[layout.K_T])
                    stepped_rows |= inside
        stepped_rows[0] = False
        assert np.array_equal(traj.free[:, 0], ~stepped_rows), scene.name


def test_engaged_contacts_match_the_dense_contact_series():
    """The contacts found from the run's intervals are those diagnostics.contact_series finds
    pressed at every time (DEM too: its frames are far apart), with the same values."""
    from collide.contact_index import ContactIndex
    from collide.trajectory import Knots
    from viewer.state import ROUND_OFF

    for scene in (load_scene("demo-bonus"), load_scene("billiards-break"), load_scene("break-3d"), _gas(30, 0.2)):
        run = run_scene(scene)
        traj, model = run.result.trajectory, run.result.model
        knots = Knots(model, traj)
        index = ContactIndex(model, traj, knots)
        t = traj.knot_times
        times = np.union1d(np.linspace(t[0], t[-1], 997), t[::5])
        states = knots.sample(times)
        dense = dg.contact_series(model, traj, times, states)
        pressed = dense.overlap[:, 0] > ROUND_OFF * model.radius.max()
        e = index.at(times, states.s[:, 0])
        keep = e.overlap > ROUND_OFF * model.radius.max()
        found = np.zeros_like(pressed)
        found[e.tk[keep], e.ck[keep]] = True
        assert pressed.any() and np.array_equal(found, pressed), scene.name
        tk, ck = e.tk[keep], e.ck[keep]
        assert index.names == dense.names
        assert np.array_equal(dense.point[tk, 0, ck], e.point[keep])
        assert np.array_equal(dense.normal_force[tk, 0, ck], e.normal_force[keep])
        if dense.friction_force is not None:
            assert np.array_equal(dense.friction_force[tk, 0, ck], e.friction_force[keep])


def test_controls_of_a_thousand_bodies_look_each_body_up_once(monkeypatch):
    """gas-box's 11 000 controls: reading their values and building the scene back find each
    body by name once, not by scanning all 1 000 for every control (seconds a run); the scene
    built back is the scene."""
    import viewer.params as vp
    from collide.scene import Scene as SceneClass

    scene = load_scene("gas-box")
    controls = scene_controls(scene)
    scans: list[int] = []
    real_set_path, real_index = vp.set_path, SceneClass.body_index

    def set_path(raw, key, value):
        scans.append(len(raw.get("body", [])) if key.startswith("body.") else 0)
        real_set_path(raw, key, value)

    def body_index(self, name):
        scans.append(len(self.bodies))
        return real_index(self, name)

    monkeypatch.setattr(vp, "set_path", set_path)
    monkeypatch.setattr(SceneClass, "body_index", body_index)
    values = values_of(scene, controls)
    built = build_scene(controls, values, controls.settings)
    assert len(scans) >= 1000 and max(scans) <= 1
    # (through display units: mm and back, to the last bit)
    assert np.allclose([b.position for b in built.bodies], [b.position for b in scene.bodies], rtol=1e-15, atol=0)
    assert [b.velocity for b in built.bodies] == [b.velocity for b in scene.bodies]


# ---------------------------------------------------------------------------------------------
# Slider latency (issue 12: every built-in under 100 ms server side)


def test_a_dem_scene_is_previewed_at_a_coarser_stable_step():
    """break-3d (DEM, 236 000 steps of 5 us: 270-480 ms a run) had no preview: a drag waited
    for every full run. Its preview takes 8 steps per contact time, within the step's
    stability limit, and shows the same break."""
    from viewer.live import preview_settings
    from viewer.params import AUTO, for_viewing

    scene = for_viewing(load_scene("break-3d"))
    preview = preview_settings(scene)
    assert preview is not None and preview.integrator == "dem" and preview.dt != AUTO
    full = run_scene(scene, record=False).result
    quick = run_scene(scene, integrator=preview.integrator, dt=preview.dt, tol=preview.tol, record=False).result
    assert 4 * int(quick.steps[0]) < int(full.steps[0])
    # The two front balls leave at the same speed and angle to a few per cent.
    assert np.allclose(quick.final.v[0, 2:, :2], full.final.v[0, 2:, :2], rtol=0.03, atol=0.01)


def test_a_new_run_of_the_same_scene_resends_only_what_changed(monkeypatch):
    """A slider drag draws a new run ten times a second: the ground and walls that did not
    move are not sent again, and each body's path is updated in place, not removed and added."""
    import viser

    from viewer.scene3d import SceneDrawer

    scene = load_scene("break-3d")
    views = [ViewRun(run_scene(replace(scene, bodies=[replace(scene.bodies[0], velocity=(v, 0.0, 0.0)),
                                                      *scene.bodies[1:]]), integrator="dem", dt=2e-5))
             for v in (2.0, 1.98)]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(views[0])
        added: list[str] = []
        for name in ("add_line_segments", "add_box", "add_frame"):
            real = getattr(server.scene, name)

            def counting(path, *args, _real=real, **kwargs):
                added.append(path)
                return _real(path, *args, **kwargs)

            monkeypatch.setattr(server.scene, name, counting)
        paths = list(drawer._paths)
        drawer.show_run(views[1])
        assert added == [] and drawer._paths == paths
        # One node holds every body's path, body 0's first: its last segment ends where body 0 does.
        end0 = len(views[1].paths[0]) - 2
        assert np.allclose(drawer._paths[0].points[end0, 1], views[1].paths[0][-1], atol=1e-6)
    finally:
        server.stop()


# ---------------------------------------------------------------------------------------------
# Sliders that the materials override (issue 12, item 5)


def test_break_3d_restitution_and_friction_sliders_act_on_its_materials_and_pair():
    """break-3d's materials and pair table give every contact its own restitution and mu, so
    [contact]'s sliders changed nothing. Those two are disabled with the reason; the material's
    and the pair's own values get sliders, and moving one changes the run."""
    scene = load_scene("break-3d")
    controls = scene_controls(scene)
    params = controls.by_ident()
    for name in ("restitution", "mu"):
        assert params[f"contact.{name}"].unused and "phenolic" in params[f"contact.{name}"].unused
    assert params["pair.0.restitution"].value == 0.95 and params["material.phenolic.restitution"].value == 0.5
    assert params["pair.0.mu"].value == 0.05 and not params["pair.0.restitution"].unused
    values = values_of(scene, controls)
    base = run_scene(build_scene(controls, values, controls.settings), record=False).result
    values["pair.0.restitution"] = 0.5
    softer = build_scene(controls, values, controls.settings)
    assert softer.pairs[0].restitution == 0.5 and softer.materials[0].restitution == 0.5
    run = run_scene(softer, record=False).result
    # The cue keeps more of its speed after a less elastic hit on the rack.
    assert float(run.final.v[0, 0, 0]) > float(base.final.v[0, 0, 0]) + 0.1


def test_contact_sliders_stay_live_where_some_contact_uses_them():
    """Where any contact takes [contact]'s value (no materials, a material without its own, a
    pair of materials with no pair table), its slider stays live."""
    from viewer.params import default_used

    for name in ("pile", "bounce", "demo-bonus", "billiards-break"):
        params = scene_controls(load_scene(name)).params
        assert not any(p.unused for p in params), name
    bodies = [{"name": "a", "material": "m1", "radius": 0.01, "position": [0, 0, 0.01], "velocity": [1, 0, 0]},
              {"name": "b", "material": "m2", "radius": 0.01, "position": [0.1, 0, 0.01]}]
    raw = {"dim": 3, "contact": {"model": "hertz", "restitution": 0.6},
           "material": [{"name": "m1", "density": 1000.0, "youngs_modulus": 1e7, "restitution": 0.9},
                        {"name": "m2", "density": 1000.0, "youngs_modulus": 1e7, "restitution": 0.8}],
           "body": bodies}
    assert not default_used(parse_scene(raw), "restitution")  # both give their own: the mixing rule
    raw["material"][1].pop("restitution")
    assert default_used(parse_scene(raw), "restitution")  # m2 takes [contact]'s for the a-b pair
    raw["pair"] = [{"materials": ["m1", "m2"], "restitution": 0.7}]
    assert not default_used(parse_scene(raw), "restitution")
    raw["wall"] = [{"point": [0, 0, 0], "normal": [0, 0, 1]}]
    assert default_used(parse_scene(raw), "restitution")  # b on the floor: m2 has none


def test_a_few_balls_paths_are_two_nodes_and_shells_show_in_contact():
    """break-3d's four balls: every ball's whole path in one line node and its path so far in
    another, each segment in its ball's colour, the one so far ending at the ball; the pale
    undeformed shell shows round the spheres in contact only."""
    import viser

    from viewer.colours import as_linear, body_colours
    from viewer.scene3d import SceneDrawer

    # Without the table (no floor, no gravity): only the balls that collide touch.
    scene = replace(load_scene("break-3d"), walls=[], gravity=None)
    view = ViewRun(run_scene(scene, integrator="dem", dt=2e-5))
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(view)
        assert not drawer.many and len(drawer._bodies) == view.n_bodies
        assert len(drawer._paths) == 1 and len(drawer._past) == 1

        def touching(frame) -> np.ndarray:
            out = np.zeros(view.n_bodies, bool)
            for c in frame.contacts:
                out[[c.i] + ([c.j] if c.j is not None else [])] = True
            return out

        # A time when some balls touch and some do not.
        times = np.concatenate([np.linspace(a, b, 50) for a, b in view.contact_windows])
        frame = next(f for f in map(view.frame, times) if touching(f).any() and not touching(f).all())
        drawer.show_frame(frame)
        assert [body["outline"].visible for body in drawer._bodies] == list(touching(frame))
        for body, centre in zip(drawer._bodies, frame.positions):
            assert np.allclose(body["frame"].position, centre)
        # The paths so far: each ball's segments in its colour, the last ending at its centre.
        past = drawer._past[0]
        points, colours = np.asarray(past.points), np.asarray(past.colors)
        assert len(points) == len(colours) == sum(drawer._past_counts)
        ends = np.cumsum(drawer._past_counts) - 1
        assert np.allclose(points[ends, 1], frame.positions, atol=1e-6)
        assert np.array_equal(colours[ends, 0], as_linear(body_colours(view.n_bodies)))
    finally:
        server.stop()


def test_many_bodies_above_the_point_count_are_drawn_as_points(monkeypatch):
    """Level of detail: above POINT_BODIES bodies ("auto") one point each, at its centre and in
    the colour mode's colour, the panel's legend saying so; the clip plane drops the points it
    hides; "spheres" draws them as instanced spheres again, and "points" below the count."""
    import viser

    import viewer.scene3d as scene3d
    from viewer.frames import settling_pile

    run = settling_pile(120, duration=0.2, fps=10)
    monkeypatch.setattr(scene3d, "POINT_BODIES", 100)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = scene3d.SceneDrawer(server.scene)
        drawer.show_run(run)
        frame = run.frame(0.1)
        drawer.show_frame(frame)
        assert drawer.points and set(drawer._batch) == {"points"}
        points = drawer._batch["points"]
        assert np.allclose(points.points, frame.positions, atol=1e-6)
        assert "120 bodies drawn as points" in drawer.legend() and "force chains:" not in drawer.legend()
        drawer.set_options(colour_by="speed")
        assert np.array_equal(points.colors, drawer.body_colours()) and len(np.unique(points.colors, axis=0)) > 1
        drawer.look.clip.on, drawer.look.clip.axis, drawer.look.clip.offset = True, 0, 0.0
        drawer.show_frame(frame)
        kept = frame.positions[:, 0] <= 0.0
        assert 0 < kept.sum() < len(kept)
        assert np.allclose(points.points, frame.positions[kept], atol=1e-6) and len(points.colors) == kept.sum()
        drawer.look.clip.on = False
        drawer.set_options(bodies="spheres")
        drawer.show_run(run)
        drawer.show_frame(frame)
        assert not drawer.points and "spheres" in drawer._batch and "points" not in drawer._batch
        monkeypatch.setattr(scene3d, "POINT_BODIES", 1000)
        drawer.set_options(bodies="points")
        drawer.show_run(run)
        assert drawer.points and "points" in drawer._batch
    finally:
        server.stop()


def test_a_blob_shadow_fades_towards_the_floor_in_its_colour():
    """A shadow at full strength is its own colour; at none, the floor's (in the linear values
    the client reads instance colours as); halfway, halfway between in those values."""
    from viewer.colours import as_linear, faded

    dark, floor = (60, 60, 70), (222, 224, 228)
    out = faded(dark, floor, np.array([1.0, 0.0, 0.5, 2.0]))
    assert np.array_equal(out[0], dark) and np.array_equal(out[3], dark)
    assert np.array_equal(out[1], as_linear(np.array(floor)))
    assert np.allclose(out[2], 0.5 * (np.array(dark) + as_linear(np.array(floor))), atol=1)


@pytest.mark.parametrize(("name", "engine"), [("newtons-cradle", "event"), ("textbook-1d", "event"),
                                              ("bounce", "event"), ("demo-bonus", "event"),
                                              ("break-3d", "dem")])
def test_the_restitution_slider_keeps_the_event_engine_where_it_runs_the_law(name, engine):
    """Restitution below 1 from the slider: the event engine where it runs the dashpot at full
    order (its steps from the tolerance, which the slider keeps), the DEM kernel at DEM's
    tolerance only where it does not (docs/method.md, "Which engine runs a scene")."""
    scene = load_scene(name)
    controls = scene_controls(scene)
    values = values_of(scene, controls)
    values["contact.restitution"] = 0.7
    settings = check_settings(scene.integrator, scene.dt, scene.tol)
    moved = build_scene(controls, values, settings)
    run = run_scene(moved, record=False)
    assert run.result.engine == engine
    if engine == "event":
        assert moved.tol == scene.tol and moved.dt == AUTO
        assert float(run.error_estimate[0]) <= scene.tol
    else:
        assert moved.tol >= DEM_TOL


def test_opening_replaces_a_grown_reader_once_the_run_is_prepared(tmp_path, monkeypatch):
    # The reader grown by the file is not replaced while the run is prepared and sent to the
    # tabs (its replacement's import of Rerun competed with them), but once that is done.
    from collide.recording import sandbox, write_recording
    from viewer.opening import OpeningRecording

    path = write_recording(run_scene(load_scene("demo-bonus")), tmp_path / "bonus.rrd")
    monkeypatch.setattr(sandbox, "_IDLE_MAX_MB", 0)  # every reader counts as grown
    idle_when_shown: list[int] = []

    def shown(opening: OpeningRecording) -> None:
        if opening.view is not None:
            with sandbox._idle_lock:
                idle_when_shown.append(len(sandbox._idle))

    opening = OpeningRecording(path, path.name)
    opening.follow(shown)
    assert opening.wait(120) and opening.error is None and opening.view is not None
    assert idle_when_shown == [0]  # no fresh reader while the run was being shown
    with sandbox._idle_lock:
        assert len(sandbox._idle) == 1 and sandbox._idle[0].proc.poll() is None


def test_states_at_knots_are_the_sampled_states():
    """`Knots.at_knots` (the angular momentum at the contact steps' ends) gives the states
    `sample` evaluates at times where every body has a knot, to round-off (a body's final knot
    is reached by `sample` from the segment before it), and None where some body has none."""
    from collide.engine import layout
    from collide.trajectory import Knots, body_knots

    for scene in (load_scene("demo-bonus"), load_scene("break-3d"), _gas(30, 0.2)):
        run = run_scene(scene)
        traj, model = run.result.trajectory, run.result.model
        knots = Knots(model, traj)
        each = [set(mine[:, layout.K_T]) for mine in body_knots(traj)]
        common = np.array(sorted(set.intersection(*each)))
        assert len(common), scene.name
        s, v, w = knots.at_knots(common)
        st = knots.sample(common)
        size = float(np.max(np.abs(st.s[:, 0])))
        speed = float(np.max(np.abs(st.v[:, 0])))
        spin = max(float(np.max(np.abs(st.w), initial=0.0)), 1e-300)
        np.testing.assert_allclose(s, st.s[:, 0], rtol=0, atol=1e-14 * size, err_msg=scene.name)
        np.testing.assert_allclose(v, st.v[:, 0], rtol=0, atol=1e-14 * speed, err_msg=scene.name)
        np.testing.assert_allclose(w, st.w[:, 0], rtol=0, atol=1e-14 * spin, err_msg=scene.name)
        lonely = np.setdiff1d(traj.knot_times, common)
        if len(lonely):
            assert knots.at_knots(lonely[:1]) is None, scene.name
