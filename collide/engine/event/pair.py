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

With friction and a tangential spring (TW's mu > 0), or rolling resistance (TW's mu_r > 0), any
contact, head-on or oblique, is `oblique.rub`'s in the relative coordinate (`rub_pair`): the line
of centres turns as the spheres slide past each other, and each sphere's spin is its own (their
motion in one plane, as `oblique.frame` asks: else PAIR_PLANE). Rolling resistance acts against
their relative spin (the DEM kernel's w_i - w_j, its cap mu_r R* F_n with R* the reduced radius),
which must then lie along the plane's normal b (no relative twist about the line of centres:
else PAIR_TWIST).
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
from collide.engine.event.oblique import CHATTER, NY, YVT, YW2, YWB, frame, rub
from collide.engine.flight import bring, touch_time, turn
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
    R_FX,
    R_MODE,
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

# S_STATUS (after event/alone.py's): a contact not head-on; a contact not answered; a rubbing
# contact whose spins twist against each other under rolling resistance, that alternates between
# stick and slip without end, or whose motion is not in one plane (`oblique`)
PAIR_OBLIQUE, PAIR_FAILED, PAIR_TWIST, PAIR_CHATTER, PAIR_PLANE = 21, 22, 23, 24, 25
HEAD_ON = 1e-12  # relative velocity across the line of centres, over the approach speed, taken as none
NO_BOX = np.zeros(4)
NO_WALLS = np.zeros((0, 6))


@jit
def pair_knots(KN, CNT, G, t, free, force, grav):
    """A knot of each sphere of G at t: the contact force on sphere 1 (3), on sphere 0 its
    reverse; free: whether they leave it in free flight."""
    acc = np.empty(3)
    for b in range(2):
        sign = 1.0 if b == 1 else -1.0
        for d in range(3):
            acc[d] = grav[d] + sign * force[d] / G[b, G_M]
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
def rubbing_pair(X, G0, n, e, b, row, grav, fl):
    """X: the spheres of G0 (at a rubbing contact's touch) at `oblique.keep`'s trail row: their
    centre of mass in free flight, the line of centres turned by the row's angle in the plane of
    n and e, each spin's part about b the row's and the rest kept; the work shared evenly."""
    tau = row[0]
    m0, m1 = G0[0, G_M], G0[1, G_M]
    total = m0 + m1
    for k in range(2):
        for c in range(G0.shape[1]):
            X[k, c] = G0[k, c]
        bring(X, k, G0[k, G_TB] + tau, grav, fl)
    turned, gap = row[4], G0[0, G_R] + G0[1, G_R] - row[1]
    cos, sin = math.cos(turned), math.sin(turned)
    for d in range(3):
        nd, ed = cos * n[d] + sin * e[d], cos * e[d] - sin * n[d]
        cm = (m0 * X[0, G_S + d] + m1 * X[1, G_S + d]) / total
        vcm = (m0 * X[0, G_V + d] + m1 * X[1, G_V + d]) / total
        rel = -row[2] * nd + row[5] * ed
        X[0, G_S + d], X[1, G_S + d] = cm - m1 / total * gap * nd, cm + m0 / total * gap * nd
        X[0, G_V + d], X[1, G_V + d] = vcm - m1 / total * rel, vcm + m0 / total * rel
    for k in range(2):
        spin, angle = (row[11], row[12]) if k == 0 else (row[7], row[6])
        wb = G0[k, G_W] * b[0] + G0[k, G_W + 1] * b[1] + G0[k, G_W + 2] * b[2]
        for d in range(3):
            X[k, G_W + d] = G0[k, G_W + d] + (spin - wb) * b[d]
            X[k, G_Q + d] = G0[k, G_Q + d]
        X[k, G_Q + 3] = G0[k, G_Q + 3]
        if fl[FL_SPIN] and tau > 0.0:  # about b by the angle turned, the rest at its constant spin
            rest = angle / tau - wb
            turn(X[k, G_Q:G_Q + 4], G0[k, G_W] + rest * b[0], G0[k, G_W + 1] + rest * b[1],
                 G0[k, G_W + 2] + rest * b[2], tau, fl[FL_PLANAR])
        X[k, G_WK] = G0[k, G_WK] + 0.5 * row[3]


@jit
def rub_pair(G, P, TW, n, t, ends, steps_left, out, rubbed, grav, fl, bufs, CNT):
    """The spheres' contact from touching (G at t, n from sphere 0 to 1) with friction and a
    tangential spring, or rolling resistance (TW[0]: mu, k_t / k_n and its root, mu_r) by
    `oblique.rub` in the relative coordinate, sphere 1 as its sphere and sphere 0's spin its
    second; G left at the contact's end (or P_STOP). Returns (knots, records, status), out as
    `rub` leaves it with the peaks of its steps."""
    KN, RC = bufs
    rel, comb = np.empty(3), np.empty(3)
    r0, r1 = G[0, G_R], G[1, G_R]
    for d in range(3):
        rel[d] = G[1, G_V + d] - G[0, G_V + d]
        comb[d] = G[1, G_W + d] + r0 / r1 * G[0, G_W + d]  # the slip's spin part as one sphere's
    e, b, in_line = frame(n, rel, comb, np.zeros(3), r1)
    scale = math.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2) + 1e-300
    for k in range(2):
        we = G[k, G_W] * e[0] + G[k, G_W + 1] * e[1] + G[k, G_W + 2] * e[2]
        in_line = in_line and G[k, G_R] * abs(we) <= 1e-12 * (scale + G[k, G_R] * abs(we))
    if not in_line:
        return KN, RC, PAIR_PLANE
    twist, size = 0.0, scale
    for d in range(3):
        twist += (G[1, G_W + d] - G[0, G_W + d]) * n[d]
    for k in range(2):
        size += G[k, G_R] * math.sqrt(G[k, G_W] ** 2 + G[k, G_W + 1] ** 2 + G[k, G_W + 2] ** 2)
    if TW[0, 3] > 0.0 and (r0 + r1) * abs(twist) > 1e-12 * size:  # (as `frame`'s one line: round-off)
        return KN, RC, PAIR_TWIST
    m0, m1, i0, i1 = G[0, G_M], G[1, G_M], G[0, G_I], G[1, G_I]
    mstar = m0 * m1 / (m0 + m1)
    T = np.array([TW[0, 0], TW[0, 1], TW[0, 2], mstar, i1, r1, 0.0, 1.0, 0.5, i0, r0, r0 + r1, 0.0, TW[0, 3], 0.0])
    y = np.zeros(NY)
    y[YVT] = rel[0] * e[0] + rel[1] * e[1] + rel[2] * e[2]
    y[YWB] = G[1, G_W] * b[0] + G[1, G_W + 1] * b[1] + G[1, G_W + 2] * b[2]
    y[YW2] = G[0, G_W] * b[0] + G[0, G_W + 1] * b[1] + G[0, G_W + 2] * b[2]
    v_in = -(rel[0] * n[0] + rel[1] * n[1] + rel[2] * n[2])
    # Steps as `alone.take_rubbing`'s, by the stick's frequency over the normal one's
    grow = 1.5 * max(1.0, math.sqrt(TW[0, 1] * (1.0 + mstar * (r1 * r1 / i1 + r0 * r0 / i0))))
    if fl[FL_RECORD]:
        f0 = law(P, 0.0, v_in)[1]
        KN = pair_knots(KN, CNT, G, t, 0.0, f0 * n, grav)
        RC = add_record(RC, CNT, t, -2, 0.0, f0)
    rub(P, T, v_in, math.ceil(ends[2] * grow), math.ceil(ends[3] * grow), steps_left, out, rubbed, y)
    if out[O_END] != ENDED and out[O_END] != STOPPED:
        return KN, RC, (PAIR_CHATTER if out[O_END] == CHATTER else PAIR_FAILED)
    X = np.empty_like(G)
    force = np.empty(3)
    out[O_DMAX], out[O_FMAX] = 0.0, 0.0
    for k in range(len(rubbed)):
        row = rubbed[k]
        out[O_DMAX], out[O_FMAX] = max(out[O_DMAX], row[1]), max(out[O_FMAX], row[8])
        if fl[FL_RECORD]:
            rubbing_pair(X, G, n, e, b, row, grav, fl)
            cos, sin = math.cos(row[4]), math.sin(row[4])
            for d in range(3):
                force[d] = row[8] * (cos * n[d] + sin * e[d]) + row[9] * (cos * e[d] - sin * n[d])
            end = out[O_END] == ENDED and k == len(rubbed) - 1
            KN = pair_knots(KN, CNT, X, t + row[0], 1.0 if end else 0.0, force, grav)
            RC = add_record(RC, CNT, t + row[0], -2, row[1], row[8])
            r = CNT[CN_RECS] - 1
            for d in range(3):  # the friction on sphere 0 (the DEM kernel's records: on i)
                RC[r, R_FX + d] = -row[9] * (cos * e[d] - sin * n[d])
            RC[r, R_MODE] = row[10]
    rubbing_pair(X, G, n, e, b, rubbed[len(rubbed) - 1], grav, fl)
    for k in range(2):
        for c in range(G.shape[1]):
            G[k, c] = X[k, c]
    return KN, RC, OK


@jit
def pair_run(G, LAW, TW, grav, fl, fp, ends):
    """Run the two spheres of G (two rows) from time 0 to fp[FP_TEND] (or, with none, their
    contact's end and fp[FP_TAIL] or the usual tail after), the law of their contact in LAW
    (impact.impact_params' P, with m* and R*), their tangential spring and rolling resistance in
    TW (1, 4: mu, k_t / k_n and its root, mu_r; mu 0: no spring, mu_r 0: no rolling resistance).
    ends: as `alone.alone_run`'s. Returns (final time, knots, records, intervals, counters,
    figures) as `run.simulate`."""
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
        KN = pair_knots(KN, CNT, G, 0.0, 1.0, n, grav)
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
        P = LAW[0].copy()
        P[P_STOP] = t_end - t
        if TW[0, 0] > 0.0 or TW[0, 3] > 0.0:
            out = np.zeros(NOUT)
            rubbed = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)]
            KN, RC, status = rub_pair(G, P, TW, n, t, ends, fl[FL_MAXSTEPS], out, rubbed, grav, fl, (KN, RC), CNT)
            ST[S_STEPS] = int(out[O_STEPS])
            FG[F_MAX_OVERLAP], FG[F_MAX_FORCE] = out[O_DMAX], out[O_FMAX]
            FG[F_DT_MIN] = out[O_TIME] / max(out[O_STEPS], 1.0)
            if status != OK:
                ST[S_STATUS] = MAXSTEPS if ST[S_STEPS] >= fl[FL_MAXSTEPS] else status
                return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:1].copy(), ST, FG
            t = t + out[O_TIME] if out[O_END] == ENDED else t_end
            if out[O_END] == ENDED:
                IV[0, V_END] = t
            return _pair_end(G, t, t_end, IV, KN, RC, CNT, ST, FG, n, grav, fp, fl)
        if across > HEAD_ON * v_in:
            ST[S_STATUS] = PAIR_OBLIQUE
            return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:1].copy(), ST, FG
        f0 = law(P, 0.0, v_in)[1]
        if record:
            KN = pair_knots(KN, CNT, G, t, 0.0, f0 * n, grav)
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
                KN = pair_knots(KN, CNT, X, t + tk, 1.0 if last else 0.0, fn * n, grav)
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
    return _pair_end(G, t, t_end, IV, KN, RC, CNT, ST, FG, n, grav, fp, fl)


@jit
def _pair_end(G, t, t_end, IV, KN, RC, CNT, ST, FG, n, grav, fp, fl):
    """`pair_run`'s flight from its contact's end to the run's, and what it returns."""
    final = t_end if t_end < math.inf else (IV[0, V_END] if CNT[CN_IVALS] else 0.0) + tail_after(fp[FP_TAIL], IV, CNT)
    if final > G[0, G_TB]:
        bring(G, 0, final, grav, fl)
        bring(G, 1, final, grav, fl)
        if fl[FL_RECORD]:
            KN = pair_knots(KN, CNT, G, final, 1.0, 0.0 * n, grav)
    return final, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG
