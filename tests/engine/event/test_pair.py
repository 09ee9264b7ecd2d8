"""Two spheres and no walls under Hertz with its damping, no friction (collide/engine/event/pair.py),
run as `collide run` runs them: head-on, in any direction, with unequal materials, radii and
masses, a common sideways drift and gravity, against the closed forms (undamped: the largest
overlap and force and the contact time) and an independent DOP853 integration of the relative
1-DOF law (the rebound); momentum holds exactly. Randomised, seeded."""

from __future__ import annotations

import numpy as np
import pytest

from collide import chung_ooi as co
from collide.dem import damping_ratio
from collide.engine.event import impact as im
from collide.run import run_scene
from collide.scene import parse_scene
from tests.test_event_laws import reference_contact


def _case(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    mats = [{"name": f"m{i}", "youngs_modulus": float(10 ** rng.uniform(7, 11)),
             "poisson_ratio": float(rng.uniform(0.2, 0.45)), "density": float(rng.uniform(1000, 8000))}
            for i in range(2)]
    radii = 10 ** rng.uniform(-3, -1, 2)
    speed = float(10 ** rng.uniform(-2, 1))
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    drift = rng.normal(size=3) * speed  # common to both: the centre of mass's motion, not the contact's
    gap = 1e-3 * radii.min()
    e = float(rng.choice([1.0, 0.9, 0.5, 0.2]))
    return {"dim": 3, "tol": 1e-8, "gravity": [0.0, -9.81, 0.0] if seed % 2 else None,
            "contact": {"model": "hertz", "restitution": e}, "material": mats,
            "body": [{"name": "a", "material": "m0", "radius": float(radii[0]), "position": [0.0, 0.0, 0.0],
                      "velocity": (drift + speed * n).tolist()},
                     {"name": "b", "material": "m1", "radius": float(radii[1]),
                      "position": ((radii.sum() + gap) * n).tolist(), "velocity": drift.tolist()}]}


@pytest.mark.parametrize("seed", range(8))
def test_head_on_pairs_match_closed_forms_and_dop853(seed):
    raw = _case(seed)
    if raw["gravity"] is None:
        del raw["gravity"]
    run = run_scene(parse_scene(raw), tol=1e-8, record=False)
    res = run.result
    assert res.engine == "event" and "two spheres and no walls" in res.engine_reason
    a, b = raw["body"]
    mats = [co.Material(m["name"], m["youngs_modulus"], m["poisson_ratio"], m["density"]) for m in raw["material"]]
    m = np.array([co.sphere_mass(mats[0], a["radius"]), co.sphere_mass(mats[1], b["radius"])])
    mstar, rstar = m[0] * m[1] / m.sum(), a["radius"] * b["radius"] / (a["radius"] + b["radius"])
    estar = co.effective_modulus(mats[0], mats[1])
    v0, v1 = np.array(a["velocity"]), np.array(b["velocity"])
    n = np.array(b["position"]) / np.linalg.norm(b["position"])
    v_in = float((v0 - v1) @ n)
    e = raw["contact"]["restitution"]
    zeta = float(damping_ratio(np.array(e), True))
    params = im.impact_params(hertz=True, mstar=mstar, estar=estar, rstar=rstar, zeta=zeta)
    v_out, t_c = reference_contact(params, v_in)
    assert res.contacts.duration[0] == pytest.approx(t_c, rel=1e-7)
    if e == 1.0:  # Hertz's closed forms
        exp = co.hertz_impact(mstar, rstar, estar, v_in)
        assert res.contacts.max_overlap[0] == pytest.approx(exp["delta_max"], rel=1e-7)
        assert res.contacts.max_normal_force[0] == pytest.approx(exp["f_max"], rel=1e-7)
        assert res.contacts.duration[0] == pytest.approx(exp["contact_time"], rel=1e-7)
    # Momentum (gravity moves both alike) and the relative rebound along the line of centres.
    g = np.array(raw.get("gravity", [0.0, 0.0, 0.0]))
    t = float(res.final.t[0])
    fv = res.final.v[0]
    momentum = m[0] * v0 + m[1] * v1 + m.sum() * g * t
    assert fv.T @ m == pytest.approx(momentum, rel=1e-12, abs=1e-12 * abs(v_in) * m.sum())
    rebound = float((fv[1] - fv[0]) @ n)
    assert rebound == pytest.approx(v_out, rel=1e-7, abs=1e-9 * v_in)
    across = (fv[1] - fv[0]) - rebound * n
    assert np.abs(across).max() <= 1e-12 * v_in
    assert int(res.steps[0]) <= 50


def test_status_codes_of_the_event_kernels_are_distinct():
    """`collide.alone._check` tells a run's stop by its status alone: a code shared by two kernels
    would name the wrong cause (a sphere held on its wall read as two spheres not head-on)."""
    from collide.engine import layout
    from collide.engine.event import alone, pair

    codes = [layout.OK, layout.NONFINITE, layout.ENERGY, layout.STALL, layout.MAXSTEPS, layout.SINGULAR,
             alone.ALONE_WALLS, alone.ALONE_FAILED, alone.ALONE_HELD, alone.ALONE_PLANE, alone.ALONE_CHATTER,
             pair.PAIR_OBLIQUE, pair.PAIR_FAILED]
    assert len(set(codes)) == len(codes)
