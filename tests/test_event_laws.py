"""The normal laws at full order (collide/engine/event/impact.py) against independent
integrations: a ball bouncing on a floor with restitution (linear dashpot, and Hertz with its
damping) against scipy's DOP853 at rtol 1e-13, and Chung & Ooi's Hertz impacts (tests 1 and 2,
other materials, sizes and speeds too) against Hertz's closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from collide.dem import damping_ratio
from collide.engine.event import impact as im
from tests.engine.event.test_impact import hertz_closed_form


def reference_contact(params, v):
    """The same 1-DOF law integrated by DOP853 (rtol 1e-13) over time, the separation (delta back
    to 0) located by scipy's event detection: (separation speed, contact time). Written from
    docs/design.md section 9 and collide/engine/dem/damping.py's formula, not from the kernel."""
    hertz, k, estar, rstar, mstar, zeta, accel = params[:7]

    def rhs(_, y):
        delta, u = max(y[0], 0.0), y[1]
        if hertz:
            kn = 2.0 * estar * math.sqrt(rstar * delta)
            elastic = 4.0 / 3.0 * estar * math.sqrt(rstar * delta) * delta
        else:
            kn, elastic = k, k * delta
        force = elastic + 2.0 * zeta * math.sqrt(mstar * kn) * u
        return [u, accel - force / mstar]

    def apart(_, y):
        return y[0]

    apart.terminal, apart.direction = True, -1
    _, span = im.estimate(params, v)
    sol = solve_ivp(rhs, (0.0, 10.0 * span), [0.0, v], method="DOP853", rtol=1e-13, atol=1e-30,
                    events=apart, first_step=span * 1e-7, max_step=span / 50)
    assert sol.status == 1  # ended at the separation
    return -sol.y_events[0][0][1], sol.t_events[0][0]


def rubber_ball(hertz, e):
    """A ball of the built-in bounce's size and density on a rigid floor under gravity, Hertz at
    two hundred times its stiffness, or a linear spring: stiff enough that ten bounces stay
    impacts (at the built-in's stiffness gravity holds the ball on the floor from the eighth)."""
    r, rho, young, nu = 0.03, 1100.0, 1e9, 0.45
    mass = 4.0 / 3.0 * math.pi * r**3 * rho
    zeta = float(damping_ratio(np.array(e), hertz))
    return im.impact_params(hertz=hertz, mstar=mass, k=1e6, estar=young / (1 - nu * nu), rstar=r, zeta=zeta,
                            accel=9.81)


@pytest.mark.parametrize("hertz", [False, True])
@pytest.mark.parametrize("e", [0.6, 0.8])
def test_ten_bounces_match_an_independent_integration(hertz, e):
    """Dropped from 1 m, the rebound speeds of ten successive bounces at tol 1e-9 are within 1e-8
    (relative) of DOP853's chain of the same law (between bounces the flight is a parabola: the
    next impact speed is the last rebound speed)."""
    params = rubber_ball(hertz, e)
    ours = theirs = math.sqrt(2 * 9.81 * 1.0)
    for bounce in range(10):
        out = im.normal_impact(params, ours, 1e-9)
        assert out[im.O_OK] == 1.0
        ours = out[im.O_VOUT]
        theirs, contact_time = reference_contact(params, theirs)
        assert ours == pytest.approx(theirs, rel=1e-8), bounce
        assert out[im.O_TIME] == pytest.approx(contact_time, rel=1e-8), bounce
        assert out[im.O_STEPS] <= 80


# Chung & Ooi (2011): test 1, alumina spheres head-on; test 2, aluminium and magnesium alloy
# spheres on a rigid plane; and others: (E, nu, density, radius, speed, head-on).
CASES = [
    (3.8e11, 0.23, 4000.0, 0.0025, 10.0, True),
    (7.0e10, 0.33, 2699.0, 0.1, 0.2, False),
    (4.0e10, 0.35, 1800.0, 0.1, 0.2, False),
    (1e6, 0.45, 1100.0, 0.03, 1e-3, False),
    (1e12, 0.2, 8000.0, 0.001, 100.0, True),
    (5e9, 0.35, 1740.0, 0.028575, 2.0, True),
]


@pytest.mark.parametrize("case", CASES)
def test_chung_ooi_hertz_impacts_at_tol_1e_8(case):
    """Largest overlap, largest force and contact time within 1e-7 of Hertz's closed forms, in at
    most 50 steps per contact; the speed out equals the speed in (no damping)."""
    young, nu, rho, r, v, head_on = case
    mass = 4.0 / 3.0 * math.pi * r**3 * rho
    if head_on:  # two equal spheres: the relative motion, reduced mass and radius
        mstar, rstar, estar, v_rel = mass / 2, r / 2, young / (2 * (1 - nu * nu)), 2 * v
    else:
        mstar, rstar, estar, v_rel = mass, r, young / (1 - nu * nu), v
    out = im.normal_impact(im.impact_params(hertz=True, mstar=mstar, estar=estar, rstar=rstar), v_rel, 1e-8)
    assert out[im.O_OK] == 1.0
    dmax, fmax, tc = hertz_closed_form(estar, rstar, mstar, v_rel)
    assert out[im.O_DMAX] == pytest.approx(dmax, rel=1e-7)
    assert out[im.O_FMAX] == pytest.approx(fmax, rel=1e-7)
    assert out[im.O_TIME] == pytest.approx(tc, rel=1e-7)
    assert out[im.O_VOUT] == pytest.approx(v_rel, rel=1e-7)
    assert out[im.O_STEPS] <= 50


@pytest.mark.parametrize("hertz, e, radius, density, drop", [
    (True, 0.8, 0.03, 1100.0, 1.0), (True, 0.6, 0.01, 7800.0, 0.3), (True, 0.95, 0.1, 900.0, 2.0),
    (False, 0.6, 0.03, 1100.0, 1.0), (False, 0.7, 0.05, 2500.0, 0.5), (False, 0.9, 0.005, 7800.0, 1.5)])
def test_ten_bounces_as_collide_run_gives_them(hertz, e, radius, density, drop):
    """A ball thrown down onto a floor, run as `collide run` runs it at --tol 1e-9 (its error measured):
    the rebound speeds of ten successive bounces within 1e-8 (relative) of DOP853's chain of the
    same 1-DOF law at rtol 1e-13, the flights between parabolas; the measured error within tol."""
    from collide.engine import layout
    from collide.run import run_scene
    from collide.scene import parse_scene

    g = 9.81
    mass = 4.0 / 3.0 * math.pi * radius**3 * density
    young, nu = 1e9, 0.3
    zeta = float(damping_ratio(np.array(e), hertz))
    # A linear spring with the Hertz contact's duration at the first impact.
    _, hertz_time = im.estimate(im.impact_params(hertz=True, mstar=mass, estar=young / (1 - nu * nu), rstar=radius),
                                math.sqrt(1.0 + 2 * g * drop))
    k = mass * (math.pi / hertz_time) ** 2
    params = im.impact_params(hertz=hertz, mstar=mass, k=k, estar=young / (1 - nu * nu), rstar=radius, zeta=zeta,
                              accel=g)
    # Thrown down at 1 m/s (--tol is relative to the fastest initial speed: a ball let go at rest has none).
    v = math.sqrt(1.0 + 2 * g * drop)
    expected, duration = [], (v - 1.0) / g
    for bounce in range(10):
        v, contact_time = reference_contact(params, v)
        expected.append(v)
        duration += contact_time + (2 * v / g if bounce < 9 else 0.5 * v / g)
    contact = ({"model": "hertz", "youngs_modulus": young, "poisson_ratio": nu} if hertz else {"k": k})
    raw = {"dim": 2, "duration": duration, "gravity": [0.0, -g], "contact": {**contact, "restitution": e},
           "body": [{"name": "ball", "radius": radius, "mass": mass, "position": [0.0, radius + drop],
                     "velocity": [0.0, -1.0]}],
           "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}
    run = run_scene(parse_scene(raw), tol=1e-9)
    assert run.result.engine == "event" and run.error_method[0] == "measured"
    assert float(run.error_estimate[0]) <= 1e-9
    traj = run.result.trajectory
    knots = traj.knots
    ends = traj.intervals[:, layout.V_END]
    assert len(ends) == 10
    got = [knots[(knots[:, layout.K_T] == end) & (knots[:, layout.K_FREE] == 1.0)][0, layout.K_V + 1] for end in ends]
    assert np.abs(np.array(got) / np.array(expected) - 1.0).max() <= 1e-8



def test_a_measuring_run_that_becomes_the_answer_brings_its_trajectory(monkeypatch):
    """The measurement's tighter runs record nothing (it compares final states); where one of them
    becomes the answer (the run missed --tol), the answer still carries that run's trajectory: its
    last knot is the answer's final state."""
    import collide.measure as measure
    from collide.engine import layout
    from collide.run import run_scene
    from collide.scene import parse_scene

    raw = {"dim": 2, "duration": 0.8, "gravity": [0.0, -9.81], "contact": {"k": 1e5, "restitution": 0.7},
           "body": [{"name": "ball", "radius": 0.02, "mass": 0.05, "position": [0.0, 0.3], "velocity": [0.2, 0.0]}],
           "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}
    first = run_scene(parse_scene(raw), tol=1e-6)
    assert first.result.trajectory is not None
    calls = []
    real = measure.outcome_distance

    def missed_once(a, b, scene):  # the first comparison says the run missed --tol
        calls.append(1)
        return 1e-3 if len(calls) == 1 else real(a, b, scene)

    monkeypatch.setattr(measure, "outcome_distance", missed_once)
    run = run_scene(parse_scene(raw), tol=1e-6)
    assert len(calls) >= 2 and run.error_method[0] == "measured"
    assert not np.array_equal(run.result.final.v, first.result.final.v)  # the tighter run's answer
    last = run.result.trajectory.knots[-1]
    assert np.array_equal(last[layout.K_V:layout.K_V + 2], run.result.final.v[0, 0])
    assert np.array_equal(last[layout.K_S:layout.K_S + 2], run.result.final.s[0, 0])
