"""The neighbour lists: sphere pairs from a cell grid (dense, or hashed where the bodies are
spread far apart), body-wall pairs, and the contact history carried from one list to the next.

A Verlet list: rebuilt when a body has moved half the skin since the last build, so no pair it
leaves out can touch before then.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import BOX_ANY, image_pairs
from collide.engine.dem.geometry import wall_height
from collide.engine.dem.layout import B_R, H_IV, H_ON, NH, S_BUILDS
from collide.engine.jit import jit, jit_inline

HASH_PRIMES = (73856093, 19349663, 83492791)
# The neighbour search's grid is dense (not hashed) where it has at most this many cells a body:
# 128 bytes a body at most, less than its state takes (a settling box has about 4).
DENSE_CELLS = np.int64(16)


@jit_inline
def _cell(x, size):
    return np.int64(math.floor(x / size))


@jit
def build_pairs(P, Bd, n, dim, reach_pad):
    """Pairs (i < j) whose gap is under reach_pad: (keys i * n + j in ascending order, i, j). A
    cell grid whose cells hold their bodies contiguously (a counting sort), searched by
    `_gather_pairs`: a dense grid over the bodies' bounding box where it has at most
    DENSE_CELLS cells a body (a body's 3 x 3 x 3 cells are then 9 runs of consecutive cells:
    the search takes about half the time of a hashed grid's 27 cells, 1 000 spheres settling in
    a box), else the grid hashed into 8 n buckets (bodies spread far apart)."""
    cells, start, order, table, span, dense = grid(P, Bd, n, dim, reach_pad)
    return pairs_range(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, 0, n)


@jit
def grid(P, Bd, n, dim, reach_pad):
    """`build_pairs`'s cell grid: each body's cell, the cells' starts in `order` (the bodies
    sorted by cell), the table's size and span, and whether it is dense."""
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, Bd[i, B_R])
    size = 2.0 * rmax + reach_pad
    lo = np.zeros(3)
    hi = np.zeros(3)
    span = np.ones(3, np.int64)
    total = 1.0
    for d in range(dim):
        lo[d], hi[d] = math.inf, -math.inf
        for i in range(n):
            lo[d], hi[d] = min(lo[d], P[i, d]), max(hi[d], P[i, d])
        total *= (hi[d] - lo[d]) / size + 1.0
    dense = total <= DENSE_CELLS * n  # (false for non-finite positions too)
    if dense:
        for d in range(dim):
            span[d] = _cell(hi[d] - lo[d], size) + 1
        table = span[0] * span[1] * span[2]
    else:
        table = 1
        while table < 8 * n:  # (few hash collisions: a collision's bodies are visited for nothing)
            table *= 2
    cells = np.zeros((n, 3), np.int64)
    bucket = np.empty(n, np.int64)
    start = np.zeros(table + 1, np.int64)
    for i in range(n):
        h = 0
        for d in range(dim):
            c = _cell(P[i, d] - lo[d], size)
            cells[i, d] = c
            h ^= c * HASH_PRIMES[d]
        bucket[i] = (cells[i, 0] * span[1] + cells[i, 1]) * span[2] + cells[i, 2] if dense else h & (table - 1)
        start[bucket[i] + 1] += 1
    for b in range(table):
        start[b + 1] += start[b]
    order = np.empty(n, np.int64)
    fill = start[:table].copy()
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    return cells, start, order, table, span, dense


@jit
def pairs_range(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, first, last):
    """The pairs (i, j) of `build_pairs` with i in first..last, from the cell `grid`: (keys, i,
    j). The pairs of consecutive ranges, put one after the other, are the whole list (the
    driver of the threads gathers them so, `dem_threads`)."""
    keys = np.empty(8 * (last - first) + 16, np.int64)
    while True:
        count = _gather_pairs(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, keys, first, last)
        if count >= 0:
            found = keys[:count].copy()  # (not a view holding the whole search buffer)
            rows = np.empty(count, np.int64)
            partners = np.empty(count, np.int64)
            i = first
            for k in range(count):  # (keys ascend: no division)
                while found[k] >= (i + 1) * n:
                    i += 1
                rows[k] = i
                partners[k] = found[k] - i * n
            return found, rows, partners
        # Out of room: start again with twice as much (rare; growing in the search loop would
        # count references to `keys` at every cell visited, which cost more than the search).
        keys = np.empty(2 * keys.shape[0], np.int64)


@jit_inline
def _partners(P, Bd, i, n, reach_pad, order, first, last, cells, cx, cy, cz, hashed, keys, count):
    """The bodies order[first:last] that are i's partners (j > i, within reach; `hashed`: from the
    cell (cx, cy, cz) itself, as a hashed bucket also holds other cells') into keys from count.
    Returns the new count."""
    for m in range(first, last):
        j = order[m]
        dx = P[j, 0] - P[i, 0]
        dy = P[j, 1] - P[i, 1]
        dz = P[j, 2] - P[i, 2]
        lim = Bd[i, B_R] + Bd[j, B_R] + reach_pad
        # Written always, kept if j is a partner: a branch here is a coin toss (j > i) that the
        # processor mispredicts half the time.
        keys[count] = i * n + j
        kept = (j > i) & (dx * dx + dy * dy + dz * dz < lim * lim)
        if hashed:
            kept &= (cells[j, 0] == cx) & (cells[j, 1] == cy) & (cells[j, 2] == cz)
        count += kept
    return count


@jit
def _gather_pairs(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, keys, first, last):
    """The pairs of `build_pairs` whose i is in first..last into keys, each body's partners
    gathered from the 3^dim cells around it and sorted among themselves. Returns their number,
    or -1 if keys is too short."""
    count = 0
    reach = 1 if dim >= 1 else 0
    ry = 1 if dim >= 2 else 0
    rz = 1 if dim >= 3 else 0
    for i in range(first, last):
        row_start = count
        for ox in range(-reach, reach + 1):
            for oy in range(-ry, ry + 1):
                cx, cy = cells[i, 0] + ox, cells[i, 1] + oy
                if dense:
                    # The cells (cx, cy, cz - 1 .. cz + 1) are consecutive: one run.
                    if cx < 0 or cx >= span[0] or cy < 0 or cy >= span[1]:
                        continue
                    row = (cx * span[1] + cy) * span[2]
                    low = row + max(cells[i, 2] - rz, 0)
                    high = row + min(cells[i, 2] + rz, span[2] - 1)
                    if count + start[high + 1] - start[low] > keys.shape[0]:
                        return -1
                    count = _partners(P, Bd, i, n, reach_pad, order, start[low], start[high + 1], cells, cx, cy, 0,
                                      False, keys, count)
                    continue
                for oz in range(-rz, rz + 1):
                    cz = cells[i, 2] + oz
                    h = ((cx * HASH_PRIMES[0]) ^ (cy * HASH_PRIMES[1]) ^ (cz * HASH_PRIMES[2])) & (table - 1)
                    if count + start[h + 1] - start[h] > keys.shape[0]:
                        return -1
                    count = _partners(P, Bd, i, n, reach_pad, order, start[h], start[h + 1], cells, cx, cy, cz, True,
                                      keys, count)
        # i's row ascending (a handful of partners: insertion sort).
        for a in range(row_start + 1, count):
            key = keys[a]
            at = a
            while at > row_start and keys[at - 1] > key:
                keys[at] = keys[at - 1]
                at -= 1
            keys[at] = key
    return count


@jit
def carry_history(old_keys, old_hist, new_keys):
    """History rows of the new pair list: the old pair's where it was listed, else zero."""
    hist = np.zeros((new_keys.shape[0], NH))
    for k in range(new_keys.shape[0]):
        hist[k, H_IV] = -1.0
    a = 0
    for k in range(new_keys.shape[0]):
        while a < old_keys.shape[0] and old_keys[a] < new_keys[k]:
            a += 1
        if a < old_keys.shape[0] and old_keys[a] == new_keys[k]:
            for c in range(NH):
                hist[k, c] = old_hist[a, c]
    return hist


@jit
def wall_list(X, Bd, WP, WL, WH, n, skin):
    """Body-wall pairs within the skin of touching, and those still engaged (with the list rebuilt
    when a body has moved half the skin, no other can touch), in order: rows (m, i, w,
    i * walls + w), m the row of their history in the new WH, carried over from the last list
    (WL, WH): the wall contacts' table sized from the contacts, not bodies x walls."""
    nw = WP.shape[0]
    count = 0
    for step in range(2):  # count, then fill: no table of every body and wall even for a moment
        out = np.empty((count if step else 0, 4), np.int64)
        count = 0
        a = 0
        for i in range(n):
            for w in range(nw):
                key = i * nw + w
                while a < WL.shape[0] and WL[a, 3] < key:
                    a += 1
                engaged = a < WL.shape[0] and WL[a, 3] == key and WH[WL[a, 0], H_ON] != 0.0
                if wall_height(X, WP, i, w) - Bd[i, B_R] < skin or engaged:
                    if step:
                        out[count, 0], out[count, 1], out[count, 2], out[count, 3] = count, i, w, key
                    count += 1
    return out, carry_history(WL[:, 3].copy(), WH, out[:, 3].copy())


@jit
def periodic_pairs(P, Bd, n, dim, reach_pad, box):
    """`build_pairs` in a periodic box: the pairs whose nearest images' gap is within reach_pad
    (`broad.image_pairs`), as (keys ascending, i, j)."""
    pairs = image_pairs(P, Bd[:, B_R].copy(), n, dim, box, reach_pad)
    keys = np.empty(pairs.shape[0], np.int64)
    for k in range(pairs.shape[0]):
        keys[k] = pairs[k, 0] * n + pairs[k, 1]
    keys = np.sort(keys)
    rows = np.empty(keys.shape[0], np.int64)
    partners = np.empty(keys.shape[0], np.int64)
    for k in range(keys.shape[0]):
        rows[k] = keys[k] // n
        partners[k] = keys[k] - rows[k] * n
    return keys, rows, partners


@jit
def rebuild(X, X0, Bd, WP, WL, WH, n, dim, skin, keys, hist, ST, box):
    """Fresh neighbour lists (pairs as keys i * n + j and as (i, j); body-wall pairs, `wall_list`),
    the listed pairs' and wall contacts' history carried over. In a periodic box (`box`) a pair
    is listed at its nearest images: the force pass meets it there."""
    if box[BOX_ANY] != 0.0:
        fresh, PI, PJ = periodic_pairs(X, Bd, n, dim, skin, box)
    else:
        fresh, PI, PJ = build_pairs(X, Bd, n, dim, skin)
    return relist(X, X0, Bd, WP, WL, WH, n, skin, keys, hist, ST, fresh, PI, PJ)


@jit
def relist(X, X0, Bd, WP, WL, WH, n, skin, keys, hist, ST, fresh, PI, PJ):
    """`rebuild` from the fresh pair list (keys, i, j): the history carried over, the body-wall
    pairs listed. Returns what `rebuild` returns."""
    hist = carry_history(keys, hist, fresh)
    X0[:, :] = X
    ST[S_BUILDS] += 1
    WL, WH = wall_list(X, Bd, WP, WL, WH, n, skin)
    return fresh, PI, PJ, hist, WL, WH
