"""Free flight (collide/engine/flight.py): a body's turn is the rotation about its spin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from collide.engine import flight


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis / np.linalg.norm(axis)])


@pytest.mark.parametrize("half", [1e-9, 1e-4, 0.00316, 0.00317, 0.0999, 0.1001, 0.7])
def test_turn_is_the_rotation_about_the_spin(half):
    """flight.turn takes small turns by series (to x^4 below a half angle of sqrt(1e-5), to x^8
    below 0.1) and larger ones by sin and cos: on either side of each switch, and from an
    arbitrary start, it is the rotation by |w| tau about w (a unit quaternion product) to
    round-off."""
    w = np.array([3.0, -4.0, 12.0])  # |w| = 13
    tau = 2.0 * half / 13.0
    start = _axis_angle(np.array([1.0, 2.0, -0.5]), 0.8)
    q = start.copy()
    flight.turn(q, w[0], w[1], w[2], tau, False)
    r = _axis_angle(w, 13.0 * tau)
    expected = np.array([r[0] * start[0] - r[1:] @ start[1:],
                         *(r[0] * start[1:] + start[0] * r[1:] + np.cross(r[1:], start[1:]))])
    assert np.abs(q - expected).max() < 4e-16
    assert abs(np.linalg.norm(q) - 1.0) < 4e-16


def test_many_small_turns_compose_to_one():
    """A thousand DEM-sized turns (series) about one axis make the one turn (sin and cos)."""
    w = np.array([0.3, 50.0, -7.0])
    many, once = _axis_angle(np.array([0.0, 0.0, 1.0]), 0.3), _axis_angle(np.array([0.0, 0.0, 1.0]), 0.3)
    for _ in range(1000):
        flight.turn(many, w[0], w[1], w[2], 1e-5, False)
    flight.turn(once, w[0], w[1], w[2], 1e-2, False)
    assert np.abs(many - once).max() < 1e-13
