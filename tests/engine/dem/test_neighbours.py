"""The DEM neighbour lists (collide/engine/dem/neighbours.py) against every pair."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("far", [False, True])
def test_neighbour_lists_hold_every_pair_within_reach(dim, far):
    """The DEM neighbour search against every pair: spheres of unequal radii packed in a small
    region (a dense cell grid) and, with `far`, one of them 100 km away (the grid is hashed
    instead); pairs (i, j) in ascending order of i * n + j."""
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


def test_carried_history_holds_the_engaged_contacts_only():
    """A rebuild's history table: the old list's engaged contacts that the new list lists, packed in
    the new list's order with their rows as they were; a closed contact, a pair never engaged and
    a pair no longer listed carry nothing; then room for a slot a pair, which the regions of
    `slot_regions` hand out without two regions meeting."""
    from collide.engine.dem.layout import H_ON, NH
    from collide.engine.dem.neighbours import carry_slots, slot_regions, take_slot

    n = 10
    PI, PJ = np.array([0, 0, 1, 2, 3, 5]), np.array([1, 4, 2, 7, 4, 9])
    HS = np.arange(4 * int(NH), dtype=float).reshape(4, int(NH))
    HS[:, H_ON] = [1.0, 0.0, 1.0, 1.0]  # slot 1: a contact that closed
    PS = np.array([2, -1, 1, 0, -1, 3])  # (0, 4), (3, 4): never engaged; (5, 9): engaged, not listed again
    NI, NJ = np.array([0, 0, 1, 2, 3, 4, 6]), np.array([1, 2, 2, 7, 4, 5, 8])
    NS, table = carry_slots(PI, PJ, PS, HS, NI, NJ, n)
    assert table.shape == (2 + len(NI), NH)
    assert list(NS) == [0, -1, -1, 1, -1, -1, -1]
    assert np.array_equal(table[0], HS[2]) and np.array_equal(table[1], HS[0])
    BB = np.array([0, 5, n])  # two shares: a pair's region is its j's share's, 4 pairs in the first
    BUMP = slot_regions(NS, table, np.array([0, 4, len(NI)]))
    taken = [int(take_slot(NS, BUMP, BB, k, NJ[k])) for k in (5, 1, 3, 2, 6)]
    assert taken == [2 + 4, 2 + 0, 1, 2 + 1, 2 + 5]  # (pair 3 keeps its own)
    assert max(taken) < table.shape[0] and len(set(taken)) == len(taken)
