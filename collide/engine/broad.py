"""Broad phase: a uniform cell grid, so that finding contacts follows the bodies, not the pairs;
union-find over bodies (clusters of contacts); and whether two bodies went through each other
unseen between two positions. In a periodic box (docs/design.md section 10) two bodies meet at
their nearest images (`nearest`): positions stay unwrapped (continuous), and `box` holds each
axis's period (0: that axis does not wrap) and whether any wraps.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.jit import jit, jit_inline
from collide.engine.layout import G_R
from collide.engine.numerics import grow_int

BOX_ANY = 3  # box[0:3]: the periods (0: no wrap); box[BOX_ANY]: 1.0 if any axis wraps
NBOX = 4
NO_BOX = np.zeros(NBOX)


@jit_inline
def nearest(dx, dy, dz, box):
    """The separation (dx, dy, dz) of two bodies taken to its nearest periodic image (the minimum
    image): each wrapping axis's component brought within half its period."""
    if box[0] > 0.0:
        dx -= box[0] * math.floor(dx / box[0] + 0.5)
    if box[1] > 0.0:
        dy -= box[1] * math.floor(dy / box[1] + 0.5)
    if box[2] > 0.0:
        dz -= box[2] * math.floor(dz / box[2] + 0.5)
    return dx, dy, dz


@jit
def near_pairs(P, rad, margin, n, dim, box):
    """Pairs (i < j) with |s_i - s_j| <= r_i + r_j + margin_i + margin_j, shape (K, 2), from
    positions P (N, 3) (in a periodic box, at the nearest image: `image_pairs`). A body whose
    reach is far above the rest's (a fast one) is checked against every body instead of setting
    the cell size for all."""
    if box[BOX_ANY] != 0.0:
        return image_pairs(P, rad + margin, n, dim, box, 0.0)
    out = np.empty((max(16, 4 * n), 2), np.int64)
    m = 0
    if n < 2:
        return out[:0]
    mean = 0.0
    for i in range(n):
        mean += rad[i] + margin[i]
    mean /= n
    size = 0.0
    for i in range(n):
        b = rad[i] + margin[i]
        if b <= 4.0 * mean:
            size = max(size, b)
    size *= 2.0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(n):
        for d in range(dim):
            lo[d] = min(lo[d], P[i, d])
            hi[d] = max(hi[d], P[i, d])
    cells = np.ones(3, np.int64)
    while True:
        total = 1
        for d in range(dim):
            cells[d] = min(int((hi[d] - lo[d]) / size) + 1, 1 << 20) if size > 0 else 1
            total *= cells[d]
        if total <= 4 * n + 64:
            break
        size *= 1.5
    head = np.full(cells[0] * cells[1] * cells[2], -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    cell = np.zeros((n, 3), np.int64)
    for i in range(n):
        if rad[i] + margin[i] > 4.0 * mean:
            continue
        for d in range(dim):
            cell[i, d] = min(max(int((P[i, d] - lo[d]) / size) if size > 0 else 0, 0), cells[d] - 1)
        key = (cell[i, 0] * cells[1] + cell[i, 1]) * cells[2] + cell[i, 2]
        nxt[i] = head[key]
        head[key] = i
    for i in range(n):
        bi = rad[i] + margin[i]
        if bi > 4.0 * mean:
            # Against everyone (another outlier only once, from the lower index).
            for j in range(n):
                if j == i or (j < i and rad[j] + margin[j] > 4.0 * mean):
                    continue
                if _close(P, i, j, bi + rad[j] + margin[j]):
                    out = grow_int(out, m)
                    out[m, 0], out[m, 1] = min(i, j), max(i, j)
                    m += 1
            continue
        a0, a1 = max(cell[i, 0] - 1, 0), min(cell[i, 0] + 1, cells[0] - 1)
        b0, b1 = max(cell[i, 1] - 1, 0), min(cell[i, 1] + 1, cells[1] - 1)
        c0, c1 = max(cell[i, 2] - 1, 0), min(cell[i, 2] + 1, cells[2] - 1)
        for a in range(a0, a1 + 1):
            for b in range(b0, b1 + 1):
                for c in range(c0, c1 + 1):
                    j = head[(a * cells[1] + b) * cells[2] + c]
                    while j >= 0:
                        if j > i and _close(P, i, j, bi + rad[j] + margin[j]):
                            out = grow_int(out, m)
                            out[m, 0], out[m, 1] = i, j
                            m += 1
                        j = nxt[j]
    return out[:m]


@jit
def image_pairs(P, half, n, dim, box, pad):
    """Pairs (i < j) whose nearest images are within half_i + half_j + pad, shape (K, 2), in a
    periodic box: a cell grid over the box along the wrapping axes (whole cells of the period,
    the neighbour cells taken around it) and over the bodies along the others. Bodies reaching
    far beyond the rest (fast ones) are checked against every body."""
    out = np.empty((max(16, 4 * n), 2), np.int64)
    m = 0
    if n < 2:
        return out[:0]
    mean = 0.0
    for i in range(n):
        mean += half[i]
    mean /= n
    size = 0.0
    for i in range(n):
        if half[i] <= 4.0 * mean:
            size = max(size, half[i])
    size = max(2.0 * size + pad, 1e-300)
    lo = np.zeros(3)
    hi = np.zeros(3)
    for d in range(dim):
        lo[d], hi[d] = math.inf, -math.inf
        for i in range(n):
            x = _wrapped(P[i, d], box[d])
            lo[d], hi[d] = min(lo[d], x), max(hi[d], x)
    cells = np.ones(3, np.int64)
    width = np.ones(3)
    while True:
        total = 1
        for d in range(dim):
            span = box[d] if box[d] > 0.0 else hi[d] - lo[d]
            cells[d] = max(min(int(span / size), 1 << 20), 1) if box[d] > 0.0 else min(int(span / size) + 1, 1 << 20)
            width[d] = box[d] / cells[d] if box[d] > 0.0 else size
            total *= cells[d]
        if total <= 4 * n + 64:
            break
        size *= 1.5
    head = np.full(cells[0] * cells[1] * cells[2], -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    cell = np.zeros((n, 3), np.int64)
    for i in range(n):
        for d in range(dim):
            x = _wrapped(P[i, d], box[d]) - (0.0 if box[d] > 0.0 else lo[d])
            cell[i, d] = min(max(int(x / width[d]), 0), cells[d] - 1)
        if half[i] > 4.0 * mean:
            continue
        key = (cell[i, 0] * cells[1] + cell[i, 1]) * cells[2] + cell[i, 2]
        nxt[i] = head[key]
        head[key] = i
    around = np.zeros((3, 3), np.int64)
    count = np.zeros(3, np.int64)
    for i in range(n):
        if half[i] > 4.0 * mean:
            for j in range(n):
                if j == i or (j < i and half[j] > 4.0 * mean):
                    continue
                if _near_image(P, i, j, half[i] + half[j] + pad, box):
                    out = grow_int(out, m)
                    out[m, 0], out[m, 1] = min(i, j), max(i, j)
                    m += 1
            continue
        for d in range(3):
            count[d] = _around(cell[i, d], cells[d], box[d] > 0.0, around[d])
        for a in range(count[0]):
            for b in range(count[1]):
                for c in range(count[2]):
                    j = head[(around[0, a] * cells[1] + around[1, b]) * cells[2] + around[2, c]]
                    while j >= 0:
                        if j > i and _near_image(P, i, j, half[i] + half[j] + pad, box):
                            out = grow_int(out, m)
                            out[m, 0], out[m, 1] = i, j
                            m += 1
                        j = nxt[j]
    return out[:m]


@jit_inline
def _wrapped(x, period):
    """x brought into [0, period) along a wrapping axis (the box's lower corner is its origin
    there: the grid needs only whole periods), else x."""
    if period > 0.0:
        return x - period * math.floor(x / period)
    return x


@jit_inline
def _around(c, cells, wraps, out):
    """The cells next to cell c along one axis (itself included, each once) into out; their number."""
    if wraps and cells < 3:
        for k in range(cells):
            out[k] = k
        return cells
    m = 0
    for o in range(-1, 2):
        k = c + o
        if wraps:
            k = (k + cells) % cells
        elif k < 0 or k >= cells:
            continue
        out[m] = k
        m += 1
    return m


@jit_inline
def _near_image(P, i, j, reach, box):
    dx, dy, dz = nearest(P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2], box)
    return dx * dx + dy * dy + dz * dz <= reach * reach


@jit
def _close(P, i, j, reach):
    dx = P[j, 0] - P[i, 0]
    dy = P[j, 1] - P[i, 1]
    dz = P[j, 2] - P[i, 2]
    return dx * dx + dy * dy + dz * dz <= reach * reach


@jit
def root_of(parent, i):
    """Union-find root, with path halving."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@jit
def join(parent, i, j):
    a, b = root_of(parent, i), root_of(parent, j)
    if a != b:
        parent[max(a, b)] = min(a, b)


@jit
def crossed(P0, P, G, n, start, other, margin, box):
    """Whether two bodies, neither the other's candidate, went through each other between P0 and
    P. Only a body that moved past its margin can have (a speed bound that failed: a body at rest
    sent on by a candidate within the window, in a row of spheres, went through the next one
    whole, touching it at neither end). Their relative motion taken straight from P0 to P; in 1D
    exact: their order flipped."""
    for i in range(n):
        mx, my, mz = P[i, 0] - P0[i, 0], P[i, 1] - P0[i, 1], P[i, 2] - P0[i, 2]
        if mx * mx + my * my + mz * mz <= margin[i] * margin[i]:
            continue
        for j in range(n):
            if j == i or listed(start, other, i, j) or listed(start, other, j, i):
                continue
            ax, ay, az = P0[j, 0] - P0[i, 0], P0[j, 1] - P0[i, 1], P0[j, 2] - P0[i, 2]
            ux = P[j, 0] - P[i, 0] - ax
            uy = P[j, 1] - P[i, 1] - ay
            uz = P[j, 2] - P[i, 2] - az
            if box[BOX_ANY] != 0.0:  # (positions are unwrapped: u is the relative motion either way)
                ax, ay, az = nearest(ax, ay, az, box)
            uu = ux * ux + uy * uy + uz * uz
            s = min(max(-(ax * ux + ay * uy + az * uz) / uu, 0.0), 1.0) if uu > 0.0 else 0.0
            cx, cy, cz = ax + ux * s, ay + uy * s, az + uz * s
            reach = G[i, G_R] + G[j, G_R]
            if cx * cx + cy * cy + cz * cz < reach * reach:
                return True
    return False


@jit_inline
def listed(start, other, i, j):
    """Whether j is among i's candidates (CSR)."""
    for k in range(start[i], start[i + 1]):
        if other[k] == j:
            return True
    return False


@jit
def largest_set(parent, n):
    size = np.zeros(n, np.int64)
    big = 0
    for i in range(n):
        r = root_of(parent, i)
        size[r] += 1
        big = max(big, size[r])
    return big
