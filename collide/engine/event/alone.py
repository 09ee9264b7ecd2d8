"""A sphere alone among walls under the laws beyond the report's (Hertz, the restitution's dashpot,
a tangential spring, rolling resistance):
`alone_run` flies it in closed form from wall to wall and takes each contact whole from
`impact.contact` at full order. It returns what `run.simulate` returns, so a run reads it the
same way.

With no friction the normal motion at a flat wall does not depend on the tangential one: during
a contact the sphere moves along the wall as in free flight (under gravity's part along it) and
along the normal as the 1-DOF contact, and its spin stays. A contact that does not separate
(gravity holds a slow, damped ball) goes on over time to the run's end. Two walls touched at
once are not this case: the run stops with ALONE_WALLS (its caller runs the DEM kernel or
refuses), as it does with ALONE_FAILED where a contact's steps did not converge.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.event.impact import (
    ENDED,
    NOUT,
    O_DELTA,
    O_DMAX,
    O_END,
    O_FMAX,
    O_STEPS,
    O_TIME,
    O_U,
    O_VOUT,
    O_WORK,
    P_STOP,
    STOPPED,
    contact,
    law,
)
from collide.engine.event.oblique import CHATTER, NY, YVT, YWB, frame, rub
from collide.engine.flight import bring, touch_time, turn
from collide.engine.jit import jit, jit_call
from collide.engine.layout import (
    CN_IVALS,
    CN_KNOTS,
    CN_RECS,
    F_DT_MIN,
    F_MAX_FORCE,
    F_MAX_OVERLAP,
    F_STATUS_A,
    F_STATUS_T,
    FL_MAXSTEPS,
    FL_PLANAR,
    FL_RECORD,
    FL_SPIN,
    FP_TAIL,
    FP_TEND,
    G_I,
    G_M,
    G_Q,
    G_R,
    G_S,
    G_TB,
    G_V,
    G_W,
    G_WK,
    K_AN,
    MAXSTEPS,
    NF,
    NK,
    NR,
    NS,
    OK,
    R_DELTA,
    R_FN,
    R_FX,
    R_FY,
    R_FZ,
    R_I,
    R_J,
    R_MODE,
    R_T,
    S_CONTACTS,
    S_JUMPS,
    S_STATUS,
    S_STEPS,
    V_END,
    V_I,
    V_J,
    V_START,
)
from collide.engine.numerics import grow
from collide.engine.records import put_knot, tail_after

# S_STATUS: a second wall within a contact; a contact not answered; spin about the wall's normal
# under rolling resistance; a rubbing contact's tangential motion not in one line; its stick and
# slip alternating without end (`oblique`)
ALONE_WALLS, ALONE_FAILED, ALONE_TWIST, ALONE_PLANE, ALONE_CHATTER = 16, 17, 18, 19, 20
NO_BOX = np.zeros(4)


@jit
def next_wall(G, WP, grav, t):
    """The first wall the sphere's free flight from t touches: (time from t, wall; inf, -1)."""
    best, wall = math.inf, -1
    for w in range(WP.shape[0]):
        tau = touch_time(G, 0, -1 - w, t, WP, grav, NO_BOX)
        if tau < best:
            best, wall = tau, w
    return best, wall


@jit
def clear_of(WP, w, s, vt, gt, span, depth):
    """Whether a contact on wall w from position s (touching it), moving along it at vt under gt
    for span seconds and pressed in by at most depth, stays clear of every other wall."""
    for o in range(WP.shape[0]):
        if o == w:
            continue
        n_o = WP[o, 3:6]
        gap = (s[0] - WP[o, 0]) * n_o[0] + (s[1] - WP[o, 1]) * n_o[1] + (s[2] - WP[o, 2]) * n_o[2]
        rate = vt[0] * n_o[0] + vt[1] * n_o[1] + vt[2] * n_o[2]
        acc = gt[0] * n_o[0] + gt[1] * n_o[1] + gt[2] * n_o[2]
        lowest = min(gap, gap + rate * span + 0.5 * acc * span * span)
        if acc > 0.0 and 0.0 < -rate / acc < span:
            lowest = min(lowest, gap - 0.5 * rate * rate / acc)
        tilt = abs(WP[w, 3] * n_o[0] + WP[w, 4] * n_o[1] + WP[w, 5] * n_o[2])
        if lowest - depth * tilt <= 0.0:  # (gap: of the centre; the radius is added by the caller)
            return False
    return True


@jit
def add_record(RC, CNT, t, w, delta, fn):
    RC = grow(RC, CNT[CN_RECS])
    put_record(RC, CNT, t, w, delta, fn)
    return RC


@jit_call
def put_record(RC, CNT, t, w, delta, fn):
    """`add_record` into an RC with room for it (called without reference counting)."""
    r = CNT[CN_RECS]
    for c in range(NR):
        RC[r, c] = 0.0
    RC[r, R_T], RC[r, R_I], RC[r, R_J], RC[r, R_DELTA], RC[r, R_FN] = t, 0.0, -1.0 - w, delta, fn
    CNT[CN_RECS] += 1


@jit
def knot(KN, CNT, G, t, free, acc, a_next):
    """A knot of the sphere's state in G at t: arriving under acc, leaving under a_next."""
    KN = grow(KN, CNT[CN_KNOTS])
    put_sphere_knot(KN, CNT, G, t, free, acc, a_next)
    return KN


@jit_call
def put_sphere_knot(KN, CNT, G, t, free, acc, a_next):
    """`knot` into a KN with room for it (called without reference counting)."""
    put_knot(KN, CNT, t, 0, free, G, 0, G_S, G_V, G_W, G_Q, acc, G[0, G_WK])
    for d in range(3):
        KN[CNT[CN_KNOTS] - 1, K_AN + d] = a_next[d]


@jit_call
def place(G, X, n, s0, vt, gt, tau, delta, u, fl):
    """X's row 0: the sphere of G (at the contact's touch) tau later, pressed delta into the wall
    of normal n at the rate u (along the wall as in free flight, its spin kept)."""
    for c in range(G.shape[1]):
        X[0, c] = G[0, c]
    for d in range(3):
        X[0, G_S + d] = s0[d] + vt[d] * tau + 0.5 * gt[d] * tau * tau - delta * n[d]
        X[0, G_V + d] = vt[d] + gt[d] * tau - u * n[d]
    if fl[FL_SPIN]:
        turn(X[0, G_Q:G_Q + 4], X[0, G_W], X[0, G_W + 1], X[0, G_W + 2], tau, fl[FL_PLANAR])


@jit
def contact_knots(KN, RC, CNT, G, X, P, n, s0, vt, gt, t, w, trail, ended, grav, fl):
    """A knot and a contact record after every step of the contact on wall w touched at t (G's
    state then), from its trail; the last knot of a contact that ended starts a free flight."""
    acc = np.empty(3)
    # Room for every step's knot and record at once, each then written in place (no growing nor
    # reference counting step by step).
    KN = grow(KN, CNT[CN_KNOTS] + len(trail))
    RC = grow(RC, CNT[CN_RECS] + len(trail))
    for k in range(len(trail)):
        tau, delta, u, work = trail[k]
        place(G, X, n, s0, vt, gt, tau, delta, u, fl)
        X[0, G_WK] = G[0, G_WK] + work
        fn = law(P, delta, u)[1]
        for d in range(3):
            acc[d] = grav[d] + fn / P[4] * n[d]
        last = ended and k == len(trail) - 1
        put_sphere_knot(KN, CNT, X, t + tau, 1.0 if last else 0.0, acc, grav if last else acc)
        put_record(RC, CNT, t + tau, w, delta, fn)
    return KN, RC


@jit
def take_contact(G, WP, LAW, grav, fl, w, t, t_end, ends, steps_left, out, trail, bufs, CNT):
    """The contact on wall w touched at t (G's base state there): the base state moved to its end
    (or t_end), knots and records of its steps where recording. Returns (end time, ok, clear,
    knots, records)."""
    KN, RC = bufs
    n = WP[w, 3:6].copy()
    vn = G[0, G_V] * n[0] + G[0, G_V + 1] * n[1] + G[0, G_V + 2] * n[2]
    gn = grav[0] * n[0] + grav[1] * n[1] + grav[2] * n[2]
    vt = np.empty(3)
    gt = np.empty(3)
    s0 = np.empty(3)
    for d in range(3):
        vt[d] = G[0, G_V + d] - vn * n[d]
        gt[d] = grav[d] - gn * n[d]
        s0[d] = G[0, G_S + d]
    P = LAW[w].copy()
    P[6] = -gn  # gravity pressing the contact
    P[P_STOP] = t_end - t
    contact(P, -vn, ends[0], ends[1], steps_left, out, trail)
    if out[O_END] != ENDED and out[O_END] != STOPPED:
        return t, False, True, KN, RC
    span = out[O_TIME]
    clear = clear_of_radius(WP, w, s0, vt, gt, span, out[O_DMAX], G[0, G_R])
    ended = out[O_END] == ENDED
    X = np.empty((1, G.shape[1]))
    if fl[FL_RECORD]:
        KN, RC = contact_knots(KN, RC, CNT, G, X, P, n, s0, vt, gt, t, w, trail, ended, grav, fl)
    place(G, X, n, s0, vt, gt, span, 0.0 if ended else out[O_DELTA], -out[O_VOUT] if ended else out[O_U], fl)
    for c in range(G.shape[1]):
        G[0, c] = X[0, c]
    G[0, G_TB] = t + span if ended else t_end
    G[0, G_WK] += out[O_WORK]
    return G[0, G_TB], True, clear, KN, RC


@jit
def rubbing_state(X, G, N, e, b, s0, row, fl):
    """X's row 0: the sphere of G (at a rubbing contact's touch) at `oblique.keep`'s trail row."""
    tau = row[0]
    wn = G[0, G_W] * N[0] + G[0, G_W + 1] * N[1] + G[0, G_W + 2] * N[2]
    for c in range(G.shape[1]):
        X[0, c] = G[0, c]
    for d in range(3):
        X[0, G_S + d] = s0[d] + row[4] * e[d] - row[1] * N[d]
        X[0, G_V + d] = row[5] * e[d] - row[2] * N[d]
        X[0, G_W + d] = wn * N[d] + row[7] * b[d]
    if fl[FL_SPIN] and tau > 0.0:  # about b by the angle turned, about N at its constant spin
        turn(X[0, G_Q:G_Q + 4], (row[6] * b[0]) / tau + wn * N[0], (row[6] * b[1]) / tau + wn * N[1],
             (row[6] * b[2]) / tau + wn * N[2], tau, fl[FL_PLANAR])
    X[0, G_WK] = G[0, G_WK] + row[3]


@jit
def take_rubbing(G, WP, LAW, TW, grav, fl, w, t, t_end, ends, steps_left, out, trail, rubbed, bufs, CNT):
    """`take_contact` with friction and a tangential spring, or rolling resistance (TW[w]: mu, k_t / k_n
    and its root, mu_r):
    the normal contact's peaks from `impact.contact`, the rest from `oblique.rub`. Returns as
    `take_contact`, and the status where it failed."""
    KN, RC = bufs
    N = WP[w, 3:6].copy()
    v, spin, s0 = G[0, G_V:G_V + 3].copy(), G[0, G_W:G_W + 3].copy(), G[0, G_S:G_S + 3].copy()
    P = LAW[w].copy()
    P[6] = -(grav[0] * N[0] + grav[1] * N[1] + grav[2] * N[2])
    P[P_STOP] = t_end - t
    v_in = -(v[0] * N[0] + v[1] * N[1] + v[2] * N[2])
    contact(P, v_in, ends[0], ends[1], steps_left, out, trail)  # the normal contact's landed peaks
    dmax, fmax, steps = out[O_DMAX], out[O_FMAX], out[O_STEPS]
    e, b, in_line = frame(N, v, spin, grav, G[0, G_R])
    if not in_line:
        return t, False, True, KN, RC, ALONE_PLANE
    if TW[w, 3] > 0.0 and spin[0] * N[0] + spin[1] * N[1] + spin[2] * N[2] != 0.0:
        return t, False, True, KN, RC, ALONE_TWIST
    T = np.array([TW[w, 0], TW[w, 1], TW[w, 2], G[0, G_M], G[0, G_I], G[0, G_R],
                  grav[0] * e[0] + grav[1] * e[1] + grav[2] * e[2], 1.0, 1.0, math.inf, 0.0, 0.0, 0.0, TW[w, 3], 0.0])
    y = np.zeros(NY)
    y[YVT] = v[0] * e[0] + v[1] * e[1] + v[2] * e[2]
    y[YWB] = spin[0] * b[0] + spin[1] * b[1] + spin[2] * b[2]
    # Steps by the stick's frequency, sqrt(k_t / k_n (1 + m r^2 / I)) times the normal one's (an
    # order-6 error grows as its sixth power), and half as many again (measured: 100 random impacts
    # at tol 1e-6 within 1e-6 of tol 1e-9, tests/engine/event/test_oblique.py)
    grow = 1.5 * max(1.0, math.sqrt(TW[w, 1] * (1.0 + G[0, G_M] * G[0, G_R] ** 2 / G[0, G_I])))
    rub(P, T, v_in, math.ceil(ends[2] * grow), math.ceil(ends[3] * grow), steps_left - steps, out, rubbed, y)
    out[O_DMAX], out[O_FMAX], out[O_STEPS] = dmax, fmax, out[O_STEPS] + steps
    if out[O_END] != ENDED and out[O_END] != STOPPED:
        return t, False, True, KN, RC, ALONE_CHATTER if out[O_END] == CHATTER else ALONE_FAILED
    X = np.empty((1, G.shape[1]))
    acc = np.empty(3)
    clear = True
    last = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for k in range(len(rubbed)):
        row = rubbed[k]
        rubbing_state(X, G, N, e, b, s0, row, fl)
        # each step's end clear of the other walls by the largest overlap and the way since the last
        way = abs(row[4] - last[4]) + abs(row[1] - last[1])
        clear = clear and clear_of_radius(WP, w, X[0, G_S:G_S + 3], np.zeros(3), np.zeros(3), 0.0, dmax + way,
                                          G[0, G_R])
        last = row
        if fl[FL_RECORD]:
            for d in range(3):
                acc[d] = grav[d] + (row[8] * N[d] + row[9] * e[d]) / G[0, G_M]
            end = out[O_END] == ENDED and k == len(rubbed) - 1
            KN = knot(KN, CNT, X, t + row[0], 1.0 if end else 0.0, acc, grav if end else acc)
            RC = add_record(RC, CNT, t + row[0], w, row[1], row[8])
            r = CNT[CN_RECS] - 1
            RC[r, R_FX], RC[r, R_FY], RC[r, R_FZ] = row[9] * e[0], row[9] * e[1], row[9] * e[2]
            RC[r, R_MODE] = row[10]
    for c in range(G.shape[1]):
        G[0, c] = X[0, c]
    G[0, G_TB] = t + out[O_TIME] if out[O_END] == ENDED else t_end
    return G[0, G_TB], True, clear, KN, RC, OK


@jit
def clear_of_radius(WP, w, s, vt, gt, span, depth, radius):
    """`clear_of` for a sphere of this radius centred at s."""
    moved = np.empty((WP.shape[0], 6))
    for o in range(WP.shape[0]):
        for d in range(3):
            moved[o, d] = WP[o, d] + radius * WP[o, 3 + d]  # each wall moved out by the radius
            moved[o, 3 + d] = WP[o, 3 + d]
    return clear_of(moved, w, s, vt, gt, span, depth)


@jit
def alone_run(G, WP, LAW, TW, grav, fl, fp, ends):
    """Run the sphere of G (one row) among the walls WP, the law of its contact with wall w in
    LAW[w] (impact.impact_params' P) and, where it rubs (a tangential spring with mu > 0, or
    rolling resistance), TW[w] (mu, k_t / k_n and its root, mu_r; mu and mu_r 0 where it does
    not), from time 0 to fp[FP_TEND] (or, with none, until it leaves
    every wall for good, and fp[FP_TAIL] or the usual tail after). ends: the steps over sigma
    at each end of a contact and per contact time between (impact.steps_for), then those of a
    rubbing contact (oblique.rub_steps). Returns (final
    time, knots, records, intervals, counters, figures) as `run.simulate`."""
    KN = np.empty((16, NK))
    RC = np.empty((16, NR))
    IV = np.empty((16, 4))
    CNT = np.zeros(4, np.int64)
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = math.inf
    record = fl[FL_RECORD]
    out = np.zeros(NOUT)
    trail = [(0.0, 0.0, 0.0, 0.0)]
    rubbed = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)]
    a_in = np.empty(3)
    t_end = fp[FP_TEND]
    t = 0.0
    if record:
        KN = knot(KN, CNT, G, 0.0, 1.0, grav, grav)
    while ST[S_STATUS] == OK:
        tau, w = next_wall(G, WP, grav, t)
        if not t + tau < t_end:
            break
        t += tau
        bring(G, 0, t, grav, fl)
        ST[S_JUMPS] += 1
        v_in = -(G[0, G_V] * WP[w, 3] + G[0, G_V + 1] * WP[w, 4] + G[0, G_V + 2] * WP[w, 5])
        f0 = law(LAW[w], 0.0, v_in)[1]
        for d in range(3):
            a_in[d] = grav[d] + f0 / LAW[w, 4] * WP[w, 3 + d]
        if record:
            KN = knot(KN, CNT, G, t, 0.0, grav, a_in)
            RC = add_record(RC, CNT, t, w, 0.0, f0)
        IV = grow(IV, CNT[CN_IVALS])
        row = CNT[CN_IVALS]
        IV[row, V_I], IV[row, V_J], IV[row, V_START], IV[row, V_END] = 0.0, -1.0 - w, t, t_end
        CNT[CN_IVALS] += 1
        ST[S_CONTACTS] += 1
        start = t
        failed = ALONE_FAILED
        if TW[w, 0] > 0.0 or TW[w, 3] > 0.0:
            t, ok, clear, KN, RC, failed = take_rubbing(G, WP, LAW, TW, grav, fl, w, t, t_end, ends,
                                                        fl[FL_MAXSTEPS] - ST[S_STEPS], out, trail, rubbed, (KN, RC),
                                                        CNT)
        else:
            t, ok, clear, KN, RC = take_contact(G, WP, LAW, grav, fl, w, t, t_end, ends, fl[FL_MAXSTEPS] - ST[S_STEPS],
                                                out, trail, (KN, RC), CNT)
        ST[S_STEPS] += int(out[O_STEPS])
        FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], out[O_DMAX])
        FG[F_MAX_FORCE] = max(FG[F_MAX_FORCE], out[O_FMAX])
        FG[F_DT_MIN] = min(FG[F_DT_MIN], out[O_TIME] / max(out[O_STEPS], 1.0))
        if not ok or not clear:
            ST[S_STATUS] = failed if not ok else ALONE_WALLS
            if not ok and ST[S_STEPS] >= fl[FL_MAXSTEPS]:
                ST[S_STATUS] = MAXSTEPS
            FG[F_STATUS_T], FG[F_STATUS_A] = start, w
            break
        if out[O_END] == ENDED:
            IV[row, V_END] = t
        if not t < t_end:
            break
    if t < t_end and ST[S_STATUS] == OK:
        t = t_end if t_end < math.inf else (IV[CNT[CN_IVALS] - 1, V_END] if CNT[CN_IVALS] else 0.0) + \
            tail_after(fp[FP_TAIL], IV, CNT)
        bring(G, 0, t, grav, fl)
        if record:
            KN = knot(KN, CNT, G, t, 1.0, grav, grav)
    # The buffers' filled rows, not copies of them: nothing writes to them after the run
    return t, KN[:CNT[CN_KNOTS]], RC[:CNT[CN_RECS]], IV[:CNT[CN_IVALS]], ST, FG
