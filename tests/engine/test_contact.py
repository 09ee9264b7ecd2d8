"""Contact geometry and friction forces of an island (collide/engine/event/contact.py, forces.py):
the hold rate against a finite difference of the slip, a 3D slide's event value as its slip
turns, the planar coupling block against the general one."""

from __future__ import annotations

import numpy as np
import pytest

from collide.engine import layout as kn
from collide.engine.event import contact, forces, modes


def pressed_island(dim: int, seed: bool, wall: bool):
    """Two spinning spheres pressed together (and the first onto a wall), as an island's tables."""
    rng = np.random.default_rng(3)
    X = np.zeros((2, int(kn.NX)))
    X[0, kn.X_S:kn.X_S + 3] = [0.0, 0.031, 0.01]
    X[1, kn.X_S:kn.X_S + 3] = [0.04, 0.0, 0.0]
    X[:, kn.X_V:kn.X_V + 3] = rng.normal(size=(2, 3))
    X[:, kn.X_W:kn.X_W + 3] = rng.normal(size=(2, 3)) * 5
    if dim == 2:
        X[:, kn.X_S + 2] = X[:, kn.X_V + 2] = 0.0
        X[:, kn.X_W] = X[:, kn.X_W + 1] = 0.0
    mass, radius = np.array([0.03, 0.02]), np.array([0.03, 0.025])
    X[:, kn.X_M], X[:, kn.X_IM], X[:, kn.X_R] = mass, 1 / mass, radius
    X[:, kn.X_I] = 0.4 * mass * radius**2
    X[:, kn.X_II] = 1 / X[:, kn.X_I]
    nc = 2 if wall else 1
    C = np.zeros((nc, int(kn.NC)))
    CI = np.zeros((nc, int(kn.NCI)), np.int64)
    CI[0, :4] = [0, 1, 0, 1]
    C[0, kn.C_K], C[0, kn.C_REACH] = 750.0, radius.sum()
    WP = np.zeros((1, 6))
    if wall:
        WP[0] = [0.0, 0.0025, 0.0, 0.0, 1.0, 0.0]
        CI[1, :4] = [0, -1, 0, -1]
        C[1, kn.C_K], C[1, kn.C_REACH] = 1500.0, radius[0]
    return X, C, CI, WP, nc, np.array([0.0, -9.81, 0.0])


def slips(X, C, CI, WP, nc, seed, spin=1, planar=False):
    contact.geometry(X, C, CI, nc, WP, seed, kn.YES)
    return np.array([contact.slip(X, C, CI, c, kn.X_V, kn.X_W, spin, planar) for c in range(nc)])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("wall", [False, True])
def test_hold_rate_is_the_slip_rate_without_friction(dim, seed, wall):
    """G (`contact.slip_rate` under springs and gravity) is the tangential part of the slip's
    rate of change along the frictionless motion: checked by a central difference."""
    X, C, CI, WP, nc, grav = pressed_island(dim, seed, wall)
    seed = np.int64(seed)
    contact.geometry(X, C, CI, nc, WP, seed, kn.YES)
    contact.springs(X, C, CI, 2, nc, grav)
    assert (C[:nc, kn.C_DELTA] > 0).all()  # really pressed: the springs act
    planar = dim == 2  # the plane's own arithmetic (its zero parts left out): the same numbers
    rates = [np.array([contact.slip_rate(X, C, CI, c, kn.X_V, kn.X_W, kn.X_A, kn.X_L, np.int64(1), seed, np.int64(1),
                                    flat) for c in range(nc)]) for flat in {planar, False}]
    assert all(np.array_equal(r, rates[0]) for r in rates)
    rate = rates[0]
    acc = X[:, kn.X_A:kn.X_A + 3].copy()
    h = 1e-6
    ends = []
    for sign in (1.0, -1.0):
        Y = X.copy()
        Y[:, kn.X_S:kn.X_S + 3] += sign * h * X[:, kn.X_V:kn.X_V + 3] + 0.5 * h * h * acc
        Y[:, kn.X_V:kn.X_V + 3] += sign * h * acc
        ends.append(slips(Y, C.copy(), CI, WP, nc, seed, planar=planar))
        assert np.array_equal(ends[-1], slips(Y, C.copy(), CI, WP, nc, seed))
    numeric = (ends[0] - ends[1]) / (2 * h)
    contact.geometry(X, C, CI, nc, WP, seed, kn.YES)
    n = C[:nc, kn.C_N:kn.C_N + 3]
    tangential = numeric - np.sum(numeric * n, axis=1, keepdims=True) * n
    # Truncation h^2 |third derivative| and rounding 1e-16 |slip| / h: both below 1e-7 relative.
    assert rate == pytest.approx(tangential, rel=1e-7, abs=1e-7 * np.abs(tangential).max())
    assert np.abs(rate).max() > 1.0  # not vacuous


def test_a_3d_slides_event_value_is_continuous_as_its_slip_turns():
    """Out of the plane a slip near the band can turn half round without slowing to it (its way
    slaved to the other forces). The slide's event value must not jump as it turns, or the root
    search bisects the jump to the clock and gives up (40 trials: a pile of 27 spheres warned of
    dozens of such steps). It is |slip| cos^2(turn / 2) - eps: |slip| - eps while the slip keeps
    its way, and -eps reversed, so a slip that reverses through the band still changes sign."""
    X, C, CI, WP, nc, grav = pressed_island(3, 0, False)
    seed = np.int64(0)
    contact.geometry(X, C, CI, nc, WP, seed, kn.YES)
    contact.springs(X, C, CI, 2, nc, grav)
    contact.set_basis(C, 0, False)
    e1, e2 = C[0, kn.C_B:kn.C_B + 3], C[0, kn.C_B + 3:kn.C_B + 6]  # the tangent plane
    X[:, kn.X_W:kn.X_W + 3] = 0.0
    X[0, kn.X_V:kn.X_V + 3] = 0.0
    eps, size, mu = 1e-6, 37e-6, 0.3  # a slip of 37 eps, as in the pile
    CI[0, kn.CI_MODE] = kn.SLIDE
    C[0, kn.C_MU], C[0, kn.C_EPS] = mu, eps
    fl = np.zeros(int(kn.NFL), np.int64)
    fl[kn.FL_SPIN], fl[kn.FL_FRICTION], fl[kn.FL_PLANAR] = 1, 1, kn.NO
    E = np.zeros((2 * nc, 4))
    turns = np.linspace(0.0, np.pi, 721)
    values, held = [], None
    for turn in turns:
        X[1, kn.X_V:kn.X_V + 3] = -size * (np.cos(turn) * e1 + np.sin(turn) * e2)
        contact.geometry(X, C, CI, nc, WP, seed, kn.YES)
        slip = np.array(contact.slip(X, C, CI, 0, kn.X_V, kn.X_W, 1, False))
        if held is None:
            held = slip / np.linalg.norm(slip)
        C[0, kn.C_HELD:kn.C_HELD + 3] = held
        assert modes.mode_events(X, C, CI, E, 2, nc, kn.E_V0, kn.E_R0, np.zeros(3, np.int64), np.zeros((6, 6)),
                              np.zeros(6), fl, 1.0, kn.YES, kn.NO)
        values.append(E[0, kn.E_V0])
    values = np.array(values)
    expected = np.linalg.norm(slip) * np.cos(turns / 2) ** 2 - eps
    assert values == pytest.approx(expected, rel=1e-9, abs=1e-9 * size)
    # Continuous: between neighbouring turns it moves by at most |slip| / 2 per radian.
    assert np.abs(np.diff(values)).max() <= 0.5 * size * (turns[1] - turns[0]) * (1 + 1e-6)
    assert values[0] > 0 > values[-1]  # and a reversal is below the band's edge


def test_a_planar_coupling_block_is_the_general_one_in_the_plane():
    """`couple_block`'s closed form in the plane (one tangent, z x n) equals the general sums'
    entry for the first tangents of the same contacts: shared bodies of either side, with and
    without spin, seed levers (slip arm apart from force arm) included. `set_basis`' plane
    tangent is the general first tangent."""
    rng = np.random.default_rng(5)
    for trial in range(200):
        X = np.zeros((3, int(kn.NX)))
        X[:, kn.X_IM], X[:, kn.X_II] = rng.uniform(0.5, 5.0, 3), rng.uniform(10.0, 500.0, 3)
        C = np.zeros((2, int(kn.NC)))
        CI = np.zeros((2, int(kn.NCI)), np.int64)
        pairs = [(0, 1), (1, 2)] if trial % 2 else [(0, 1), (2, 0)]
        for c, (i, j) in enumerate(pairs):
            angle = rng.uniform(0.0, 2 * np.pi)
            C[c, kn.C_N:kn.C_N + 3] = np.cos(angle), np.sin(angle), 0.0
            C[c, [kn.C_LIF, kn.C_LJF, kn.C_LIS, kn.C_LJS]] = rng.uniform(0.02, 0.05, 4)
            CI[c, kn.CI_I], CI[c, kn.CI_J] = i, j
            # The plane's tangent (z x n, unnormalised: n is a unit vector) is the general
            # basis' first to round-off.
            contact.set_basis(C, c, True)
            in_plane = C[c, kn.C_B:kn.C_B + 3].copy()
            contact.set_basis(C, c, False)
            assert np.abs(in_plane - C[c, kn.C_B:kn.C_B + 3]).max() <= 4e-16
        shared = ({*pairs[0]} & {*pairs[1]}).pop()
        for spin in (0, 1):
            planar, general = np.zeros((1, 1)), np.zeros((2, 2))
            forces.couple_block(X, C, CI, 0, 1, shared, spin, 1, planar, 0, 0)
            forces.couple_block(X, C, CI, 0, 1, shared, spin, 2, general, 0, 0)
            assert planar[0, 0] == pytest.approx(general[0, 0], rel=1e-13, abs=1e-13 * np.abs(general).max())
