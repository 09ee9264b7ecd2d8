"""Windows (collide/engine/event/windows.py): the stretches where nothing touches, crossed in closed
form (`jump`), and the run's end when what still approaches is the step's error."""

from __future__ import annotations

import pytest

from collide.run import run_scene
from collide.scene import load_scene, parse_scene


def test_free_flight_jumps_count_the_stretches_where_nothing_touches() -> None:
    """`jumps` counts the contact-free stretches crossed in closed form, not the engine's windows:
    two spheres meeting once cross two (the approach and the tail after they part); a ball between
    two walls 1 m apart at 2 m/s, from the middle, meets them at 0.225 s and 0.675 s (plus a
    contact's duration each) within 1 s, and crosses one stretch more than its contacts."""
    r = run_scene(load_scene("demo-1d"), record=False, measure=False).result
    assert int(r.contacts.count[0]) == 1
    assert int(r.jumps[0]) == 2
    raw = {"name": "box", "dim": 2, "duration": 1.0, "contact": {"k": 1e5},
           "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [0.5, 0.0], "velocity": [2.0, 0.0]}],
           "wall": [{"point": [0.0, 0.0], "normal": [1.0, 0.0]}, {"point": [1.0, 0.0], "normal": [-1.0, 0.0]}]}
    r = run_scene(parse_scene(raw), record=False, measure=False).result
    assert int(r.contacts.count[0]) == 2
    assert int(r.jumps[0]) == 3


@pytest.mark.parametrize("k", [1e6, 5.5e6])
def test_a_cradle_ends_when_what_still_approaches_is_the_steps_error(k: float) -> None:
    """A cradle of touching balls leaves its first four at rest to the step's error (1e-8 m/s at
    tol 1e-7, shrinking with it). Those velocities closed gaps 11 hours (k = 1e6) and a month
    (k = 5.5e6) later, and the run went on to meet them. It ends after the wave, as at a tighter
    tolerance, with the last ball at 1 m/s."""
    scene = load_scene("newtons-cradle", [f"contact.k={k}"])
    r = run_scene(scene, record=False).result
    tight = run_scene(scene, tol=1e-10, record=False).result
    assert float(r.final.t[0]) < 1.0
    assert float(r.final.t[0]) == pytest.approx(float(tight.final.t[0]), rel=1e-3)
    assert abs(float(r.final.v[0, -1, 0]) - 1.0) < 100 * scene.tol
