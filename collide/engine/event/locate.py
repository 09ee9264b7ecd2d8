"""Event location: one step of an island that ends on its first event (a contact's start or end,
a friction mode's change), found by trial steps aimed at the crossing its values and rates
foresee (`step_events`), and the limits on a step from sliding slips that turn.
"""

from __future__ import annotations

import math

from collide.engine.event.contact import cap, geometry, overlap, response, slip, slip_rate, springs
from collide.engine.event.modes import flips, mode_events
from collide.engine.event.spring import stretch_drift
from collide.engine.event.substep import hold_pull, kick_start, settle, step
from collide.engine.jit import jit_call, jit_inline, jit_part
from collide.engine.layout import (
    AIM,
    C_EPS,
    C_HELD,
    C_N,
    CI_MODE,
    CREEP_LIMIT,
    E_R0,
    E_R1,
    E_RC,
    E_V0,
    E_V1,
    E_VC,
    EPS64,
    EVENT_RES,
    FL_DAMPED,
    FL_FRICTION,
    FL_PLANAR,
    FL_SEED,
    FL_SPIN,
    FL_SPRING,
    FORESEE_SPAN,
    LATE_SAFETY,
    MAP_END,
    MODE_TOL,
    NO,
    NUDGE_SHARE,
    Q_ENG,
    QF_D0,
    QF_D1,
    QF_DB,
    QF_DP,
    QF_R0,
    QF_R1,
    QF_RB,
    QF_RP,
    S_ATTEMPTS,
    SIXTH7,
    SLIDE,
    STICK,
    STICK_SCALE,
    STIFF_SLIDE_IMPULSES,
    SUZUKI,
    TOUCH_TOL,
    TRIALS,
    VERLET,
    X_A,
    X_F,
    X_F0,
    X_L,
    X_L0,
    X_MK,
    X_S,
    X_UA,
    X_V,
    X_V0,
    X_W,
    X_W0,
    YES,
    YOSHIDA,
    YOSHIDA_ERROR,
)
from collide.engine.numerics import bracketed_root, first_root, hermite_dip, hermite_root


@jit_inline
def first_crossing(QF, nq, d_col, r_col, share, length, tol):
    """The first crossing (a share of the span, inf if none) of the candidates' overlaps between
    an earlier trial end (overlaps and rates in columns d_col, r_col of QF) and the last one
    (QF_D1, QF_R1), share * length (s) apart: on the cubic Hermite through both ends, where the
    overlap changes sign beyond the touch tolerance `tol`. The rates are scaled by share, then
    length, as the search always did (a rounding apart moved a chaotic pile's outcome)."""
    first = math.inf
    for k in range(nq):
        d0, d1 = QF[k, d_col], QF[k, QF_D1]
        if (d0 > tol and d1 < -tol) or (d0 < -tol and d1 > tol):
            first = min(first, hermite_root(d0, d1, QF[k, r_col] * share * length,
                                            QF[k, QF_R1] * share * length))
    return first


@jit_inline
def slip_turn(X, C, CI, nc, fl, h, negligible):
    """The largest angle (rad) a sliding contact's slip turned by over the step just taken (h),
    seen in the contact's frame: from its direction at the step's start (held, carried onto the
    end's tangent plane) to its direction at the end, and that contact (-1 if none). Zero in the
    plane, where a slip cannot turn. A contact whose friction changes the slip by at most
    `negligible` over the step is left out: however its force turned, the step's error from it
    is no more than an event landed to the tolerance makes (a slip grazing the band turns
    half round in a ten-millionth of a second: followed, a dozen steps)."""
    if fl[FL_PLANAR]:
        return 0.0, -1
    top = 0.0
    which = -1
    for c in range(nc):
        friction_force = cap(C, CI, c)
        if CI[c, CI_MODE] != SLIDE or friction_force * response(X, C, CI, c, fl[FL_SPIN]) * h <= negligible:
            continue
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, fl[FL_SPIN], False)
        nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
        hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
        hn = hx * nx + hy * ny + hz * nz
        hx, hy, hz = hx - hn * nx, hy - hn * ny, hz - hn * nz
        cross = math.sqrt((hy * sz - hz * sy) ** 2 + (hz * sx - hx * sz) ** 2 + (hx * sy - hy * sx) ** 2)
        angle = math.atan2(cross, hx * sx + hy * sy + hz * sz)
        if angle > top:
            top, which = angle, c
    return top, which


@jit_inline
def stiff_slide(X, C, CI, nc, dt, spin):
    """The shortest time scale |slip| / (mu F_n K) of the sliding contacts whose slip is within
    STIFF_SLIDE_IMPULSES steps' friction impulse (|slip| < n mu F_n K dt), inf if none: there, out
    of the plane, the slip's direction is slaved to the other forces on that time scale (just
    after a stick-to-slide change, closing in on the band, or sliding on while its friction
    barely yields), and the step is chosen by it (`run_island`)."""
    tau = math.inf
    for c in range(nc):
        if CI[c, CI_MODE] != SLIDE:
            continue
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, False)
        rate = cap(C, CI, c) * response(X, C, CI, c, spin)
        mag = math.sqrt(sx * sx + sy * sy + sz * sz)
        if STIFF_SLIDE_IMPULSES * rate * dt > mag:
            tau = min(tau, mag / rate)
    return tau


@jit_inline
def mode_dip(E, modes, frac, h_full, passed):
    """Where (a fraction of h_full) a mode value positive at both ends of a trial step of `frac`
    first goes below zero on the cubic Hermite through its values and closed-form rates: a
    slip that reaches the band's edge and leaves it again inside the step, which the signs at
    its ends do not show. inf if none is seen."""
    first = math.inf
    for k in range(modes):
        e0, e1 = E[k, E_V0], E[k, E_V1]
        r0, r1 = E[k, E_R0] * h_full * frac, E[k, E_R1] * h_full * frac
        if k == passed or not (e0 > MODE_TOL and e1 > MODE_TOL and math.isfinite(r0) and math.isfinite(r1)):
            continue
        first = min(first, hermite_dip(e0, e1, r0, r1, -MODE_TOL) * frac)
    return first


@jit_inline
def foresee(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, WP, grav, stuck, A, b, fl, scale):
    """The first time (from the step's start) at which a contact is foreseen to start or end or a
    friction mode to change: where the parabola through a value's start, rate and rate of change
    reaches zero. The rates of change, and a stuck contact's rate (its values have no closed
    form; theirs is a line), are differences to a state FORESEE_SPAN of the step on by the
    start's velocities and accelerations (the bodies are left there: the step restarts; its mode
    values in E[:, E_V1:]). inf if nothing is foreseen."""
    span = FORESEE_SPAN * h_full
    if fl[FL_SPRING]:
        stretch_drift(X, C, CI, nc, span, WP, fl[FL_SPIN], fl[FL_SEED])
    for a in range(na):
        for d in range(3):
            acc = X[a, X_A + d] + (X[a, X_F + d] if fl[FL_FRICTION] else 0.0)
            X[a, X_S + d] += span * (X[a, X_V + d] + 0.5 * span * acc)
            X[a, X_V + d] += span * acc
            if fl[FL_FRICTION]:
                X[a, X_W + d] += span * X[a, X_L + d]
    soon = math.inf
    tol = TOUCH_TOL
    for k in range(nq):
        d0, r0 = QF[k, QF_D0], QF[k, QF_R0]
        if abs(d0) > tol:
            r1 = overlap(G, GI, X, Q, QF, k, t + span, WP, grav)[1]
            sign = 1.0 if d0 > 0.0 else -1.0
            soon = min(soon, first_root(sign * d0, sign * r0, sign * (r1 - r0) / span))
    if not fl[FL_FRICTION]:
        return soon
    geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
    springs(X, C, CI, na, nc, grav)
    # With the start's hold system (1e-4 of a step on, the geometry has barely turned: the
    # differences aim the first trial, and the break's trials and outcome came out the same).
    known = mode_events(X, C, CI, E, na, nc, E_V1, E_R1, stuck, A, b, fl, scale, NO, NO)
    for k in range(2 * nc):
        e0, r0 = E[k, E_V0], E[k, E_R0]
        if not (e0 > MODE_TOL and known):
            continue
        if math.isfinite(r0):
            if math.isfinite(E[k, E_R1]):
                soon = min(soon, first_root(e0, r0, (E[k, E_R1] - r0) / span))
        else:
            soon = min(soon, first_root(e0, (E[k, E_V1] - e0) / span, 0.0))
    return soon


@jit_inline
def turning_nudges(X, C, CI, na, nc, fl, nudge, reach, negligible, span, vc, wc, fc, lc):
    """The event search's nudges (see `run_island`) out of the plane, shortened where a sliding
    slip turns fast, at the state in columns (vc, wc) with its friction accelerations in (fc, lc)
    and its springs' in X_A (a step's start, or a trial's end that nudges would go on from).
    Its friction f = mu F_n K (as a slip rate) turns at theta' = |G_perp| / |slip| (G the slip's
    rate under every force, taken across the slip), with |slip| the least it can shrink to within
    `span` (at twice its rate now, and not below the band's edge eps, where the slide ends): a
    Verlet substep of h errs on it by about f h^3 theta'^2 / 12, a Yoshida step by
    YOSHIDA_ERROR f h^5 theta'^4, each held within NUDGE_SHARE of `negligible`, as an
    oscillator's error is. Unbounded, the nudges of a scene of six spinning spheres on a floor
    went back across a slip turning 6 000 rad/s at a trial's end (0.03 rad/s at the step's
    start), and it ran 3e-4 off at tol 1e-10."""
    spin, seed = fl[FL_SPIN], fl[FL_SEED]
    for a in range(na):
        for d in range(3):
            X[a, X_UA + d] = X[a, X_A + d] + X[a, fc + d]
    for c in range(nc):
        if CI[c, CI_MODE] != SLIDE:
            continue
        sx, sy, sz = slip(X, C, CI, c, vc, wc, spin, False)
        size = math.sqrt(sx * sx + sy * sy + sz * sz)
        if size == 0.0:
            return 0.0, 0.0
        ux, uy, uz = sx / size, sy / size, sz / size
        gx, gy, gz = slip_rate(X, C, CI, c, vc, wc, X_UA, lc, spin, seed, YES, False)
        along = gx * ux + gy * uy + gz * uz  # d|slip|/dt
        gx, gy, gz = gx - along * ux, gy - along * uy, gz - along * uz
        least = max(size + 2.0 * min(along, 0.0) * span, C[c, C_EPS])
        rate = (gx * gx + gy * gy + gz * gz) / (least * least)  # theta'^2
        force = cap(C, CI, c) * response(X, C, CI, c, spin)
        if force * rate > 0.0:
            nudge = min(nudge, (12.0 * NUDGE_SHARE * negligible / (force * rate)) ** (1.0 / 3.0))
            reach = min(reach, (NUDGE_SHARE * negligible / (YOSHIDA_ERROR * force * rate * rate)) ** 0.2)
    return nudge, reach


@jit_call
def first_trial(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, weights, WP, grav, stuck, A, b, fl, scale,
                negligible, nudge, reach, briefs, exact, ST):
    """A step's first trial from its start: to just past the first event `foresee` sees coming, or
    the whole step. Returns (h, work, ok, nudge, reach and the kicks' pull_rate, warm, one_pass)."""
    # The kicks' start and their hold forces' pull, from the step's start (its modes hold through
    # the step; the pull is a bound with CONTRACTION_SAFETY's margin, which a trial's share of
    # the step's impulse stays within), before `foresee` moves the bodies on.
    pull_rate, warm, one_pass = 0.0, True, False
    if fl[FL_FRICTION]:
        warm, one_pass = kick_start(CI, nc, fl[FL_PLANAR] == YES, fl[FL_DAMPED])
        if warm and not one_pass:  # only a warm kick with stuck contacts reads it
            pull_rate = hold_pull(X, C, CI, nc)
        if nudge > 0.0 and fl[FL_PLANAR] != YES:
            nudge, reach = turning_nudges(X, C, CI, na, nc, fl, nudge, reach, negligible, h_full, X_V0, X_W0, X_F0,
                                          X_L0)
    # Where an event is foreseen inside the step, the first trial ends just past it: its end then
    # brackets the event closely, and the search lands there with nudges from it. Unforeseen, a
    # whole step only found it and a second one aimed at it (the billiards break tried 155 whole
    # steps for its 80; now 77 for 83). Very soon (a contact's mode changing just after another's
    # changed its forces), the trial is a nudge to twice that time, whose end brackets the
    # change or, if the value slows, is a short step of its own.
    soon = math.inf
    if nudge > 0.0:
        soon = foresee(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, WP, grav, stuck, A, b, fl, scale)
    if 2.0 * soon <= min(reach, h_full):
        h = 2.0 * soon
        work, ok = step(X, C, CI, na, nc, h, VERLET if h <= nudge else YOSHIDA, WP, grav, stuck, A, b, fl, YES, exact,
                        pull_rate, warm, one_pass)
    else:
        h = min(AIM * soon, h_full)
        # The fewest substeps whose error is within SHORT_SHARE of a whole step's (see `briefs`),
        # chosen in place here and below: a compiled function returning the array cost the break
        # 3 % (1.467 -> 1.515 ms), and an inlined one, without reference counting, may not return
        # one (it corrupted the heap).
        composition = YOSHIDA if h <= briefs[0] else (SUZUKI if h <= briefs[1] else (
            SIXTH7 if h <= briefs[2] else weights))
        work, ok = step(X, C, CI, na, nc, h, composition, WP, grav, stuck, A, b, fl, YES, exact, pull_rate, warm,
                        one_pass)
        ST[S_ATTEMPTS] += 1
    return h, work, ok, nudge, reach, pull_rate, warm, one_pass


@jit_call
def pressing_from_touching(G, GI, X, Q, QF, nq, t, h, WP, grav, tol):
    """A candidate touching at the step's start with no approach speed that presses at its end
    (it began with the step: a Newton's cradle), or -1."""
    for k in range(nq):
        if Q[k, Q_ENG] == 0 and -tol <= QF[k, QF_D0] <= tol:
            d1, r1 = overlap(G, GI, X, Q, QF, k, t + h, WP, grav)
            if d1 > tol:
                return k
    return -1


@jit_call
def contact_aim(G, GI, X, Q, QF, nq, t, h, h_full, frac, WP, grav, tol, past, below, ahead, creep, aimed):
    """Where a trial ending at `frac` of the step aims next for the contacts' starts and ends: the
    first crossing of the cubics through the candidates' overlaps (from the step's start, or
    between the longest trial short of a crossing and the shortest past one). Returns (theta: inf
    if none, whether one crossed within the trial, whether it fell short of a known crossing,
    and the search's past, below, ahead, creep)."""
    for k in range(nq):
        QF[k, QF_D1], QF[k, QF_R1] = overlap(G, GI, X, Q, QF, k, t + h, WP, grav)
    first = first_crossing(QF, nq, QF_D0, QF_R0, h, 1.0, tol)
    theta = math.inf
    crossing = first < math.inf
    if crossing:
        theta = first * frac
        ahead, creep = math.inf, 0
        if frac < past:
            past = frac
            for k in range(nq):
                QF[k, QF_DP], QF[k, QF_RP] = QF[k, QF_D1], QF[k, QF_R1]
            if 0.0 < below < frac:
                # Between the longest trial that fell short and this one: the cubic from the
                # step's start misses by far more (in a pile, each refinement from below that
                # went just past was sent 0.6 % of the step back: 40 trials in a cycle).
                gap = frac - below
                first = first_crossing(QF, nq, QF_DB, QF_RB, gap, h_full, tol)
                if first < math.inf:
                    theta = below + first * gap
                if gap <= EVENT_RES:
                    # Bracketed to a billionth of the step: a trial's end is path-dependent at
                    # round-off (nudged forwards and back), and the search wandered there to
                    # the last trial. Landing this close starts or ends the contact with an
                    # overlap error of rate times that: its impulse, of order (omega h)^2 1e-18.
                    theta = frac
            elif below >= frac:
                below = 0.0  # crossed before it: a contact that came and went within the step
    short = past < math.inf and frac < past and not crossing
    if short and frac > below:
        below = frac
        for k in range(nq):
            QF[k, QF_DB], QF[k, QF_RB] = QF[k, QF_D1], QF[k, QF_R1]
    if short:
        # Fell short: the crossing lies between this trial's end and the shorter crossing one.
        gap = past - frac
        first = math.inf
        for k in range(nq):
            d0, d1, dp = QF[k, QF_D0], QF[k, QF_D1], QF[k, QF_DP]
            if (d1 > tol and dp < -tol) or (d1 < -tol and dp > tol):
                first = min(first, hermite_root(d1, dp, QF[k, QF_R1] * gap * h_full, QF[k, QF_RP] * gap * h_full))
            elif abs(d1) <= tol and ((d0 > tol and dp < -tol) or (d0 < -tol and dp > tol)):
                # Landed on a crossing (within the touch tolerance): this trial is the event.
                # Aiming past it at a later contact's crossing instead went round in a cycle
                # when two contacts of a rack ended a hair apart (the step then ran past both).
                first = 0.0
        if first < math.inf:
            theta = frac + first * gap
            # Short trials whose aims shrink slowly (each more than half the last) creep at a
            # crossing the nudged trials do not reach: nudges forwards add their errors (by
            # design, a thousandth of the event tolerance each), the crossing trial's end
            # came by another path, and its overlap was 2e-6 where theirs stayed at -8e-8
            # (40 trials, in a pile of 27 spheres). The step ends here, short of the crossing,
            # and the next one lands it from its own start.
            creep = creep + 1 if aimed and theta - frac > 0.5 * ahead else 0
            ahead = theta - frac
            if creep >= CREEP_LIMIT:
                theta = frac
    return theta, crossing, short, past, below, ahead, creep


@jit_call
def first_mode_root(E, modes, passed, frac, h):
    """The mode value crossed in this trial whose root comes first, and how many crossed."""
    best = -1
    guess = math.inf
    crossed = 0
    for k in range(modes):
        e0, e1 = E[k, E_V0], E[k, E_V1]
        if k == passed or not (e0 > MODE_TOL and e1 < -MODE_TOL):
            continue
        crossed += 1
        # The first root on the cubic through both ends' values and rates where they have
        # closed forms: a slip entering the band from its edge crosses it, and its near
        # edge's value rises and falls back with the far edge's, whose secant aims at
        # once; the near one's secant aims at the start (measured: 11 trials instead of 3).
        r0, r1 = E[k, E_R0] * h, E[k, E_R1] * h
        at = hermite_root(e0, e1, r0, r1) if math.isfinite(r0) and math.isfinite(r1) else e0 / (e0 - e1)
        if at * frac < guess:
            guess = at * frac
            best = k
    return best, crossed


@jit_call
def mode_landed(C, CI, E, nc, col, best, crossed, crossing, theta, frac, lo, f_lo, h, h_full, omega, scale, fl):
    """Whether the pending mode value `col` has landed at this trial's end."""
    f = E[col, E_V1]
    # The only value crossed in this trial, with no contact's start or end before it.
    alone = crossed == 1 and best == col and not (crossing and theta <= frac)
    # A hold force through zero that `decide` flips at this end, near enough past it
    # (see `flips`): landed.
    flip = alone and col >= nc and fl[FL_PLANAR] == YES and flips(C, CI, E, nc, col - nc, h, omega, scale)
    # A stuck contact's value (its margin to mu F_n, its hold force along the held
    # slip) just past zero: held on past the change for `late` (from the line through
    # the bracket), the friction is off by at most |f| (as a force: see `mode_events`)
    # and changes the slip by |f| late / 2 over STICK_SCALE, second order in `late`
    # where a slide's or the band's value errs by its own size: the landing takes that
    # within MODE_TOL (LATE_SAFETY over) instead of |f| itself. The break's
    # stick-to-slide landings took 2.8 trials each, now 1.8.
    late_ok = False
    if alone and f < 0.0 < f_lo and CI[col % nc, CI_MODE] == STICK:
        late = (frac - lo) * h_full * f / (f - f_lo)
        late_ok = LATE_SAFETY * 0.5 * -f * late <= MODE_TOL * STICK_SCALE
    return flip or late_ok or (abs(f) <= MODE_TOL and (best < 0 or best == col))


@jit_call
def root_estimate(E, col, h, trial, fresh, frac, f, slope, lo, f_lo, hi, f_hi, s_lo, s_hi, ta, fa, tb, fb,
                  widths, bisecting):
    """The next aim at the pending mode value's root in its bracket [lo, hi]. Returns (estimate,
    bisecting)."""
    estimate = bracketed_root(lo, f_lo, hi, f_hi, ta, fa, tb, fb, frac, f)
    if fresh:
        # The cubic from the bracket's start (the step's or the clear trial's),
        # its start rate scaled as the search always did from the step's start.
        gap = frac - lo
        s0 = s_lo * gap if lo > 0.0 else E[col, E_R0] * h
        if math.isfinite(s0) and math.isfinite(slope):
            estimate = lo + gap * hermite_root(f_lo, f, s0, slope * gap)
    else:
        # The cubic through both ends' values and rates: a slip that leaves the
        # band with no rate grows as a parabola, which Newton from the steep end
        # only halved its way into (ten trials for one event in the bonus demo).
        # Only where both rates fall as the value does across the bracket: a
        # rate from before a mode change just at the step's start points the
        # cubic the wrong way (measured: 12 trials where Newton took 5).
        cubic = math.nan
        if s_lo <= 0.0 and s_hi <= 0.0:
            cubic = lo + (hi - lo) * hermite_root(f_lo, f_hi, s_lo * (hi - lo), s_hi * (hi - lo))
        if lo < cubic < hi:
            estimate = cubic
        else:
            # Newton from the bracket's end where the value changes fastest: past
            # a mode change the smoothed friction can leave the value nearly
            # flat, and a step from that end (or a secant through it) creeps.
            steep, end, f_end = s_lo, lo, f_lo
            if not (abs(s_lo) >= abs(s_hi)) or not math.isfinite(s_lo):
                steep, end, f_end = s_hi, hi, f_hi
            if math.isfinite(steep) and steep != 0 and lo < end - f_end / steep < hi:
                estimate = end - f_end / steep
        # Safeguard: after a few trials, a value that did not halve in two
        # (interpolation creeping along a flat side, or a jump: a stuck contact's
        # hold force as a neighbour's slip passes zero) is bisected from then on.
        # Interleaved with interpolation, a jump took two trials a halving and
        # ran out of trials (a pile of 27 spheres).
        bisecting = bisecting or (trial >= 8 and abs(f) > 0.5 * widths[0])
        if bisecting:
            estimate = 0.5 * (lo + hi)
    return estimate, bisecting


@jit_call
def next_trial(X, C, CI, na, nc, h, h_next, weights, WP, grav, stuck, A, b, fl, exact, pull_rate, warm, one_pass,
               nudge, reach, negligible, briefs, work, ST):
    """The trial to h_next: nudged on from the last trial's end when close to it, else a step
    from the start. Returns (work, ok)."""
    near_nudge, near_reach = nudge, reach
    if nudge > 0.0 and abs(h_next - h) <= reach and fl[FL_FRICTION] and fl[FL_PLANAR] != YES:
        # Out of the plane, as far as the slips turning at this trial's end allow.
        near_nudge, near_reach = turning_nudges(X, C, CI, na, nc, fl, nudge, reach, negligible, abs(h_next - h),
                                                X_V, X_W, X_F, X_L)
    # (Where the step's map ends on a Hertz contact's end (MAP_END, MAP_BOTH), not back from a
    # trial past that end:
    # over it the force was not smooth, and its error would stay in the nudge's end.)
    if nudge > 0.0 and abs(h_next - h) <= near_reach and (h_next > h or X[0, X_MK] < MAP_END):
        # Close to the last trial's end (a root search's last refinements): one Verlet
        # substep from there, forwards or back, a ninth of the cost of a step from the start,
        # or a little further a Yoshida step, a third of it.
        near = VERLET if abs(h_next - h) <= near_nudge else YOSHIDA
        more, ok = step(X, C, CI, na, nc, h_next - h, near, WP, grav, stuck, A, b, fl, NO, exact, pull_rate,
                        warm, one_pass)
        work += more
    else:
        composition = YOSHIDA if h_next <= briefs[0] else (SUZUKI if h_next <= briefs[1] else (
            SIXTH7 if h_next <= briefs[2] else weights))
        work, ok = step(X, C, CI, na, nc, h_next, composition, WP, grav, stuck, A, b, fl, YES, exact, pull_rate,
                        warm, one_pass)
        ST[S_ATTEMPTS] += 1
    return work, ok


@jit_call
def open_bracket(E, col, clear, frac, h_full):
    """A new bracket [lo, hi] for mode value `col`, which crossed in this trial: from the clear
    trial's end, or the step's start. Returns (lo, f_lo, hi, f_hi, s_lo, s_hi, ta, fa, tb, fb)."""
    start = clear if clear < frac else 0.0  # a value back below zero before it: a dip
    at_v, at_r = (E[col, E_VC], E[col, E_RC]) if start > 0.0 else (E[col, E_V0], E[col, E_R0])
    lo, f_lo, hi, f_hi = start, at_v, frac, E[col, E_V1]
    s_lo, s_hi = at_r * h_full, E[col, E_R1] * h_full
    ta, fa, tb, fb = math.nan, math.nan, start, at_v
    return lo, f_lo, hi, f_hi, s_lo, s_hi, ta, fa, tb, fb


@jit_call
def turn_limit(X, C, CI, nc, fl, h, negligible, max_turn, frac, theta, past, limited):
    """The step shortened where a sliding slip turned by more than `max_turn` in this trial.
    Returns (theta, past, limited)."""
    turned, turner = slip_turn(X, C, CI, nc, fl, h, negligible)
    if turned > max_turn:
        # The turning angle grows about in proportion to the step near the edge.
        limited = turner
        limit = frac * max(0.8 * max_turn / turned, 0.05)
        if limit < theta:
            # A contact's start or end beyond the shortened step is the next step's:
            # aimed at again from there, the search went round in a cycle between the
            # crossing and the turning limit, and the step ran past the crossing.
            theta = limit
            past = math.inf
    return theta, past, limited


@jit_call
def dip_and_clear(E, modes, frac, h_full, passed, passed_at, pending, best, dipped, clear, theta):
    """A trial's mode values that dip below zero inside it (the step shortened into the dip), and
    the longest clear trial (no value crossed nor dipped: its values and rates kept in E_VC,
    E_RC). Returns (theta, dipped, clear)."""
    clean = modes > 0 and best < 0  # no mode value crossed in this trial
    # Not on a trial that ends just past a jump: the cubics through its ends span the jump (the
    # other values' rates jump with it), and one dipped far back; bracketed there anew, the
    # root just past the jump ran out of trials (a pile of 27 spheres).
    if modes and not pending and not dipped and not frac >= passed_at:
        dip = mode_dip(E, modes, frac, h_full, passed)
        if dip < theta:
            # A slip that comes back to the band's edge and leaves it again within the step
            # (it may stick there) shows no change of sign at the step's ends: the step is
            # shortened into the dip, and the crossing is then bracketed as any other.
            theta = dip
            dipped = True
            clean = False
    if clean and frac > clear:
        clear = frac
        for k in range(modes):
            E[k, E_VC], E[k, E_RC] = E[k, E_V1], E[k, E_R1]
    return theta, dipped, clear


@jit_part
def step_events(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, weights, WP, grav, stuck, A, b, fl, scale,
                max_turn, negligible, nudge, reach, briefs, exact, ST, omega):
    """One step from the start state; where an event would happen inside it, shortened to land there,
    each refinement re-stepping from the start (one within `nudge` of the last trial's
    end is a Verlet substep from there, one within `reach` a Yoshida step, and one from the start up
    to `briefs` long a composition of fewer substeps; and the first trial ends just past the first
    event `foresee` sees coming). Contacts starting or ending: a cubic Hermite through the overlaps
    at both ends of a trial; friction modes: a bracketed root find (Hermite with both ends' rates
    where they have closed forms, then inverse quadratic interpolation, secant or Newton in the
    bracket). In 3D a sliding slip may turn by at most `max_turn` (rad) a step, unless its friction
    changes the slip by at most `negligible` over the step: just after it leaves the band's edge it
    turns on a time scale of eps over its rate, far below a step, and the step is shortened to
    follow it. Returns (h taken, work, ok, the contact whose turning limited the step or -1, a
    candidate that began pressing from touching within the step: -1 if none, else the step was not
    taken, whether the search landed: False if it ran out of trials, and the step may have passed
    an event)."""
    limited = -1
    tol = TOUCH_TOL
    h, work, ok, nudge, reach, pull_rate, warm, one_pass = first_trial(
        G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, weights, WP, grav, stuck, A, b, fl, scale, negligible,
        nudge, reach, briefs, exact, ST)
    if not ok:
        return h, work, False, limited, -1, True
    # A contact touching at the start with no approach speed that presses by the end began with
    # the step: it is engaged from the start and the step taken again (a Newton's cradle).
    k = pressing_from_touching(G, GI, X, Q, QF, nq, t, h, WP, grav, tol)
    if k >= 0:
        return 0.0, work, True, limited, k, True
    modes = 2 * nc if fl[FL_FRICTION] else 0
    # The longest trial at whose end no mode value had crossed zero (nor dipped below it): every
    # root lies past it, and a new one is bracketed from there (from the step's start, two values
    # that jump took turns: each time one was bracketed to a few billionths of the step the
    # other crossed there first and was bisected again from the start, and the step ran out of
    # trials in a pile of 27 spheres). Its values and rates are in E_VC, E_RC.
    clear = 0.0
    for k in range(modes):
        E[k, E_VC], E[k, E_RC] = E[k, E_V0], E[k, E_R0]
    pending = False
    col = -1
    lo, hi, f_lo, f_hi = 0.0, 1.0, 0.0, 0.0
    s_lo, s_hi = math.nan, math.nan
    widths = (math.inf, math.inf)  # |value| at the last two trials of the pending root
    bisecting = False  # the pending root's value did not halve in two trials: a jump, bisected
    passed = -1
    passed_at = math.nan  # the trial end just past the passed mode value's jump
    ta, fa, tb, fb = math.nan, math.nan, math.nan, math.nan
    past = math.inf
    below = 0.0  # the longest trial that fell short of `past` (its overlaps in QF_DB, QF_RB)
    ahead, creep = math.inf, 0  # the last short trial's aim past its end; short trials creeping
    aimed = False  # this trial's end was aimed at a contact's crossing (not at a mode's root)
    shortest = 16.0 * EPS64 * (abs(t) + abs(h_full))
    located = False
    dipped = False
    for trial in range(TRIALS):
        frac = h / h_full
        theta, crossing, short, past, below, ahead, creep = contact_aim(
            G, GI, X, Q, QF, nq, t, h, h_full, frac, WP, grav, tol, past, below, ahead, creep, aimed)
        crossing_aim = theta
        best = -1
        if modes:
            if not mode_events(X, C, CI, E, na, nc, E_V1, E_R1, stuck, A, b, fl, scale, NO, YES):
                return h, work, False, limited, -1, True
            best, crossed = first_mode_root(E, modes, passed, frac, h)
            fresh = best >= 0 and (not pending or best != col)
            if fresh:
                col = best
                lo, f_lo, hi, f_hi, s_lo, s_hi, ta, fa, tb, fb = open_bracket(E, col, clear, frac, h_full)
                widths = (math.inf, math.inf)
                bisecting = False
                pending = True
            if pending:
                f = E[col, E_V1]
                slope = E[col, E_R1] * h_full
                if not fresh:
                    if f < 0:
                        hi, f_hi, s_hi = frac, f, slope
                    else:
                        lo, f_lo, s_lo = frac, f, slope
                if mode_landed(C, CI, E, nc, col, best, crossed, crossing, theta, frac, lo, f_lo, h, h_full, omega,
                               scale, fl):
                    pending = False
                    if short:
                        theta = math.inf
                elif hi - lo <= EVENT_RES or (hi - lo) * h_full <= shortest:
                    # A jump in the event value (a stuck contact's hold force can change sign at
                    # once, as a neighbour's slip passes zero), or a root bracketed to a billionth
                    # of the step (landed: late by that, its error is that share of a step's
                    # friction impulse): the step ends just past it. Bisected on to the clock's
                    # resolution, a jump took more than the 40 trials (a pile of 27 spheres).
                    pending = False
                    passed = col
                    theta = hi
                    passed_at = hi
                else:
                    estimate, bisecting = root_estimate(E, col, h, trial, fresh, frac, f, slope, lo, f_lo, hi, f_hi,
                                                        s_lo, s_hi, ta, fa, tb, fb, widths, bisecting)
                    widths = (widths[1], abs(f))
                    theta = min(theta, estimate)
                    ta, fa, tb, fb = tb, fb, frac, f
            if short and not pending and abs(frac - passed_at) <= 1e-12 * frac:
                # Landed just past a jump, short of a contact's crossing: the step ends here, as
                # at a root (aimed on at the crossing, the search ran out of trials in a pile).
                theta = math.inf
        theta, dipped, clear = dip_and_clear(E, modes, frac, h_full, passed, passed_at, pending, best, dipped,
                                             clear, theta)
        if modes and not pending:
            theta, past, limited = turn_limit(X, C, CI, nc, fl, h, negligible, max_turn, frac, theta, past, limited)
        if not (theta < math.inf and abs(theta - frac) > 1e-12 * max(frac, 1e-300)):
            located = True
            break
        aimed = theta == crossing_aim
        # Never shorter than a few ticks of the clock: an event closer than that is taken as passed.
        h_next = max(h_full * max(theta, 1e-12), shortest)
        work, ok = next_trial(X, C, CI, na, nc, h, h_next, weights, WP, grav, stuck, A, b, fl, exact, pull_rate, warm,
                              one_pass, nudge, reach, negligible, briefs, work, ST)
        h = h_next
        if not ok:
            return h, work, False, limited, -1, True
    if fl[FL_FRICTION]:
        # The step is taken: its stuck slips go back on the band's edge, with the hold system the
        # last kick solved at this geometry and these modes (settled at every trial's end, a
        # third of the settling went on trials the search then threw away).
        done, good = settle(X, C, CI, na, nc, stuck, A, b, fl, NO)
        work += done
        if not good:
            return h, work, False, limited, -1, located
    return h, work, True, limited, -1, located
