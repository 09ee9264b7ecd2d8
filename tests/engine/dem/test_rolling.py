"""Rolling resistance (collide/engine/dem/rolling.py): where a rolling ball stops, against the closed
form."""

from __future__ import annotations

import pytest

from collide.run import run_scene
from collide.scene import parse_scene
from tests.engine.event.test_alone import _rolling


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


def test_dem_converges_to_the_event_engines_rolling_and_held_as_its_step_halves():
    """A ball dropped 1 mm with backspin that bounces, slides, rolls and stops (`_rolling`). DEM's
    rolling resistance (the cap, below it a viscous torque stopping the spin in ROLL_STEPS
    steps) tends to the event engine's rolling and held modes (the same cap and direction,
    `rolling_cap` and `rolling_torque`, at the vanishing step): where the thrown ball ends up
    differs from the event engine's answer at tol 1e-8 by an error that halves with the step
    (first order: each halving's ratio between 1.8 and 2.2; measured 2.01, 2.00) and is 2.3e-4 of
    the distance at 1 us (within 5e-4)."""
    event = run_scene(parse_scene(_rolling(tol=1e-8)), record=False).result
    assert event.engine == "event", event.engine_reason
    assert "between rolling and held located" in event.engine_reason
    x_event = float(event.final.s[0, 0, 0])
    assert float(event.final.w[0].ravel()[-1]) == 0.0  # held at the end
    errors = []
    for dt in (4e-6, 2e-6, 1e-6):
        dem = run_scene(parse_scene(_rolling(integrator="dem", dt=dt)), record=False).result
        errors.append(abs(float(dem.final.s[0, 0, 0]) - x_event))
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    assert all(1.8 < q < 2.2 for q in ratios), (errors, ratios)
    assert errors[-1] < 5e-4 * abs(x_event)
