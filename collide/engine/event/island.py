"""An island: bodies linked by engaged contacts, stepped together over a window from event to
event (`run_island`) while the rest of the scene flies free; a sphere alone on a wall goes to
its closed form (`rest_phase`).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import NBOX
from collide.engine.dem.damping import dashpot
from collide.engine.dem.geometry import reduced
from collide.engine.event.contact import engaged, geometry, overlap, springs, stored
from collide.engine.event.locate import step_events, stiff_slide
from collide.engine.event.modes import decide, flips, mode_events
from collide.engine.event.rest import rest_phase, rest_ready
from collide.engine.event.spring import held, keep_stretches, load_stretches, sawtooth, stretch_start
from collide.engine.flight import bring, touch_time
from collide.engine.jit import jit, jit_call, jit_inline, jit_part
from collide.engine.layout import (
    BAND,
    C_DELTA,
    C_EPS,
    C_ESTAR,
    C_FN,
    C_GAMMA,
    C_K,
    C_KTR,
    C_MSTAR,
    C_MU,
    C_N,
    C_REACH,
    C_RSTAR,
    C_SH,
    C_ZETA,
    CI_EDGE,
    CI_GI,
    CI_GJ,
    CI_GRAZE,
    CI_I,
    CI_J,
    CI_MODE,
    CI_PRESS,
    CI_Q,
    CN_KNOTS,
    E_FORCED,
    E_R0,
    E_R1,
    E_V0,
    E_V1,
    EDGE_TOL,
    ENERGY,
    EPS64,
    F_DT_MIN,
    F_MAX_FORCE,
    F_MAX_OVERLAP,
    F_STATUS_A,
    F_STATUS_B,
    F_STATUS_T,
    F_UNLOCATED_T,
    FL_AUTO,
    FL_DAMPED,
    FL_FRICTION,
    FL_HERTZ,
    FL_MAXSTEPS,
    FL_PLANAR,
    FL_RECORD,
    FL_SEED,
    FL_SPIN,
    FL_SPRING,
    FL_TURNS,
    FLIP,
    FP_BOX,
    FP_DT,
    FP_EVENT_TOL,
    FP_OMEGA_H,
    FP_SCALE,
    G_I,
    G_II,
    G_IM,
    G_M,
    G_MAT,
    G_R,
    G_S,
    G_TB,
    G_WK,
    GI_KNOT,
    GI_LOC,
    GRAZE_SHARE,
    K_AN,
    K_FREE,
    K_T,
    KAHAN6_ERROR,
    LATE,
    MAP_BOTH,
    MAP_END,
    MAP_NONE,
    MAP_SHARE,
    MAP_START,
    MAXSTEPS,
    MODE_TOL,
    NC,
    NCI,
    NE,
    NO,
    NONFINITE,
    NUDGE_SHARE,
    NX,
    OK,
    Q_ENG,
    Q_I,
    Q_J,
    QF_D0,
    QF_R0,
    QF_REACH,
    QF_SH,
    S_STATUS,
    S_STEPS,
    S_UNLOCATED,
    SAWTOOTH,
    SHORT_SHARE,
    SINGULAR,
    SIXTH7_ERROR,
    SLIDE,
    SPRING,
    STALL,
    STALL_LIMIT,
    STIFF_SLIDE_POWER,
    STIFF_SLIDE_SPAN,
    SUZUKI_ERROR,
    TINY_LIMIT,
    TOUCH_TOL,
    TP_EPS,
    TP_ESTAR,
    TP_K,
    TP_KTR,
    TP_MU,
    TP_ZETA,
    VERLET_ERROR,
    WINDOW_STEPS,
    X_A,
    X_F,
    X_F0,
    X_FO,
    X_I,
    X_II,
    X_IM,
    X_L,
    X_L0,
    X_M,
    X_MD,
    X_MH,
    X_MK,
    X_MP,
    X_MR,
    X_MU,
    X_Q,
    X_R,
    X_S,
    X_S0,
    X_V,
    X_W,
    YES,
    YOSHIDA_ERROR,
)
from collide.engine.records import add_knot, intervals, record_step, share


@jit
def gather(G, GI, X, XI, C, CI, Q, QF, nq, bodies_params, hertz, spring):
    """Set up the island's engaged contacts (C, CI) and their bodies (X, XI) from the engaged
    candidates; returns (bodies, contacts). `hertz`: the contacts are Hertz's (E* and R*; the
    tables' k is then the run's bound on the stiffness dF/d delta, `collide.model.hertz_bound`);
    `spring`: friction has a tangential spring (C_KTR, the tables' k_t / k_n)."""
    ptab, wtab = bodies_params
    na = 0
    nc = 0
    for k in range(nq):
        if Q[k, Q_ENG] == 0:
            continue
        for side in range(2):
            g = Q[k, Q_I] if side == 0 else Q[k, Q_J]
            if g >= 0 and GI[g, GI_LOC] < 0:
                GI[g, GI_LOC] = na
                XI[na] = g
                for d in range(13):
                    X[na, X_S + d] = G[g, G_S + d]
                X[na, X_IM] = G[g, G_IM]
                X[na, X_II] = G[g, G_II]
                X[na, X_R] = G[g, G_R]
                X[na, X_M] = G[g, G_M]
                X[na, X_I] = G[g, G_I]
                na += 1
        gi, gj = Q[k, Q_I], Q[k, Q_J]
        CI[nc, CI_I] = GI[gi, GI_LOC]
        CI[nc, CI_J] = GI[gj, GI_LOC] if gj >= 0 else gj
        CI[nc, CI_GI] = gi
        CI[nc, CI_GJ] = gj
        CI[nc, CI_Q] = k
        mi = int(G[gi, G_MAT])
        if gj >= 0:
            mj = int(G[gj, G_MAT])
            C[nc, C_K], C[nc, C_MU], C[nc, C_EPS] = ptab[mi, mj, TP_K], ptab[mi, mj, TP_MU], ptab[mi, mj, TP_EPS]
            zeta, mstar = ptab[mi, mj, TP_ZETA], reduced(G[gi, G_M], G[gj, G_M])
            estar, rstar = ptab[mi, mj, TP_ESTAR], reduced(G[gi, G_R], G[gj, G_R])
        else:
            C[nc, C_K], C[nc, C_MU], C[nc, C_EPS] = wtab[mi, TP_K], wtab[mi, TP_MU], wtab[mi, TP_EPS]
            zeta, mstar = wtab[mi, TP_ZETA], G[gi, G_M]
            estar, rstar = wtab[mi, TP_ESTAR], G[gi, G_R]
        C[nc, C_ESTAR] = estar if hertz else 0.0
        C[nc, C_RSTAR], C[nc, C_ZETA], C[nc, C_MSTAR] = rstar, zeta, mstar
        # The DEM kernel's dashpot at the stiffness k (Hertz's at its bound: the kicks take it at
        # the overlap, `dashpots`).
        C[nc, C_GAMMA] = dashpot(zeta, mstar, C[nc, C_K]) if zeta > 0.0 else 0.0
        C[nc, C_REACH] = QF[k, QF_REACH]
        for d in range(3):
            C[nc, C_SH + d] = QF[k, QF_SH + d]
        C[nc, C_KTR] = (ptab[mi, mj, TP_KTR] if gj >= 0 else wtab[mi, TP_KTR]) if spring else 0.0
        CI[nc, CI_MODE] = SPRING  # a spring's mode comes from its stretch (`spring_mode`), kept across phases
        nc += 1
    return na, nc


@jit_inline
def island_omega(X, C, CI, na, nc):
    """The stiffest frequency of the engaged contacts: exact for one contact, otherwise a
    Gershgorin bound on the mass-symmetrised stiffness matrix (rows k/m_i + k/sqrt(m_i m_j)), a
    tangential spring's stiffness counted with its levers where it is the stiffer."""
    if nc == 1 and C[0, C_KTR] == 0.0:
        i, j = CI[0, CI_I], CI[0, CI_J]
        return math.sqrt(C[0, C_K] * (X[i, X_IM] + (X[j, X_IM] if j >= 0 else 0.0)))
    for a in range(na):
        X[a, X_FO] = 0.0
    for c in range(nc):
        i, j = CI[c, CI_I], CI[c, CI_J]
        k = C[c, C_K]
        if C[c, C_KTR] > 0.0:
            # A tangential spring k_t = ratio k acts on the slip through K (spins included):
            # as a spring of ratio K m times k on each body.
            lever = 1.0
            for b in (i, j):
                if b >= 0:
                    lever = max(lever, 1.0 + X[b, X_R] ** 2 * X[b, X_II] * X[b, X_M])
            k = max(k, C[c, C_KTR] * k * lever)
        if j >= 0:
            cross = k * math.sqrt(X[i, X_IM] * X[j, X_IM])
            X[i, X_FO] += k * X[i, X_IM] + cross
            X[j, X_FO] += k * X[j, X_IM] + cross
        else:
            X[i, X_FO] += k * X[i, X_IM]
    top = 0.0
    for a in range(na):
        top = max(top, X[a, X_FO])
    return math.sqrt(top)


@jit_inline
def energy(X, C, na, nc, grav, spin):
    """Kinetic, rotational, gravitational and spring energy (`stored`) of the island's stepped bodies."""
    e = 0.0
    for a in range(na):
        for d in range(3):
            e += 0.5 * X[a, X_M] * X[a, X_V + d] ** 2 - X[a, X_M] * grav[d] * X[a, X_S + d]
            if spin:
                e += 0.5 * X[a, X_I] * X[a, X_W + d] ** 2
    for c in range(nc):
        e += stored(C, c) + held(C, c)
    return e


@jit_inline
def energy_scale(X, C, na, nc, grav, spin):
    """The energy the island's stepped bodies can exchange, whatever the origin of heights: kinetic,
    rotational and spring energy, and each body's weight over its radius (what a bounce or a
    settling exchanges with gravity at the least). Its total energy (`energy`) is zero for a ball
    dropped from the origin: growth measured against that alone is round-off judged unstable."""
    e = 0.0
    g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
    for a in range(na):
        e += X[a, X_M] * g * X[a, X_R]
        for d in range(3):
            e += 0.5 * X[a, X_M] * X[a, X_V + d] ** 2
            if spin:
                e += 0.5 * X[a, X_I] * X[a, X_W + d] ** 2
    for c in range(nc):
        e += stored(C, c) + held(C, c)
    return e


@jit_call
def island_rows(Q, nq):
    """Rows enough for the island's bodies: two per pair, one per wall contact."""
    size = 0
    for k in range(nq):
        size += 1 if Q[k, Q_J] < 0 else 2
    return size


@jit_call
def engage(G, GI, X, Q, QF, nq, t, WP, grav):
    """Mark the candidates engaged at t (Q_ENG); returns how many are."""
    n_eng = 0
    for k in range(nq):
        d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
        # Contacts found late keep that mark through the restarts at this time: re-marked as
        # ordinary ones, touching contacts easing apart in a rack dropped out and were found
        # late again, one after another, until the run stalled. A step taken clears it.
        on = engaged(Q, k, d, r, WP, grav)
        Q[k, Q_ENG] = (LATE if Q[k, Q_ENG] == LATE else 1) if on else 0
        n_eng += 1 if on else 0
    return n_eng


@jit_call
def fly_free(G, Q, nq, t, W, WP, grav, stalled, ST, FG, box):
    """Nothing engaged: on in closed form to the first touch. Returns (t, stalled, whether the
    island is done in this window: no touch before W, or a stall)."""
    tau = math.inf
    for k in range(nq):
        tau = min(tau, touch_time(G, Q[k, Q_I], Q[k, Q_J], t, WP, grav, box))
    if t + tau >= W:
        return t, stalled, True
    # A touch closer than the clock resolves lands on its next tick (late by less than one:
    # the clock's resolution at t), where it is found touching; a float clock's ticks
    # grow with t (5.7e-14 s at 256 s), and a bounce landed on time to within a tick came
    # down just short of the floor, over and over. The same touch met at every tick is
    # still a stall.
    stalled = stalled + 1 if t + tau == t else 0
    if stalled > STALL_LIMIT:
        ST[S_STATUS] = STALL
        FG[F_STATUS_T], FG[F_STATUS_A] = t, 2.0
        return t, stalled, True
    t = t + tau if stalled == 0 else np.nextafter(t, math.inf)
    return t, stalled, False


@jit_call
def bring_engaged(G, Q, nq, t, grav, fl):
    """The bodies of the engaged contacts brought to t along their free flights."""
    for k in range(nq):
        for side in range(2):
            g = Q[k, Q_I] if side == 0 else Q[k, Q_J]
            if g >= 0 and Q[k, Q_ENG]:
                bring(G, g, t, grav, fl)


@jit_call
def phase_settings(X, C, CI, na, nc, weights, fl, fp, scale):
    """A contact phase's step and event search settings, from its stiffest contact. Returns
    (omega, dt, max_turn, negligible, nudge, reach, briefs, exact)."""
    omega = island_omega(X, C, CI, na, nc)
    dt = fp[FP_OMEGA_H] / omega if fl[FL_AUTO] else fp[FP_DT]
    # A slip may turn by the angle the stiffest contact's oscillation advances in a step.
    max_turn = max(dt * omega, 1e-3)
    negligible = fp[FP_EVENT_TOL] * scale
    # How far a Verlet substep (and a Yoshida step) may reach in the event search: its error
    # a thousandth of the event tolerance. Out of the plane too, where a sliding slip turning
    # fast shortens both (`turning_nudges`): 142 random 3D scenes and four 3D breaks at tol
    # 1e-4, 1e-6 and 1e-7, and 16 piles of 27 spheres, landed every event with errors against
    # runs at a thousandth of the tolerance as before (median ratio 1.00), in fewer steps and
    # a third of the trials from a step's start. (Unbounded, searches once ran out of trials
    # in 6 of 300 random 3D scenes, and a scene drifted 3e-4 off at tol 1e-10.)
    nudge = 0.0
    reach = 0.0
    if omega > 0:
        nudge = (NUDGE_SHARE * fp[FP_EVENT_TOL] / VERLET_ERROR) ** (1.0 / 3.0) / omega
        # A Yoshida step costs a third of kahan6's; with three substeps or fewer it saves nothing.
        reach = (NUDGE_SHARE * fp[FP_EVENT_TOL] / YOSHIDA_ERROR) ** 0.2 / omega if weights.shape[0] > 3 else nudge
    # A trial from the step's start up to these long (an event soon after it) is one Yoshida
    # step, a third of kahan6's substeps, one of Suzuki's (5 of 9) or one of Yoshida's sixth
    # order (7 of 9): each one's error at most SHORT_SHARE of a whole step's.
    briefs = (0.0, 0.0, 0.0)
    if omega > 0 and fl[FL_PLANAR] == YES and weights.shape[0] > 3:
        budget = SHORT_SHARE * KAHAN6_ERROR * (omega * dt) ** 7
        briefs = ((budget / YOSHIDA_ERROR) ** 0.2 / omega, (budget / SUZUKI_ERROR) ** 0.2 / omega,
                  (budget / SIXTH7_ERROR) ** (1.0 / 7.0) / omega)
    # A kick's fixed point is left with a ten-thousandth of the event tolerance: thousands of
    # kicks stay far below the tolerance (at 1e-6, 1e-11 each; a pass fewer in most kicks).
    exact = max(4.0 * EPS64, 1e-4 * fp[FP_EVENT_TOL])
    return omega, dt, max_turn, negligible, nudge, reach, briefs, exact


@jit
def phase_knots(G, GI, X, XI, KN, CNT, na, t, grav):
    """Where a body's free flight ends and its steps begin: its knot at t, now stepped."""
    for a in range(na):
        g = XI[a]
        last = GI[g, GI_KNOT]
        if not (last >= 0 and KN[last, K_T] == t):
            KN = add_knot(KN, CNT, t, g, 0.0, X, a, X_S, X_V, X_W, X_Q, grav, G[g, G_WK])
            last = CNT[CN_KNOTS] - 1
            GI[g, GI_KNOT] = last
        KN[last, K_FREE] = 0.0
        for d in range(3):
            KN[last, K_AN + d] = X[a, X_A + d]
    return KN


@jit_call
def start_modes(G, X, XI, C, CI, E, na, nc, stuck, A, b, WP, grav, fl, scale, carried, stepped):
    """The friction modes and their values at a step's start (`decide`, `mode_events`), or the
    last step's end values where it met no mode's edge. Returns False where the hold system is
    singular."""
    if carried:
        # The last step met no mode's edge: decide would keep every mode (in the plane a
        # held direction counts by its side only) and settle nothing (the step's end
        # did), and its mode values at the end are this step's at the start.
        for k in range(2 * nc):
            E[k, E_V0], E[k, E_R0] = E[k, E_V1], E[k, E_R1]
    elif fl[FL_FRICTION]:
        if not stepped:
            geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
            springs(X, C, CI, na, nc, grav)
        # The modes are decided with the friction cap itself (see `cap`).
        for c in range(nc):
            CI[c, CI_PRESS] = 0
        done, ok, turned, solved = decide(X, C, CI, na, nc, stuck, A, b, fl, scale)
        share(G, XI, na, done)
        if not ok or not mode_events(X, C, CI, E, na, nc, E_V0, E_R0, stuck, A, b, fl, scale,
                                     YES if turned else NO, YES if solved else NO):
            return False
        for c in range(nc):
            # The step goes on with the cap's branch at its start: a damped slide's F_n below
            # zero, or on zero and heading below (an F_n event just landed), is watched from
            # below (its return through zero is the next event) with no friction meanwhile.
            k = nc + c
            CI[c, CI_PRESS] = 1
            if CI[c, CI_MODE] == SLIDE and (E[k, E_V0] < -MODE_TOL or (abs(E[k, E_V0]) <= MODE_TOL
                                                                       and E[k, E_R0] < 0)):
                CI[c, CI_PRESS] = -1
                E[k, E_V0], E[k, E_R0] = -E[k, E_V0], -E[k, E_R0]
            # A mode that starts on its edge and leaves it (a slide that cannot be held
            # yet, a slip entering the band) may come back through it within the step:
            # counted as just inside, that return is an event like any other (unless
            # the last step found the slip grazing the edge: CI_GRAZE, below).
            for k in (c, nc + c):
                E[k, E_FORCED] = NO
                if abs(E[k, E_V0]) <= MODE_TOL and E[k, E_R0] > 0 and not CI[c, CI_GRAZE]:
                    E[k, E_V0] = 2.0 * MODE_TOL
                    E[k, E_FORCED] = YES
            CI[c, CI_GRAZE] = NO
    return True


@jit_call
def mark_start(G, GI, X, XI, Q, QF, KN, na, nq, t, WP, grav, fric, record):
    """The step's start state (X_S0...), its friction (X_F0, X_L0) and candidates' overlaps (QF_D0,
    QF_R0), which every trial starts from."""
    for a in range(na):
        for d in range(13):
            X[a, X_S0 + d] = X[a, X_S + d]
        # The friction at the start (the mode values just solved it): every trial from
        # the start opens with it.
        for d in range(3 if fric else 0):
            X[a, X_F0 + d], X[a, X_L0 + d] = X[a, X_F + d], X[a, X_L + d]
        if record and fric:
            # The acceleration the coming step starts with (its modes).
            for d in range(3):
                KN[GI[XI[a], GI_KNOT], K_AN + d] = X[a, X_A + d] + X[a, X_F + d]
    for k in range(nq):
        QF[k, QF_D0], QF[k, QF_R0] = overlap(G, GI, X, Q, QF, k, t, WP, grav)


@jit_call
def step_length(X, C, CI, nc, dt, omega, W, t, grown, turner, spin, fric, fl):
    """The step to try: dt, to the window's end, grown back from a turning-limited one, and cut
    in a stiff sliding layer. Returns (h_full, grown)."""
    if grown < math.inf and not (turner >= 0 and CI[turner, CI_MODE] == SLIDE):
        # The step grows back from a turning-limited one while that slip slides on; one
        # that turned into the band took a dozen doubling steps back from a
        # ten-millionth of a second (most of the steps of a pile of 27 spheres).
        grown = math.inf
    h_full = min(dt, W - t, grown)
    if fric and fl[FL_TURNS]:
        tau = stiff_slide(X, C, CI, nc, dt, spin)
        if tau < math.inf:
            layer = dt * min(1.0, (dt * omega) ** STIFF_SLIDE_POWER)
            # A step of one to STIFF_SLIDE_SPAN of the layer's time scales is cut to one.
            h_full = min(h_full, min(layer, tau) if layer < STIFF_SLIDE_SPAN * tau else layer)
    return h_full, grown


@jit_call
def mark_grazes(CI, E, nc):
    """A band value counted as just inside that this step landed at once, no further from its
    edge than it started (within MODE_TOL): a slip grazing the band's edge, heading in at first
    and turning out again within MODE_TOL of it. Counted as just inside again, it was landed
    again a step on, each step shorter, until the run stalled (a pile of 27 spheres: 20 000 steps
    at t = 0.394634 s). The next step leaves its value as it is (CI_GRAZE): over it the slip
    strays from the edge by no more than the event tolerance allows a landing."""
    for k in range(2 * nc):
        if E[k, E_FORCED] == YES and abs(E[k, E_V1]) <= MODE_TOL and CI[k % nc, CI_MODE] == BAND:
            CI[k % nc, CI_GRAZE] = YES


@jit_call
def check_state(X, C, na, nc, ST, FG, fl):
    """A step's end state: non-finite or past the step limit (ST[S_STATUS]); the largest overlap
    and normal force so far while it is fine."""
    for a in range(na):
        for d in range(6):
            if not math.isfinite(X[a, X_S + d]):
                ST[S_STATUS] = NONFINITE
    if ST[S_STEPS] > fl[FL_MAXSTEPS]:
        ST[S_STATUS] = MAXSTEPS
    if ST[S_STATUS] != OK:
        return False
    for c in range(nc):
        FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], C[c, C_DELTA])
        FG[F_MAX_FORCE] = max(FG[F_MAX_FORCE], C[c, C_FN])
    return True


@jit_call
def engagement_changed(G, GI, X, Q, QF, nq, t, WP, grav):
    """Whether a candidate's engagement changed at t (a contact started or ended)."""
    changed = False
    for k in range(nq):
        d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
        if engaged(Q, k, d, r, WP, grav) != Q[k, Q_ENG]:
            changed = True
    return changed


@jit_call
def carried_on(E, nc, fric, located, fl):
    """Every mode value clear of its edge at the step's end, by twice what decide counts as on it
    (its own closing trial evaluated them there, at these modes)."""
    carried = fric and located and fl[FL_PLANAR] == YES
    for k in range(2 * nc if carried else 0):
        if not E[k, E_V1] > 2.0 * EDGE_TOL:
            carried = False
            break
    return carried


@jit_call
def end_phase(G, GI, X, XI, Q, QF, KN, na, nq, t, WP, grav, record, changed):
    """The phase ends at t: the stepped bodies go back to base states there, and those whose
    every contact has ended fly freely from their last knot."""
    for a in range(na):
        g = XI[a]
        for d in range(13):
            G[g, G_S + d] = X[a, X_S + d]
        G[g, G_TB] = t
        GI[g, GI_LOC] = -1
    if record and changed:
        for a in range(na):
            g = XI[a]
            still = False
            for k in range(nq):
                if Q[k, Q_I] == g or Q[k, Q_J] == g:
                    d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
                    still = still or engaged(Q, k, d, r, WP, grav)
            if not still and GI[g, GI_KNOT] >= 0:
                KN[GI[g, GI_KNOT], K_FREE] = 1.0


@jit_inline
def closing(X, C, CI, c):
    """Contact c's overlap rate (> 0 while approaching) at the island's velocities."""
    i, j = CI[c, CI_I], CI[c, CI_J]
    rate = 0.0
    for d in range(3):
        rate += (X[i, X_V + d] - (X[j, X_V + d] if j >= 0 else 0.0)) * C[c, C_N + d]
    return rate


@jit_inline
def reach_overlap(C, c, rate):
    """The overlap Hertz contact c would reach from its overlap at this overlap rate, all its
    relative kinetic energy stored: 8/15 E* sqrt(R*) (d^2.5 - delta^2.5) = m* rate^2 / 2."""
    delta = max(C[c, C_DELTA], 0.0)
    grow = 15.0 / 16.0 * C[c, C_MSTAR] * rate * rate / (C[c, C_ESTAR] * math.sqrt(C[c, C_RSTAR]))
    return (delta ** 2.5 + grow) ** 0.4


@jit_call
def hertz_start(X, C, CI, nc, t, omega):
    """The youngest Hertz contact's start and the length of its start region (its force's
    derivatives are singular at its start): MAP_SHARE of the time its approach takes to reach its
    largest overlap (d / rate), at least MAP_SHARE / omega. A contact touching (its overlap within
    TOUCH_TOL of its reach) and not separating starts at t; one pressing and approaching within
    its region began its overlap over its rate ago (a little earlier than that: its force slows
    it; run_island takes that at a window's start only). (-inf, 0) where none is within its start
    region."""
    begun, region = -math.inf, 0.0
    for c in range(nc):
        rate = closing(X, C, CI, c)
        if C[c, C_ESTAR] <= 0.0 or rate < 0.0:
            continue
        span = MAP_SHARE / omega
        if rate > 0.0:
            span = max(span, MAP_SHARE * reach_overlap(C, c, rate) / rate)
        if C[c, C_DELTA] <= TOUCH_TOL * C[c, C_REACH]:
            age = 0.0
        elif rate > 0.0 and C[c, C_DELTA] / rate < span:
            age = C[c, C_DELTA] / rate
        else:
            continue
        if t - age > begun:
            begun, region = t - age, span
    return begun, region


@jit_call
def set_map(X, C, CI, nc, t, anchor, region, h_full, dt, omega, W, fl):
    """The step's map of time (X_MK...; `substep.mapped_step`) and its length: within `region`
    of a Hertz contact's start (`anchor`, `hertz_start`), MAP_START to the region's end; else where
    a Hertz contact may end within its end region (MAP_SHARE of the time its energy takes to
    leave it, at its overlap rate) and two steps (its overlap over its rate, which its force
    shortens), MAP_END, at least half as long again as that (the event search lands the end, on
    which the map's end then falls)."""
    X[0, X_MK] = MAP_NONE
    if not fl[FL_HERTZ] or not omega > 0.0:
        return h_full
    X[0, X_MH], X[0, X_MD], X[0, X_MP] = region, dt, 4.0 if fl[FL_DAMPED] else 2.0
    X[0, X_MR] = 1.0 / omega
    soonest = math.inf
    for c in range(nc):
        rate = closing(X, C, CI, c)
        if C[c, C_ESTAR] > 0.0 and rate < 0.0:
            to_end = max(C[c, C_DELTA], 0.0) / -rate
            if to_end <= MAP_SHARE * reach_overlap(C, c, rate) / -rate + 2.0 * dt:
                soonest = min(soonest, to_end)
    left = anchor + region - t
    if left > 1e-3 * dt and not soonest < left:
        X[0, X_MK], X[0, X_MU] = MAP_START, t - anchor
        return min(W - t, left)
    if soonest < math.inf:
        # A contact's end within a start region: at the start itself, a map singular at both
        # ends of the step; later on, the end's (the start's force is smooth by then).
        X[0, X_MK] = MAP_BOTH if left > 1e-3 * dt and t == anchor else MAP_END
        return min(W - t, max(h_full, 1.5 * soonest))
    return h_full


@jit_call
def count_unlocated(ST, FG, t):
    """A step whose event search ran out of trials (it may have passed an event)."""
    if ST[S_UNLOCATED] == 0:
        FG[F_UNLOCATED_T] = t
    ST[S_UNLOCATED] += 1


@jit_call
def restart_late(X, Q, na, late):
    """Candidate `late` began pressing within the step: back to the step's start, engaged."""
    for a in range(na):
        for d in range(13):
            X[a, X_S + d] = X[a, X_S0 + d]
    Q[late, Q_ENG] = LATE


@jit_call
def clear_late(Q, nq):
    """A step taken: contacts found late are ordinary engaged ones again."""
    for k in range(nq):
        if Q[k, Q_ENG] == LATE:
            Q[k, Q_ENG] = 1


@jit_call
def phase_checks(t, t_phase, idle, e_start, e_end, e_room, ST, FG):
    """A contact phase's end: a stall or an energy blow-up (ST[S_STATUS]). Returns the count of
    phases in a row that ended where they began."""
    # Phases that end where they began, over and over, are a stall, never a hang.
    idle = idle + 1 if t == t_phase else 0
    if idle > STALL_LIMIT and ST[S_STATUS] == OK:
        ST[S_STATUS] = STALL
        FG[F_STATUS_T] = t
    # An unstable step multiplies the energy every step: half the scale is reached in a few.
    if e_end - e_start > 0.5 * e_room + 1e-300 and ST[S_STATUS] == OK:
        ST[S_STATUS] = ENERGY
        FG[F_STATUS_T], FG[F_STATUS_A], FG[F_STATUS_B] = t, e_start, e_end
    return idle


@jit_part
def run_island(G, GI, Q, QF, T, W, tables, SP, WP, grav, weights, fl, fp, bufs, CNT, ST, FG):
    """Advance the island of candidate contacts Q (N_Q, 3) from T to W: free flight in closed
    form while nothing is engaged, event-located steps of the bodies with engaged contacts while
    something is; SP: the tangential springs' stretches by pair (`spring`). Returns the (grown)
    recording buffers; problems go to ST[S_STATUS]."""
    KN, RC, IV, OP = bufs
    spin, fric, record = fl[FL_SPIN], fl[FL_FRICTION], fl[FL_RECORD]
    scale = fp[FP_SCALE]
    nq = Q.shape[0]
    size = island_rows(Q, nq)
    X = np.zeros((size, NX))
    XI = np.zeros(size, np.int64)
    C = np.zeros((nq, NC))
    CI = np.zeros((nq, NCI), np.int64)
    E = np.zeros((2 * nq, NE))
    stuck = np.zeros(3 * nq, np.int64)
    m_cap = min(nq, 48)
    A = np.zeros((2 * m_cap, 2 * m_cap))
    b = np.zeros(2 * nq)
    t = T
    stalled = 0
    tiny = 0
    restarts = 0
    idle = 0  # contact phases in a row that ended where they began
    anchor, region = -math.inf, 0.0  # the last start of a Hertz contact and its region (`set_map`)
    while t < W and ST[S_STATUS] == OK:
        n_eng = engage(G, GI, X, Q, QF, nq, t, WP, grav)
        IV, OP = intervals(Q, nq, t, IV, OP, CNT, ST)
        if n_eng == 0:
            t, stalled, done = fly_free(G, Q, nq, t, W, WP, grav, stalled, ST, FG, fp[FP_BOX:FP_BOX + NBOX])
            if done:
                break
            continue
        # A contact phase: the bodies of the engaged contacts are stepped.
        bring_engaged(G, Q, nq, t, grav, fl)
        na, nc = gather(G, GI, X, XI, C, CI, Q, QF, nq, tables, fl[FL_HERTZ], fl[FL_SPRING])
        load_stretches(SP, C, CI, Q, nq, nc, G.shape[0], fl[FL_SPRING])
        if 2 * nc > A.shape[0] and fric:
            A = np.zeros((2 * nc, 2 * nc))
        omega, dt, max_turn, negligible, nudge, reach, briefs, exact = phase_settings(X, C, CI, na, nc, weights, fl,
                                                                                      fp, scale)
        grown = math.inf
        turner = -1  # the contact whose turning last limited a step
        FG[F_DT_MIN] = min(FG[F_DT_MIN], dt)
        geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
        springs(X, C, CI, na, nc, grav)
        if fl[FL_HERTZ] and omega > 0.0:
            begun, span = hertz_start(X, C, CI, nc, t, omega)
            # A contact begun here; or, at a window's start (no start known), one begun before
            # (estimated: the overlap of one pressed from touching at rest grows as t^3.5).
            if begun == t or (anchor == -math.inf and begun > anchor):
                anchor, region = begun, span
        e_start = energy(X, C, na, nc, grav, spin)
        t_phase = t
        e_room = max(abs(e_start), energy_scale(X, C, na, nc, grav, spin))
        if record:
            KN = phase_knots(G, GI, X, XI, KN, CNT, na, t, grav)
        changed = False
        if rest_ready(X, C, CI, na, nc, nq, fl):
            # Stopped short of W without an end, the steps go on from where it stopped.
            t, KN, RC, changed = rest_phase(G, GI, X, XI, C, CI, t, W, WP, grav, fl, fp, KN, RC, CNT, ST, FG)
        carried = False
        # After a step the state's geometry and spring accelerations are the step's end's (its
        # last trial left them there; they depend on the positions only).
        stepped = False
        since = ST[S_STEPS]
        while t < W and not changed and ST[S_STATUS] == OK:
            if ST[S_STEPS] - since >= WINDOW_STEPS and rest_ready(X, C, CI, na, nc, nq, fl):
                # The closed form again after as many steps as a window spans, as the next
                # window would: a window of a body alone on a wall can be far longer (and what
                # stopped it, a slip turning fast or mode changes piling up, has mostly passed).
                t, KN, RC, changed = rest_phase(G, GI, X, XI, C, CI, t, W, WP, grav, fl, fp, KN, RC, CNT, ST, FG)
                carried = stepped = False
                grown, turner = math.inf, -1
                since = ST[S_STEPS]
                continue
            if not start_modes(G, X, XI, C, CI, E, na, nc, stuck, A, b, WP, grav, fl, scale, carried, stepped):
                ST[S_STATUS] = SINGULAR
                FG[F_STATUS_T] = t
                break
            if sawtooth(CI, nc, fl[FL_SPRING]):
                ST[S_STATUS] = SAWTOOTH
                FG[F_STATUS_T] = t
                break
            mark_start(G, GI, X, XI, Q, QF, KN, na, nq, t, WP, grav, fric, record)
            stretch_start(C, nc, False)
            h_full, grown = step_length(X, C, CI, nc, dt, omega, W, t, grown, turner, spin, fric, fl)
            h_full = set_map(X, C, CI, nc, t, anchor, region, h_full, dt, omega, W, fl)
            h, work, ok, limited, late, located = step_events(
                G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, weights, WP, grav, stuck, A, b, fl, scale, max_turn,
                negligible, nudge, reach, briefs if X[0, X_MK] == MAP_NONE else (0.0, 0.0, 0.0), exact, ST, omega)
            if not located:
                count_unlocated(ST, FG, t)
            if late >= 0:
                # Engage it from here: back to the step's start, and a new phase.
                restart_late(X, Q, na, late)
                stretch_start(C, nc, True)
                changed = True
                restarts += 1
                if restarts > STALL_LIMIT:
                    ST[S_STATUS] = STALL
                    FG[F_STATUS_T], FG[F_STATUS_A] = t, 3.0
                break
            restarts = 0
            clear_late(Q, nq)
            # After a step the turning limited, let the next ones grow back by doubling.
            if limited >= 0:
                grown, turner = 2.0 * h, limited
            else:
                grown = 2.0 * grown if grown < dt else math.inf
            if not ok:
                ST[S_STATUS] = SINGULAR
                FG[F_STATUS_T] = t
                break
            if fric and located and not carried and h < GRAZE_SHARE * h_full:
                mark_grazes(CI, E, nc)
            stalled = stalled + 1 if h == 0.0 else 0
            # Steps a thousand times shorter than the contact's, on and on, are events piling up
            # (a Zeno cascade of mode changes): refused, not ground through for hours.
            tiny = tiny + 1 if h < 1e-3 * dt else 0
            if stalled > STALL_LIMIT or tiny > TINY_LIMIT:
                ST[S_STATUS] = STALL
                FG[F_STATUS_T] = t
                break
            # A step to the window's end lands on it exactly.
            t = W if (h == h_full and h_full == W - t) else t + h
            ST[S_STEPS] += 1
            stepped = True
            share(G, XI, na, work)
            if not check_state(X, C, na, nc, ST, FG, fl):
                FG[F_STATUS_T] = t
                break
            if record:
                KN, RC = record_step(KN, RC, CNT, G, GI, X, XI, C, CI, na, nc, t, fl)
            if engagement_changed(G, GI, X, Q, QF, nq, t, WP, grav):
                changed = True
            carried = carried_on(E, nc, fric, located, fl)
            if fric and located and not carried and not changed and fl[FL_PLANAR] == YES and h > 0.0:
                # A stuck contact whose hold force came to zero here (from above, over this step)
                # and would cross the band quickly enough: `decide` flips it to the other edge.
                for c in range(nc):
                    if flips(C, CI, E, nc, c, h, omega, scale):
                        CI[c, CI_EDGE] = FLIP
        # The phase ends here: the stepped bodies go back to base states at t.
        e_end = energy(X, C, na, nc, grav, spin)
        idle = phase_checks(t, t_phase, idle, e_start, e_end, e_room, ST, FG)
        if fl[FL_SPRING]:
            keep_stretches(G, GI, X, SP, C, CI, Q, QF, nc, t, WP, grav, G.shape[0])
        end_phase(G, GI, X, XI, Q, QF, KN, na, nq, t, WP, grav, record, changed)
    return KN, RC, IV, OP
