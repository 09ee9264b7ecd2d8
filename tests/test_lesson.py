"""Perfectly inelastic contacts (restitution 0) and the lesson's numbers (viewer.lesson), without
a browser: the common velocity against (m1 v1 + m2 v2) / (m1 + m2), momentum to the run's
residual, the scene switches."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from collide.run import run_scene
from collide.scene import SceneError, load_scene, parse_scene
from viewer.drag import snapped
from viewer.lesson import common_velocity, lesson_csv, moment, with_dimensions, with_restitution
from viewer.params import for_viewing
from viewer.state import ViewRun


def _sticky_run(scene):
    return run_scene(for_viewing(with_restitution(scene, 0.0)), record=True)


@pytest.mark.parametrize("name", ["textbook-1d", "textbook-unequal", "demo-1d"])
def test_restitution_zero_ends_at_the_common_velocity(name):
    scene = with_dimensions(load_scene(name), 1)
    run = _sticky_run(scene)
    r = run.result
    m = r.model.mass[0]
    v0, v1 = r.initial.v[0], r.final.v[0]
    common = common_velocity(m, v0)
    u0 = float(np.max(np.abs(v0 - common)))  # the relative speed the dashpot takes away
    assert u0 > 0
    # Critically damped: the relative velocity decays as (1 - w t) e^(-w t) until the contact
    # lets go (round-off); the bodies leave together.
    np.testing.assert_allclose(v1, np.broadcast_to(common, v1.shape), rtol=0, atol=1e-9 * u0)
    p0, p1 = m @ v0, m @ v1
    residual = float(ViewRun(run).residuals["momentum"])
    scale = max(float(np.sum(m * np.abs(v0[:, 0]))), float(np.sum(m * np.abs(v1[:, 0]))))
    assert abs(float(p1[0] - p0[0])) <= (residual + 4 * np.finfo(float).eps) * scale
    assert residual < 1e-12
    # Energy: what is left is the centre of mass's; the rest went to the dashpot.
    kinetic = 0.5 * float(np.sum(m * v1[:, 0] ** 2))
    assert kinetic == pytest.approx(0.5 * float(m.sum()) * float(common[0]) ** 2, rel=1e-8)


def test_restitution_zero_head_on_in_2d():
    raw = {"dim": 2, "tol": 1e-3, "contact": {"k": 1500.0, "mu": 0.0, "restitution": 1.0},
           "body": [{"name": "a", "mass": 0.03, "radius": 0.03, "position": [0.0, 0.0], "velocity": [1.5, 0.0]},
                    {"name": "b", "mass": 0.05, "radius": 0.03, "position": [0.2, 0.0], "velocity": [-0.5, 0.0]}]}
    run = _sticky_run(parse_scene(raw, "head-on"))
    r = run.result
    common = common_velocity(r.model.mass[0], r.initial.v[0])
    np.testing.assert_allclose(r.final.v[0], np.broadcast_to(common, (2, 2)), rtol=0, atol=2e-9)


def test_restitution_zero_with_hertz_is_refused():
    raw = {"dim": 1, "contact": {"model": "hertz", "youngs_modulus": 1e7, "poisson_ratio": 0.3, "restitution": 0.0},
           "body": [{"name": "a", "mass": 0.03, "radius": 0.03, "position": 0.0, "velocity": 1.0},
                    {"name": "b", "mass": 0.03, "radius": 0.03, "position": 0.2, "velocity": 0.0}]}
    with pytest.raises(SceneError, match="linear spring only"):
        parse_scene(raw, "hertz-sticky")
    raw["contact"] = {"k": 1500.0, "restitution": 0.0}
    with pytest.raises(SceneError, match="give it a duration"):
        parse_scene(raw, "no-end")
    raw["duration"] = 0.5
    assert parse_scene(raw, "ends").contact.restitution == 0.0
    raw["contact"]["restitution"] = -0.1
    with pytest.raises(SceneError, match="restitution"):
        parse_scene(raw, "negative")


def test_elastic_scenes_keep_their_law():
    """A restitution above 0 maps to the same dashpot as before (zeta from -ln e)."""
    from collide.dem import damping_ratio

    e = np.array([0.9, 0.5, 0.05, 1.0])
    le = np.log(e)
    np.testing.assert_array_equal(damping_ratio(e, False), -le / np.sqrt(le**2 + np.pi**2))
    assert damping_ratio(np.array([0.0]), False)[0] == 1.0


def test_switch_to_a_line_and_back():
    bonus = load_scene("demo-bonus")
    line = with_dimensions(bonus, 1)
    assert line.dim == 1 and not line.has_spin
    assert [b.position for b in line.bodies] == [(b.position[0],) for b in bonus.bodies]
    assert [b.velocity for b in line.bodies] == [(b.velocity[0],) for b in bonus.bodies]
    assert [b.mass for b in line.bodies] == [b.mass for b in bonus.bodies]
    plane = with_dimensions(load_scene("textbook-1d"), 2)
    assert plane.dim == 2 and all(b.position[1] == 0.0 and b.velocity[1] == 0.0 for b in plane.bodies)
    # Dropping the offsets can put two balls on top of each other: refused, not run.
    raw = copy.deepcopy(bonus.source)
    raw["body"][1]["position"] = [0.0, 0.5]
    with pytest.raises(SceneError, match="overlap"):
        with_dimensions(parse_scene(raw, "stacked"), 1)


def test_lesson_numbers_are_the_runs():
    view = ViewRun(run_scene(for_viewing(load_scene("demo-bonus")), record=True))
    r = view.run.result
    before, after = moment(view, view.t0), moment(view, view.t1)
    m = r.model.mass[0]
    np.testing.assert_allclose(before.total_momentum, m @ r.initial.v[0], rtol=1e-14, atol=1e-17)
    np.testing.assert_allclose(after.total_momentum, m @ r.final.v[0], rtol=1e-12, atol=1e-17)
    rows = [line.split(",") for line in lesson_csv(view, 0.5 * (view.t0 + view.t1)).decode().splitlines()[2:]]
    table = {(q, b, c): [float(x) for x in rest] for q, b, c, *rest in rows}
    for k, a in enumerate("xy"):
        parts = np.sum([table[("momentum", name, a)] for name in view.names], axis=0)
        np.testing.assert_allclose(parts, table[("momentum", "total", a)], rtol=1e-14, atol=1e-17)
        assert table[("momentum", "total", a)][0] == before.total_momentum[k]
    held = [table[(q, n, "")][2] for q in ("kinetic", "rotational") for n in view.names]
    assert table[("energy", "total", "")][2] == pytest.approx(sum(held) + table[("elastic", "total", "")][2])


def test_snapped_rounds_to_the_step():
    np.testing.assert_allclose(snapped(np.array([0.01234, -0.00051]), 1e-3), [0.012, -0.001], atol=1e-15)
    assert str(snapped(np.array([-0.0004]), 1e-3)[0]) == "0.0"
