"""Contact geometry of an island (collide/engine/event/contact.py): the hold rate against a finite
difference of the slip."""

from __future__ import annotations

import numpy as np
import pytest

from collide.engine import layout
from collide.engine.event import contact
from tests.engine.event.tables import pressed_island


def slips(X, C, CI, WP, nc, seed, spin=1, planar=False):
    contact.geometry(X, C, CI, nc, WP, seed, layout.YES)
    return np.array([contact.slip(X, C, CI, c, layout.X_V, layout.X_W, spin, planar) for c in range(nc)])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("wall", [False, True])
def test_hold_rate_is_the_slip_rate_without_friction(dim, seed, wall):
    """G (`contact.slip_rate` under springs and gravity) is the tangential part of the slip's
    rate of change along the frictionless motion: checked by a central difference."""
    X, C, CI, WP, nc, grav = pressed_island(dim, seed, wall)
    seed = np.int64(seed)
    contact.geometry(X, C, CI, nc, WP, seed, layout.YES)
    contact.springs(X, C, CI, 2, nc, grav)
    assert (C[:nc, layout.C_DELTA] > 0).all()  # really pressed: the springs act
    planar = dim == 2  # the plane's own arithmetic (its zero parts left out): the same numbers
    rates = [np.array([contact.slip_rate(X, C, CI, c, layout.X_V, layout.X_W, layout.X_A, layout.X_L, np.int64(1), seed,
                                         np.int64(1), flat) for c in range(nc)]) for flat in {planar, False}]
    assert all(np.array_equal(r, rates[0]) for r in rates)
    rate = rates[0]
    acc = X[:, layout.X_A:layout.X_A + 3].copy()
    h = 1e-6
    ends = []
    for sign in (1.0, -1.0):
        Y = X.copy()
        Y[:, layout.X_S:layout.X_S + 3] += sign * h * X[:, layout.X_V:layout.X_V + 3] + 0.5 * h * h * acc
        Y[:, layout.X_V:layout.X_V + 3] += sign * h * acc
        ends.append(slips(Y, C.copy(), CI, WP, nc, seed, planar=planar))
        assert np.array_equal(ends[-1], slips(Y, C.copy(), CI, WP, nc, seed))
    numeric = (ends[0] - ends[1]) / (2 * h)
    contact.geometry(X, C, CI, nc, WP, seed, layout.YES)
    n = C[:nc, layout.C_N:layout.C_N + 3]
    tangential = numeric - np.sum(numeric * n, axis=1, keepdims=True) * n
    # Truncation h^2 |third derivative| and rounding 1e-16 |slip| / h: both below 1e-7 relative.
    assert rate == pytest.approx(tangential, rel=1e-7, abs=1e-7 * np.abs(tangential).max())
    assert np.abs(rate).max() > 1.0  # not vacuous
