"""The run loop: velocity Verlet steps (`verlet`) with the force pass (`forces`) between the
kicks, neighbour lists rebuilt when a body has moved half the skin (`neighbours`), free flight in
closed form where nothing touches (`flight`), frames and energy parts recorded (`records`), to
the end: a duration, rest, or every contact over and none to come."""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import NBOX
from collide.engine.dem.flight import fly, free_time, may_meet
from collide.engine.dem.forces import forces, peak_record
from collide.engine.dem.layout import (
    B_MAT,
    F_DIM,
    F_MAXSTEPS,
    F_RECORD,
    F_SPIN,
    G_DAMP,
    G_FIRST,
    G_LAST,
    G_STATUS_T,
    G_STORED,
    G_TOUCH,
    H_ON,
    MAXSTEPS,
    NEP,
    NFIG,
    NH,
    NK,
    NONFINITE,
    NPT,
    NR,
    NSTAT,
    P_BOX,
    P_COAST_GAP,
    P_DT,
    P_FRAME,
    P_NOW,
    P_NOW_KINETIC,
    P_NOW_PEAK,
    P_NOW_STEPS,
    P_REST,
    P_SKIN,
    P_TEND,
    S_JUMPS,
    S_PAIRS,
    S_STATUS,
    S_STEPS,
    T_ROLL,
)
from collide.engine.dem.neighbours import rebuild
from collide.engine.dem.records import energy_row, frame, stored, work_total
from collide.engine.dem.verlet import drift, kick, kick_kick_drift, kinetic
from collide.engine.jit import jit, jit_inline
from collide.engine.numerics import grow


@jit_inline
def _at_end(t, t_end):
    """Whether t is the end (to round-off)."""
    return t >= t_end * (1.0 - 1e-12)


@jit_inline
def _step_length(t, dt, t_end):
    """The step from t: dt, or what is left to the end; and whether it is the last."""
    if _at_end(t + dt, t_end):
        return t_end - t, True
    return dt, False


@jit
def _outputs(n, nw):
    """The run's stats and figures, and every body's and wall contact's arrays, as they start."""
    ST = np.zeros(NSTAT, np.int64)
    FG = np.zeros(NFIG)
    FG[G_FIRST] = np.nan
    FG[G_LAST] = np.nan
    FG[G_STATUS_T] = np.nan
    # The wall contacts' history: rows of the wall list (`neighbours.wall_list`), none yet.
    return ST, FG, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, NPT)), np.zeros((n, 3)), np.zeros((0, NH))


@jit
def _materials(Bd, n):
    MAT = np.empty(n, np.int64)
    for a in range(n):
        MAT[a] = np.int64(Bd[a, B_MAT])
    return MAT


@jit
def _any_rolling(tabs, wtabs, spin):
    """Whether any contact has rolling resistance (the kick books it only then)."""
    rolling = False
    if spin:
        for table in (tabs.reshape((-1, tabs.shape[-1])), wtabs):
            for r in range(table.shape[0]):
                rolling |= table[r, T_ROLL] > 0.0
    return rolling


@jit
def _coast(X, X0, V, W, Qo, F, Bd, WK, WP, WH, grav, fl, fp, t, ever, PI, PJ, PS, HS, BB, BUMP, WL, ST, KN, nkn):
    """Where nothing touches: fly in closed form as far as no contact can begin (free flight is
    not stepped, as in the event engine), the neighbour lists made fresh for it. Returns
    (whether the run is over, t, the lists, KN, nkn)."""
    if never_again(X, V, Bd, WP, grav, fp):
        return True, t, PI, PJ, PS, HS, BB, BUMP, WL, WH, KN, nkn
    PI, PJ, PS, HS, BB, BUMP, WL, WH = rebuild(X, X0, Bd, WP, WL, WH, X.shape[0], fl[F_DIM], fp[P_SKIN], PI, PJ, PS,
                                               HS, ST, fp[P_BOX:P_BOX + NBOX])
    over, t, KN, nkn = flight(X, V, W, Qo, F, Bd, WK, WP, grav, fl, fp, t, ever, PI, PJ, WL, ST, KN, nkn)
    return over, t, PI, PJ, PS, HS, BB, BUMP, WL, WH, KN, nkn


@jit
def never_again(X, V, Bd, WP, grav, fp):
    """Whether nothing touches and nothing ever can, with no end set: the run is over, whether or
    not anything touched before (bodies moving apart from the start, with nothing ahead, would
    be stepped on until the step limit)."""
    return not math.isfinite(fp[P_TEND]) and not may_meet(X, V, Bd, WP, grav, X.shape[0], fp[P_BOX:P_BOX + NBOX])


@jit
def flight(X, V, W, Qo, F, Bd, WK, WP, grav, fl, fp, t, ever, PI, PJ, WL, ST, KN, nkn):
    """Coasting's flight, the neighbour lists (PI, PJ, WL) fresh: as far as no contact can begin
    (`flight.free_time`), if longer than two steps; the one-thread loop (`_coast`) and the
    threads' driver (`dem_threads`) rebuild the lists each their own way, then fly here.
    Returns (whether the run is over, t, KN, nkn)."""
    n, planar, spin, record = X.shape[0], fl[F_DIM] < 3, fl[F_SPIN], fl[F_RECORD]
    dt, t_end, skin = fp[P_DT], fp[P_TEND], fp[P_SKIN]
    box = fp[P_BOX:P_BOX + NBOX]
    tau = free_time(X, V, Bd, PI, PJ, WL, WP, grav, n, skin, box)
    if _at_end(t + tau, t_end):
        tau = t_end - t
    over = False
    if tau > 2.0 * dt:
        # (Many bodies: two frames at each of many short coasts would outnumber the frames' rule.)
        framed = record != 0 and (nkn == 0 or t + tau - KN[nkn - 1, 0] >= fp[P_COAST_GAP])
        KN, nkn = fly(X, V, W, Qo, F, Bd, WK, grav, tau, t, n, spin, planar, framed, KN, nkn)
        t += tau
        ST[S_JUMPS] += 1
        over = _at_end(t, t_end) or (not math.isfinite(t_end) and ever and not may_meet(X, V, Bd, WP, grav, n, box))
    return over, t, KN, nkn


@jit
def _finish(X, V, W, Qo, F, Bd, WK, PS, HS, WH, PI, PJ, WL, t, record, ST, FG, KN, nkn, REC, nrec):
    """The run's totals into FG, its last frame if not recorded yet, and the peaks of the
    contacts still engaged. Returns (KN, nkn, REC, nrec)."""
    n = X.shape[0]
    FG[G_STORED] = stored(PS, HS, WH)
    for c in range(3):
        FG[G_DAMP + c] = work_total(WK, n, c)
    if record and (nkn == 0 or KN[nkn - 1, 0] < t):
        KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
    if record:
        REC = grow(REC, nrec + PS.shape[0] + WL.shape[0])
        for k in range(PS.shape[0]):
            s = PS[k]
            if s >= 0 and HS[s, H_ON] != 0.0:
                nrec = peak_record(HS, s, REC, nrec, PI[k], PJ[k])
        for m in range(WL.shape[0]):
            k, i, w = WL[m, 0], WL[m, 1], WL[m, 2]
            if WH[k, H_ON] != 0.0:
                nrec = peak_record(WH, k, REC, nrec, i, -1 - w)
    return KN, nkn, REC, nrec


@jit
def dem_run(X, V, W, Qo, Bd, tabs, wtabs, WP, grav, fl, fp):
    """Run to the end (duration, rest, or every contact over and none to come) at the fixed
    step fp[P_DT]. X, V, W (N, 3) and Qo (N, 4) are updated in place; WK (N, 3) returns each
    body's share of the work of damping, friction and rolling resistance. Returns (t, WK,
    knots, records, intervals, energy parts, stats, figures)."""
    n = X.shape[0]
    dim, planar, spin = fl[F_DIM], fl[F_DIM] < 3, fl[F_SPIN]
    dt, t_end, rest, skin = fp[P_DT], fp[P_TEND], fp[P_REST], fp[P_SKIN]
    box = fp[P_BOX:P_BOX + NBOX]
    record = fl[F_RECORD]
    ST, FG, F, T, PT, WK, WH = _outputs(n, WP.shape[0])
    KN, REC, IV, EP = np.zeros((0, NK)), np.zeros((0, NR)), np.zeros((0, 4)), np.zeros((0, NEP))
    nkn, nrec, niv, nep = 0, 0, 0, 0
    MAT = _materials(Bd, n)
    wt = wtabs.reshape((wtabs.shape[0], 1, wtabs.shape[1]))
    rolling = _any_rolling(tabs, wtabs, spin)
    X0 = X.copy()
    none = np.zeros(0, np.int64)
    PI, PJ, PS, HS, BB, BUMP, WL, WH = rebuild(X, X0, Bd, WP, np.zeros((0, 4), np.int64), WH, n, dim, skin, none,
                                               none, none, np.zeros((0, NH)), ST, box)
    t = 0.0
    scratch = np.zeros(4)
    # IV and REC get room for every listed contact to open and be recorded before forces runs,
    # so that no array is replaced inside its loops (that costs reference counting per contact);
    # checked here, as a call returning the arrays costs as much at a few bodies.
    most = PI.shape[0] + WL.shape[0]
    if record:
        IV = grow(IV, niv + most)
        REC = grow(REC, nrec + most)
    engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wt, grav,
                                fl, 0.0, t, n, FG, ST, IV, niv, REC, nrec, record != 0, scratch, box)
    if record:
        KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
        EP = grow(EP, nep)
        EP[nep, :] = 0.0  # nothing done yet (grow leaves new rows unset)
        nep += 1
    next_frame = fp[P_FRAME]
    peak = kinetic(V, W, Bd, n)
    ever = engaged > 0
    steps = 0
    last = False
    fused = False  # this step's opening kick and drift done by the last step's `kick_kick_drift`
    moved = 0.0
    while not last:
        if engaged == 0:
            over, t, PI, PJ, PS, HS, BB, BUMP, WL, WH, KN, nkn = _coast(X, X0, V, W, Qo, F, Bd, WK, WP, WH, grav,
                                                                         fl, fp, t, ever, PI, PJ, PS, HS, BB, BUMP,
                                                                         WL, ST, KN, nkn)
            if over:
                break
        h, last = _step_length(t, dt, t_end)
        if h <= 0.0:
            break
        if not fused:
            kick(V, W, F, T, PT, Bd, 0.5 * h, n, WK, rolling, False)
            moved = drift(X, X0, V, W, Qo, h, n, spin, planar)
        if 4.0 * moved > skin * skin:
            PI, PJ, PS, HS, BB, BUMP, WL, WH = rebuild(X, X0, Bd, WP, WL, WH, n, dim, skin, PI, PJ, PS, HS, ST,
                                                       box)
        t = t + h
        steps += 1
        record_now = record != 0 and (t >= next_frame or last)
        most = PI.shape[0] + WL.shape[0]  # the lists may have been rebuilt
        if record and niv + most >= IV.shape[0]:
            IV = grow(IV, niv + most)
        if record and nrec + most >= REC.shape[0]:  # a frame's records, or the peaks of phases that end
            REC = grow(REC, nrec + most)
        engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wt,
                                    grav, fl, h, t, n, FG, ST, IV, niv, REC, nrec, record_now, scratch, box)
        # The closing kick and, where nothing before the next step reads the velocities at this
        # step's end (no frame to record, no free flight, no end or rest to test), the next
        # step's opening kick and drift with it, in one pass over the bodies.
        h_next, _ = _step_length(t, dt, t_end)  # as the next step will take it
        fused = engaged != 0 and not last and not record_now and h_next > 0.0 and rest <= 0.0 and steps < fl[F_MAXSTEPS]
        if fused:
            kinetic_now, moved = kick_kick_drift(X, X0, V, W, Qo, F, T, PT, Bd, WK, 0.5 * h, 0.5 * h_next, h_next,
                                                 0, n, rolling, spin, planar)
        else:
            kinetic_now = kick(V, W, F, T, PT, Bd, 0.5 * h, n, WK, rolling, True)
        if engaged:
            FG[G_TOUCH] += h
            ever = True
        if not math.isfinite(kinetic_now):
            ST[S_STATUS] = NONFINITE
            FG[G_STATUS_T] = t
            break
        peak = max(peak, kinetic_now)
        if record_now:
            KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
            EP, nep = energy_row(EP, nep, t, WK, PS, HS, WH, n)
            while next_frame <= t:
                next_frame += fp[P_FRAME]
        if steps & 255 == 0:
            fp[P_NOW] = t
            fp[P_NOW_STEPS] = steps
            fp[P_NOW_KINETIC] = kinetic_now
            fp[P_NOW_PEAK] = peak
        if steps >= fl[F_MAXSTEPS]:
            ST[S_STATUS] = MAXSTEPS
            FG[G_STATUS_T] = t
            break
        if rest > 0.0 and ever and kinetic_now < rest * peak:
            break
        if not math.isfinite(t_end) and ever and engaged == 0 and not may_meet(X, V, Bd, WP, grav, n, box):
            break
    ST[S_STEPS] = steps
    ST[S_PAIRS] = PI.shape[0]
    KN, nkn, REC, nrec = _finish(X, V, W, Qo, F, Bd, WK, PS, HS, WH, PI, PJ, WL, t, record, ST, FG, KN, nkn, REC,
                                 nrec)
    return t, WK, KN[:nkn], REC[:nrec], IV[:niv], EP[:nep], ST, FG
