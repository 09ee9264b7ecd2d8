"""The neighbour lists: sphere pairs from a cell grid (dense, or hashed where the bodies are
spread far apart), body-wall pairs, and the contact history carried from one list to the next.

A Verlet list: rebuilt when a body has moved half the skin since the last build, so no pair it
leaves out can touch before then. A listed pair is (i, j) and a slot (PS): the row of its history
in a table (HS) that holds only contacts, not every listed pair (most listed pairs never touch
before the next build). The table's first rows are the contacts engaged at the build, packed;
then room for a slot for every listed pair, taken in order as contacts start (`take_slot`: a
region a thread, bump pointers), untouched and so not resident until taken. A pair keeps its
slot until the next build, however often it closes and opens again.
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
    """Pairs (i < j) whose gap is under reach_pad, in ascending order of i * n + j: (i, j). A
    cell grid whose cells hold their bodies contiguously (a counting sort), searched by
    `_gather_pairs`: a dense grid over the bodies' bounding box where it has at most
    DENSE_CELLS cells a body (a body's 3 x 3 x 3 cells are then 9 runs of consecutive cells:
    the search takes about half the time of a hashed grid's 27 cells, 1 000 spheres settling in
    a box), else the grid hashed into 8 n buckets (bodies spread far apart)."""
    cells, start, order, table, span, dense = grid(P, Bd, n, dim, reach_pad)
    keys, count = keys_range(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, 0, n)
    rows = np.empty(count, np.int64)
    partners = np.empty(count, np.int64)
    split_keys(keys, count, 0, n, rows, partners, 0)
    return rows, partners


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
def keys_range(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, first, last):
    """The keys i * n + j of `build_pairs`'s pairs with i in first..last, ascending, in a buffer
    (keys, count). The keys of consecutive ranges, put one after the other, are the whole list
    (the driver of the threads searches so, `dem_threads`, then `split_keys` each range into one
    list: no range's (i, j) beside the joined list's)."""
    keys = np.empty(8 * (last - first) + 16, np.int64)
    while True:
        count = _gather_pairs(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, keys, first, last)
        if count >= 0:
            return keys, count
        # Out of room: start again with twice as much (rare; growing in the search loop would
        # count references to `keys` at every cell visited, which cost more than the search).
        keys = np.empty(2 * keys.shape[0], np.int64)


@jit
def split_keys(keys, count, first, n, rows, partners, at):
    """keys[:count] (ascending, i from first on) as (i, j) into rows and partners from row at."""
    i = first
    for k in range(count):  # (keys ascend: no division)
        while keys[k] >= (i + 1) * n:
            i += 1
        rows[at + k] = i
        partners[at + k] = keys[k] - i * n


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


@jit_inline
def first_row(rows, value):
    """The first of the ascending `rows` at or past value (a binary search)."""
    lo, hi = 0, rows.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if rows[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit_inline
def _first_pair(PI, PJ, n, key):
    """`first_row` of the old pair list's keys: where a range of the new list starts its walk
    through the old one."""
    lo, hi = 0, PI.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if PI[mid] * n + PJ[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit_inline
def _match(PI, PJ, PS, HS, a, key, n):
    """The old list's row a advanced to the first pair at or past `key`; and the slot of the
    contact it holds for that key if engaged (else -1). Returns (a, slot)."""
    while a < PI.shape[0] and PI[a] * n + PJ[a] < key:
        a += 1
    if a < PI.shape[0] and PI[a] * n + PJ[a] == key and PS[a] >= 0 and HS[PS[a], H_ON] != 0.0:
        return a, PS[a]
    return a, np.int64(-1)


@jit
def carry_rows(PI, PJ, PS, HS, NI, NJ, n, k0, k1, e, NS, table):
    """The new pairs k0..k1's part of `carry_slots`: with `table` holding rows, their slots into
    NS and the engaged contacts they carry into table's rows from e on; without (no rows),
    only counted. Ranges of the new list, each starting at its carried contacts' count before
    it, make `carry_slots`'s table whatever the ranges (`dem_threads` runs them side by side).
    Returns the contacts carried."""
    fill = table.shape[0] > 0
    a = _first_pair(PI, PJ, n, NI[k0] * n + NJ[k0]) if k0 < k1 else 0
    start = e
    for k in range(k0, k1):
        a, s = _match(PI, PJ, PS, HS, a, NI[k] * n + NJ[k], n)
        if fill:
            NS[k] = -1
            if s >= 0:
                for c in range(NH):
                    table[e, c] = HS[s, c]
                NS[k] = e
        e += s >= 0
    return e - start


@jit
def carry_slots(PI, PJ, PS, HS, NI, NJ, n):
    """The new pair list's (NI, NJ) slots and history table: the contacts engaged in the old list
    (PI, PJ, PS, HS) that the new one lists, packed into its first rows in the new list's order,
    then room for a slot for every new pair (left unset and so not resident: `take_slot` starts
    a row when it takes it). Counted first (`carry_rows`): no table of every pair even for a
    moment. Returns (slots, table)."""
    none = np.empty((0, NH))
    NS = np.empty(NI.shape[0], np.int64)
    e = carry_rows(PI, PJ, PS, HS, NI, NJ, n, 0, NI.shape[0], 0, NS, none)
    table = np.empty((e + NI.shape[0], NH))
    carry_rows(PI, PJ, PS, HS, NI, NJ, n, 0, NI.shape[0], 0, NS, table)
    return NS, table


@jit
def slot_regions(PS, HS, starts):
    """Where each share of the bodies takes its new contacts' slots: share r's pairs are those
    whose second body is its own (`starts[r]` of them before its: `threads.plan`), from the
    table's row `carried + starts[r]` on (`carry_slots` left a slot a pair after the carried
    contacts), so that threads take slots without meeting."""
    carried = HS.shape[0] - PS.shape[0]
    bump = np.empty(starts.shape[0] - 1, np.int64)
    for r in range(bump.shape[0]):
        bump[r] = carried + starts[r]
    return bump


@jit_inline
def take_slot(PS, BUMP, BB, k, j):
    """Pair k's slot: its own if it has one, else the next free row of the region of its second
    body j's share (BB: the shares' body bounds; whoever works a pair out owns its j: `threads`),
    its row's columns then set by whoever opens the contact."""
    if PS[k] < 0:
        r = 0
        while BB[r + 1] <= j:
            r += 1
        PS[k] = BUMP[r]
        BUMP[r] += 1
    return PS[k]


@jit
def wall_rows(X, Bd, WP, WL, WH, skin, lo, hi, at, NWL, NWH):
    """Bodies lo..hi's part of `wall_list`: with NWL holding rows, their body-wall pairs into NWL
    and NWH from row at on (rows (m, i, w, i * walls + w), the history carried from the last
    list (WL, WH) where it listed the pair, else none); without, only counted. Ranges of the
    bodies, each from the count before it, make the whole list whatever the ranges. Returns
    the pairs."""
    nw = WP.shape[0]
    fill = NWL.shape[0] > 0
    a = first_row(WL[:, 3], lo * nw)
    count = 0
    for i in range(lo, hi):
        for w in range(nw):
            key = i * nw + w
            while a < WL.shape[0] and WL[a, 3] < key:
                a += 1
            listed = a < WL.shape[0] and WL[a, 3] == key
            engaged = listed and WH[WL[a, 0], H_ON] != 0.0
            if wall_height(X, WP, i, w) - Bd[i, B_R] < skin or engaged:
                if fill:
                    m = at + count
                    NWL[m, 0], NWL[m, 1], NWL[m, 2], NWL[m, 3] = m, i, w, key
                    if listed:
                        NWH[m, :] = WH[WL[a, 0], :]
                    else:
                        NWH[m, :] = 0.0
                        NWH[m, H_IV] = -1.0
                count += 1
    return count


@jit
def wall_list(X, Bd, WP, WL, WH, n, skin):
    """Body-wall pairs within the skin of touching, and those still engaged (with the list rebuilt
    when a body has moved half the skin, no other can touch), in order: rows (m, i, w,
    i * walls + w), m the row of their history in the new WH, carried over from the last list
    (WL, WH): the wall contacts' table sized from the contacts, not bodies x walls (counted
    first, `wall_rows`, then filled)."""
    count = wall_rows(X, Bd, WP, WL, WH, skin, 0, n, 0, np.empty((0, 4), np.int64), np.empty((0, NH)))
    NWL, NWH = np.empty((count, 4), np.int64), np.empty((count, NH))
    wall_rows(X, Bd, WP, WL, WH, skin, 0, n, 0, NWL, NWH)
    return NWL, NWH


@jit
def periodic_pairs(P, Bd, n, dim, reach_pad, box):
    """`build_pairs` in a periodic box: the pairs whose nearest images' gap is within reach_pad
    (`broad.image_pairs`), in ascending order of i * n + j: (i, j)."""
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
    return rows, partners


@jit
def rebuild(X, X0, Bd, WP, WL, WH, n, dim, skin, PI, PJ, PS, HS, ST, box):
    """Fresh neighbour lists: pairs (i, j) and their slots in a fresh history table
    (`carry_slots`), one region for their new contacts' slots (BB, BUMP: `slot_regions`); and
    body-wall pairs (`wall_list`); the engaged contacts' history carried over. In a periodic box
    (`box`) a pair is listed at its nearest images: the force pass meets it there. Returns (PI,
    PJ, PS, HS, BB, BUMP, WL, WH)."""
    if box[BOX_ANY] != 0.0:
        NI, NJ = periodic_pairs(X, Bd, n, dim, skin, box)
    else:
        NI, NJ = build_pairs(X, Bd, n, dim, skin)
    return relist(X, X0, Bd, WP, WL, WH, n, skin, PI, PJ, PS, HS, ST, NI, NJ)


@jit
def relist(X, X0, Bd, WP, WL, WH, n, skin, PI, PJ, PS, HS, ST, NI, NJ):
    """`rebuild` from the fresh pair list (NI, NJ): their slots and history table carried over
    from the old list (PI, PJ, PS, HS: `carry_slots`), the body-wall pairs listed. Returns what
    `rebuild` returns."""
    NS, table = carry_slots(PI, PJ, PS, HS, NI, NJ, n)
    BB = np.zeros(2, np.int64)  # (one share: every body)
    BB[1] = n
    starts = np.zeros(2, np.int64)
    starts[1] = NI.shape[0]
    X0[:, :] = X
    ST[S_BUILDS] += 1
    WL, WH = wall_list(X, Bd, WP, WL, WH, n, skin)
    return NI, NJ, NS, table, BB, slot_regions(NS, table, starts), WL, WH
