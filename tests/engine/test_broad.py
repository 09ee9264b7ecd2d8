"""Broad phase (collide/engine/broad.py): the cell grid's near pairs against every pair, and the
union-find's clusters against scipy's connected components."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from collide.engine import broad


def _every_pair(P: np.ndarray, rad: np.ndarray, margin: np.ndarray) -> set[tuple[int, int]]:
    """Pairs (i < j) within r_i + r_j + margin_i + margin_j, from all n (n - 1) / 2 distances."""
    reach = rad + margin
    i, j = np.triu_indices(len(P), 1)
    d = P[j] - P[i]
    close = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2] <= (reach[i] + reach[j]) ** 2
    return set(zip(i[close].tolist(), j[close].tolist()))


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("fast", [0, 1, 3])
def test_near_pairs_are_every_pair_within_reach(dim: int, fast: int) -> None:
    """Spheres of unequal radii and margins packed so that many pairs are in reach, `fast` of them
    with a margin far above the rest's (checked against every body, not through the grid): the
    grid finds exactly the pairs that a check of every pair finds, each once, i < j."""
    rng = np.random.default_rng(10 * dim + fast)
    for n in (0, 1, 2, 30, 400):
        P = np.zeros((n, 3))
        P[:, :dim] = rng.uniform(-1.0, 1.0, (n, dim)) * n ** (1 / dim) * 0.2
        rad = rng.uniform(0.05, 0.2, n)
        margin = rng.uniform(0.0, 0.1, n)
        margin[:min(fast, n)] = rng.uniform(5.0, 20.0, min(fast, n))
        pairs = broad.near_pairs(P, rad, margin, n, dim, broad.NO_BOX)
        expected = _every_pair(P, rad, margin)
        found = [tuple(p) for p in pairs.tolist()]
        assert len(found) == len(set(found)) and all(i < j for i, j in found)
        assert set(found) == expected
        assert n < 30 or len(expected) > n // 2  # not vacuous


def test_joined_bodies_are_scipys_connected_components() -> None:
    """Bodies joined pair by pair (`join`) share a root (`root_of`) exactly when scipy's connected
    components put them together, and `largest_set` is the largest component's size."""
    rng = np.random.default_rng(4)
    for n, links in ((1, 0), (10, 4), (200, 150), (200, 400)):
        parent = np.arange(n, dtype=np.int64)
        i, j = rng.integers(0, n, links), rng.integers(0, n, links)
        for a, b in zip(i, j):
            broad.join(parent, a, b)
        roots = np.array([broad.root_of(parent, k) for k in range(n)])
        graph = coo_matrix((np.ones(links), (i, j)), shape=(n, n))
        count, labels = connected_components(graph, directed=False)
        # The same partition: each component has one root, each root one component.
        assert len(set(zip(roots.tolist(), labels.tolist()))) == count == len(set(roots.tolist()))
        assert broad.largest_set(parent, n) == np.bincount(labels).max()


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("cells", [1, 2, 7])
def test_image_pairs_are_every_pair_within_reach_at_the_nearest_image(dim: int, cells: int) -> None:
    """In a periodic box (some axes wrapping, positions unwrapped by whole periods and more) the
    grid finds exactly the pairs whose nearest images are within reach, each once, i < j: with a
    period of one, two (neighbour cells that are the same cell) or several cells, a fast body too."""
    rng = np.random.default_rng(100 * dim + cells)
    n = 120
    rad = rng.uniform(0.02, 0.05, n)
    half = rad.copy()
    half[0] = 0.6  # a body reaching far beyond the rest: checked against every body
    period = np.zeros(3)
    period[:dim] = cells * 2.0 * (2 * 0.05 + 0.01)
    period[dim - 1] = 0.0 if dim > 1 else period[0]  # the last axis does not wrap (in 2D and 3D)
    box = np.array([*period, 1.0])
    P = np.zeros((n, 3))
    P[:, :dim] = rng.uniform(0.0, 1.0, (n, dim)) * np.where(period[:dim] > 0, period[:dim], 0.6)
    P[:, :dim] += rng.integers(-3, 4, (n, dim)) * period[:dim]  # unwrapped: whole periods away
    pairs = broad.image_pairs(P, half, n, dim, box, 0.01)
    i, j = np.triu_indices(n, 1)
    d = P[j] - P[i]
    safe = np.where(period > 0, period, 1.0)
    d -= np.where(period > 0, period * np.floor(d / safe + 0.5), 0.0)
    close = (d * d).sum(axis=1) <= (half[i] + half[j] + 0.01) ** 2
    found = [tuple(p) for p in pairs.tolist()]
    assert len(found) == len(set(found)) and all(a < b for a, b in found)
    assert set(found) == set(zip(i[close].tolist(), j[close].tolist()))
    assert close.sum() > n // 4  # not vacuous
