"""Pairs of spheres that may touch, found on a cell grid in time linear in the spheres (no numba:
the scene's set-up runs before the engine is chosen, docs/design.md section 10).

A grid of cells of side `cell` holds spheres of radius at most cell / 2: two of them that touch
have centres less than one cell apart along every axis, so they sit in the same or neighbouring
cells. Cells are found by sorting a hash of their integer coordinates; two cells that share a hash
only add candidates, which the caller's distance test drops. Spheres of very different sizes are
split into classes of radii within a factor 2 (`size_classes`), each on its own grid, so a few big
spheres do not make every cell big.
"""

from __future__ import annotations

from collections.abc import Iterator
from itertools import product

import numpy as np

_PRIMES = np.array([73856093, 19349663, 83492791], dtype=np.int64)
_CLIP = float(2**50)  # cell coordinates beyond this merge (more candidates, none lost)
QUERY_CHUNK = 1 << 13  # queries whose neighbour ranges are held at once (27 ranges each in 3D)
PAIR_CHUNK = 1 << 18  # candidate pairs expanded at once (memory: about 15 MB, with their distances)
DENSE_PER_SPHERE = 8  # cells per sphere up to which the grid indexes cells directly
DENSE_MIN = 1 << 16


def _cells(pos: np.ndarray, origin: np.ndarray, cell: float) -> np.ndarray:
    return np.clip(np.floor((pos - origin) / cell), -_CLIP, _CLIP).astype(np.int64)


def _hash(k: np.ndarray) -> np.ndarray:
    h = k[:, 0] * _PRIMES[0]
    for axis in range(1, k.shape[1]):
        h = h ^ (k[:, axis] * _PRIMES[axis])
    return h


class Grid:
    """Spheres' centres sorted by cell. `cell` must be at least twice the largest radius of the
    spheres stored and of those that query it."""

    def __init__(self, pos: np.ndarray, cell: float, origin: np.ndarray) -> None:
        self.cell, self.origin = float(cell), origin
        dim = pos.shape[1]
        self.offsets = np.array(list(product((-1, 0, 1), repeat=dim)), dtype=np.int64)
        k = _cells(pos, origin, self.cell)
        # Cells indexed directly (padded by 2, so a query's neighbours need no bounds check) when
        # they are not many more than the spheres; a sparse scene spread far: sorted hashes.
        self.low = (k.min(axis=0) if len(k) else np.zeros(dim, dtype=np.int64)) - 2
        self.shape = ((k.max(axis=0) + 2) if len(k) else self.low + 4) - self.low + 1
        self.dense = float(np.prod(self.shape.astype(float))) <= max(DENSE_PER_SPHERE * len(k), DENSE_MIN)
        if self.dense:
            self.strides = np.cumprod(np.concatenate([self.shape[1:], [1]])[::-1])[::-1].astype(np.int64)
            ids = (k - self.low) @ self.strides
            self.order = np.argsort(ids, kind="stable")
            self.start = np.zeros(int(np.prod(self.shape)) + 1, dtype=np.int64)
            np.cumsum(np.bincount(ids, minlength=len(self.start) - 1), out=self.start[1:])
            self.steps = self.offsets @ self.strides
        else:
            keys = _hash(k)
            self.order = np.argsort(keys, kind="stable")
            self.keys = keys[self.order]

    def _ranges(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the spheres of the cells next to cells k (n, dim) lie in `order`: [lo, hi),
        one row per neighbour. A query beyond the padded grid is moved onto its edge: its true
        neighbours hold no spheres, the edge's only add candidates."""
        if not self.dense:
            lo = np.empty((len(self.offsets), len(k)), dtype=np.int64)
            hi = np.empty_like(lo)
            for row, off in enumerate(self.offsets):
                h = _hash(k + off)
                # Sorted queries: numpy's search starts each from the last (3 times quicker on a
                # million keys than scattered queries' cache misses).
                order = np.argsort(h)
                h = h[order]
                lo[row, order] = np.searchsorted(self.keys, h, "left")
                hi[row, order] = np.searchsorted(self.keys, h, "right")
            return lo, hi
        inner = np.clip(k - self.low, 1, self.shape - 2) @ self.strides
        ids = inner[None, :] + self.steps[:, None]
        return self.start[ids], self.start[ids + 1]

    def candidates(self, q_pos: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Chunks of (query index, stored index): every stored sphere in a cell next to each
        query's, a pair at most once per neighbouring cell."""
        for start in range(0, len(q_pos), QUERY_CHUNK):
            lo, hi = self._ranges(_cells(q_pos[start:start + QUERY_CHUNK], self.origin, self.cell))
            yield from self._expand(lo, hi, start)

    def _expand(self, lo: np.ndarray, hi: np.ndarray, start: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The pairs of one chunk of queries, split so at most about PAIR_CHUNK are held at once."""
        counts = hi - lo
        total = np.cumsum(counts.sum(axis=0))
        first, n = 0, len(total)
        while first < n:
            done = int(total[first - 1]) if first else 0
            last = max(int(np.searchsorted(total, done + PAIR_CHUNK, "right")), first + 1)
            c = counts[:, first:last].ravel()
            q = np.tile(np.arange(first, last), len(self.offsets))
            q = np.repeat(q, c) + start
            begin = np.repeat(lo[:, first:last].ravel(), c)
            within = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
            yield q, self.order[begin + within]
            first = last


def size_classes(radius: np.ndarray) -> list[np.ndarray]:
    """Indices of the spheres in classes of radii within a factor 2 of the class's largest,
    largest radii first: a class's grid (cell twice its largest radius) answers queries from its
    own class and every later one."""
    order = np.argsort(-radius, kind="stable")
    r = radius[order]
    level = np.floor(np.log2(r[0] / r)).astype(np.int64)
    level = np.maximum.accumulate(np.maximum(level, 0))  # never smaller after a larger radius
    cuts = np.flatnonzero(np.diff(level)) + 1
    return np.split(order, cuts)
