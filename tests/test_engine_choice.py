"""The engine chosen by what a run needs (issue 51): a sphere alone among walls under Hertz or the
restitution's dashpot runs in the event engine at full order (collide/alone.py), every other
scene with these laws in DEM; the JSON says which and why, and a user may force either. Through
`collide run`: ten bounces against scipy's DOP853 chain of the same 1-DOF law, the built-in
bounce at --tol 1e-9 against a run at 1e-11, the choice, forcing it, and bad input."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from collide.engine import layout
from collide.engine.event import impact as im
from collide.measure import outcome_distance
from collide.run import run_scene
from collide.scene import SceneError, load_scene, parse_scene
from collide.stepper import RunError
from tests.test_event_laws import reference_contact, rubber_ball
from tests.test_hardening import _main, _one_line_error

G = 9.81


def ball_on_floor(hertz: bool, e: float, duration: float) -> dict:
    """tests/test_event_laws.rubber_ball as a scene: r = 0.03 m, 1100 kg/m^3, Hertz at E = 1e9 Pa
    (nu 0.45) or a linear spring of 1e6 N/m, let go 1 m above a floor, moving along it at 0.3 m/s
    (the run's tolerance is relative to that speed)."""
    contact = {"model": "hertz", "youngs_modulus": 1e9, "poisson_ratio": 0.45} if hertz else {"k": 1e6}
    contact["restitution"] = e
    return {"dim": 2, "duration": duration, "gravity": [0.0, -G], "contact": contact,
            "body": [{"name": "ball", "radius": 0.03, "mass": 4.0 / 3.0 * math.pi * 0.03**3 * 1100.0,
                      "position": [0.0, 1.03],
                      "velocity": [0.3, 0.0]}],
            "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}


def reference_chain(hertz: bool, e: float, bounces: int) -> tuple[list[float], float]:
    """DOP853's rebound speeds of successive bounces (flights between are parabolas), and when
    the last contact ends."""
    params = rubber_ball(hertz, e)
    speed = math.sqrt(2 * G * 1.0)
    t = speed / G
    speeds = []
    for _ in range(bounces):
        speed, contact_time = reference_contact(params, speed)
        speeds.append(speed)
        t += contact_time + (2 * speed / G if len(speeds) < bounces else 0.0)
    return speeds, t


def rebound_speeds(run) -> np.ndarray:
    """The vertical speed at the end of each recorded contact: the knot that starts the flight."""
    traj = run.result.trajectory
    knots = traj.knots
    ends = traj.intervals[:, layout.V_END]
    speeds = []
    for end in ends:
        row = np.flatnonzero((knots[:, layout.K_T] == end) & (knots[:, layout.K_FREE] == 1.0))
        speeds.append(knots[row[0], layout.K_V + 1])
    return np.array(speeds)


@pytest.mark.parametrize(("hertz", "e"), [(True, 0.8), (False, 0.6), (True, 0.6)])
def test_ten_bounces_of_a_run_match_an_independent_integration(hertz, e):
    """At tol 1e-9 a run's rebound speeds of ten successive bounces are within 1e-8 (relative) of
    DOP853 at rtol 1e-13 chaining the same law, and the energy balance closes."""
    speeds, last_end = reference_chain(hertz, e, 10)
    scene = parse_scene(ball_on_floor(hertz, e, last_end + 0.5 * speeds[-1] / G))
    run = run_scene(scene, tol=1e-9)
    assert run.result.engine == "event"
    assert int(run.result.contacts.count[0]) == 10
    ours = rebound_speeds(run)
    assert ours == pytest.approx(np.array(speeds), rel=1e-8)
    assert float(run.result.final.t[0]) == pytest.approx(scene.duration)
    from collide import diagnostics as dg

    assert dg.residuals(run.result).energy[0] < 1e-9


def test_bounce_at_tol_1e9_holds_against_1e11():
    """The built-in bounce runs at --tol 1e-9 (DEM reaches 6e-5), measured, and its outcome is
    within the tolerance of a run at 1e-11 and within ten times its own estimate (the
    measurement's rule, tests/test_error_estimate.py: a difference to a run at a tenth of the
    tolerance, which a first-order-in-tol error leaves about a tenth short)."""
    scene = load_scene("bounce")
    coarse = run_scene(scene, tol=1e-9, record=False)
    fine = run_scene(scene, tol=1e-11, record=False)
    assert coarse.result.engine == "event" and coarse.error_method == ["measured"]
    off = outcome_distance(coarse.result, fine.result, scene)
    assert off <= 1e-9 and off <= 10 * float(coarse.error_estimate[0]) <= 1e-8, (off, coarse.error_estimate)
    assert float(coarse.error_estimate[0]) <= 1e-9


def test_a_run_ending_inside_a_contact_is_the_contact_stopped_there():
    """A duration that ends mid-contact: the state there matches DOP853 integrating the same
    contact to that time (the overlap and its rate)."""
    from scipy.integrate import solve_ivp

    params = rubber_ball(True, 0.8)
    v_in = math.sqrt(2 * G)
    touch = v_in / G
    _, span = im.estimate(params, v_in)
    stop = 0.4 * span
    run = run_scene(parse_scene(ball_on_floor(True, 0.8, touch + stop)), tol=1e-10, record=False)
    hertz, _, estar, rstar, mstar, zeta, accel = params[:7]

    def rhs(_, y):
        delta, u = max(y[0], 0.0), y[1]
        kn = 2.0 * estar * math.sqrt(rstar * delta)
        force = 4.0 / 3.0 * estar * math.sqrt(rstar * delta) * delta + 2.0 * zeta * math.sqrt(mstar * kn) * u
        return [u, accel - force / mstar]

    sol = solve_ivp(rhs, (0.0, stop), [0.0, v_in], method="DOP853", rtol=1e-13, atol=1e-30, max_step=span / 50)
    delta, rate = sol.y[0, -1], sol.y[1, -1]
    y, vy = float(run.result.final.s[0, 0, 1]), float(run.result.final.v[0, 0, 1])
    assert 0.03 - y == pytest.approx(delta, rel=1e-7)
    assert -vy == pytest.approx(rate, rel=1e-7)


def test_a_ball_coming_to_rest_is_held_by_the_floor():
    """A slow, damped ball that gravity keeps on the floor: the contact goes on to the run's end,
    and the overlap settles at the linear spring's m g / k."""
    raw = ball_on_floor(False, 0.3, 1.5)
    raw["body"][0]["position"] = [0.0, 0.0305]
    run = run_scene(parse_scene(raw), tol=1e-8, record=False)
    mass = 4.0 / 3.0 * math.pi * 0.03**3 * 1100.0
    assert run.result.engine == "event"
    assert 0.03 - float(run.result.final.s[0, 0, 1]) == pytest.approx(mass * G / 1e6, rel=1e-6)
    assert abs(float(run.result.final.v[0, 0, 1])) < 1e-9


def _json(args, monkeypatch, capsys, tmp_path) -> dict:
    code, out, err = _main(["run", *args, "--json", "--no-record"], monkeypatch, capsys, tmp_path)
    assert code == 0, err
    return json.loads(out)


PAIR = {"dim": 2, "duration": 0.05, "tol": 1e-3,
        "contact": {"model": "hertz", "youngs_modulus": 1e8, "restitution": 0.7},
        "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0], "velocity": [1.0, 0.0]},
                 {"name": "b", "mass": 1.0, "radius": 0.1, "position": [0.3, 0.0]}]}
# Three spheres under these laws: the islands', with Coulomb friction or a tangential spring (in
# 3D the spring is DEM's).
TRIO = {**PAIR, "body": PAIR["body"] + [{"name": "c", "mass": 1.0, "radius": 0.1, "position": [0.6, 0.0]}]}
# Damped, with friction: the first sphere spins into the second off the line of centres, which
# passes it on to the third.
RUBBING_TRIO = {**TRIO, "duration": 0.4, "contact": {**PAIR["contact"], "mu": 0.3},
                "body": [{**TRIO["body"][0], "spin": 30.0}, {**TRIO["body"][1], "position": [0.3, 0.03]},
                         TRIO["body"][2]]}
SPRUNG_TRIO = {**TRIO, "contact": {**RUBBING_TRIO["contact"], "tangential": "spring"}}


def _in_3d(raw: dict) -> dict:
    """The same scene in 3D, in the z = 0 plane (spins about z)."""
    out = copy.deepcopy(raw)
    out["dim"] = 3
    for body in out["body"]:
        for key in ("position", "velocity"):
            if key in body:
                body[key] = list(body[key]) + [0.0]
        if "spin" in body:
            body["spin"] = [0.0, 0.0, float(body["spin"])]
    return out


def _scene_file(tmp_path, raw: dict) -> str:
    from collide.scene import dump_toml

    path = tmp_path / "scene.toml"
    path.write_text(dump_toml(raw))
    return str(path)


def test_the_json_says_which_engine_ran_and_why(monkeypatch, capsys, tmp_path):
    alone = _json(["bounce"], monkeypatch, capsys, tmp_path)
    assert alone["engine"] == "event" and "sphere alone among walls" in alone["engine_reason"]
    assert "model = 'hertz'" in alone["engine_reason"]
    pair = _json([_scene_file(tmp_path, PAIR)], monkeypatch, capsys, tmp_path)
    assert pair["engine"] == "event" and "two spheres and no walls" in pair["engine_reason"]
    trio = _json([_scene_file(tmp_path, TRIO)], monkeypatch, capsys, tmp_path)
    assert trio["engine"] == "event" and "Hertz's force and its dashpot" in trio["engine_reason"]
    rubbing = _json([_scene_file(tmp_path, RUBBING_TRIO)], monkeypatch, capsys, tmp_path)
    assert rubbing["engine"] == "event" and "Hertz's force and its dashpot" in rubbing["engine_reason"]
    assert "each friction mode change located" in rubbing["engine_reason"]
    sprung = _json([_scene_file(tmp_path, SPRUNG_TRIO)], monkeypatch, capsys, tmp_path)
    assert sprung["engine"] == "event" and "with the tangential spring" in sprung["engine_reason"]
    assert "in the islands' steps" in sprung["engine_reason"]
    # In 3D the spring inside an island is DEM's still.
    sprung3 = _json([_scene_file(tmp_path, _in_3d(SPRUNG_TRIO))], monkeypatch, capsys, tmp_path)
    assert sprung3["engine"] == "dem" and "3 spheres" in sprung3["engine_reason"]
    assert "a tangential spring between spheres inside an island" in sprung3["engine_reason"]
    assert "in 3D" in sprung3["engine_reason"]
    # Not head-on, the line of centres turns during the contact: the islands take it.
    oblique = copy.deepcopy(PAIR)
    oblique["body"][1]["position"], oblique["duration"] = [0.3, 0.05], 0.2
    grazing = _json([_scene_file(tmp_path, oblique)], monkeypatch, capsys, tmp_path)
    assert grazing["engine"] == "event" and "islands" in grazing["engine_reason"]
    report = _json(["demo-bonus"], monkeypatch, capsys, tmp_path)
    assert report["engine"] == "event" and "the report's contact law" in report["engine_reason"]


def test_either_engine_may_be_forced(monkeypatch, capsys, tmp_path):
    dem = _json(["bounce", "--integrator", "dem"], monkeypatch, capsys, tmp_path)
    assert dem["engine"] == "dem" and "asked for" in dem["engine_reason"]
    event = _json(["bounce", "--set", "integrator='kahan6'", "--tol", "1e-6"], monkeypatch, capsys, tmp_path)
    assert event["engine"] == "event"
    # The event engine asked for where it cannot run the scene: one line with the cause.
    code, out, err = _main(["run", _scene_file(tmp_path, _in_3d(SPRUNG_TRIO)), "--integrator", "kahan6",
                            "--no-record"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, "3 spheres")
    code, out, err = _main(["run", "bounce", "--integrator", "seed", "--no-record"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, "the report's update runs its contact law only")
    with pytest.raises(SceneError, match="3 spheres"):
        parse_scene({**_in_3d(SPRUNG_TRIO), "integrator": "kahan6"})
    # Damped Hertz with Coulomb friction between spheres: the islands', forced or not.
    rubbing = _json([_scene_file(tmp_path, RUBBING_TRIO), "--integrator", "kahan6"], monkeypatch, capsys, tmp_path)
    assert rubbing["engine"] == "event"


def test_bad_input_is_refused_or_sent_where_it_runs(monkeypatch, capsys, tmp_path):
    code, out, err = _main(["run", "bounce", "--tol", "1e-14", "--no-record"], monkeypatch, capsys, tmp_path)
    assert code != 0 and len(err.splitlines()) == 1 and "finer than a sphere's contacts reach" in err
    assert "Traceback" not in err
    # A given step: not the sphere alone's own contacts (their steps come from --tol), but the
    # islands, which step Hertz at it, and say so.
    given = _json(["bounce", "--dt", "2e-5", "--set", "duration=0.5"], monkeypatch, capsys, tmp_path)
    assert given["engine"] == "event" and "Hertz's force and its dashpot" in given["engine_reason"]
    assert "islands' steps" in given["engine_reason"]
    # A tolerance DEM cannot reach, for a scene only DEM runs: the existing refusal, with its cause.
    code, out, err = _main(["run", _scene_file(tmp_path, _in_3d(SPRUNG_TRIO)), "--tol", "1e-9", "--no-record"],
                           monkeypatch, capsys, tmp_path)
    assert code != 0 and "DEM steps per contact" in err and len(err.splitlines()) == 1
    # The islands reach it where they run the law: damped Hertz with Coulomb friction, measured.
    rubbing = _json([_scene_file(tmp_path, RUBBING_TRIO), "--tol", "1e-9"], monkeypatch, capsys, tmp_path)
    assert rubbing["engine"] == "event" and rubbing["error_method"] == "measured"
    assert rubbing["error_estimate"] <= 1e-9


LANDING = math.sqrt(2 * 0.25 / G)  # a ball of r = 0.05 m let go at y = 0.3 m reaches the floor
# ... 10 um from a side wall at x = -0.1 m that it moves toward at 0.5 m/s.
CORNER = {"dim": 2, "duration": 0.6, "gravity": [0.0, -G], "tol": 1e-3,
          "contact": {"model": "hertz", "youngs_modulus": 1e7, "restitution": 0.8},
          "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [-0.05 + 1e-5 + 0.5 * LANDING, 0.3],
                    "velocity": [-0.5, 0.0]}],
          "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}, {"point": [-0.1, 0.0], "normal": [1.0, 0.0]}]}


def test_two_walls_at_once_go_to_dem_or_are_refused():
    """A ball landing in a corner touches the floor while it reaches the side wall: two contacts
    at once are DEM's; chosen by itself the run goes there and says why, forced it is refused."""
    run = run_scene(parse_scene(copy.deepcopy(CORNER)), record=False)
    assert run.result.engine == "dem" and "another wall" in run.result.engine_reason
    with pytest.raises(RunError, match="another wall"):
        run_scene(parse_scene({**copy.deepcopy(CORNER), "integrator": "kahan6"}), record=False)


def test_the_laws_have_one_kernel_type_for_any_count_of_walls():
    """The sphere-alone kernel is compiled for the type of its law table once (the warm-up's
    one wall): two walls or more gave an F-ordered copy, a second signature compiled in the run."""
    import numba

    from collide.alone import law_rows
    from collide.run import compile_scenes

    types = set()
    for walls in (CORNER["wall"][:1], CORNER["wall"], CORNER["wall"] + [{"point": [0.5, 0.0], "normal": [-1.0, 0.0]}]):
        model, _ = compile_scenes([parse_scene({**copy.deepcopy(CORNER), "wall": walls})])
        rows = law_rows(model)
        assert rows.shape[0] == len(walls) and rows.flags.c_contiguous and not rows.flags.writeable
        types.add(numba.typeof(rows))
    assert len(types) == 1


def _off_centre_reference(m: np.ndarray, r: np.ndarray, x: np.ndarray, v: np.ndarray, estar: float,
                          e: float) -> np.ndarray:
    """Two spheres meeting off-centre under Hertz and its dashpot, integrated independently: the
    relative motion p'' = F n / m* (central force, F = 4/3 E* sqrt(R*) delta^1.5 + 2 zeta
    sqrt(m* 2 E* sqrt(R* delta)) delta', unclipped) by DOP853 (rtol 1e-13) from the touch, found in
    closed form, to the separation, located by scipy; the final velocities (they never meet
    again)."""
    from scipy.integrate import solve_ivp

    from collide.model import damping_ratio

    mstar, reach = m[0] * m[1] / m.sum(), r.sum()
    rstar = r[0] * r[1] / reach
    zeta = float(damping_ratio(np.array(e), True))
    p, u = x[1] - x[0], v[1] - v[0]
    # |p + u t| = reach: the touch.
    a, b, c = u @ u, 2.0 * p @ u, p @ p - reach**2
    t = (-b - math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    y = np.concatenate([p + u * t, u])

    def rhs(_, z):
        q, w = z[:3], z[3:]
        dist = math.sqrt(q @ q)
        delta, rate = reach - dist, -(q @ w) / dist
        force = 4.0 / 3.0 * estar * math.sqrt(rstar) * max(delta, 0.0) ** 1.5 + \
            2.0 * zeta * math.sqrt(mstar * 2.0 * estar * math.sqrt(rstar * max(delta, 0.0))) * rate
        return np.concatenate([w, force * q / dist / mstar])

    def apart(_, z):
        return reach - math.sqrt(z[:3] @ z[:3])

    apart.terminal, apart.direction = True, -1.0
    # Start a hair inside the contact (the event function starts at zero otherwise).
    y = solve_ivp(rhs, (0.0, 1.0), y, method="DOP853", rtol=1e-13, atol=1e-18, events=apart,
                  first_step=1e-9).y[:, -1]
    centre = (m[0] * v[0] + m[1] * v[1]) / m.sum()
    return np.array([centre - m[1] / m.sum() * y[3:], centre + m[0] / m.sum() * y[3:]])


@pytest.mark.parametrize(("offset", "e"), [(0.3, 1.0), (0.7, 0.6), (0.95, 0.9)])
def test_two_spheres_meeting_off_centre_run_in_the_islands_at_full_order(offset, e):
    """Two spheres and no walls meeting off-centre (impact parameter `offset` of the reach, up to
    grazing) under Hertz and its dashpot: the line of their centres turns, which the pair's
    relative coordinate does not take, so the islands do, at tol 1e-9 within 1e-8 of DOP853 (the
    test of the chains and cradles) and within 10 times the measured estimate."""
    young, poisson = 1e8, 0.3
    m, r = np.array([0.3, 0.7]), np.array([0.02, 0.03])
    x = np.array([[0.0, 0.0, 0.0], [0.1, offset * r.sum(), 0.0]])
    v = np.array([[1.5, 0.0, 0.0], [-0.2, -0.05, 0.0]])
    raw = {"dim": 3, "tol": 1e-9, "duration": 0.2, "contact": {"model": "hertz", "restitution": e},
           "material": [{"name": "ball", "youngs_modulus": young, "poisson_ratio": poisson}],
           "body": [{"name": f"b{i}", "mass": float(m[i]), "radius": float(r[i]), "position": x[i].tolist(),
                     "velocity": v[i].tolist(), "material": "ball"} for i in range(2)]}
    run = run_scene(parse_scene(raw), record=False)
    assert run.result.engine == "event" and "islands" in run.result.engine_reason
    assert run.error_method[0] == "measured"
    got = run.result.final.v[0]
    reference = _off_centre_reference(m, r, x, v, young / (2.0 * (1.0 - poisson**2)), e)
    error = np.abs(got - reference).max() / np.abs(v).max()
    assert error <= 1e-8
    assert error <= 10.0 * run.error_estimate[0]


def test_a_tangential_spring_between_two_spheres_runs_in_the_event_engine(monkeypatch, capsys, tmp_path):
    """Two spheres and no walls meeting off-centre with friction and a tangential spring: the
    event engine, the JSON saying how; a third sphere makes an island, which takes the spring in
    2D; in 3D it is DEM's, with that cause."""
    spring = {**PAIR["contact"], "mu": 0.3, "tangential": "spring", "tangential_stiffness_ratio": 0.8}
    pair = {**copy.deepcopy(PAIR), "contact": spring}
    pair["body"][1]["position"], pair["duration"] = [0.3, 0.05], 0.2
    rubbing = _json([_scene_file(tmp_path, pair)], monkeypatch, capsys, tmp_path)
    assert rubbing["engine"] == "event" and "two spheres and no walls" in rubbing["engine_reason"]
    assert "stick and slip located" in rubbing["engine_reason"]
    trio = _json([_scene_file(tmp_path, {**TRIO, "contact": spring})], monkeypatch, capsys, tmp_path)
    assert trio["engine"] == "event" and "with the tangential spring" in trio["engine_reason"]
    trio3 = _json([_scene_file(tmp_path, _in_3d({**TRIO, "contact": spring}))], monkeypatch, capsys, tmp_path)
    assert trio3["engine"] == "dem" and "tangential spring between spheres inside an island" in trio3["engine_reason"]
