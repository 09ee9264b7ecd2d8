"""A run as windows: from each window's start, the contacts that may go on or start within it
(`window_candidates`), their islands run one by one (`run_island`), the window redone shorter
when a contact was missed (`missed_contact`), and stretches where nothing touches crossed in
closed form to the next contact (`next_contact`).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import BOX_ANY, NBOX, crossed, join, largest_set, near_pairs, nearest, root_of
from collide.engine.event.island import run_island
from collide.engine.flight import account_contacts, free_state, meets_again, next_contact, positions_at, speed_scales
from collide.engine.jit import jit, jit_call, jit_inline, jit_part
from collide.engine.layout import (
    CN_IVALS,
    CN_OPEN,
    F_STATUS_A,
    F_STATUS_T,
    FL_AUTO,
    FL_DIM,
    FL_RECORD,
    FL_SPRING,
    FP_BOX,
    FP_CAP,
    FP_DT,
    FP_END_SLOW,
    FP_NOW,
    FP_NOW_STEPS,
    FP_OMEGA_H,
    FP_SLOW,
    FP_TAIL,
    FP_TEND,
    G_I,
    G_IM,
    G_M,
    G_MAT,
    G_R,
    G_W,
    GI_KNOT,
    ISLAND_SLACK,
    K_FREE,
    LONE_WINDOW_STEPS,
    MAX_RETRIES,
    NG,
    NO,
    NQF,
    OK,
    Q_I,
    Q_J,
    QF_REACH,
    QF_SH,
    S_JUMPS,
    S_RETRIES,
    S_STATUS,
    S_STEPS,
    S_WINDOWS,
    STALL,
    STALL_LIMIT,
    TOUCH_TOL,
    TP_K,
    V_END,
    WINDOW_SAFETY,
    WINDOW_STEPS,
    YES,
)
from collide.engine.records import tail_after


@jit
def engaged_now(G, P, V, n, WP, grav, dim, box):
    """Contacts engaged at positions P and velocities V: (K, 2), walls as (i, -1 - wall)."""
    margin = np.zeros(n)
    for i in range(n):
        margin[i] = 2.0 * TOUCH_TOL * G[i, G_R]
    pairs = near_pairs(P, G[:, G_R], margin, n, dim, box)
    out = np.empty((pairs.shape[0] + n * WP.shape[0] + 1, 2), np.int64)
    m = 0
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        dx, dy, dz = _apart(P, i, j, box)
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        reach = G[i, G_R] + G[j, G_R]
        d = (reach - dist) / reach
        r = (V[i, 0] - V[j, 0]) * dx + (V[i, 1] - V[j, 1]) * dy + (V[i, 2] - V[j, 2]) * dz
        if d > TOUCH_TOL or (d >= -TOUCH_TOL and r > 0):
            out[m, 0], out[m, 1] = i, j
            m += 1
    for w in range(WP.shape[0]):
        into = grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5] < 0
        for i in range(n):
            h = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + (P[i, 2] - WP[w, 2]) * WP[w, 5]
            d = (G[i, G_R] - h) / G[i, G_R]
            r = -(V[i, 0] * WP[w, 3] + V[i, 1] * WP[w, 4] + V[i, 2] * WP[w, 5])
            if d > TOUCH_TOL or (d >= -TOUCH_TOL and (r > 0 or (r == 0 and into))):
                out[m, 0], out[m, 1] = i, -1 - w
                m += 1
    return out[:m]


@jit_part
def window_candidates(G, P, V, n, eng, tables, horizon, safety, WP, grav, dim, box):
    """Contacts that may go on or start within the window: pairs and walls whose gap could close
    within `horizon`, each body's speed bounded by the energy its engaged cluster holds (spin
    included: friction can turn it into motion), plus gravity's pull. (K, 2), and each body's
    margin (how far it was taken to move)."""
    ptab, wtab = tables
    parent = np.arange(n)
    for p in range(eng.shape[0]):
        if eng[p, 1] >= 0:
            join(parent, eng[p, 0], eng[p, 1])
    pool = np.zeros(n)
    clustered = np.zeros(n, np.bool_)
    for p in range(eng.shape[0]):
        i, j = eng[p, 0], eng[p, 1]
        mi = int(G[i, G_MAT])
        if j >= 0:
            k = ptab[mi, int(G[j, G_MAT]), TP_K]
            dx, dy, dz = _apart(P, i, j, box)
            delta = G[i, G_R] + G[j, G_R] - math.sqrt(dx * dx + dy * dy + dz * dz)
            clustered[j] = True
        else:
            w = -1 - j
            k = wtab[mi, TP_K]
            delta = G[i, G_R] - ((P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4]
                                 + (P[i, 2] - WP[w, 2]) * WP[w, 5])
        clustered[i] = True
        pool[root_of(parent, i)] += 0.5 * k * max(delta, 0.0) ** 2
    for i in range(n):
        if clustered[i]:
            pool[root_of(parent, i)] += 0.5 * G[i, G_M] * (V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) + \
                0.5 * G[i, G_I] * (G[i, G_W] ** 2 + G[i, G_W + 1] ** 2 + G[i, G_W + 2] ** 2)
    g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
    margin = np.empty(n)
    for i in range(n):
        speed = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2)
        if clustered[i]:
            speed = max(speed, math.sqrt(2.0 * pool[root_of(parent, i)] / G[i, G_M]))
        margin[i] = safety * (speed * horizon + 0.5 * g * horizon * horizon) + 2.0 * TOUCH_TOL * G[i, G_R]
    pairs = near_pairs(P, G[:, G_R], margin, n, dim, box)
    out = np.empty((pairs.shape[0] + n * WP.shape[0], 2), np.int64)
    m = 0
    for p in range(pairs.shape[0]):
        out[m, 0], out[m, 1] = pairs[p, 0], pairs[p, 1]
        m += 1
    for w in range(WP.shape[0]):
        for i in range(n):
            gap = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + \
                (P[i, 2] - WP[w, 2]) * WP[w, 5] - G[i, G_R]
            if gap <= margin[i]:
                out[m, 0], out[m, 1] = i, -1 - w
                m += 1
    return out[:m], margin


@jit_part
def missed_contact(G, P, V, n, t, cand, WP, grav, dim, P0, margin, box):
    """Whether bodies (or a body and a wall) overlap at t without having been candidates, or
    went through each other since the window's start (positions P0)."""
    positions_at(G, n, t, grav, P, V)
    # Each body's candidates, for a quick lookup (CSR).
    start = np.zeros(n + 1, np.int64)
    for k in range(cand.shape[0]):
        start[cand[k, 0] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start.copy()
    other = np.empty(cand.shape[0], np.int64)
    for k in range(cand.shape[0]):
        other[fill[cand[k, 0]]] = cand[k, 1]
        fill[cand[k, 0]] += 1
    eng = engaged_now(G, P, V, n, WP, grav, dim, box)
    for p in range(eng.shape[0]):
        i, j = eng[p, 0], eng[p, 1]
        if j >= 0:
            dx, dy, dz = _apart(P, i, j, box)
            reach = G[i, G_R] + G[j, G_R]
            deep = reach - math.sqrt(dx * dx + dy * dy + dz * dz) > 1e-9 * reach
        else:
            w = -1 - j
            h = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + (P[i, 2] - WP[w, 2]) * WP[w, 5]
            deep = G[i, G_R] - h > 1e-9 * G[i, G_R]
        if not deep:
            continue
        found = False
        for k in range(start[i], start[i + 1]):
            if other[k] == j:
                found = True
                break
        if not found:
            return True
    return crossed(P0, P, G, n, start, other, margin, box)


@jit
def lone_on_walls(cand, eng, n):
    """Whether a window's candidates are its engaged contacts and each a body alone on one wall
    (a ball resting or rolling on a floor): nothing else can come in, and its rest phase may
    repeat its cycles over a long window."""
    if cand.shape[0] != eng.shape[0]:
        return False
    seen = np.zeros(n, np.int64)
    for k in range(cand.shape[0]):
        if cand[k, 1] >= 0 or seen[cand[k, 0]]:
            return False
        seen[cand[k, 0]] = 1
    return True


@jit_part
def jump(G, P, V, n, t, t_end, search, ticks, WP, grav, dim, fp, IV, CNT, ST, FG, graph):
    """Nothing touches at t: on in closed form to the next contact start, or the run ends (nothing
    to record in free flight). `graph`: who met whom so far (`account_contacts`). Returns (t,
    t_end, search, ticks, whether the run stops here)."""
    small = YES if n <= 64 else NO
    box = fp[FP_BOX:FP_BOX + NBOX]
    parent, count, seen = graph
    account_contacts(IV, CNT, parent, count, seen)
    scale = speed_scales(V, n, parent)
    if (t_end == math.inf and small == YES and CNT[CN_IVALS] > 0 and fp[FP_END_SLOW] > 0.0
            and not meets_again(G, P, V, n, t, WP, grav, count, fp[FP_SLOW], fp[FP_END_SLOW],
                                run_end(t, fp, IV, CNT) - t, scale, box)):
        # What still approaches closes slower than the run resolves velocities (its
        # tolerance): the step's error, not a contact to come (a Newton's cradle at k =
        # 1e6, tol 1e-7, left its balls at 1e-8 m/s and met them again 11 hours later).
        t = t_end = run_end(t, fp, IV, CNT)
        ST[S_JUMPS] += 1
        return t, t_end, search, ticks, True
    if search == math.inf:
        fastest = 0.0
        for i in range(n):
            fastest = max(fastest, math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2))
        search = 4.0 * G[0, G_R] / fastest if fastest > 0 else 1.0
    horizon = min(search, t_end - t)
    if box[BOX_ANY] != 0.0:
        # In a periodic box a contact is looked for at the nearest images now: no further ahead
        # than a body can move before another image could come nearer (a scene there has an end).
        horizon = min(horizon, periodic_reach(V, n, fp[FP_CAP]))
        small = NO
    tau = next_contact(G, P, V, n, t, WP, grav, dim, horizon, small, fp[FP_SLOW], scale, box)
    if tau <= horizon or (small == YES and tau < math.inf):
        if not min(t + tau, t_end) > t:
            # A contact due closer than the clock resolves lands on its next tick (see
            # run_island); one that still does not engage tick after tick (bodies far
            # from the origin, where positions are coarse) is refused, never a hang.
            ticks += 1
            if ticks > STALL_LIMIT:
                ST[S_STATUS] = STALL
                FG[F_STATUS_T] = t
                return t, t_end, search, ticks, True
            t = np.nextafter(t, math.inf)
            ST[S_JUMPS] += 1
            return t, t_end, search, ticks, False
        ticks = 0
        t = min(t + tau, t_end)
        ST[S_JUMPS] += 1
        search = 2.0 * tau if tau > 0 else search
        return t, t_end, search, ticks, False
    ST[S_JUMPS] += 1
    if t_end < math.inf:
        t = min(t + horizon, t_end)
        search *= 2.0
        return t, t_end, search, ticks, False
    tau = next_contact(G, P, V, n, t, WP, grav, dim, horizon, YES, fp[FP_SLOW], scale, box)
    if tau < math.inf:
        t += tau
        return t, t_end, search, ticks, False
    t = t_end = run_end(t, fp, IV, CNT)  # no contact ahead
    return t, t_end, search, ticks, True


@jit_inline
def _apart(P, i, j, box):
    """Body j's centre less body i's (at the nearest image in a periodic box)."""
    dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
    if box[BOX_ANY] != 0.0:
        dx, dy, dz = nearest(dx, dy, dz, box)
    return dx, dy, dz


@jit_inline
def image_shift(G, i, j, t, grav, box, out):
    """What takes body j's centre to its image nearest body i's at t, into out (3,)."""
    px, py, pz, _, _, _ = free_state(G, i, t, grav)
    qx, qy, qz, _, _, _ = free_state(G, j, t, grav)
    dx, dy, dz = qx - px, qy - py, qz - pz
    ex, ey, ez = nearest(dx, dy, dz, box)
    out[0], out[1], out[2] = ex - dx, ey - dy, ez - dz


@jit_inline
def any_above(values, cap):
    """Whether any value exceeds cap (a loop: numpy's max would make every cached load of the
    engine import numba's array maths, and with it scipy's linear algebra, 0.3 s of CPU)."""
    for k in range(values.shape[0]):
        if values[k] > cap:
            return True
    return False


@jit_inline
def periodic_reach(V, n, cap):
    """How long no two bodies close or part by more than 2 `cap`, at their speeds now (gravity
    cancels in their relative motion)."""
    fastest = 0.0
    for i in range(n):
        fastest = max(fastest, math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2))
    return cap / fastest if fastest > 0.0 else math.inf


@jit_call
def window_omega(G, eng, tables):
    """The stiffest engaged contact's angular frequency."""
    omega = 0.0
    ptab, wtab = tables
    for p in range(eng.shape[0]):
        i, j = eng[p, 0], eng[p, 1]
        mi = int(G[i, G_MAT])
        k = ptab[mi, int(G[j, G_MAT]), TP_K] if j >= 0 else wtab[mi, TP_K]
        omega = max(omega, math.sqrt(k * (G[i, G_IM] + (G[j, G_IM] if j >= 0 else 0.0))))
    return omega


@jit
def clusters(pairs, n):
    """Union-find parents of the bodies joined by `pairs` (walls, j < 0, join nothing)."""
    parent = np.arange(n)
    for k in range(pairs.shape[0]):
        if pairs[k, 1] >= 0:
            join(parent, pairs[k, 0], pairs[k, 1])
    return parent


@jit_part
def run_islands(G, GI, cand, parent, n, t, horizon, tables, SP, WP, grav, weights, fl, fp, bufs, CNT, ST, FG):
    """Every island of the window's candidates (bucketed by the island's root: a counting sort)
    run from t to t + horizon. Returns the buffers."""
    KN, RC, IV, OP = bufs
    count = np.zeros(n + 1, np.int64)
    for k in range(cand.shape[0]):
        count[root_of(parent, cand[k, 0]) + 1] += 1
    for i in range(n):
        count[i + 1] += count[i]
    fill = count.copy()
    order = np.empty(cand.shape[0], np.int64)
    for k in range(cand.shape[0]):
        r = root_of(parent, cand[k, 0])
        order[fill[r]] = k
        fill[r] += 1
    for r in range(n):
        k0, k1 = count[r], count[r + 1]
        if k1 == k0:
            continue
        Q = np.zeros((k1 - k0, 3), np.int64)
        QF = np.zeros((k1 - k0, NQF))
        for k in range(k0, k1):
            i, j = cand[order[k], 0], cand[order[k], 1]
            Q[k - k0, Q_I], Q[k - k0, Q_J] = i, j
            QF[k - k0, QF_REACH] = G[i, G_R] + (G[j, G_R] if j >= 0 else 0.0)
            if j >= 0 and fp[FP_BOX + BOX_ANY] != 0.0:
                image_shift(G, i, j, t, grav, fp[FP_BOX:FP_BOX + NBOX], QF[k - k0, QF_SH:QF_SH + 3])
        KN, RC, IV, OP = run_island(G, GI, Q, QF, t, t + horizon, tables, SP, WP, grav, weights, fl, fp,
                                    (KN, RC, IV, OP), CNT, ST, FG)
        if ST[S_STATUS] != OK:
            break
    return KN, RC, IV, OP


@jit_call
def restore_window(G, GI, KN, IV, OP, CNT, saved_G, saved_GI, saved_CNT, saved_OP, saved_flags, n):
    """Back to the window's start, to redo it."""
    for i in range(n):
        for d in range(NG):
            G[i, d] = saved_G[i, d]
        GI[i, 0], GI[i, 1] = saved_GI[i, 0], saved_GI[i, 1]
    for d in range(4):
        CNT[d] = saved_CNT[d]
    for k in range(CNT[CN_OPEN]):
        OP[k] = saved_OP[k]
        IV[OP[k], V_END] = math.nan
    for i in range(n):
        if GI[i, GI_KNOT] >= 0:
            KN[GI[i, GI_KNOT], K_FREE] = saved_flags[i]


@jit_part
def windows(G, GI, tables, WP, grav, weights, fl, fp, bufs, CNT, ST, FG):
    """Advance every body to the run's end (see the README's engine notes): jump to the next
    contact start while nothing touches; otherwise a window of islands. Returns the buffers and
    the final time."""
    KN, RC, IV, OP = bufs
    n = G.shape[0]
    dim = fl[FL_DIM]
    box = fp[FP_BOX:FP_BOX + NBOX]
    P = np.zeros((n, 3))
    V = np.zeros((n, 3))
    t = 0.0
    t_end = fp[FP_TEND]
    search = math.inf
    span = float(WINDOW_STEPS)  # the next window's length, in steps of its stiffest contact
    ticks = 0  # jumps in a row to a contact due within the clock's resolution
    graph = (np.arange(n), np.zeros(n), np.zeros(1, np.int64))
    # The tangential springs' stretches by pair (a wall w's column n + w): `spring`.
    SP = np.zeros((n, n + WP.shape[0]) if fl[FL_SPRING] else (1, 1))
    while ST[S_STATUS] == OK and t < t_end:
        fp[FP_NOW] = t
        fp[FP_NOW_STEPS] = ST[S_STEPS]
        positions_at(G, n, t, grav, P, V)
        eng = engaged_now(G, P, V, n, WP, grav, dim, box)
        if eng.shape[0] == 0:
            t, t_end, search, ticks, stop = jump(G, P, V, n, t, t_end, search, ticks, WP, grav, dim, fp, IV, CNT, ST,
                                                 FG, graph)
            if stop:
                break
            continue
        # A window: islands of the bodies that may meet within it.
        omega = window_omega(G, eng, tables)
        step_est = fp[FP_OMEGA_H] / omega if fl[FL_AUTO] else fp[FP_DT]
        horizon = min(span * step_est, t_end - t)
        saved_G = G.copy()
        saved_GI = GI.copy()
        saved_CNT = CNT.copy()
        saved_OP = OP[:CNT[CN_OPEN]].copy()
        saved_SP = SP.copy()
        saved_flags = np.zeros(n)
        for i in range(n):
            if GI[i, GI_KNOT] >= 0:
                saved_flags[i] = KN[GI[i, GI_KNOT], K_FREE]
        # The largest cluster of touching bodies: islands much bigger than it mean the window
        # is long enough for free bodies to chain up, and every step would cost the chain.
        touching = largest_set(clusters(eng, n), n)
        retries = 0
        safety = WINDOW_SAFETY
        halved = False
        P0 = P.copy()
        while True:
            cand, margin = window_candidates(G, P, V, n, eng, tables, horizon, safety, WP, grav, dim, box)
            parent = clusters(cand, n)
            if box[BOX_ANY] != 0.0 and any_above(margin, fp[FP_CAP]):
                # A body that may move further than this within the window could meet another
                # image than the nearest it was found at.
                horizon *= 0.5
                halved = True
                continue
            if largest_set(parent, n) > max(ISLAND_SLACK * touching, 16) and horizon > 4.0 * step_est:
                horizon *= 0.5
                halved = True
                continue
            # Not recorded: a recording's residuals are drawn where every body has a knot, at
            # window ends among others (two balls on a floor, apart: 8 such in 0.3 s, not 94).
            # A lone body stepped (a slip turning too fast for the closed form) then takes other
            # steps recorded than not: the two differ by the stepped path's own error. With a
            # given dt nothing repeats.
            lone = fl[FL_AUTO] and not fl[FL_RECORD] and lone_on_walls(cand, eng, n)
            if not lone and horizon > WINDOW_STEPS * step_est:
                # A window grown past WINDOW_STEPS while its bodies were each alone on a wall: now
                # something may come in.
                horizon = min(WINDOW_STEPS * step_est, t_end - t)
                halved = True
                continue
            KN, RC, IV, OP = run_islands(G, GI, cand, parent, n, t, horizon, tables, SP, WP, grav, weights, fl, fp,
                                         (KN, RC, IV, OP), CNT, ST, FG)
            if ST[S_STATUS] != OK or not missed_contact(G, P, V, n, t + horizon, cand, WP, grav, dim, P0, margin, box):
                break
            # A contact between islands: a speed bound failed. Redo the window, shorter and safer.
            ST[S_RETRIES] += 1
            retries += 1
            if retries > MAX_RETRIES:
                ST[S_STATUS] = STALL
                FG[F_STATUS_T], FG[F_STATUS_A] = t, 1.0
                break
            restore_window(G, GI, KN, IV, OP, CNT, saved_G, saved_GI, saved_CNT, saved_OP, saved_flags, n)
            SP[:] = saved_SP
            horizon *= 0.25
            safety *= 2.0
            positions_at(G, n, t, grav, P, V)
        t += horizon
        ST[S_WINDOWS] += 1
        search = math.inf
        # The next window starts from this one's length, or twice it if it was not cut: the
        # candidates of a window far too long cost most of a dense run (gas-box: 64 steps, its
        # islands spanning the box, halved to 16 in each of its windows, 3 candidate searches).
        span = min(LONE_WINDOW_STEPS if lone else WINDOW_STEPS,
                   horizon / step_est * (1.0 if halved or retries > 0 else 2.0))
    return KN, RC, IV, OP, t


@jit
def run_end(t, fp, IV, CNT):
    """When a run that ends by itself ends: a tail after the last separation (free flight since),
    or after t if nothing ever touched."""
    tail = tail_after(fp[FP_TAIL], IV, CNT)
    if CNT[CN_IVALS] == 0:
        return t + tail
    last = 0.0
    for k in range(CNT[CN_IVALS]):
        if IV[k, V_END] == IV[k, V_END]:
            last = max(last, IV[k, V_END])
    return last + tail
