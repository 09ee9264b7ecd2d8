"""Friction forces of an island (collide/engine/event/forces.py): the planar coupling block against
the general one."""

from __future__ import annotations

import numpy as np
import pytest

from collide.engine import layout
from collide.engine.event import contact, forces


def test_a_planar_coupling_block_is_the_general_one_in_the_plane():
    """`couple_block`'s closed form in the plane (one tangent, z x n) equals the general sums'
    entry for the first tangents of the same contacts: shared bodies of either side, with and
    without spin, seed levers (slip arm apart from force arm) included. `set_basis`' plane
    tangent is the general first tangent."""
    rng = np.random.default_rng(5)
    for trial in range(200):
        X = np.zeros((3, int(layout.NX)))
        X[:, layout.X_IM], X[:, layout.X_II] = rng.uniform(0.5, 5.0, 3), rng.uniform(10.0, 500.0, 3)
        C = np.zeros((2, int(layout.NC)))
        CI = np.zeros((2, int(layout.NCI)), np.int64)
        pairs = [(0, 1), (1, 2)] if trial % 2 else [(0, 1), (2, 0)]
        for c, (i, j) in enumerate(pairs):
            angle = rng.uniform(0.0, 2 * np.pi)
            C[c, layout.C_N:layout.C_N + 3] = np.cos(angle), np.sin(angle), 0.0
            C[c, [layout.C_LIF, layout.C_LJF, layout.C_LIS, layout.C_LJS]] = rng.uniform(0.02, 0.05, 4)
            CI[c, layout.CI_I], CI[c, layout.CI_J] = i, j
            # The plane's tangent (z x n, unnormalised: n is a unit vector) is the general
            # basis' first to round-off.
            contact.set_basis(C, c, True)
            in_plane = C[c, layout.C_B:layout.C_B + 3].copy()
            contact.set_basis(C, c, False)
            assert np.abs(in_plane - C[c, layout.C_B:layout.C_B + 3]).max() <= 4e-16
        shared = ({*pairs[0]} & {*pairs[1]}).pop()
        for spin in (0, 1):
            planar, general = np.zeros((1, 1)), np.zeros((2, 2))
            forces.couple_block(X, C, CI, 0, 1, shared, spin, 1, planar, 0, 0)
            forces.couple_block(X, C, CI, 0, 1, shared, spin, 2, general, 0, 0)
            assert planar[0, 0] == pytest.approx(general[0, 0], rel=1e-13, abs=1e-13 * np.abs(general).max())
