"""Rolling resistance (collide/engine/dem/rolling.py): where a rolling ball stops, against the closed
form."""

from __future__ import annotations

import pytest

from collide.run import run_scene
from collide.scene import parse_scene


def test_rolling_resistance_stops_a_rolling_ball_where_the_closed_form_says():
    """A solid ball rolling without slip under a torque mu_r r F_n decelerates at 5/7 mu_r g:
    it stops after v^2 / (2 a). Within 2 %: the contact's own compliance and the step."""
    g, mu_r, r, v0 = 9.81, 0.05, 0.02, 0.5
    raw = {"dim": 3, "integrator": "dem", "dt": 2e-5, "duration": 2.0, "gravity": [0.0, 0.0, -g],
           "contact": {"model": "hertz", "youngs_modulus": 1e7, "poisson_ratio": 0.3, "restitution": 0.3,
                       "mu": 0.8, "tangential": "spring", "rolling_friction": mu_r},
           "body": [{"name": "a", "radius": r, "mass": 0.1, "position": [0.0, 0.0, r],
                     "velocity": [v0, 0.0, 0.0], "spin": [0.0, v0 / r, 0.0]}],
           "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]}
    scene = parse_scene(raw)
    result = run_scene(scene, record=False).result
    a = 5.0 / 7.0 * mu_r * g
    assert result.final.s[0, 0, 0] == pytest.approx(v0**2 / (2 * a), rel=2e-2)
    assert abs(result.final.v[0, 0, 0]) < 1e-3 * v0
    assert result.dissipation[0, 2] == pytest.approx(0.5 * 0.1 * v0**2 * 1.4, rel=5e-2)
