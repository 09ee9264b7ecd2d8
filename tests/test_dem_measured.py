"""DEM runs outside the one-impact error model have their error measured (collide.measure), as
event runs do: a ball bouncing on under Hertz with a dashpot, against an independent run at
DEM's finest step."""

from __future__ import annotations

import pytest

from collide import dem
from collide.measure import outcome_distance
from collide.model import compile_scenes
from collide.run import run_scene
from collide.scene import load_scene

# The reference's own error: DEM's model gives 6e-5 at its finest step, and the model missed the
# bouncing ball by up to 7.9 times (tol 1e-3 against 1e-4): ten times it covers the reference.
REFERENCE_SLACK = 10.0
DEM = ["integrator='dem'"]  # (the event engine runs the bounce by itself: a sphere alone among walls)

BOUNCES = {
    "built-in": [],
    "lower, livelier": ["body.ball.position=[0.0,0.53]", "contact.restitution=0.9"],
    "stiffer, faster": ["material.rubber.youngs_modulus=5e7", "body.ball.velocity=[1.0,0.0]", "duration=1.5"],
}


def _reference(overrides: list[str]):
    scene = load_scene("bounce", [*DEM, *overrides])
    model, state = compile_scenes([scene])
    contact_time = float(dem.contact_time(model, state)[0][0])
    finest = contact_time / dem.MAX_STEPS_PER_CONTACT
    return run_scene(load_scene("bounce", [*DEM, *overrides, f"dt={finest}"]), record=False, max_steps=10**8)


@pytest.mark.parametrize("overrides", BOUNCES.values(), ids=BOUNCES.keys())
def test_bouncing_ball_error_is_measured_and_holds(overrides):
    scene = load_scene("bounce", [*DEM, *overrides])
    run = run_scene(scene, record=False)
    assert run.error_method == ["measured"]
    reference = _reference(overrides)
    off = outcome_distance(run.result, reference.result, scene)
    allowed = float(run.error_estimate[0]) + REFERENCE_SLACK * dem.TOL_FLOOR
    assert off <= allowed, f"off by {off:.3g}, reported {float(run.error_estimate[0]):.3g}"
    assert float(run.error_estimate[0]) <= float(run.tol[0]) or run.result.warnings


def test_given_dt_says_the_error_was_not_measured():
    run = run_scene(load_scene("bounce", [*DEM, "dt=2e-5"]), record=False)
    assert run.error_method == ["model"]
    assert any("the error was not measured (a given dt)" in w for w in run.result.warnings)


def test_tolerance_past_dem_reach_says_so():
    run = run_scene(load_scene("bounce", [*DEM, "tol=1e-4"]), record=False)
    assert run.error_method == ["model"]
    assert any("finer than the integrator reaches" in w for w in run.result.warnings)


def test_single_impact_keeps_the_model():
    """One short impact is what DEM's model was measured on: no second run."""
    scene = load_scene("bounce", [*DEM, "duration=0.5"])
    run = run_scene(scene, record=False)
    assert int(run.result.contacts.count[0]) == 1
    assert run.error_method == ["model"] and not run.result.warnings
