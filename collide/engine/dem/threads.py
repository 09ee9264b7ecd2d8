"""The force pass and the kicks on several threads, bit for bit as on one (`collide.dem_threads`
drives them; each kernel releases the GIL and works on one thread's share).

The bodies are split into contiguous ranges, one a thread, balanced by bodies, pairs and wall
contacts (`plan`). Each pair (i, j), i < j, is worked out by the thread that owns j; the pair list
is sorted by i. A pair whose i is another thread's (a "cross" pair: a few where the bodies are
numbered in space, as a filled box) gives i's share to a buffer. A step:

1. `weights` then `inbound_pass`: each thread sets its bodies' forces to their weights, then works
   out its inbound cross pairs in the list's order: j's share added to its own rows, i's share
   into the buffer, every element of it written once onto -0.0 (adding -0.0 changes nothing, not
   even a zero's sign); then it raises its flag (`barrier.raise_flag`);
2. `own_pass`: its pairs whose i is its own, in the list's order, the outgoing cross pairs' i
   shares taken from the buffer once the threads that work them out have raised their flags
   (waited for at the first such pair: in a box numbered in space the pairs at the end of a
   thread's range, long done), then its bodies' wall contacts; then it kicks its bodies;
3. every thread meets at the barrier, the one meeting of a step: the step's figures (contacts,
   energy, distance moved) are summed from the threads' rows and the next step may read any body.

Every body's force, torque and parts then receive the same additions in the same order as in
the one-thread pass (`forces.forces`: weight, pairs in key order (a j's inbound pairs, whose i
are lower, before its own), walls), so the sums are equal bit for bit whatever the number of
threads (tests/engine/dem/test_threads.py).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import BOX_ANY, NBOX
from collide.engine.dem.barrier import barrier_wait, raise_flag, wait_flag
from collide.engine.dem.contact import contact_force, contact_into
from collide.engine.dem.forces import _close, _peak, pair_gap
from collide.engine.dem.geometry import wall_height
from collide.engine.dem.layout import (
    B_II,
    B_IM,
    B_M,
    B_R,
    F_DIM,
    F_MAXSTEPS,
    F_RECORD,
    F_SPIN,
    G_FIRST,
    G_FORCE,
    G_LAST,
    G_OVERLAP,
    G_TOUCH,
    H_IV,
    H_KT,
    H_ON,
    H_PEAK,
    H_XI,
    NPT,
    P_BOX,
    P_DT,
    P_NOW,
    P_NOW_KINETIC,
    P_NOW_PEAK,
    P_NOW_STEPS,
    P_REST,
    P_SKIN,
    P_TEND,
    S_CONTACTS,
)
from collide.engine.dem.loop import _step_length
from collide.engine.dem.neighbours import first_row, take_slot
from collide.engine.dem.verlet import _drift_body, _half_kick, kick_kick_drift, kinetic_parts
from collide.engine.jit import jit, jit_inline

# A cross pair's buffer row, i's share: force (3), friction torque (3), rolling torque (3), parts
# (NPT).
XF, XT, XTR, XPT = 0, 3, 6, 9
NX = 9 + int(NPT)
# A cross pair's state in a step (SF): not engaged, engaged, engaged and opened, closed.
IDLE, ENGAGED, OPENED, CLOSED = 0, 1, 2, 3
# A thread's figures of a step (STT rows): engaged, opened, closed, deepest, strongest, kinetic
# energy, moved, whether it fused the kicks, events (pairs, walls).
ST_ENG, ST_OPEN, ST_CLOSE, ST_DEEP, ST_STRONG, ST_E, ST_MOVED, ST_FUSED, ST_EVP, ST_EVW = range(10)
NST = 10
# A row's length in STT: padded to 192 bytes, so that no two threads' rows share a cache line
# (each thread counts its contacts into its row as it goes).
NST_ROW = 24


@jit
def plan(PI, WL, n, cut):
    """The threads' shares of a pair list: body bounds, pair bounds (by i) and wall bounds, each
    (threads + 1,), and each thread's work: its bodies, the pairs whose i is its own and its
    wall contacts (the pairs it works out are those whose j is its own: as many, but for the
    few that join two shares, where the bodies are numbered in space; `dem_threads._Balance`
    learns what the count misses). Thread t's share of the whole ends at the fraction cut[t + 1]
    (cut: (threads + 1,), from 0 to 1). Binary searches in the sorted lists, no pass over them:
    the driver's part of a plan; the passes over the pairs are the threads' (`plan_count`,
    `plan_cross`)."""
    threads = cut.shape[0] - 1
    total = n + PI.shape[0] + WL.shape[0]
    bounds = np.zeros(threads + 1, np.int64)
    bounds[threads] = n
    for t in range(1, threads):
        lo, hi = bounds[t - 1], n
        while lo < hi:  # the first body whose work before it reaches the cut
            mid = (lo + hi) // 2
            if _work_before(PI, WL, mid) < cut[t] * total:
                lo = mid + 1
            else:
                hi = mid
        bounds[t] = lo
    kb = np.empty(threads + 1, np.int64)
    wb = np.empty(threads + 1, np.int64)
    shares = np.empty(threads, np.int64)
    for t in range(threads + 1):
        kb[t] = first_row(PI, bounds[t])
        wb[t] = first_row(WL[:, 1], bounds[t])
    for t in range(threads):
        shares[t] = (bounds[t + 1] - bounds[t]) + (kb[t + 1] - kb[t]) + (wb[t + 1] - wb[t])
    return bounds, kb, wb, shares


@jit_inline
def _work_before(PI, WL, a):
    return a + first_row(PI, a) + first_row(WL[:, 1], a)


@jit_inline
def _owner(bounds, r, j):
    """The share of body j, at or past share r."""
    while bounds[r + 1] <= j:
        r += 1
    return r


@jit
def plan_count(PJ, bounds, kb, r, CNT):
    """Thread r's pairs (those whose i is its own) counted by the share of their j into CNT[r]."""
    count = np.zeros(CNT.shape[1], np.int64)  # (a row of its own: no line shared with another thread)
    for k in range(kb[r], kb[r + 1]):
        count[_owner(bounds, r, PJ[k])] += 1
    CNT[r, :] = count


@jit
def plan_slots(CNT):
    """From every thread's counts (`plan_count`): bounds of each thread's cross-pair slots by i
    ("outgoing", sb) and by j ("inbound", ib), each (threads + 1,); where thread r's cross pairs
    with each share's j start in the inbound slots (AT: (threads, threads)); and the slot
    regions' starts (`neighbours.slot_regions`: the pairs whose j is in each share, before
    it)."""
    threads = CNT.shape[0]
    sb = np.zeros(threads + 1, np.int64)
    ib = np.zeros(threads + 1, np.int64)
    starts = np.zeros(threads + 1, np.int64)
    for r in range(threads):
        for q in range(threads):
            starts[q + 1] += CNT[r, q]
            if q != r:
                sb[r + 1] += CNT[r, q]
                ib[q + 1] += CNT[r, q]
    for r in range(threads):
        sb[r + 1] += sb[r]
        ib[r + 1] += ib[r]
        starts[r + 1] += starts[r]
    AT = np.zeros((threads, threads), np.int64)
    for q in range(threads):
        at = ib[q]
        for r in range(threads):
            if r != q:
                AT[r, q] = at
                at += CNT[r, q]
    return sb, ib, AT, starts


@jit
def plan_cross(PJ, bounds, kb, r, sb, AT, cross, inbound):
    """Thread r's cross pairs (its i, another's j): each slot's pair into cross from sb[r] on (the
    slots in the list's order), and the slot into the inbound slots of its j's share (each
    share's in the list's order), from AT[r]."""
    at = AT[r].copy()
    s = sb[r]
    for k in range(kb[r], kb[r + 1]):
        q = _owner(bounds, r, PJ[k])
        if q != r:
            cross[s] = k
            inbound[at[q]] = s
            at[q] += 1
            s += 1


@jit_inline
def _open_here(hist, k):
    """Start contact k's history as `forces._open` does (its interval row, if recorded, and the
    run's counts are set after the pass, by `events` and the driver)."""
    hist[k, H_ON] = 1.0
    for c in range(3):
        hist[k, H_XI + c] = 0.0
    hist[k, H_KT] = 0.0
    hist[k, H_PEAK + 1] = -math.inf
    hist[k, H_IV] = -1.0


@jit_inline
def _close_here(hist, k):
    """End contact k's phase as `forces._close` does when nothing is recorded."""
    hist[k, H_ON] = 0.0
    for c in range(4):
        hist[k, H_XI + c] = 0.0
    hist[k, H_IV] = -1.0


@jit_inline
def _begin(hist, k, record, STT, row):
    """A contact engaged: opened if it was not (counted). Returns whether it opened."""
    if hist[k, H_ON] != 0.0:
        return False
    _open_here(hist, k)
    STT[row, ST_OPEN] += 1.0
    return True


@jit_inline
def _end(hist, k, record, STT, row):
    """A contact no longer engaged: its phase closed now, or after the pass if recorded (its
    peak and interval rows). Returns whether it was engaged."""
    if hist[k, H_ON] == 0.0:
        return False
    if not record:
        _close_here(hist, k)
    STT[row, ST_CLOSE] += 1.0
    return True


@jit_inline
def _begin_pair(PS, HS, BB, BUMP, k, j, record, STT, row):
    """`_begin` for listed pair k (second body j), whose history is row PS[k] of HS (a slot
    taken if it has none: `neighbours.take_slot`). Returns (its slot, whether it opened)."""
    s = PS[k]
    if s >= 0 and HS[s, H_ON] != 0.0:
        return s, False
    s = take_slot(PS, BUMP, BB, k, j)
    HS[s, H_ON] = 0.0  # (a slot just taken holds nothing yet)
    return s, _begin(HS, s, record, STT, row)


@jit_inline
def _end_pair(PS, HS, k, record, STT, row):
    """`_end` for listed pair k (one never engaged since the lists were built has no slot)."""
    return PS[k] >= 0 and _end(HS, PS[k], record, STT, row)


@jit_inline
def _engaged(tally, delta, fn):
    """A pass's tally (engaged, deepest, strongest) with one more engaged contact: kept in locals
    and written to the thread's row once a pass (`_keep`), as `forces.forces` keeps its own, not
    read and written through the row at every contact."""
    return tally[0] + 1.0, max(tally[1], delta), max(tally[2], fn)


@jit_inline
def _tally(STT, row):
    return STT[row, ST_ENG], STT[row, ST_DEEP], STT[row, ST_STRONG]


@jit_inline
def _keep(STT, row, tally):
    STT[row, ST_ENG], STT[row, ST_DEEP], STT[row, ST_STRONG] = tally[0], tally[1], tally[2]


@jit
def inbound_pass(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, tabs, fl, dt, t, record, q0, q1, inbound, cross,
                 XB, SF, STT, row, out, box):
    """Thread `row`'s inbound cross pairs (inbound[q0:q1]: those whose j is its own, in the
    list's order): j's share added to its rows of F, T and PT (after its weight, before its
    own pairs, as in the one-thread pass), i's into XB, the pair's state into SF (a pair in a
    periodic box at its nearest images). Two copies, the nearest-image test folded away in the
    one without (as `forces.forces`)."""
    if box[BOX_ANY] != 0.0:
        _inbound(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, tabs, fl, dt, t, record, q0, q1, inbound,
                 cross, XB, SF, STT, row, out, box, True)
    else:
        _inbound(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, tabs, fl, dt, t, record, q0, q1, inbound,
                 cross, XB, SF, STT, row, out, box, False)


@jit_inline
def _inbound(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, tabs, fl, dt, t, record, q0, q1, inbound, cross, XB,
             SF, STT, row, out, box, periodic):
    tally = _tally(STT, row)
    for q in range(q0, q1):
        s = inbound[q]
        k = cross[s]
        i, j = PI[k], PJ[k]
        SF[s] = IDLE
        apart, dx, dy, dz, d2, reach = pair_gap(X, Bd, i, j, box, periodic)
        if apart:
            if _end_pair(PS, HS, k, record, STT, row):
                SF[s] = CLOSED
            continue
        dist = math.sqrt(d2)
        inv = 1.0 / dist
        delta = reach - dist
        hs, opened = _begin_pair(PS, HS, BB, BUMP, k, j, record, STT, row)
        SF[s] = OPENED if opened else ENGAGED
        XB[s, :] = -0.0
        side = XB[s:s + 1]
        fn = contact_into(X, V, W, side[:, XF:XF + 3], side[:, XT:XT + 3], side[:, XTR:XTR + 3], side[:, XPT:], 0,
                          F, T, T, PT, j, Bd, i, j, dx * inv, dy * inv, dz * inv, delta, tabs, MAT[i], MAT[j], HS, hs,
                          fl, dt, out)
        tally = _engaged(tally, delta, fn)
        if record:
            _peak(HS, hs, t, delta, fn, out)
    _keep(STT, row, tally)


@jit
def weights(F, T, PT, Bd, grav, lo, hi):
    """Bodies lo..hi's forces set to their weights, torques and parts to zero, as `forces.forces`
    starts (one fill of the share's rows, as it fills all)."""
    g0, g1, g2 = grav[0], grav[1], grav[2]
    T[lo:hi, :] = 0.0
    PT[lo:hi, :] = 0.0
    for a in range(lo, hi):
        m = Bd[a, B_M]
        F[a, 0], F[a, 1], F[a, 2] = m * g0, m * g1, m * g2


@jit_inline
def _take(XB, s, F, T, PT, a):
    """A cross pair's share for its body i, added in the one-thread pass's order (friction
    torque, rolling torque, force and parts)."""
    for d in range(3):
        T[a, d] += XB[s, XT + d]
    for d in range(3):
        T[a, d] += XB[s, XTR + d]
    for d in range(3):
        F[a, d] += XB[s, XF + d]
    for c in range(NPT):
        PT[a, c] += XB[s, XPT + c]


@jit
def own_pass(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wtabs, fl, dt, t, record,
             bd, row, XB, SF, STT, EVP, EVW, out, box, meet):
    """Thread `row`'s bodies' forces (`_own`), in two copies as `inbound_pass`."""
    if box[BOX_ANY] != 0.0:
        _own(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wtabs, fl, dt, t, record,
             bd, row, XB, SF, STT, EVP, EVW, out, box, meet, True)
    else:
        _own(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wtabs, fl, dt, t, record,
             bd, row, XB, SF, STT, EVP, EVW, out, box, meet, False)


@jit_inline
def _own(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wtabs, fl, dt, t, record, bd,
         row, XB, SF, STT, EVP, EVW, out, box, meet, periodic):
    """Thread `row`'s own pairs (those whose i and j are its own), and its outgoing cross pairs'
    i shares from XB once the threads that work them out have raised their flags (`meet`: the
    thread's row of the barrier; waited for at the first such pair, and so before any of its
    bodies that another thread reads moves), in the list's order, after its inbound pairs; then
    its bodies' wall contacts (bd: its body, pair, wall and slot starts, then ends). Events
    (pairs: 2 k, + 1 if closed; walls: 2 m, + 1) go to EVP from the thread's first pair and EVW
    from its first wall contact, if recorded."""
    hi, k0, k1, m0, m1, s = bd[1], bd[2], bd[3], bd[4], bd[5], bd[6]
    nw = 0
    tally = _tally(STT, row)
    waited = False
    for k in range(k0, k1):
        i, j = PI[k], PJ[k]
        if j >= hi:
            if not waited:
                for other in range(row + 1, STT.shape[0]):
                    wait_flag(meet, other)
                waited = True
            state = SF[s]
            if state == ENGAGED or state == OPENED:
                _take(XB, s, F, T, PT, i)
            if record and (state == OPENED or state == CLOSED):
                EVP[k0 + nw] = 2 * k + (state == CLOSED)
                nw += 1
            s += 1
            continue
        apart, dx, dy, dz, d2, reach = pair_gap(X, Bd, i, j, box, periodic)
        if apart:
            if _end_pair(PS, HS, k, record, STT, row) and record:
                EVP[k0 + nw] = 2 * k + 1
                nw += 1
            continue
        dist = math.sqrt(d2)
        inv = 1.0 / dist
        hs, opened = _begin_pair(PS, HS, BB, BUMP, k, j, record, STT, row)
        if opened and record:
            EVP[k0 + nw] = 2 * k
            nw += 1
        delta = reach - dist
        fn = contact_force(X, V, W, F, T, PT, Bd, i, j, dx * inv, dy * inv, dz * inv, delta, tabs, MAT[i], MAT[j],
                           HS, hs, fl, dt, out)
        tally = _engaged(tally, delta, fn)
        if record:
            _peak(HS, hs, t, delta, fn, out)
    _keep(STT, row, tally)
    STT[row, ST_EVP] = nw
    STT[row, ST_EVW] = _walls(X, V, W, F, T, PT, Bd, MAT, WL, WH, WP, wtabs, fl, dt, t, record, m0, m1, STT, row,
                              EVW, out)


@jit_inline
def _walls(X, V, W, F, T, PT, Bd, MAT, WL, WH, WP, wtabs, fl, dt, t, record, m0, m1, STT, row, EVW, out):
    """Body-wall contacts m0..m1 (as `forces.forces`). Returns the events written to EVW."""
    nw = 0
    tally = _tally(STT, row)
    for m in range(m0, m1):
        k, i, w = WL[m, 0], WL[m, 1], WL[m, 2]
        delta = Bd[i, B_R] - wall_height(X, WP, i, w)
        if delta <= 0.0:
            if _end(WH, k, record, STT, row) and record:
                EVW[m0 + nw] = 2 * m + 1
                nw += 1
            continue
        if _begin(WH, k, record, STT, row) and record:
            EVW[m0 + nw] = 2 * m
            nw += 1
        fn = contact_force(X, V, W, F, T, PT, Bd, i, -1 - w, -WP[w, 3], -WP[w, 4], -WP[w, 5], delta, wtabs, MAT[i], 0,
                           WH, k, fl, dt, out)
        tally = _engaged(tally, delta, fn)
        if record:
            _peak(WH, k, t, delta, fn, out)
    _keep(STT, row, tally)
    return nw


@jit
def events(EVP, EVW, kb, wb, STT, PI, PJ, WL, PS, HS, WH, IV, niv, REC, nrec, t, FG):
    """The recorded contacts' starts and ends of a step, in the one-thread pass's order (pairs
    by key, then walls): interval rows, and closed phases' peaks (IV and REC have room).
    Returns (niv, nrec)."""
    threads = STT.shape[0]
    for table in range(2):
        for r in range(threads):
            first = kb[r] if table == 0 else wb[r]
            count = np.int64(STT[r, ST_EVP + table])
            for q in range(first, first + count):
                if table == 0:
                    e = EVP[q]
                    k = PS[e >> 1]
                    i, j = PI[e >> 1], PJ[e >> 1]
                    H = HS
                else:
                    e = EVW[q]
                    k, i, j = WL[e >> 1, 0], WL[e >> 1, 1], -1 - WL[e >> 1, 2]
                    H = WH
                if e & 1:
                    nrec = _close(H, k, IV, t, FG, REC, nrec, i, j)
                else:
                    IV[niv, 0], IV[niv, 1], IV[niv, 2], IV[niv, 3] = i, j, t, np.nan
                    H[k, H_IV] = niv
                    niv += 1
    return niv, nrec


@jit
def kick_share(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, lo, hi, rolling, spin, planar, close, fuse, EB,
               STT, row):
    """Bodies lo..hi: the closing half kick h_close (if `close`) and the next step's opening half
    kick h_open and drift h (if `fuse`), body by body as `verlet.kick_kick_drift` makes them. Into
    STT: the kinetic energy after the closing kick (each body's also into EB (N, 2) if it has
    rows), the largest squared distance from X0 after the drift, and whether it drifted. The
    usual case (both kicks, no body's energy kept) is the one-thread loop's own pass
    (`verlet.kick_kick_drift` on the share's range): a copy of it here, its tests folded in
    another way, took 13 % longer."""
    if close and fuse and EB.shape[0] == 0:
        e, moved = kick_kick_drift(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, lo, hi, rolling, spin,
                                   planar)
        STT[row, ST_E] = e
        STT[row, ST_FUSED] = 1.0
        STT[row, ST_MOVED] = max(STT[row, ST_MOVED], moved)
    else:
        _kicks(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, lo, hi, rolling, spin, planar, close, fuse, EB,
               EB.shape[0] > 0, STT, row)


@jit_inline
def _kicks(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, lo, hi, rolling, spin, planar, close, fuse, EB, keep,
           STT, row):
    e = 0.0
    moved = 0.0
    for a in range(lo, hi):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2]
        if close:
            v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_close, im, ii, spins, F, T, PT, rolling, v0, v1, v2, w0, w1,
                                                w2)
            lin, rot = kinetic_parts(Bd, a, v0, v1, v2, w0, w1, w2)
            e += lin
            e += rot
            if keep:
                EB[a, 0], EB[a, 1] = lin, rot
        if fuse:
            v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_open, im, ii, spins, F, T, PT, rolling, v0, v1, v2, w0, w1,
                                                w2)
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        if fuse:
            moved = max(moved, _drift_body(X, X0, Qo, a, v0, v1, v2, w0, w1, w2, h, spin, planar))
    if close:  # (a late drift leaves the row's figures as the other threads read them)
        STT[row, ST_E] = e
        STT[row, ST_FUSED] = 1.0 if fuse else 0.0
    STT[row, ST_MOVED] = max(STT[row, ST_MOVED], moved)


@jit
def energy_sum(EB, n):
    """The kinetic energy summed body by body, as `verlet.kick` sums it."""
    e = 0.0
    for a in range(n):
        e += EB[a, 0]
        e += EB[a, 1]
    return e


# The run's state between `run_share` calls (CTL): time, steps, whether the last step fused the
# next one's opening kick and drift, the squared distance moved, the next frame's time, the
# kinetic energy's peak, whether anything touched yet, contacts engaged, interval and record
# rows, the last kinetic energy, why the call returned, whether this step's opening kick and
# drift are done (the call returned to rebuild or grow), whether to step on without coasting.
(C_T, C_STEPS, C_FUSED, C_MOVED, C_NEXT, C_PEAK, C_EVER, C_ENGAGED, C_NIV, C_NREC, C_KIN, C_REASON, C_OPENED,
 C_STAY) = range(14)
NCTL = 14
# Why `run_share` returned: to coast (nothing touches), the end, to rebuild the lists, to record a
# frame (the step done on one thread), to grow IV and REC, non-finite numbers, the step limit,
# rest, to ask whether anything can meet again (no end set), the last step done.
(R_COAST, R_END, R_REBUILD, R_RECORD, R_GROW, R_NONFINITE, R_MAXSTEPS, R_REST, R_MEET, R_LAST) = range(10)


@jit_inline
def _sum_col(S, c):
    total = 0.0
    for r in range(S.shape[0]):
        total += S[r, c]
    return total


@jit_inline
def _max_col(S, c):
    best = 0.0
    for r in range(S.shape[0]):
        best = max(best, S[r, c])
    return best


@jit
def _figures(S, ST, FG, t, record):
    """A step's contact counts and figures from the threads' rows S, as `forces.forces` keeps them."""
    opened = np.int64(_sum_col(S, ST_OPEN))
    ST[S_CONTACTS] += opened
    if opened > 0 and not FG[G_FIRST] <= t:
        FG[G_FIRST] = t
    if not record and _sum_col(S, ST_CLOSE) > 0.0:
        FG[G_LAST] = t
    FG[G_OVERLAP] = max(FG[G_OVERLAP], _max_col(S, ST_DEEP))
    FG[G_FORCE] = max(FG[G_FORCE], _max_col(S, ST_STRONG))


@jit
def run_share(r, barrier, X, X0, V, W, Qo, F, T, PT, Bd, MAT, WK, PI, PJ, PS, HS, SBB, BUMP, WL, WH, WP, tabs,
              wtabs, grav, fl, fp, rolling, ST, FG, IV, REC, RB, kb, wb, cross, inbound, XB, SF, EVP, EVW, EB, STT, PM,
              outs, CTL):
    """Thread r's part of the run's steps (every thread runs it at once, with the same control
    flow, meeting at `barrier` once a step, at its end), from the state in CTL until the run
    needs what only the driver does (`dem_threads`: coasting, rebuilding the lists, recording a
    frame, growing IV and REC) or ends. STT (2, threads, NST) and PM (2, threads) alternate
    between steps, so that no thread writes a row another may still read. Thread 0 keeps the
    run's figures and writes CTL back. New contacts take their slots from the regions SBB,
    BUMP (`neighbours.take_slot`), which are the list's whatever the threads that run this
    stretch (the all-threads plan's)."""
    threads = STT.shape[1]
    n = X.shape[0]
    dt, t_end, rest, skin = fp[P_DT], fp[P_TEND], fp[P_REST], fp[P_SKIN]
    spin, planar, record = fl[F_SPIN], fl[F_DIM] < 3, fl[F_RECORD] != 0
    t, steps, fused, moved = CTL[C_T], np.int64(CTL[C_STEPS]), CTL[C_FUSED] != 0.0, CTL[C_MOVED]
    next_frame, peak, ever, engaged = CTL[C_NEXT], CTL[C_PEAK], CTL[C_EVER] != 0.0, np.int64(CTL[C_ENGAGED])
    niv, nrec, kinetic_now = np.int64(CTL[C_NIV]), np.int64(CTL[C_NREC]), CTL[C_KIN]
    opened, stay = CTL[C_OPENED] != 0.0, CTL[C_STAY] != 0.0
    lo, hi = RB[r, 0], RB[r, 1]
    box = fp[P_BOX:P_BOX + NBOX]
    reason = R_END
    while True:
        if engaged == 0 and not opened and not stay:
            reason = R_COAST
            break
        stay = False
        h, last = _step_length(t, dt, t_end)
        if h <= 0.0:
            reason = R_END
            break
        p = (steps + 1) & 1  # this step's rows
        if not opened:
            if not fused:
                PM[p, r] = _open_share(X, X0, V, W, Qo, F, T, PT, Bd, WK, 0.5 * h, h, lo, hi, rolling, spin, planar)
                barrier_wait(barrier)
                moved = 0.0
                for q in range(threads):
                    moved = max(moved, PM[p, q])
            if 4.0 * moved > skin * skin:
                reason = R_REBUILD
                break
        opened = False
        if record and (t + h >= next_frame or last):
            reason = R_RECORD
            break
        most = PI.shape[0] + WL.shape[0]
        if record and (niv + most >= IV.shape[0] or nrec + most >= REC.shape[0]):
            reason = R_GROW
            break
        t = t + h
        steps += 1
        h_next, _ = _step_length(t, dt, t_end)
        fuse_ok = not last and h_next > 0.0 and rest <= 0.0 and steps < fl[F_MAXSTEPS]
        S = STT[p]
        S[r, :] = 0.0
        weights(F, T, PT, Bd, grav, lo, hi)
        inbound_pass(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, SBB, BUMP, tabs, fl, h, t, record, RB[r, 8],
                     RB[r, 9], inbound, cross, XB, SF, S, r, outs[r], box)
        raise_flag(barrier)
        own_pass(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, SBB, BUMP, WL, WH, WP, tabs, wtabs, fl, h, t,
                 record, RB[r], r, XB, SF, S, EVP, EVW, outs[r], box, barrier)
        kick_share(X, X0, V, W, Qo, F, T, PT, Bd, WK, 0.5 * h, 0.5 * h_next, h_next, lo, hi, rolling, spin, planar,
                   True, fuse_ok and S[r, ST_ENG] > 0.0, EB, S, r)
        barrier_wait(barrier)
        engaged = np.int64(_sum_col(S, ST_ENG))
        fused = engaged != 0 and fuse_ok
        behind = False  # a share with no contact of its own did not know it could drift
        for q in range(threads):
            behind |= fused and S[q, ST_FUSED] == 0.0
        if behind and S[r, ST_FUSED] == 0.0:
            kick_share(X, X0, V, W, Qo, F, T, PT, Bd, WK, 0.5 * h, 0.5 * h_next, h_next, lo, hi, rolling, spin,
                       planar, False, True, EB, S, r)
        kinetic_now = energy_sum(EB, n) if rest > 0.0 else _sum_col(S, ST_E)
        if r == 0:
            _figures(S, ST, FG, t, record)
            if record:
                niv, nrec = events(EVP, EVW, kb, wb, S, PI, PJ, WL, PS, HS, WH, IV, niv, REC, nrec, t, FG)
                CTL[C_NIV], CTL[C_NREC] = niv, nrec
            if engaged:
                FG[G_TOUCH] += h
            if steps & 255 == 0:
                fp[P_NOW] = t
                fp[P_NOW_STEPS] = steps
                fp[P_NOW_KINETIC] = kinetic_now
                fp[P_NOW_PEAK] = max(peak, kinetic_now)
        if behind or record:  # the late drifts, thread 0's contact starts and ends: seen by all
            barrier_wait(barrier)
            niv, nrec = np.int64(CTL[C_NIV]), np.int64(CTL[C_NREC])
        moved = _max_col(S, ST_MOVED)
        if engaged:
            ever = True
        if not math.isfinite(kinetic_now):
            reason = R_NONFINITE
            break
        peak = max(peak, kinetic_now)
        if steps >= fl[F_MAXSTEPS]:
            reason = R_MAXSTEPS
            break
        if rest > 0.0 and ever and kinetic_now < rest * peak:
            reason = R_REST
            break
        if not math.isfinite(t_end) and ever and engaged == 0:
            reason = R_MEET
            break
        if last:
            reason = R_LAST
            break
    if r == 0:
        CTL[C_T], CTL[C_STEPS], CTL[C_FUSED], CTL[C_MOVED] = t, steps, 1.0 if fused else 0.0, moved
        CTL[C_NEXT], CTL[C_PEAK], CTL[C_EVER], CTL[C_ENGAGED] = next_frame, peak, 1.0 if ever else 0.0, engaged
        CTL[C_NIV], CTL[C_NREC], CTL[C_KIN], CTL[C_REASON] = niv, nrec, kinetic_now, reason
        CTL[C_OPENED] = 1.0 if reason == R_REBUILD or reason == R_RECORD or reason == R_GROW else 0.0


@jit_inline
def _open_share(X, X0, V, W, Qo, F, T, PT, Bd, WK, h2, h, lo, hi, rolling, spin, planar):
    """Bodies lo..hi's opening half kick h2 and drift h (as `verlet.kick` then `verlet.drift`).
    Returns the largest squared distance from X0."""
    moved = 0.0
    for a in range(lo, hi):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h2, im, ii, spins, F, T, PT, rolling,
                                            V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        moved = max(moved, _drift_body(X, X0, Qo, a, v0, v1, v2, w0, w1, w2, h, spin, planar))
    return moved
