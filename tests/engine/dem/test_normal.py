"""The normal laws (collide/engine/dem/normal.py): a Hertz impact against its closed form."""

from __future__ import annotations

import pytest

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import parse_scene
from tests.dem_scenes import GLASS, hertz_closed_form


@pytest.mark.parametrize("wall", [False, True])
def test_hertz_impact_matches_closed_form(wall):
    """delta_max, F_max and contact time within 1 % (Chung & Ooi tests 1 and 2); at ~4000 steps
    per contact the step adds under 0.1 %."""
    r, m, v = 0.01, 0.011728, 10.0
    bodies = [{"name": "a", "radius": r, "mass": m, "position": [0.0, 0.0, r + (0.0 if wall else 0.0)],
               "velocity": [0.0, 0.0, -v]}]
    if wall:
        walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
        bodies[0]["position"] = [0.0, 0.0, r * 1.0001]
        m_star, r_star, e_star, speed = m, r, GLASS["youngs_modulus"] / (1 - 0.2**2), v
    else:
        walls = []
        bodies[0]["position"] = [0.0, 0.0, 0.0]
        bodies[0]["velocity"] = [v, 0.0, 0.0]
        bodies.append({"name": "b", "radius": r, "mass": m, "position": [2.0001 * r, 0.0, 0.0],
                       "velocity": [-v, 0.0, 0.0]})
        m_star, r_star, e_star, speed = m / 2, r / 2, GLASS["youngs_modulus"] / (2 * (1 - 0.2**2)), 2 * v
    delta, force, time = hertz_closed_form(m_star, r_star, e_star, speed)
    raw = {"dim": 3, "integrator": "dem", "dt": time / 4000, "contact": {"model": "hertz", **GLASS},
           "body": bodies, "wall": walls}
    result = run_scene(parse_scene(raw), record=False).result
    assert result.contacts.max_overlap[0] == pytest.approx(delta, rel=1e-3)
    assert result.contacts.max_normal_force[0] == pytest.approx(force, rel=1e-3)
    assert result.contacts.duration[0] == pytest.approx(time, rel=1e-3)
    assert dg.residuals(result).energy[0] < 1e-6  # elastic: nothing is lost but round-off and O(dt^2)
