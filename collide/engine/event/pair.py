"""Two spheres alone (no walls) under the laws beyond the report's (Hertz, the restitution's
dashpot), without friction: `pair_run` flies both in closed form and takes their contact whole
from `impact.contact` at full order, in the relative coordinate. It returns what `run.simulate`
returns, so a run reads it the same way.

Between two frictionless spheres the force is central and gravity cancels in their relative
motion, so the contact is the 1-DOF normal contact of the reduced mass m* = m_i m_j / (m_i + m_j)
and radius R* = r_i r_j / (r_i + r_j) while the line of centres keeps its direction: head-on (no
relative velocity across that line at touching; a grazing contact turns the line, and the run
stops with PAIR_OBLIQUE, its caller running the DEM kernel or refusing). Their centre of mass
flies on under gravity; after separating they never meet again.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.event.alone import add_record
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
from collide.engine.flight import bring, touch_time
from collide.engine.jit import jit
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
    FL_RECORD,
    FP_TAIL,
    FP_TEND,
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
from collide.engine.records import add_knot, tail_after

PAIR_OBLIQUE, PAIR_FAILED = 21, 22  # S_STATUS (after event/alone.py's): a contact not head-on; a contact not answered
HEAD_ON = 1e-12  # relative velocity across the line of centres, over the approach speed, taken as none
NO_BOX = np.zeros(4)
NO_WALLS = np.zeros((0, 6))


@jit
def pair_knots(KN, CNT, G, t, free, fn, n, grav):
    """A knot of each sphere of G at t: the contact force fn pushes them apart along n (from
    sphere 0 to sphere 1); free: whether they leave it in free flight."""
    acc = np.empty(3)
    for b in range(2):
        sign = 1.0 if b == 1 else -1.0
        for d in range(3):
            acc[d] = grav[d] + sign * fn / G[b, G_M] * n[d]
        KN = add_knot(KN, CNT, t, b, free, G, b, G_S, G_V, G_W, G_Q, acc, G[b, G_WK])
        if free:
            for d in range(3):
                KN[CNT[CN_KNOTS] - 1, K_AN + d] = grav[d]  # leaving in free flight
    return KN


@jit
def place_pair(G, X, G0, n, tau, delta, u, work, grav, fl):
    """X: the spheres of G0 (at touching) tau later, pressed delta together at the rate u along
    n, their centre of mass in free flight and each spin kept; the dashpot's work shared evenly."""
    for b in range(2):
        for c in range(G0.shape[1]):
            X[b, c] = G0[b, c]
        bring(X, b, G0[b, G_TB] + tau, grav, fl)
    m0, m1 = G0[0, G_M], G0[1, G_M]
    total = m0 + m1
    gap = G0[0, G_R] + G0[1, G_R] - delta
    for d in range(3):
        cm = (m0 * X[0, G_S + d] + m1 * X[1, G_S + d]) / total
        vcm = (m0 * X[0, G_V + d] + m1 * X[1, G_V + d]) / total
        X[0, G_S + d], X[1, G_S + d] = cm - m1 / total * gap * n[d], cm + m0 / total * gap * n[d]
        X[0, G_V + d], X[1, G_V + d] = vcm + m1 / total * u * n[d], vcm - m0 / total * u * n[d]
    X[0, G_WK] = G0[0, G_WK] + 0.5 * work
    X[1, G_WK] = G0[1, G_WK] + 0.5 * work


@jit
def approach(G, n):
    """(normal approach speed, speed across the line of centres) of the spheres of G along n."""
    vn, across = 0.0, 0.0
    for d in range(3):
        vn += (G[0, G_V + d] - G[1, G_V + d]) * n[d]
    for d in range(3):
        rel = G[1, G_V + d] - G[0, G_V + d] + vn * n[d]
        across += rel * rel
    return vn, math.sqrt(across)


@jit
def pair_run(G, LAW, grav, fl, fp, ends):
    """Run the two spheres of G (two rows) from time 0 to fp[FP_TEND] (or, with none, their
    contact's end and fp[FP_TAIL] or the usual tail after), the law of their contact in LAW
    (impact.impact_params' P, with m* and R*). ends: as `alone.alone_run`'s. Returns (final time,
    knots, records, intervals, counters, figures) as `run.simulate`."""
    KN = np.empty((16, NK))
    RC = np.empty((16, NR))
    IV = np.empty((16, 4))
    CNT = np.zeros(4, np.int64)
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = math.inf
    record = fl[FL_RECORD]
    t_end = fp[FP_TEND]
    n = np.zeros(3)
    if record:
        KN = pair_knots(KN, CNT, G, 0.0, 1.0, 0.0, n, grav)
    tau = touch_time(G, 0, 1, 0.0, NO_WALLS, grav, NO_BOX)
    t = tau
    if t < t_end:
        bring(G, 0, t, grav, fl)
        bring(G, 1, t, grav, fl)
        ST[S_JUMPS] += 1
        dist = 0.0
        for d in range(3):
            n[d] = G[1, G_S + d] - G[0, G_S + d]
            dist += n[d] * n[d]
        for d in range(3):
            n[d] /= math.sqrt(dist)
        v_in, across = approach(G, n)
        IV = grow(IV, 0)
        IV[0, V_I], IV[0, V_J], IV[0, V_START], IV[0, V_END] = 0.0, 1.0, t, t_end
        CNT[CN_IVALS] = 1
        ST[S_CONTACTS] = 1
        FG[F_STATUS_T], FG[F_STATUS_A] = t, 1.0
        if across > HEAD_ON * v_in:
            ST[S_STATUS] = PAIR_OBLIQUE
            return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:1].copy(), ST, FG
        P = LAW[0].copy()
        P[P_STOP] = t_end - t
        f0 = law(P, 0.0, v_in)[1]
        if record:
            KN = pair_knots(KN, CNT, G, t, 0.0, f0, n, grav)
            RC = add_record(RC, CNT, t, -2, 0.0, f0)  # (j = -1 - w: sphere 1)
        out = np.zeros(NOUT)
        trail = [(0.0, 0.0, 0.0, 0.0)]
        contact(P, v_in, ends[0], ends[1], fl[FL_MAXSTEPS], out, trail)
        ST[S_STEPS] = int(out[O_STEPS])
        FG[F_MAX_OVERLAP], FG[F_MAX_FORCE] = out[O_DMAX], out[O_FMAX]
        FG[F_DT_MIN] = out[O_TIME] / max(out[O_STEPS], 1.0)
        if out[O_END] != ENDED and out[O_END] != STOPPED:
            ST[S_STATUS] = MAXSTEPS if ST[S_STEPS] >= fl[FL_MAXSTEPS] else PAIR_FAILED
            return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:1].copy(), ST, FG
        ended = out[O_END] == ENDED
        X = np.empty_like(G)
        if record:
            for k in range(len(trail)):
                tk, delta, u, work = trail[k]
                place_pair(G, X, G, n, tk, delta, u, work, grav, fl)
                fn = law(P, delta, u)[1]
                last = ended and k == len(trail) - 1
                KN = pair_knots(KN, CNT, X, t + tk, 1.0 if last else 0.0, fn, n, grav)
                RC = add_record(RC, CNT, t + tk, -2, delta, fn)
        span = out[O_TIME]
        place_pair(G, X, G, n, span, 0.0 if ended else out[O_DELTA], -out[O_VOUT] if ended else out[O_U], out[O_WORK],
                   grav, fl)
        for b in range(2):
            for c in range(G.shape[1]):
                G[b, c] = X[b, c]
        t = t + span if ended else t_end
        if ended:
            IV[0, V_END] = t
    final = t_end if t_end < math.inf else (IV[0, V_END] if CNT[CN_IVALS] else 0.0) + tail_after(fp[FP_TAIL], IV, CNT)
    if final > G[0, G_TB]:
        bring(G, 0, final, grav, fl)
        bring(G, 1, final, grav, fl)
        if record:
            KN = pair_knots(KN, CNT, G, final, 1.0, 0.0, n, grav)
    return final, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG
