"""Issue 53: runs refused that should run (a drop from the origin judged unstable, a long bounce
stalled on the clock), runs that ran when they should end or be refused (a DEM scene with
nothing to meet, a tolerance below round-off, a contact too stiff for float64) and scene keys of
the wrong type. Each refusal is one line and exit 2; each run is checked against a closed form."""

from __future__ import annotations

import copy
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.run import ROUND_OFF_SLACK, TOL_FLOOR, run_scene
from collide.scene import SceneError, parse_scene
from collide.stepper import RunError
from tests.test_hardening import _main, _one_line_error

G = 9.81


def _drop(y0: float, duration: float, k: float = 1e6, floor: float = -1.0) -> dict:
    """A ball (1 kg, r = 0.1 m) let go at rest at height y0 above a floor at `floor`."""
    return {"dim": 2, "duration": duration, "gravity": [0.0, -G], "contact": {"k": k},
            "body": [{"name": "ball", "mass": 1.0, "radius": 0.1, "position": [0.0, y0]}],
            "wall": [{"point": [0.0, floor], "normal": [0.0, 1.0]}]}


def bounce_state(t: float, y0: float, top: float, m: float, k: float) -> tuple[float, float, float]:
    """Height and vertical velocity at t of a ball let go at rest at y0 onto a floor it touches at
    height `top`, on a linear spring k with no damping, and the bounce's period. In contact the
    overlap oscillates about m g / k: delta = d_eq + A sin(omega s - phi), from delta = 0 at the
    touch (speed v0) to delta = 0 again, (pi + 2 phi) / omega later."""
    v0 = math.sqrt(2.0 * G * (y0 - top))
    fall = v0 / G
    omega = math.sqrt(k / m)
    d_eq = G / omega**2
    amp = math.hypot(d_eq, v0 / omega)
    phi = math.asin(d_eq / amp)
    touch = (math.pi + 2.0 * phi) / omega
    period = 2.0 * fall + touch
    tau = math.fmod(t, period)
    if tau < fall:
        return y0 - 0.5 * G * tau**2, -G * tau, period
    if tau < fall + touch:
        s = tau - fall
        return top - d_eq - amp * math.sin(omega * s - phi), -amp * omega * math.cos(omega * s - phi), period
    s = tau - fall - touch
    return top + v0 * s - 0.5 * G * s * s, v0 - G * s, period


def test_a_drop_from_the_origin_runs_and_rebounds_as_the_closed_form() -> None:
    # Its total energy is zero (potential measured from the origin): the stability check once
    # refused the drop as energy growing from 3.5e-27 J to 6.8e-14 J.
    for y0 in (0.0, 1e-3):
        run = run_scene(parse_scene(_drop(y0, 2.0)), record=False)
        y, v, period = bounce_state(2.0, y0, -0.9, 1.0, 1e6)
        assert 2.0 > 2 * period  # two bounces and more
        v0 = math.sqrt(2 * G * (y0 + 0.9))
        error = float(run.error_estimate[0])
        assert abs(run.result.final.v[0, 0, 1] - v) <= error * v0
        assert abs(run.result.final.s[0, 0, 1] - y) <= error * v0 * 2.0


@pytest.mark.parametrize("span", [5000.0, 86400.0])
def test_an_elastic_bounce_runs_for_hours_and_keeps_its_apex(span: float) -> None:
    # A float clock's tick at 256 s (5.7e-14 s) let a touch landed on time fall just short of
    # the floor, over and over: the run stopped advancing there. At an apex (a whole number of
    # periods) the ball is back at its start height, at rest.
    _, _, period = bounce_state(0.0, 0.0, -0.9, 1.0, 1e6)
    apexes = math.floor(span / period)
    duration = apexes * period
    run = run_scene(parse_scene(_drop(0.0, duration)), record=False)
    assert run.result.final.t[0] == pytest.approx(duration, rel=1e-15)
    v0 = math.sqrt(2 * G * 0.9)
    error = float(run.error_estimate[0])
    v_end = float(run.result.final.v[0, 0, 1])
    y_end = float(run.result.final.s[0, 0, 1])
    assert abs(v_end) <= error * v0, (v_end, error)
    # The apex height: the energy the final state holds, as a height (position errors at the apex
    # are second order in the period's).
    assert abs(y_end + v_end**2 / (2 * G)) <= error * 0.9, y_end


def test_a_contact_far_from_the_origin_runs_to_the_elastic_closed_form() -> None:
    # Found by the fuzz (seed 30): a contact due 3.3e5 s ahead, 5e5 m from the origin, where a
    # touch landed on time falls short by less than a tick of the clock. Refused as a stall
    # before; landed on the clock's next tick, it runs (the overlap there, 7e-3 m, is resolved
    # to 2e-8 by positions near 2e5 m).
    m1, m2, u1, u2 = 0.17, 0.0254, -1.030623169262384, 0.5600746729841526
    raw = {"dim": 1, "contact": {"k": 1000.0},
           "body": [{"name": "ball1", "mass": m1, "radius": 0.03, "position": 527749.8607955186, "velocity": u1},
                    {"name": "ball2", "mass": m2, "radius": 0.1, "position": 0.425, "velocity": u2}]}
    run = run_scene(parse_scene(raw), record=False)
    assert int(run.result.contacts.count[0]) == 1
    v1 = ((m1 - m2) * u1 + 2 * m2 * u2) / (m1 + m2)
    v2 = ((m2 - m1) * u2 + 2 * m1 * u1) / (m1 + m2)
    # The model's estimate for this step, relative to the fastest initial speed; the light ball's
    # outcome came within 1.02 of it (its positions' round-off here is 4e-9 of the overlap): the
    # step's error, as near the origin, within twice the model.
    error = 2.0 * float(run.error_estimate[0]) * max(abs(u1), abs(u2))
    assert abs(run.result.final.v[0, 0, 0] - v1) <= error and abs(run.result.final.v[0, 1, 0] - v2) <= error


def _box_pair(duration: float, speed: float) -> dict:
    """Two equal balls between two walls 2 m apart (1D), one moving: elastic, they swap
    velocities at every collision, and one is always at rest between collisions."""
    return {"dim": 1, "duration": duration, "contact": {"k": 1e6},
            "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": -0.5, "velocity": speed},
                     {"name": "b", "mass": 1.0, "radius": 0.1, "position": 0.5, "velocity": 0.0}],
            "wall": [{"point": -1.0, "normal": 1.0}, {"point": 1.0, "normal": -1.0}]}


def test_two_balls_in_a_box_run_a_day() -> None:
    speed = 0.05
    run = run_scene(parse_scene(_box_pair(86400.0, speed)), record=False)
    result = run.result
    assert result.final.t[0] == 86400.0
    assert int(result.contacts.count[0]) > 1000
    error = float(run.error_estimate[0])
    energy = float(dg.residuals(result).energy[0])
    assert energy <= 10 * error, (energy, error)
    x = result.final.s[0, :, 0]
    clear = x[1] - x[0] > 0.2 and x[0] > -0.9 and x[1] < 0.9
    if clear:  # between collisions one ball is at rest and the other carries the whole speed
        v = np.sort(np.abs(result.final.v[0, :, 0]))
        assert v[0] <= 10 * error * speed and abs(v[1] - speed) <= 10 * error * speed, v


def _apart() -> dict:
    return {"dim": 2, "integrator": "dem", "tol": 1e-2, "contact": {"restitution": 0.5},
            "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0], "velocity": [-1.0, 0.0]},
                     {"name": "b", "mass": 1.0, "radius": 0.1, "position": [1.0, 0.0], "velocity": [1.0, 0.0]}]}


def test_a_dem_run_with_nothing_to_meet_ends_at_once() -> None:
    started = time.perf_counter()
    run = run_scene(parse_scene(_apart()), record=False)
    assert time.perf_counter() - started < 30.0  # was 20 million steps; any real bound is far below
    assert run.result.final.t[0] == 0.0 and int(run.result.steps[0]) == 0
    assert any("can ever meet" in w for w in run.result.warnings)
    # One that parts after a collision ends too, and one coming back to a wall under gravity does not.
    raw = _apart()
    raw["body"][1]["velocity"] = [-2.0, 0.0]
    met = run_scene(parse_scene(raw), record=False)
    assert int(met.result.contacts.count[0]) == 1 and not met.result.warnings
    assert met.result.final.v[0, 1, 0] > met.result.final.v[0, 0, 0]


def test_a_tolerance_below_round_off_is_refused_with_a_given_step(monkeypatch, capsys, tmp_path: Path) -> None:
    code, out, err = _main(["run", "demo-bonus", "--dt", "1e-5", "--tol", "1e-30", "--no-record"],
                           monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, f"the finest reachable is about {TOL_FLOOR['kahan6']:.0e}")
    with pytest.raises(RunError, match="below what 'verlet' reaches"):
        run_scene(parse_scene(_box_pair(1.0, 1.0)), integrator="verlet", dt=1e-5, tol=1e-13)


def _head_on(k: float) -> dict:
    return {"dim": 1, "contact": {"k": k},
            "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": 0.0, "velocity": 1.0},
                     {"name": "b", "mass": 1.0, "radius": 0.1, "position": 1.0}]}


def test_a_contact_too_stiff_for_float64_is_refused_with_its_limit(monkeypatch, capsys, tmp_path: Path) -> None:
    # At k = 1e26 a head-on collision lost half its energy and exited 0 with a warning.
    with pytest.raises(RunError, match="too stiff") as info:
        run_scene(parse_scene(_head_on(1e26)), record=False)
    limit = float(str(info.value).split("at most k = ")[1].split(" ")[0])
    # Just under the limit the outcome's round-off is within ROUND_OFF_SLACK tolerances, on top of
    # the step's error (within one): an elastic head-on pair of equal masses swaps velocities.
    # Beyond the limit the round-off is past the tolerance for certain.
    run = run_scene(parse_scene(_head_on(0.9 * limit)), record=False)
    bound = (1 + ROUND_OFF_SLACK) * 1e-6
    assert abs(run.result.final.v[0, 1, 0] - 1.0) <= bound
    assert abs(run.result.final.v[0, 0, 0]) <= bound
    with pytest.raises(RunError, match="too stiff"):
        run_scene(parse_scene(_head_on(1.2 * limit)), record=False)
    scene = tmp_path / "stiff.toml"
    scene.write_text('dim = 1\n[contact]\nk = 1e26\n[[body]]\nname = "a"\nmass = 1.0\nradius = 0.1\nposition = 0.0\n'
                     'velocity = 1.0\n[[body]]\nname = "b"\nmass = 1.0\nradius = 0.1\nposition = 1.0\n')
    code, out, err = _main(["run", str(scene), "--no-record"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, "at most k = ")


_BASE = {
    "name": "s", "description": "d", "dim": 2, "dt": "auto", "integrator": "dem", "duration": 1.0, "tail": 0.1,
    "tol": 1e-2, "gravity": [0.0, -9.8], "rest": 0.1,
    "contact": {"model": "hertz", "k": 1e4, "mu": 0.1, "eps": 1e-6, "lever": "contact", "youngs_modulus": 1e7,
                "poisson_ratio": 0.3, "restitution": 0.9, "tangential": "spring", "tangential_stiffness_ratio": 0.3,
                "rolling_friction": 0.01},
    "material": [{"name": "steel", "density": 7800.0, "youngs_modulus": 2e8, "poisson_ratio": 0.3, "mu": 0.2,
                  "restitution": 0.8, "rolling_friction": 0.0}],
    "pair": [{"materials": ["steel", "steel"], "mu": 0.1, "restitution": 0.9, "rolling_friction": 0.0}],
    "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "inertia": "solid", "position": [0.0, 0.5],
              "velocity": [1.0, 0.0], "spin": 0.0, "material": "steel"},
             {"name": "b", "radius": 0.1, "position": [1.0, 0.5], "material": "steel"}],
    "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}],
}
# Values of the wrong type for most keys (a key that takes one of them is checked for the rest).
_WRONG = [[1.0], ["x"], [], {"a": 1}, {}, "x", True, False, [[1.0]], [True, 1.0]]


def _key_paths(table: dict, prefix: tuple = ()) -> list[tuple]:
    out = []
    for key, value in table.items():
        out.append(prefix + (key,))
        if isinstance(value, dict):
            out += _key_paths(value, prefix + (key,))
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for i, item in enumerate(value):
                out += [prefix + (key, i)] + _key_paths(item, prefix + (key, i))
    return out


def test_every_scene_key_of_the_wrong_type_is_a_scene_error() -> None:
    parse_scene(_BASE)
    for path in _key_paths(_BASE):
        for wrong in _WRONG:
            raw = copy.deepcopy(_BASE)
            table = raw
            for part in path[:-1]:
                table = table[part]
            table[path[-1]] = copy.deepcopy(wrong)
            try:
                parse_scene(raw)
            except SceneError as exc:
                assert "\n" not in str(exc)
                continue
            # Accepted: only where the value is of the key's own kind.
            ok = isinstance(wrong, str) and path[-1] in ("name", "description", "inertia") or \
                path[-1] in ("contact",) and wrong == {} or path[-1] in ("pair", "wall") and wrong == [] or \
                path[-1] == "spin" and wrong == [1.0]
            assert ok, (path, wrong)


def test_a_material_given_as_a_list_is_one_line(monkeypatch, capsys, tmp_path: Path) -> None:
    scene = tmp_path / "mat.toml"
    scene.write_text('[[material]]\nname = "steel"\ndensity = 7800.0\n[[body]]\nname = "a"\nmaterial = ["steel"]\n'
                     'radius = 0.1\nposition = [0.0, 0.0]\nvelocity = [1.0, 0.0]\n[[body]]\nname = "b"\nmass = 1.0\n'
                     'radius = 0.1\nposition = [1.0, 0.0]\n')
    code, out, err = _main(["run", str(scene), "--no-record"], monkeypatch, capsys, tmp_path)
    _one_line_error(code, out, err, "body.a.material: expected a material's name")


def test_a_run_with_no_duration_is_refused_at_its_step_limit_and_max_steps_moves_it(monkeypatch, capsys,
                                                                                    tmp_path) -> None:
    """A run with no duration has a smaller step limit than one with a duration (collide/limits.py):
    the cradle ends by itself in a few dozen steps; held to 20 (more than one contact takes) it is
    refused in one line naming the way out, and `--max-steps` is that limit for either kind of run."""
    from collide.limits import MAX_STEPS_DEFAULT, OPEN_RUN_STEPS, step_limit

    assert step_limit([None, 1.0], None) == OPEN_RUN_STEPS < MAX_STEPS_DEFAULT == step_limit([1.0, 2.0], None)
    assert step_limit([None], 7) == 7
    # A fine step is the user's to pay for: 50 contacts' worth of it, up to the limit with a duration.
    assert step_limit([None], None, 1e5) == 5_000_000 and step_limit([None], None, 1e7) == MAX_STEPS_DEFAULT
    # The seed updates every body at every step: its limit is also one of body-steps (a given limit wins).
    from collide.limits import SEED_BODY_STEPS

    assert step_limit([1.0], None, every_body=26) == SEED_BODY_STEPS // 26 < MAX_STEPS_DEFAULT
    assert step_limit([1.0], None, every_body=2) == MAX_STEPS_DEFAULT
    assert step_limit([None], None, every_body=10**6) == OPEN_RUN_STEPS and step_limit([1.0], 7, every_body=26) == 7
    from collide.scene import load_scene

    cradle = run_scene(load_scene("newtons-cradle"), record=False)
    steps = int(cradle.result.steps[0])
    assert 20 < steps < OPEN_RUN_STEPS
    code, out, err = _main(["run", "newtons-cradle", "--no-record", "--max-steps", "20"], monkeypatch, capsys,
                           tmp_path)
    _one_line_error(code, out, err, "had not ended after")
    assert "--set duration=" in err and "--max-steps" in err
    code, out, _ = _main(["run", "newtons-cradle", "--no-record", "--json", "--max-steps", str(steps)],
                         monkeypatch, capsys, tmp_path)
    assert code == 0 and f'"steps": {steps}' in out
    # With a duration the limit is said before the run (DEM: the steps are known).
    code, out, err = _main(["run", "bounce", "--integrator", "dem", "--no-record", "--max-steps", "100"], monkeypatch,
                           capsys, tmp_path)
    _one_line_error(code, out, err, "(limit 100)")


def test_a_measurement_the_integrator_cannot_reach_leaves_the_run_answered(monkeypatch, capsys, tmp_path) -> None:
    """The seed (first order) meets --tol 3e-4 on the cradle, but the tenth of it that would
    measure the error needs more steps per contact than it may take: the run is answered with the
    model's estimate and a warning saying so (it was refused after the whole run)."""
    args = ["run", "newtons-cradle", "--integrator", "seed", "--tol", "3e-4", "--set", "duration=0.1",
            "--no-record", "--json"]
    code, out, err = _main(args, monkeypatch, capsys, tmp_path)
    assert code == 0, err
    summary = json.loads(out)
    assert any("could not be measured" in w and "3e-05" in w for w in summary["warnings"]), summary["warnings"]
    assert summary["error_method"] == "model"
    final = {b["name"]: b["velocity"] for b in summary["bodies"]}
    assert abs(final["ball5"] - 1.0) < 0.01  # the last ball leaves with the first one's speed


def test_a_measurement_forecast_past_the_step_limit_is_not_started(measuring_runs) -> None:
    """The cradle's error is measured by a run at a tenth of its tolerance, which takes more
    steps than the cradle's own. With a step limit that leaves fewer than the forecast, the
    tighter run is not started (only to be refused at the limit, minutes later in a long run):
    the answer carries the model's estimate and says why; with room to spare it is measured."""
    from collide.scene import load_scene

    cradle = load_scene("newtons-cradle")
    measured = run_scene(cradle, record=False)
    assert measured.error_method == ["measured"] and measuring_runs
    steps = int(measured.result.steps[0])
    measuring_runs.clear()
    tight = run_scene(cradle, record=False, max_steps=steps + 1)
    assert measuring_runs == [] and tight.error_method == ["model"]
    assert any("would take about" in w and "left of the step limit" in w for w in tight.result.warnings)



def test_the_seed_is_held_to_its_body_steps(monkeypatch) -> None:
    """The seed's step limit counts every body it updates: with the body-step budget made small,
    the five-ball cradle is refused at that budget over five, naming it (here before it starts:
    one contact would take more steps than that)."""
    import collide.limits as limits
    from collide.scene import load_scene

    monkeypatch.setattr(limits, "OPEN_RUN_STEPS", 10)
    monkeypatch.setattr(limits, "SEED_BODY_STEPS", 5 * 40)
    scene = load_scene("newtons-cradle")
    with pytest.raises(RunError, match=r"\(limit 40\)"):
        run_scene(scene, integrator="seed", tol=3e-4, record=False, dt=None)
