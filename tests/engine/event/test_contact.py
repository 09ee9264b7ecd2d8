"""Contact geometry of an island (collide/engine/event/contact.py): the hold rate against a finite
difference of the slip; a damped Hertz contact's pressing value's rate against one of the value."""

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


def _damped_hertz(dim: int, wall: bool, squeeze: float):
    """`pressed_island` under Hertz with its dashpot (e = 0.4): the pair's overlap `squeeze`
    times its tables' (the wall's about so), so an end's small overlaps are seen too."""
    from collide.engine.dem.damping import dashpot
    from collide.model import damping_ratio

    X, C, CI, WP, nc, grav = pressed_island(dim, 0, wall)
    zeta = float(damping_ratio(np.array(0.4), True))
    for c in range(nc):
        C[c, layout.C_ESTAR], C[c, layout.C_ZETA] = 1e7, zeta
        C[c, layout.C_RSTAR] = 0.0136 if c == 0 else 0.03
        C[c, layout.C_MSTAR] = 0.012 if c == 0 else 0.03
        C[c, layout.C_K] = 1e6  # a bound on the stiffness, as `collide.model.hertz_bound` sets it
        C[c, layout.C_GAMMA] = dashpot(zeta, C[c, layout.C_MSTAR], C[c, layout.C_K])
    contact.geometry(X, C, CI, nc, WP, np.int64(0), layout.YES)
    C[0, layout.C_REACH] -= (1.0 - squeeze) * C[0, layout.C_DELTA]
    if wall:
        WP[0, 1] -= (1.0 - squeeze) * C[1, layout.C_DELTA] * 0.9
    return X, C, CI, WP, nc, grav


def _pressing(X, C, CI, WP, nc, grav):
    """Each contact's `contact.press` (value, rate) at X, the accelerations of the springs, gravity and
    the dashpots (no friction) in X_T; and those accelerations."""
    contact.geometry(X, C, CI, nc, WP, np.int64(0), layout.YES)
    contact.springs(X, C, CI, 2, nc, grav)
    X[:, layout.X_F:layout.X_F + 3] = 0.0
    contact.dashpots(X, C, CI, nc, layout.X_V, layout.X_F)
    X[:, layout.X_T:layout.X_T + 3] = X[:, layout.X_A:layout.X_A + 3] + X[:, layout.X_F:layout.X_F + 3]
    return np.array([contact.press(X, C, CI, c, layout.X_T) for c in range(nc)]), X[:, layout.X_T:layout.X_T + 3]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("wall", [False, True])
@pytest.mark.parametrize("squeeze", [1.0, 1e-3])
def test_the_pressing_value_of_a_damped_hertz_contact_has_the_rate_it_reports(dim, wall, squeeze):
    """`contact.press`: a damped Hertz contact's F_n = F_el + gamma(delta) delta' over gamma(delta)
    (in units of the dashpot at the contact's bound), its rate along the motion under springs,
    gravity and the dashpots checked by a central difference, at the tables' overlaps and at a
    thousandth of them (towards the contact's end, where F_n's own rate goes as delta^(-3/4)); its
    sign is F_n's. (Leaving out the term of gamma's growth, gamma_delta, misses by 19 % to 42 %.)"""
    X, C, CI, WP, nc, grav = _damped_hertz(dim, wall, squeeze)
    pressing, acc = _pressing(X, C, CI, WP, nc, grav)
    value, rate, acc = pressing[:, 0], pressing[:, 1], acc.copy()
    assert (C[:nc, layout.C_DELTA] > 0).all()
    assert np.array_equal(np.sign(value), np.sign(C[:nc, layout.C_FN]))
    speed = np.abs(X[:, layout.X_V:layout.X_V + 3]).max()
    h = 1e-4 * C[:nc, layout.C_DELTA].min() / speed  # far inside the overlap's time and the contact's period
    ends = []
    for sign in (1.0, -1.0):
        Y = X.copy()
        Y[:, layout.X_S:layout.X_S + 3] += sign * h * X[:, layout.X_V:layout.X_V + 3] + 0.5 * h * h * acc
        Y[:, layout.X_V:layout.X_V + 3] += sign * h * acc
        ends.append(_pressing(Y, C.copy(), CI, WP, nc, grav)[0][:, 0])
    numeric = (ends[0] - ends[1]) / (2 * h)
    assert rate == pytest.approx(numeric, rel=1e-6)
    assert np.abs(rate).max() > 1.0  # not vacuous
