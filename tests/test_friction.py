"""The friction modes' kinematics: the hold rate against a finite difference of the slip, its
slope in the impulse, and the order the compositions keep with friction."""

from __future__ import annotations

import numpy as np
import pytest

from collide import friction as fr
from collide import physics as ph
from collide.accuracy import outcome, speed_scale
from collide.integrators import geometry
from collide.model import compile_scenes
from collide.run import run_scene
from collide.scene import load_scene, parse_scene
from collide.stepper import max_frequency


def pressed_pair(dim: int, lever: str, wall: bool):
    """Two spinning spheres pressed together (and onto a wall), every contact forced to stick,
    with a 3D friction direction off the slip's so that it turns with the normal."""
    def vec(*x: float) -> list[float]:
        return list(x[:dim])

    spins = ([3.0], [-5.0]) if dim == 2 else ([1.0, -2.0, 3.0], [0.5, 2.0, -1.0])
    raw = {"dim": dim, "contact": {"k": 1500.0, "mu": 0.5, "lever": lever},
           "body": [{"name": "a", "mass": 0.03, "radius": 0.03, "position": vec(0.0, 0.5, 0.0),
                     "velocity": vec(1.0, 0.3, -0.2), "spin": spins[0]},
                    {"name": "b", "mass": 0.02, "radius": 0.025, "position": vec(0.5, 0.5, 0.0),
                     "velocity": vec(-1.0, 0.5, 0.4), "spin": spins[1]}]}
    if wall:
        raw["wall"] = [{"point": vec(0.0, -1.0, 0.0), "normal": vec(0.0, 1.0, 0.0)}]
    model, state = compile_scenes([parse_scene(raw)])
    state.s[0, 0] = np.array([0.0, 0.031, 0.01])[:dim]  # overlapping each other (and the wall)
    state.s[0, 1] = np.array([0.04, 0.0, 0.0])[:dim]
    if wall:
        model.wall_point[0] = np.array([0.0, 0.0025, 0.0])[:dim]
    c = ph.contact_geometry(model, state.s)
    engaged = ph.Engaged((c.overlap > 0).astype(float), (c.wall_overlap > 0).astype(float))
    g = geometry(model, state.s, engaged)
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    rows = fr.contact_rows(model, g.c, g.fn, g.fw)
    frame, _ = fr.decide_modes(model, rows, state, acc, engaged, np.array([2.0]))
    modes = frame.modes
    live = np.concatenate((engaged.pair, engaged.wall.reshape(1, -1)), axis=1) > 0
    modes.mode[:] = np.where(live, fr.STICK, fr.BAND)
    if dim == 3:
        modes.entry = modes.entry + 0.3 * np.array([0.0, 0.0, 1.0])
    return model, state, engaged, modes, live[0]


def along(model, s, vel, engaged, modes):
    g = geometry(model, s, engaged)
    frame = fr.geometry_frame(model, g.c, g.fn, g.fw, modes)
    return np.add.reduce(fr.slip(model, frame.rows, vel) * frame.unit, -1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("lever", ["seed", "contact"])
@pytest.mark.parametrize("wall", [False, True])
def test_hold_rate_is_the_slip_rate_without_friction(dim, lever, wall):
    model, state, engaged, modes, live = pressed_pair(dim, lever, wall)
    g = geometry(model, state.s, engaged)
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    frame = fr.geometry_frame(model, g.c, g.fn, g.fw, modes)
    vel = np.concatenate((state.v.reshape(1, -1), state.w.reshape(1, -1)), axis=1)
    rate, slope = fr.hold_rate(model, frame, vel, acc)
    # Central difference along the frictionless motion (spins do not change without friction).
    h = 1e-6
    gen_acc = np.concatenate((acc.reshape(1, -1), np.zeros((1, state.w[0].size))), axis=1)
    ahead = along(model, state.s + h * state.v + 0.5 * h * h * acc, vel + h * gen_acc, engaged, modes)
    behind = along(model, state.s - h * state.v + 0.5 * h * h * acc, vel - h * gen_acc, engaged, modes)
    numeric = (ahead - behind) / (2 * h)
    # Truncation h^2 |third derivative| and rounding 1e-16 |slip| / h: both below 1e-7 relative.
    assert rate[0, live] == pytest.approx(numeric[0, live], rel=1e-7, abs=1e-7 * np.abs(numeric).max())
    # G is affine in the contact's own impulse: its slope from a finite impulse is exact.
    for contact in np.nonzero(live)[0]:
        lam = np.zeros(rate.shape)
        lam[0, contact] = 1e-4
        coords = (lam[..., None] * frame.unit).reshape(1, 1, -1)
        moved = vel - model.inv_mass_gen * (coords @ frame.rows.impulse_rows)[:, 0]
        finite = (fr.hold_rate(model, frame, moved, acc)[0][0, contact] - rate[0, contact]) / 1e-4
        assert slope[0, contact] == pytest.approx(finite, rel=1e-8, abs=1e-6)


def test_friction_keeps_sixth_order():
    """The bonus demo slides, sticks on the band's edge, leaves it and slides again: kahan6 keeps
    its order through all of it, because a stuck contact is held symmetrically."""
    scene = load_scene("demo-bonus")
    model, _ = compile_scenes([scene])
    omega = float(max_frequency(model)[0])
    reference = outcome(run_scene(scene, dt=0.01 / omega, record=False).result)
    errors = [np.abs(outcome(run_scene(scene, dt=x / omega, record=False).result) - reference).max()
              / speed_scale(scene) for x in (0.4, 0.2)]
    order = np.log2(errors[0] / errors[1])
    assert errors[1] < 1e-8
    assert order > 5.0


def tilted_bonus(**changes) -> dict:
    """The bonus demo in 3D with the first ball thrown and both spinning out of the plane."""
    raw = {"name": "tilted", "dim": 3, "contact": {"k": 1500.0, "mu": 0.5, "lever": "seed"},
           "body": [{"name": "ball1", "mass": 0.0254, "radius": 0.03021, "position": [0.0, 0.01, 0.0],
                     "velocity": [1.0, 0.0, 0.3], "spin": [2.0, -1.0, 3.0]},
                    {"name": "ball2", "mass": 0.0254, "radius": 0.03021, "position": [0.5, 0.0, 0.0],
                     "velocity": [-2.0, 0.0, 0.0], "spin": [-1.0, 4.0, -5.0]}]}
    raw.update(changes)
    return raw


def test_error_regime_knows_when_friction_leaves_the_plane():
    from collide.run import error_regime

    assert error_regime(load_scene("demo-bonus")) == "friction"
    assert error_regime(load_scene("demo-2d-moving")) == "smooth"
    flat = tilted_bonus()
    flat["body"][0].update(velocity=[1.0, 0.0, 0.0], spin=[0.0, 0.0, 3.0])
    flat["body"][1].update(spin=[0.0, 0.0, -5.0])
    assert error_regime(parse_scene(flat)) == "friction"
    assert error_regime(parse_scene(tilted_bonus())) == "friction-3d"


def test_friction_out_of_the_plane_meets_its_first_order_estimate():
    """The estimate is honest out of the plane (first order), and a tol that would take minutes
    is refused with the tol that is reachable."""
    from collide.stepper import RunError

    scene = parse_scene(tilted_bonus())
    with pytest.raises(RunError, match="first order"):
        run_scene(scene, tol=1e-6, record=False)
    model, _ = compile_scenes([scene])
    omega = float(max_frequency(model)[0])
    reference = outcome(run_scene(scene, dt=0.005 / omega, record=False).result)
    run = run_scene(scene, tol=1e-3, record=False)
    error = np.abs(outcome(run.result) - reference).max() / speed_scale(scene)
    assert run.error_estimate[0] == pytest.approx(1e-3)
    assert error <= 1e-3


@pytest.mark.parametrize("scalar", [True, False])
def test_stiff_friction_at_a_tight_tolerance_does_not_stall(monkeypatch, scalar):
    """At k = 1e12 N/m a stick-to-slide change came due closer than the clock resolves at
    t = 0.147 s (2.8e-17 s): the step to it did not move the time, and the run stalled. Such an
    event is now taken as passed (by under 1e-15 s)."""
    from collide import integrators

    monkeypatch.setattr(integrators, "SCALAR_PAIRS", scalar)
    run = run_scene(load_scene("demo-bonus", ["contact.k=1e12"]), tol=1e-9, record=False)
    assert int(run.result.steps[0]) < 60
    reference = run_scene(load_scene("demo-bonus", ["contact.k=1e12"]), tol=1e-11, record=False)
    scene = load_scene("demo-bonus")
    assert np.abs(outcome(run.result) - outcome(reference.result)).max() / speed_scale(scene) < 1e-8
