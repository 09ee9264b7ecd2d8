"""The DEM kernel's free flight (collide/engine/dem/flight.py): whether a body may meet a wall
again."""

from __future__ import annotations

import numpy as np

G = 9.81


def test_a_ball_rising_from_a_floor_under_gravity_may_meet_it_again() -> None:
    from collide.engine.dem import layout as dk
    from collide.engine.dem.flight import will_meet

    X, V = np.array([[0.0, 0.3, 0.0]]), np.array([[0.0, 1.0, 0.0]])
    bodies = np.zeros((1, int(dk.NB)))
    bodies[0, dk.B_R] = 0.1
    floor = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    assert will_meet(X, V, bodies, floor, np.array([0.0, -G, 0.0]), 1)
    assert not will_meet(X, V, bodies, floor, np.zeros(3), 1)
    assert not will_meet(X, V, bodies, floor, np.array([0.0, G, 0.0]), 1)
