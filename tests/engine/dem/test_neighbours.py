"""The DEM neighbour lists (collide/engine/dem/neighbours.py) against every pair."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("far", [False, True])
def test_neighbour_lists_hold_every_pair_within_reach(dim, far):
    """The DEM neighbour search against every pair: spheres of unequal radii packed in a small
    region (a dense cell grid) and, with `far`, one of them 100 km away (the grid is hashed
    instead); keys ascending, each with its pair's (i, j)."""
    from collide.engine.dem.layout import B_R, NB
    from collide.engine.dem.neighbours import DENSE_CELLS, build_pairs

    rng = np.random.default_rng(dim)
    for n in (1, 2, 40, 300):
        P = np.zeros((n, 3))
        P[:, :dim] = rng.uniform(-1.0, 1.0, (n, dim)) * n ** (1 / dim) * 0.4
        if far:
            P[0, :dim] = 1e5
        bodies = np.zeros((n, int(NB)))
        bodies[:, B_R] = rng.uniform(0.1, 0.5, n)
        pad = 0.1
        size = 2 * bodies[:, B_R].max() + pad
        cells = np.prod(np.ptp(P[:, :dim], axis=0) / size + 1.0)
        assert (cells > DENSE_CELLS * n) == (far and n > 1)  # the grid kind this case is for
        rows, partners = build_pairs(P, bodies, n, dim, pad)
        gap = np.linalg.norm(P[:, None] - P[None], axis=-1) - bodies[:, None, B_R] - bodies[None, :, B_R]
        i, j = np.nonzero(np.triu(gap < pad, 1))
        assert n < 40 or len(i) > n // 2  # not vacuous
        assert np.array_equal(rows, i) and np.array_equal(partners, j)
