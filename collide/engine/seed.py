"""The report's own update (section III), on its fixed grid: springs clamped at zero overlap,
the report's friction, one kick-drift-kick per step (`seed_run`, the `seed` integrator).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import NBOX, near_pairs
from collide.engine.flight import account_contacts, bring, meets_again, next_contact, positions_at, speed_scales, turn
from collide.engine.jit import jit
from collide.engine.layout import (
    CN_IVALS,
    CN_KNOTS,
    CN_RECS,
    F_DT_MIN,
    F_MAX_OVERLAP,
    F_STATUS_T,
    FL_DIM,
    FL_FRICTION,
    FL_MAXSTEPS,
    FL_PLANAR,
    FL_RECORD,
    FL_SEED,
    FL_SPIN,
    FP_DT,
    FP_END_SLOW,
    FP_NOW,
    FP_NOW_STEPS,
    FP_SLOW,
    FP_TAIL,
    FP_TEND,
    G_I,
    G_II,
    G_IM,
    G_M,
    G_MAT,
    G_Q,
    G_R,
    G_S,
    G_TB,
    G_V,
    G_W,
    G_WK,
    K_AN,
    K_FREE,
    K_T,
    MAXSTEPS,
    NF,
    NK,
    NONFINITE,
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
    S_STATUS,
    S_STEPS,
    SLIDE,
    STALL,
    TP_EPS,
    TP_K,
    TP_MU,
    V_END,
    V_I,
    V_J,
    V_START,
    YES,
)
from collide.engine.numerics import grow
from collide.engine.records import add_knot, tail_after


@jit
def seed_forces(G, pairs, WP, grav, tables, fl, force, facc, alp, RC, CNT, t_rec):
    """The report's forces at the bodies' base states: springs clamped at zero overlap, and
    friction mu F_n against the slip when it exceeds eps (explicit), the slip measured with the
    slip lever and the torque applied at the contact point. Fills force (springs), facc
    (friction, as accelerations) and alp, records each pressed contact at t_rec (when
    recording); returns the largest overlap and the records."""
    ptab, wtab = tables
    n = G.shape[0]
    seed, spin, fric = fl[FL_SEED], fl[FL_SPIN], fl[FL_FRICTION]
    for i in range(n):
        for d in range(3):
            force[i, d] = 0.0
            facc[i, d] = 0.0
            alp[i, d] = 0.0
    top = 0.0
    npair = pairs.shape[0]
    for p in range(npair + n * WP.shape[0]):
        if p < npair:
            i, j = pairs[p, 0], pairs[p, 1]
        else:
            i, j = (p - npair) % n, -1 - (p - npair) // n
        r = G[i, G_R]
        mi = int(G[i, G_MAT])
        if j >= 0:
            dx, dy, dz = G[j, G_S] - G[i, G_S], G[j, G_S + 1] - G[i, G_S + 1], G[j, G_S + 2] - G[i, G_S + 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            nx, ny, nz = dx / dist, dy / dist, dz / dist
            delta = r + G[j, G_R] - dist
            mj = int(G[j, G_MAT])
            k, mu, eps = ptab[mi, mj, TP_K], ptab[mi, mj, TP_MU], ptab[mi, mj, TP_EPS]
            half = 0.5 * delta
        else:
            w = -1 - j
            dist = (G[i, G_S] - WP[w, 0]) * WP[w, 3] + (G[i, G_S + 1] - WP[w, 1]) * WP[w, 4] + \
                (G[i, G_S + 2] - WP[w, 2]) * WP[w, 5]
            nx, ny, nz = -WP[w, 3], -WP[w, 4], -WP[w, 5]
            delta = r - dist
            k, mu, eps = wtab[mi, TP_K], wtab[mi, TP_MU], wtab[mi, TP_EPS]
            half = delta
        if delta <= 0.0:
            continue
        top = max(top, delta)
        fn = k * delta
        if fl[FL_RECORD]:
            RC = grow(RC, CNT[CN_RECS])
            row = CNT[CN_RECS]
            RC[row, R_T], RC[row, R_I], RC[row, R_J] = t_rec, i, j
            RC[row, R_DELTA], RC[row, R_FN] = delta, fn
            RC[row, R_FX], RC[row, R_FY], RC[row, R_FZ], RC[row, R_MODE] = 0.0, 0.0, 0.0, 0.0
            CNT[CN_RECS] += 1
        force[i, 0] -= fn * nx
        force[i, 1] -= fn * ny
        force[i, 2] -= fn * nz
        if j >= 0:
            force[j, 0] += fn * nx
            force[j, 1] += fn * ny
            force[j, 2] += fn * nz
        if not fric:
            continue
        lif = r - half
        ljf = G[j, G_R] - half if j >= 0 else 0.0
        lis = r if seed else lif
        ljs = (G[j, G_R] if seed else ljf) if j >= 0 else 0.0
        rx, ry, rz = G[i, G_V], G[i, G_V + 1], G[i, G_V + 2]
        lx, ly, lz = lis * G[i, G_W], lis * G[i, G_W + 1], lis * G[i, G_W + 2]
        if j >= 0:
            rx, ry, rz = rx - G[j, G_V], ry - G[j, G_V + 1], rz - G[j, G_V + 2]
            lx, ly, lz = lx + ljs * G[j, G_W], ly + ljs * G[j, G_W + 1], lz + ljs * G[j, G_W + 2]
        rn = rx * nx + ry * ny + rz * nz
        sx = rx - rn * nx + ly * nz - lz * ny
        sy = ry - rn * ny + lz * nx - lx * nz
        sz = rz - rn * nz + lx * ny - ly * nx
        mag = math.sqrt(sx * sx + sy * sy + sz * sz)
        if not mag > eps:
            continue
        f = -mu * fn / mag
        fx, fy, fz = f * sx, f * sy, f * sz
        if fl[FL_RECORD]:
            row = CNT[CN_RECS] - 1
            RC[row, R_FX], RC[row, R_FY], RC[row, R_FZ], RC[row, R_MODE] = fx, fy, fz, SLIDE
        cx, cy, cz = ny * fz - nz * fy, nz * fx - nx * fz, nx * fy - ny * fx
        facc[i, 0] += fx * G[i, G_IM]
        facc[i, 1] += fy * G[i, G_IM]
        facc[i, 2] += fz * G[i, G_IM]
        if spin:
            alp[i, 0] += lif * G[i, G_II] * cx
            alp[i, 1] += lif * G[i, G_II] * cy
            alp[i, 2] += lif * G[i, G_II] * cz
        if j >= 0:
            facc[j, 0] -= fx * G[j, G_IM]
            facc[j, 1] -= fy * G[j, G_IM]
            facc[j, 2] -= fz * G[j, G_IM]
            if spin:
                alp[j, 0] += ljf * G[j, G_II] * cx
                alp[j, 1] += ljf * G[j, G_II] * cy
                alp[j, 2] += ljf * G[j, G_II] * cz
    return top, RC


@jit
def seed_run(G, tables, WP, grav, fl, fp):
    """The report's update on its grid of dt: forces from the current state, then w += alpha dt,
    s += v dt + a dt^2 / 2, v += a dt (first order; it reproduces the report's tables). Free
    flight between contacts jumps whole steps in closed form, so every step lands on the grid.
    Returns what `simulate` returns."""
    n = G.shape[0]
    dim = fl[FL_DIM]
    dt = fp[FP_DT]
    spin, planar, record = fl[FL_SPIN], fl[FL_PLANAR], fl[FL_RECORD]
    KN = np.empty((max(64, 4 * n), NK))
    RC = np.empty((64, NR))
    IV = np.empty((16, 4))
    CNT = np.zeros(4, np.int64)
    parent, count, seen = np.arange(n), np.zeros(n), np.zeros(1, np.int64)  # account_contacts
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = dt
    P = np.zeros((n, 3))
    V = np.zeros((n, 3))
    force = np.zeros((n, 3))
    facc = np.zeros((n, 3))
    alp = np.zeros((n, 3))
    acc = np.zeros((n, 3))
    g3, box = np.zeros(3), np.zeros(NBOX)  # no box, writable as the event engine's (NO_BOX: a 2nd compile)
    for d in range(3):
        g3[d] = grav[d]
    knot_of = np.zeros(n, np.int64)
    if record:
        for i in range(n):
            KN = add_knot(KN, CNT, 0.0, i, 1.0, G, i, G_S, G_V, G_W, G_Q, g3, 0.0)
            knot_of[i] = i
    t = 0.0
    t_end = fp[FP_TEND]
    in_contact = False
    # Free flights count against the step limit: far out in time the positions may no longer
    # resolve a step's approach (the cradle at tol 3e-4 met its balls again at t = 1.5e5 s and
    # flew there one step at a time without end).
    flights = 0

    while t < t_end * (1 - 1e-15) and ST[S_STATUS] == OK:
        fp[FP_NOW] = t
        fp[FP_NOW_STEPS] = ST[S_STEPS]
        positions_at(G, n, t, grav, P, V)
        margin = np.zeros(n)
        for i in range(n):
            margin[i] = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) * dt + 1e-12 * G[i, G_R]
        pairs = near_pairs(P, G[:, G_R], margin, n, dim, box)
        for i in range(n):
            bring(G, i, t, grav, fl)
        top, RC = seed_forces(G, pairs, WP, grav, tables, fl, force, facc, alp, RC, CNT, t + dt)
        if top > 0.0:
            if not in_contact:
                in_contact = True

                IV = grow(IV, CNT[CN_IVALS])
                IV[CNT[CN_IVALS], V_I] = -1.0
                IV[CNT[CN_IVALS], V_J] = -1.0
                IV[CNT[CN_IVALS], V_START] = t
                IV[CNT[CN_IVALS], V_END] = math.nan
                CNT[CN_IVALS] += 1
                ST[S_CONTACTS] += 1
            FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], top)
            before = 0.0
            after = 0.0
            for i in range(n):
                for d in range(3):
                    acc[i, d] = force[i, d] * G[i, G_IM] + grav[d] + facc[i, d]
            # Work against friction: what the friction kick removes at the start of the step.
            for i in range(n):
                for d in range(3):
                    vm = G[i, G_V + d] + facc[i, d] * dt
                    before += 0.5 * G[i, G_M] * G[i, G_V + d] ** 2
                    after += 0.5 * G[i, G_M] * vm * vm
                    if spin:
                        before += 0.5 * G[i, G_I] * G[i, G_W + d] ** 2
                        after += 0.5 * G[i, G_I] * (G[i, G_W + d] + alp[i, d] * dt) ** 2
            work = before - after
            if record:
                # A knot where the step starts (within a seed step the motion is exactly
                # quadratic: the step's acceleration on both of its sides).
                for i in range(n):
                    last = knot_of[i]
                    if KN[last, K_T] < t:
                        KN = add_knot(KN, CNT, t, i, 0.0, G, i, G_S, G_V, G_W, G_Q, g3, G[i, G_WK])
                        last = CNT[CN_KNOTS] - 1
                        knot_of[i] = last
                    KN[last, K_FREE] = 0.0
                    for d in range(3):
                        KN[last, K_AN + d] = acc[i, d]
            for i in range(n):
                w0x, w0y, w0z = G[i, G_W], G[i, G_W + 1], G[i, G_W + 2]
                for d in range(3):
                    G[i, G_W + d] += alp[i, d] * dt
                    G[i, G_S + d] += G[i, G_V + d] * dt + 0.5 * acc[i, d] * dt * dt
                    G[i, G_V + d] += acc[i, d] * dt
                if spin:
                    turn(G[i, G_Q:G_Q + 4], 0.5 * (w0x + G[i, G_W]), 0.5 * (w0y + G[i, G_W + 1]),
                         0.5 * (w0z + G[i, G_W + 2]), dt, planar)
                G[i, G_WK] += work / n
                G[i, G_TB] = t + dt
            t += dt
            ST[S_STEPS] += 1
            if ST[S_STEPS] > fl[FL_MAXSTEPS]:
                ST[S_STATUS] = MAXSTEPS
            for i in range(n):
                for d in range(6):
                    if not math.isfinite(G[i, G_S + d]):
                        ST[S_STATUS] = NONFINITE
            if record:
                for i in range(n):
                    KN = add_knot(KN, CNT, t, i, 0.0, G, i, G_S, G_V, G_W, G_Q, acc[i], G[i, G_WK])
                    knot_of[i] = CNT[CN_KNOTS] - 1
            continue
        if in_contact:
            in_contact = False
            IV[CNT[CN_IVALS] - 1, V_END] = t
            if record:
                for i in range(n):
                    KN[knot_of[i], K_FREE] = 1.0
                    for d in range(3):
                        KN[knot_of[i], K_AN + d] = grav[d]
        # Free flight: whole steps in closed form, up to the step in which a contact begins.
        positions_at(G, n, t, grav, P, V)
        account_contacts(IV, CNT, parent, count, seen)
        scale = speed_scales(V, n, parent)
        tau = next_contact(G, P, V, n, t, WP, grav, dim, math.inf, YES, fp[FP_SLOW], scale, box)
        tail = math.ceil(tail_after(fp[FP_TAIL], IV, CNT) / dt) * dt if t_end == math.inf else 0.0
        if (tau < math.inf and t_end == math.inf and CNT[CN_IVALS] > 0 and fp[FP_END_SLOW] > 0.0
                and not meets_again(G, P, V, n, t, WP, grav, count, fp[FP_SLOW], fp[FP_END_SLOW], tail, scale, box)):
            tau = math.inf  # closes slower than the run resolves: the step's error (as `windows`)
        if tau == math.inf and t_end == math.inf:
            t_end = t + tail
        jump = min(math.floor(tau / dt) * dt if tau < math.inf else math.inf, t_end - t)
        if jump <= 0.0:
            jump = dt  # a contact begins within this step: take it with the spring clamped
            for i in range(n):
                bring(G, i, t + dt, grav, fl)
        flights += 1
        if not t + jump > t or ST[S_STEPS] + flights > fl[FL_MAXSTEPS]:
            ST[S_STATUS] = STALL
            FG[F_STATUS_T] = t
            break
        t += jump
    for i in range(n):
        bring(G, i, t, grav, fl)
        if record and KN[knot_of[i], K_T] < t:
            KN = add_knot(KN, CNT, t, i, 1.0, G, i, G_S, G_V, G_W, G_Q, g3, G[i, G_WK])
    if in_contact:
        IV[CNT[CN_IVALS] - 1, V_END] = t
    return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG
