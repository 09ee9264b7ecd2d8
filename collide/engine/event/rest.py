"""A sphere alone on a flat wall in closed form (`rest_phase`): the overlap is a harmonic
oscillation, and within each friction mode the slip and spin follow from it; the phase runs from
mode change to mode change, and repeats a cycle that recurs (`rest_repeat`).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.event.contact import geometry, springs
from collide.engine.flight import turn
from collide.engine.jit import jit, jit_call, jit_inline
from collide.engine.layout import (
    BAND,
    C_DELTA,
    C_EPS,
    C_FF,
    C_K,
    C_MU,
    CI_J,
    CI_MODE,
    EPS64,
    F_MAX_FORCE,
    F_MAX_OVERLAP,
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
    FP_EVENT_TOL,
    G_WK,
    GI_KNOT,
    K_AN,
    MAXSTEPS,
    NO,
    S_REST,
    S_STATUS,
    S_STEPS,
    SLIDE,
    STICK,
    TOUCH_TOL,
    X_A,
    X_F,
    X_I,
    X_II,
    X_L,
    X_M,
    X_Q,
    X_R,
    X_S,
    X_V,
    X_W,
    YES,
)
from collide.engine.numerics import dot3, hermite_dip
from collide.engine.records import record_step, share

# A sphere on a flat wall in closed form
#
# With one linear spring and a flat wall, the overlap is a harmonic oscillation whatever the
# friction does (friction is tangential and the wall does not turn), and within each friction
# mode the slip and spin follow from it in closed form, in any direction: band, v and w constant
# (under the wall's share of gravity); slide along a fixed direction, integrals of delta and
# delta^2; stick, the spin in the plane times sqrt(I/m + l^2) constant (l = r - delta, the lever;
# with gravity along the wall, less an integral). A slide whose slip turns (the spin in the
# plane or gravity along the wall off the slip) has none: `rest_aim` holds it along its mean
# direction over each interval. A ball resting, rolling or sliding on a floor then costs its mode
# changes, not the thousands of steps its bob (period 2 pi / omega) takes stepped.

REST_SAMPLES = 8  # intervals per period of the bob: the event values are checked at their ends
# A cycle whose velocities changed by at most this, over the speeds, repeats with that change as a
# drift (a rolling ball's, by the band's dissipation: 7e-13 a period); the drift's own change,
# left out, goes as the square of the cycles jumped (in the band, the drift itself, as their
# number): within REST_DRIFT of the event tolerance.
REST_RECUR, REST_DRIFT = 1e-9, 1e-3
REST_RING = 4  # events whose states are kept to find a cycle
REST_SLIP = 1e-6  # a cycle's length off whole periods of the bob by more than this share: not one
REST_SNAP = 17
REST_STILL, REST_DRIFTING, REST_SLIDING = 0, 1, 2  # what a repeated cycle carries on (rest_repeat)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
GL_X = 0.5 * (_GL_X + 1.0)  # nodes and weights on [0, 1]: to round-off over an eighth of a period
GL_W = 0.5 * _GL_W
# Sliding, friction's work (force times slip: both swing with the bob, the product at twice its
# frequency) takes eight: with four, 2e-8 of an interval's work was left (the energy balance of a
# bounce 2e-9 off); eight leave 1e-20.
_GL8_X, _GL8_W = np.polynomial.legendre.leggauss(8)
GL8_X = 0.5 * (_GL8_X + 1.0)
GL8_W = 0.5 * _GL8_W
# The integral from 0 to each Gauss point of the polynomial through values at all of them.
_GL8_INTEGRALS = [np.polynomial.Polynomial.fit(GL8_X, np.eye(8)[j], 7, domain=[0, 1], window=[0, 1]).integ()
                  for j in range(8)]
GL8_S = np.array([[_GL8_INTEGRALS[j](x) for j in range(8)] for x in GL8_X])
# Tangential quantities are pairs in the wall's tangent basis (e1, e2 = n x e1): the velocity v,
# the spin turned into the plane (n x w: the slip is u = v + l n x w) and the friction force;
# the spin about n is constant. h: the direction a mode holds (the slide's, the stuck slip's).
RP_OM, RP_DEQ, RP_C, RP_S, RP_R, RP_M, RP_II, RP_K, RP_MU, RP_EPS = range(10)
RP_G, RP_V, RP_TW, RP_H, RP_LINE = 10, 12, 14, 16, 18
NRP = 19  # RP_LINE: a slide's start slip along h over its size (1 unless it turns)
REST_STUCK_LIMIT = 8  # events in a row closer than the clock resolves: the stepped path takes over
_GL2 = math.sqrt(3.0) / 6.0
GL2_X = np.array([0.5 - _GL2, 0.5 + _GL2])  # two Gauss points on [0, 1], for the Magnus commutator
GL2_COMMUTATOR = math.sqrt(3.0) / 12.0
REST_PARALLEL = 1e-12  # |a x h| / |a| below which a slide's slip counts as keeping its direction h
REST_AIM_PASSES = 6  # iterations of a turning slide's mean direction, at most
REST_AIMED = 1e-14  # its change (rad) taken as converged
REST_TURN_HALVINGS = 4  # a turning slide's interval halved more than this (a turn too fast for it): stepped
REST_TURN_BUDGET = 1e-3  # ... its error per interval, over the tolerance


@jit_inline
def rest_normal(P, tau):
    """Overlap and its rate at tau into the interval."""
    om = P[RP_OM]
    return rest_normal_at(P, math.cos(om * tau), math.sin(om * tau))


@jit_inline
def rest_normal_at(P, c, s):
    """Overlap and its rate where the bob's phase om tau has cosine c and sine s."""
    return P[RP_DEQ] + P[RP_C] * c + P[RP_S] * s, P[RP_OM] * (P[RP_S] * c - P[RP_C] * s)


@jit_inline
def rest_at(P, mode, tau):
    """(delta, delta', v1, v2, tw1, tw2, f1, f2) at tau into the interval in friction mode `mode`:
    band (or no friction), slide along -h, stick with the slip held at eps h."""
    om = P[RP_OM]
    return rest_at_phase(P, mode, tau, math.cos(om * tau), math.sin(om * tau))


@jit_inline
def rest_at_phase(P, mode, tau, c, s):
    """`rest_at` with the bob's phase om tau given by its cosine c and sine s (one table of them
    serves every interval of the same length)."""
    d, dd = rest_normal_at(P, c, s)
    r, m, ii = P[RP_R], P[RP_M], P[RP_II]
    g1, g2, h1, h2 = P[RP_G], P[RP_G + 1], P[RP_H], P[RP_H + 1]
    v1, v2, w1, w2 = P[RP_V], P[RP_V + 1], P[RP_TW], P[RP_TW + 1]
    if mode == SLIDE:
        om, deq, cc, ss = P[RP_OM], P[RP_DEQ], P[RP_C], P[RP_S]
        x = om * tau
        sx = s
        half = math.sin(0.5 * x)
        osc = (cc * sx + 2.0 * ss * half * half) / om  # integral of delta's oscillating part
        d1 = deq * tau + osc
        s2 = math.sin(2.0 * x) / (4.0 * om)
        d2 = (deq * deq * tau + 2.0 * deq * osc + cc * cc * (0.5 * tau + s2) + ss * ss * (0.5 * tau - s2)
              + cc * ss * sx * sx / om)
        push = P[RP_MU] * P[RP_K]
        dv, dw = push * d1 / m, push * ii * (r * d1 - d2)
        return (d, dd, v1 + g1 * tau - dv * h1, v2 + g2 * tau - dv * h2, w1 - dw * h1, w2 - dw * h2,
                -push * d * h1, -push * d * h2)
    if mode == STICK:
        lever = r - d
        if ii > 0.0:
            # (r - delta) changes the response to the hold force, and the stuck spin with it:
            # tw sqrt(I/m + l^2) is constant, less the integral the tangential gravity adds.
            inertia = 1.0 / (m * ii)
            start = r - (P[RP_DEQ] + P[RP_C])
            lam = 0.0
            if g1 != 0.0 or g2 != 0.0:
                for q in range(GL_X.shape[0]):
                    dq, _ = rest_normal(P, tau * GL_X[q])
                    lam += GL_W[q] * (r - dq) / math.sqrt(inertia + (r - dq) ** 2)
                lam *= tau
            a, b = math.sqrt(inertia + start * start), math.sqrt(inertia + lever * lever)
            w1, w2 = (w1 * a - g1 * lam) / b, (w2 * a - g2 * lam) / b
        resp = 1.0 / m + lever * lever * ii
        eps = P[RP_EPS]
        return (d, dd, eps * h1 - lever * w1, eps * h2 - lever * w2, w1, w2, (dd * w1 - g1) / resp,
                (dd * w2 - g2) / resp)
    return d, dd, v1 + g1 * tau, v2 + g2 * tau, w1, w2, 0.0, 0.0


@jit_inline
def rest_events(P, mode, tau, touch, out):
    """Event values and their rates at tau into the interval, into out (3, 2): the contact's end
    (overlap past -touch), then the mode's: band, eps - |u|; slide, u.h - eps (u.h - eps cos a
    for a turning slip, held along its mean direction h at an angle a from its start: see
    rest_aim; a slide started on the band's edge starts at zero); stick, the margin
    to mu F_n and the hold force against the held slip."""
    d, dd, v1, v2, w1, w2, f1, f2 = rest_at(P, mode, tau)
    r, m, ii, eps = P[RP_R], P[RP_M], P[RP_II], P[RP_EPS]
    g1, g2, h1, h2 = P[RP_G], P[RP_G + 1], P[RP_H], P[RP_H + 1]
    lever = r - d
    out[0, 0], out[0, 1] = d + touch, dd
    out[1, 0], out[1, 1] = math.inf, 0.0
    out[2, 0], out[2, 1] = math.inf, 0.0
    if mode < 0:
        return
    u1, u2 = v1 + lever * w1, v2 + lever * w2
    resp = 1.0 / m + lever * lever * ii
    if mode == BAND:
        mag = math.hypot(u1, u2)
        rate = (u1 * (g1 - dd * w1) + u2 * (g2 - dd * w2)) / mag if mag > 0.0 else 0.0
        out[1, 0], out[1, 1] = eps - mag, -rate
    elif mode == SLIDE:
        out[1, 0] = u1 * h1 + u2 * h2 - eps * P[RP_LINE]
        out[1, 1] = h1 * (f1 * resp + g1 - dd * w1) + h2 * (f2 * resp + g2 - dd * w2)
    else:
        ddd = -P[RP_OM] ** 2 * (d - P[RP_DEQ])
        fd1 = (ddd * w1 + 3.0 * lever * dd * ii * f1) / resp
        fd2 = (ddd * w2 + 3.0 * lever * dd * ii * f2) / resp
        mag = math.hypot(f1, f2)
        cap = P[RP_MU] * P[RP_K]
        out[1, 0] = cap * d - mag
        out[1, 1] = cap * dd - ((f1 * fd1 + f2 * fd2) / mag if mag > 0.0 else 0.0)
        out[2, 0], out[2, 1] = -(f1 * h1 + f2 * h2), -(fd1 * h1 + fd2 * h2)


@jit_inline
def rest_root(P, mode, k, lo, g_lo, hi, g_hi, touch, out, clock):
    """A root of event value k in [lo, hi] (g_lo >= 0 > g_hi), by the Illinois method."""
    side = 0
    for _ in range(200):
        if hi - lo <= clock:
            break
        mid = hi - g_hi * (hi - lo) / (g_hi - g_lo)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        rest_events(P, mode, mid, touch, out)
        g = out[k, 0]
        if g < 0.0:
            hi, g_hi = mid, g
            if side == -1:
                g_lo *= 0.5
            side = -1
        else:
            lo, g_lo = mid, g
            if side == 1:
                g_hi *= 0.5
            side = 1
    return hi


@jit_inline
def rest_first(P, mode, h, touch, start, ends, out, clock):
    """The first event within the interval [0, h]: (its time, which: -1 none, 0 the contact's
    end, 1 or 2 the mode's). `start` (3, 2): the values and rates at 0; `ends`, `out`: room."""
    rest_events(P, mode, h, touch, ends)
    first, which = math.inf, -1
    # A slip's value is a difference of velocities (v + l tw, about the speed, less eps): their
    # round-off.
    noise = 4.0 * EPS64 * (abs(P[RP_V]) + abs(P[RP_V + 1]) + P[RP_R] * (abs(P[RP_TW]) + abs(P[RP_TW + 1])))
    for k in range(3):
        g0, g1 = start[k, 0], ends[k, 0]
        if not math.isfinite(g0) or not math.isfinite(g1):
            continue
        lo, g_lo = 0.0, max(g0, 0.0)
        floor = noise if k == 1 and mode != STICK else 0.0
        if g0 < floor:
            # A mode just entered whose value starts a hair below zero (the round-off of the
            # state it was judged on), or a slip's within its round-off of it: its root is where
            # it crosses back down, after it rose clear. Where its rate says, if it rises; else,
            # or if not clear there, the first of points 16 times apart from the clock's tick
            # where it is, unless it falls clear below first (it is leaving: the root is now).
            # A rate of round-off whose value rises by the rate's own rate is a slip at the bob's
            # turn, its hold force through zero: from an assumed zero at 0, the secant found the
            # slip leaving the band at once, and the hold force reversing at once, over and over,
            # until the stepped path took over (a ball rolling at k = 1e5 N/m, from its first
            # tenth of a second); and a slide at the bob's top, where mu F_n is nil, its slip 3e-17
            # off the band's edge and leaving it at 3e-11 m/s^2, met the edge in its round-off
            # (8e-17) 30 000 times in 0.2 s.
            if g0 < 0.0 and start[k, 1] > 0.0:
                lo = min(h, -4.0 * g0 / start[k, 1] + clock)
                rest_events(P, mode, lo, touch, out)
                g_lo = out[k, 0]
            if not (lo > 0.0 and g_lo >= floor):
                lo, g_lo = 0.0, max(g0, 0.0)
                tau = clock
                while tau < h:
                    rest_events(P, mode, tau, touch, out)
                    if out[k, 0] >= floor and out[k, 0] > 0.0:
                        lo, g_lo = tau, out[k, 0]
                        break
                    if out[k, 0] < min(2.0 * g0, -floor):
                        break
                    tau *= 16.0
        hi, g_hi = math.nan, math.nan
        if g1 < 0.0 and lo < h:
            hi, g_hi = h, g1
        else:
            # A value positive at both ends that dips below zero between, on the cubic through
            # both ends' values and rates (then checked at the true value).
            x = hermite_dip(g0, g1, start[k, 1] * h, ends[k, 1] * h, 0.0)
            if x < math.inf:
                rest_events(P, mode, x * h, touch, out)
                if out[k, 0] < 0.0:
                    hi, g_hi = x * h, out[k, 0]
        if hi == hi and first < hi:
            # An earlier value's root bounds this one's: below zero there, it crossed before.
            hi = math.nan
            if lo < first:
                rest_events(P, mode, first, touch, out)
                if out[k, 0] < 0.0:
                    hi, g_hi = first, out[k, 0]
        if hi == hi:
            first = rest_root(P, mode, k, lo, g_lo, hi, g_hi, touch, out, clock)
            which = k
    return first, which


@jit_inline
def rest_mode(u1, u2, t1, t2, cap, resp, eps, tol):
    """The friction mode of a slip u whose rate without friction is t, the direction it holds and
    whether the slip is on the band's edge: slide outside the band, band inside, and on its edge
    stick while mu F_n can hold it there. On the edge the slip is held (or slides on) along t:
    the hold force's reverse (as the stepped path's `decide`)."""
    mag = math.hypot(u1, u2)
    if mag > eps + tol:
        return SLIDE, u1 / mag, u2 / mag, False
    if mag < eps - tol or u1 * t1 + u2 * t2 <= 0.0:
        return BAND, 0.0, 0.0, False
    rate = math.hypot(t1, t2)
    return (STICK if rate / resp <= cap else SLIDE), t1 / rate, t2 / rate, True


@jit_inline
def rest_turns(P):
    """Whether gravity along the wall or the spin turned into it turns a slide's slip off h."""
    h1, h2 = P[RP_H], P[RP_H + 1]
    for a in (RP_G, RP_TW):
        a1, a2 = P[a], P[a + 1]
        if abs(a1 * h2 - a2 * h1) > REST_PARALLEL * math.hypot(a1, a2):
            return True
    return False


@jit_inline
def rest_spin(n, e1, e2, w_n, w1, w2, i):
    """Component i of the spin from its part about n and the pair n x w in the basis."""
    return w_n * n[i] + w2 * e1[i] - w1 * e2[i]


@jit
def rest_aim(P, h, touch, start, ends, out, clock, budget):
    """A slide whose slip turns, over [0, h]: friction held along one direction for the interval,
    the mean of the slip's direction weighted by the friction force up to the interval's first
    event, found by iteration. The slip's direction phi follows phi' = (u x b) / |u|^2 (b its
    rate without friction: friction along the slip does not turn it), integrated at the Gauss
    points on the polynomial through them. The velocities' error is then of second order in the
    turn: 1/2 int A (phi - mean)^2 (A the slip's deceleration by friction), which must be within
    `budget`, else the interval is halved. Returns (the first event's time, which, the
    interval's length; 0 if it became too short)."""
    r, push, m, ii, g1, g2 = P[RP_R], P[RP_MU] * P[RP_K], P[RP_M], P[RP_II], P[RP_G], P[RP_G + 1]
    rate = np.empty(GL8_X.shape[0])
    weight = np.empty(GL8_X.shape[0])
    # The slip's direction at the start: the state's own.
    lever = r - (P[RP_DEQ] + P[RP_C])
    base = math.atan2(P[RP_V + 1] + lever * P[RP_TW + 1], P[RP_V] + lever * P[RP_TW])
    for _ in range(REST_TURN_HALVINGS):
        error = math.inf
        for passes in range(REST_AIM_PASSES + 1):
            rest_events(P, SLIDE, 0.0, touch, start)
            tau, which = rest_first(P, SLIDE, h, touch, start, ends, out, clock)
            if passes == REST_AIM_PASSES:
                break
            reach = min(tau, h)
            total = 0.0
            for q in range(GL8_X.shape[0]):
                d, dd, v1, v2, w1, w2, _, _ = rest_at(P, SLIDE, reach * GL8_X[q])
                lever = r - d
                u1, u2 = v1 + lever * w1, v2 + lever * w2
                rate[q] = (u1 * (g2 - dd * w2) - u2 * (g1 - dd * w1)) / (u1 * u1 + u2 * u2)
                weight[q] = GL8_W[q] * push * d * (1.0 / m + lever * lever * ii)
                total += weight[q]
            mean, error = 0.0, 0.0
            for q in range(GL8_X.shape[0]):
                # A plain sum, not `@`: numba's matrix product needs scipy's BLAS.
                turned = 0.0
                for j in range(GL8_X.shape[0]):
                    turned += GL8_S[q, j] * rate[j]
                turned *= reach
                mean += weight[q] * turned
                error += weight[q] * turned * turned
            mean /= total
            error = 0.5 * reach * (error - total * mean * mean)
            c, s = math.cos(base + mean), math.sin(base + mean)
            moved = math.hypot(c - P[RP_H], s - P[RP_H + 1])
            P[RP_H], P[RP_H + 1], P[RP_LINE] = c, s, math.cos(mean)
            if moved <= REST_AIMED:
                break
        if error <= budget:
            return tau, which, h
        h *= 0.5
    return math.inf, -1, 0.0


@jit
def rest_ready(X, C, CI, na, nc, nq, fl):
    """Whether this contact phase runs in closed form: one sphere on one wall, undamped, the
    contact's own step (dt auto) and the true lever, the linear spring, no tangential spring."""
    return (fl[FL_AUTO] and nq == 1 and na == 1 and nc == 1 and CI[0, CI_J] < 0 and not fl[FL_SEED]
            and not fl[FL_DAMPED] and not fl[FL_HERTZ] and not fl[FL_SPRING])


@jit_call
def rest_basis(n, planar, e1, e2):
    """The wall's tangent basis e1, e2 = n x e1 (in the plane: e1 = n x z, e2 = -z)."""
    if planar:
        e1[0], e1[1] = n[1], -n[0]  # n x z: the in-plane tangent (e2 = -z)
    else:
        # n x the axis least along n.
        a = 0 if abs(n[0]) <= min(abs(n[1]), abs(n[2])) else (1 if abs(n[1]) <= abs(n[2]) else 2)
        e1[(a + 1) % 3], e1[(a + 2) % 3] = n[(a + 2) % 3], -n[(a + 1) % 3]
        e1 /= math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    e2[0], e2[1], e2[2] = n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]


@jit_call
def rest_choose(G, XI, P, mode, decided, reached, lever, d_a, dd_a, v1, v2, w1, w2, m, ii, k):
    """The friction mode at an interval's start (a fresh decision, or out of the plane a stuck
    slip's hold direction again), with the slip put on the band's edge where the mode holds it
    there. Returns (mode, decided, whether newly decided, turning)."""
    chosen = False
    u1, u2 = v1 + lever * w1, v2 + lever * w2
    t1, t2 = P[RP_G] - dd_a * w1, P[RP_G + 1] - dd_a * w2
    resp = 1.0 / m + lever * lever * ii
    edge = mode == STICK
    if decided:
        # Out of the plane the hold force turns as the bob swings: the stuck slip follows
        # its reverse, put there at each interval's start (as the stepped path's steps).
        rate = math.hypot(t1, t2)
        if rate > 0.0:
            P[RP_H], P[RP_H + 1] = t1 / rate, t2 / rate
    else:
        # On the edge within what the state's round-off leaves (the normal velocity's
        # share of a velocity turned into the contact's frame; the root's ticks), and
        # by construction where a slide or the band just reached it (a turning slide's
        # end is off by its second-order error: 2e-12 of its size was taken to slide on).
        tol = 1e-12 * (math.hypot(v1, v2) + lever * math.hypot(w1, w2) + abs(dd_a))
        if reached:
            tol = math.inf
        mode, P[RP_H], P[RP_H + 1], edge = rest_mode(u1, u2, t1, t2, P[RP_MU] * k * d_a, resp,
                                                     P[RP_EPS], tol)
        decided = chosen = True
    if edge:
        # The slip put on the edge along h by the friction impulse that does that (its
        # work is friction's); in the plane h is the slip's own direction already.
        j1 = (P[RP_EPS] * P[RP_H] - u1) / resp
        j2 = (P[RP_EPS] * P[RP_H + 1] - u2) / resp
        P[RP_V], P[RP_V + 1] = v1 + j1 / m, v2 + j2 / m
        P[RP_TW], P[RP_TW + 1] = w1 + lever * ii * j1, w2 + lever * ii * j2
        gain = 0.5 * m * (P[RP_V] ** 2 + P[RP_V + 1] ** 2 - v1 * v1 - v2 * v2)
        if ii > 0.0:
            gain += 0.5 / ii * (P[RP_TW] ** 2 + P[RP_TW + 1] ** 2 - w1 * w1 - w2 * w2)
        share(G, XI, 1, -gain)
    turning = mode == SLIDE and rest_turns(P)
    return mode, decided, chosen, turning


@jit_call
def rest_move(X, P, mode, h, om, r, n, e1, e2, w_n, d_a, d, spun, phases, phases_h, phases_n):
    """The positions and the spin's turn over an interval of length h by Gauss-Legendre, and
    friction's work per unit time (from its force and the slip, not from the energies: a check).
    Returns (spent, phases_h, phases_n)."""
    along1, along2, spent = 0.0, 0.0, 0.0
    spun[:] = 0.0  # the mean spin in the plane
    nodes, weights = (GL8_X, GL8_W) if mode == SLIDE else (GL_X, GL_W)
    if h != phases_h or nodes.shape[0] != phases_n:
        # The bob's phase at the quadrature nodes: the same for every interval of this length.
        phases_h, phases_n = h, nodes.shape[0]
        for q in range(phases_n):
            phases[q, 0], phases[q, 1] = math.cos(om * (h * nodes[q])), math.sin(om * (h * nodes[q]))
    for q in range(nodes.shape[0]):
        dq, _, vq1, vq2, wq1, wq2, fq1, fq2 = rest_at_phase(P, mode, h * nodes[q], phases[q, 0], phases[q, 1])
        along1 += weights[q] * vq1
        along2 += weights[q] * vq2
        for i in range(3):
            spun[i] += weights[q] * rest_spin(n, e1, e2, 0.0, wq1, wq2, i)
        spent -= weights[q] * (fq1 * (vq1 + (r - dq) * wq1) + fq2 * (vq2 + (r - dq) * wq2))
    for i in range(3):
        X[0, X_S + i] += n[i] * (d_a - d) + (e1[i] * along1 + e2[i] * along2) * h
        spun[i] = (spun[i] + w_n * n[i]) * h
    return spent, phases_h, phases_n


@jit_call
def rest_turn(X, P, mode, h, n, e1, e2, w_n, spun, planar):
    """The orientation turned by the interval's spin `spun`."""
    if planar:
        X[0, X_Q] += spun[2]
    else:
        if mode == STICK or mode == SLIDE:
            # The spin's direction changes: fourth-order Magnus, the commutator of the
            # spins at two Gauss points added to the mean's turn.
            _, _, _, _, a1, a2, _, _ = rest_at(P, mode, h * GL2_X[0])
            _, _, _, _, b1, b2, _, _ = rest_at(P, mode, h * GL2_X[1])
            ax, ay, az = (rest_spin(n, e1, e2, w_n, a1, a2, 0), rest_spin(n, e1, e2, w_n, a1, a2, 1),
                          rest_spin(n, e1, e2, w_n, a1, a2, 2))
            bx, by, bz = (rest_spin(n, e1, e2, w_n, b1, b2, 0), rest_spin(n, e1, e2, w_n, b1, b2, 1),
                          rest_spin(n, e1, e2, w_n, b1, b2, 2))
            c = GL2_COMMUTATOR * h * h
            spun[0] -= c * (ay * bz - az * by)
            spun[1] -= c * (az * bx - ax * bz)
            spun[2] -= c * (ax * by - ay * bx)
        turn(X[0, X_Q:X_Q + 4], spun[0], spun[1], spun[2], 1.0, NO)


@jit_call
def rest_forces(X, C, CI, P, WP, grav, FG, e1, e2, d_a, dd_a, d, dd, f1, f2, m, r, k, ii, mode, fric):
    """An interval's end: the deepest overlap and force so far, the contact's geometry, spring and
    friction there."""
    # The deepest overlap (and force) of the interval: at its end, or inside where the bob turns.
    deepest = max(d_a, d) if not (dd_a > 0.0 and dd < 0.0) else P[RP_DEQ] + math.hypot(P[RP_C], P[RP_S])
    FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], deepest)
    FG[F_MAX_FORCE] = max(FG[F_MAX_FORCE], k * deepest)
    geometry(X, C, CI, 1, WP, NO, NO)
    springs(X, C, CI, 1, 1, grav)
    for i in range(3):
        force = f1 * e1[i] + f2 * e2[i]
        C[0, C_FF + i] = force
        X[0, X_F + i] = force / m
        X[0, X_L + i] = (r - d) * ii * (f2 * e1[i] - f1 * e2[i])  # (-l n) x F / I
    CI[0, CI_MODE] = mode if fric else BAND


@jit_call
def rest_cycles(G, XI, X, C, CI, P, WP, t, W, n, grav, spin, planar, fp, mode, which, whole, bob, ends, snap, lap,
                snaps, marks, ring):
    """Nothing here depends on the position along the wall or the orientation: once the state
    recurs (the bob's phase, the velocities, the mode), the motion repeats (a ball resting,
    rolling or sliding straight). A cycle is looked for between two events of the same kind, or
    over a period of the bob without events, and repeated in one go (`rest_repeat`). Returns (t,
    lap, ring)."""
    depth = P[RP_DEQ] + math.hypot(P[RP_C], P[RP_S])
    if which > 0:
        # An event: the state may recur at a later one of the same kind (stuck and in the
        # band in turn, twice a period, as a ball rolls in 3D).
        lap = -1
        for e in range(REST_RING):
            if marks[e, 0] == mode and marks[e, 1] == which:
                jumped = rest_repeat(G, XI, X, C, CI, WP, t, W, snaps[e], depth, bob, n, grav, spin, planar,
                                     fp[FP_EVENT_TOL], REST_DRIFTING, 0.0, 0.0)
                if jumped != t:
                    t = jumped
                    marks[:, 0] = -9
                    break
        e = ring % REST_RING
        ring += 1
        rest_snapshot(G, XI, X, C, t, snaps[e], 0.0)
        marks[e, 0], marks[e, 1] = mode, which
    elif whole and lap >= 0:
        lap += 1
        if lap == REST_SAMPLES:
            # A period without events (stuck, sliding, in the band or no friction).
            kind = REST_SLIDING if mode == SLIDE else (REST_DRIFTING if mode == STICK else REST_STILL)
            t = rest_repeat(G, XI, X, C, CI, WP, t, W, snap, depth, bob, n, grav, spin, planar,
                            fp[FP_EVENT_TOL], kind, ends[1, 0], math.hypot(P[RP_TW], P[RP_TW + 1]))
            rest_snapshot(G, XI, X, C, t, snap, ends[1, 0])
            lap = 0
    else:
        rest_snapshot(G, XI, X, C, t, snap, ends[1, 0])
        lap = 0 if which < 0 else -1
    return t, lap, ring


@jit
def rest_phase(G, GI, X, XI, C, CI, t, W, WP, grav, fl, fp, KN, RC, CNT, ST, FG):
    """Advance a sphere on a wall (see rest_ready) in closed form from t to W or to the contact's
    end, recording a knot at the end of every interval. Returns (t, KN, RC, ended); stopped short
    of both, the stepped path goes on: a slide whose slip turns too fast for `rest_aim`, or mode
    changes piling up closer than the clock resolves."""
    spin, record, planar = fl[FL_SPIN], fl[FL_RECORD], fl[FL_PLANAR] == YES
    fric = fl[FL_FRICTION] and C[0, C_MU] > 0.0
    w_k = -1 - CI[0, CI_J]
    n = WP[w_k, 3:6]  # out of the wall, towards the sphere
    e1 = np.zeros(3)
    e2 = np.zeros(3)
    rest_basis(n, planar, e1, e2)
    m, r, k = X[0, X_M], X[0, X_R], C[0, C_K]
    ii = X[0, X_II] if spin else 0.0
    om = math.sqrt(k / m)
    P = np.zeros(NRP)
    P[RP_OM], P[RP_DEQ], P[RP_R], P[RP_M], P[RP_II], P[RP_K] = om, -dot3(grav, n) / (om * om), r, m, ii, k
    P[RP_MU], P[RP_EPS] = C[0, C_MU], C[0, C_EPS]
    P[RP_G], P[RP_G + 1] = dot3(grav, e1), dot3(grav, e2)
    touch = 2.0 * TOUCH_TOL * r
    bob = 2.0 * math.pi / om
    span = bob / REST_SAMPLES
    start = np.zeros((3, 2))
    ends = np.zeros((3, 2))
    out = np.zeros((3, 2))
    spun = np.zeros(3)
    phases = np.zeros((GL8_X.shape[0], 2))  # cos and sin of om h x_q for the interval length phases_h
    phases_h, phases_n = -1.0, 0
    mode = -1
    geometry(X, C, CI, 1, WP, NO, NO)
    springs(X, C, CI, 1, 1, grav)
    decided = False
    announce = False
    turning = False
    reached = False
    quick = 0
    # A turning slide's error per interval, over the speeds: a thousandth of the tolerance (an
    # impact takes a few such intervals; a run with many is measured, as a stepped one).
    budget = max(4.0 * EPS64, REST_TURN_BUDGET * fp[FP_EVENT_TOL])
    # Cycles that recur are repeated in one go (`rest_cycles`); not when recording, whose knots
    # every interval gives.
    snap = np.zeros(REST_SNAP)
    lap = -1  # whole intervals without events since `snap`; -1: none taken
    snaps = np.zeros((REST_RING, REST_SNAP))  # the state at the last few events, and their kinds
    marks = np.full((REST_RING, 2), -9)
    ring = 0
    while t < W:
        d_a = C[0, C_DELTA]
        dd_a = -dot3(X[0, X_V:X_V + 3], n)
        w_n = dot3(X[0, X_W:X_W + 3], n)
        P[RP_C], P[RP_S] = d_a - P[RP_DEQ], dd_a / om
        # n x w in the basis is (-w.e2, w.e1).
        v1, v2 = dot3(X[0, X_V:X_V + 3], e1), dot3(X[0, X_V:X_V + 3], e2)
        w1, w2 = -dot3(X[0, X_W:X_W + 3], e2), dot3(X[0, X_W:X_W + 3], e1)
        P[RP_V], P[RP_V + 1], P[RP_TW], P[RP_TW + 1], P[RP_LINE] = v1, v2, w1, w2, 1.0
        lever = r - d_a
        if fric and (not decided or (mode == STICK and not planar)):
            mode, decided, chosen, turning = rest_choose(G, XI, P, mode, decided, reached, lever, d_a, dd_a, v1, v2,
                                                         w1, w2, m, ii, k)
            announce = announce or chosen
        if announce and record:
            # The acceleration the mode starts with, after the last knot's (a jump there).
            _, _, _, _, _, _, f1, f2 = rest_at(P, mode, 0.0)
            last = GI[XI[0], GI_KNOT]
            for i in range(3):
                KN[last, K_AN + i] = X[0, X_A + i] + (f1 * e1[i] + f2 * e2[i]) / m
        announce = False
        h = min(span, W - t)
        clock = 4.0 * EPS64 * (abs(t) + h)
        if turning:
            scale = math.hypot(v1, v2) + lever * math.hypot(w1, w2) + abs(dd_a)
            tau, which, h = rest_aim(P, h, touch, start, ends, out, clock, budget * scale)
            if h == 0.0:
                rest_put(X, P, dd_a, n, e1, e2, w_n)
                return t, KN, RC, False
        else:
            rest_events(P, mode, 0.0, touch, start)
            tau, which = rest_first(P, mode, h, touch, start, ends, out, clock)
        whole = which < 0 and h == span
        landed = W if tau >= h and h == W - t else t + min(tau, h)
        if landed == t and which == 0 and tau <= h:
            # The contact ends closer than the clock resolves: on its next tick (a tick past the
            # end, the overlap is gone by at most the speed times a tick), not again and again.
            landed = min(np.nextafter(t, math.inf), W)
        h = landed - t
        quick = quick + 1 if which > 0 and h <= clock else 0
        if quick > REST_STUCK_LIMIT:
            rest_put(X, P, dd_a, n, e1, e2, w_n)
            return t, KN, RC, False
        d, dd, v1, v2, w1, w2, f1, f2 = rest_at(P, mode, h)
        spent, phases_h, phases_n = rest_move(X, P, mode, h, om, r, n, e1, e2, w_n, d_a, d, spun, phases, phases_h,
                                              phases_n)
        if spin:
            rest_turn(X, P, mode, h, n, e1, e2, w_n, spun, planar)
        P[RP_V], P[RP_V + 1], P[RP_TW], P[RP_TW + 1] = v1, v2, w1, w2
        rest_put(X, P, dd, n, e1, e2, w_n)
        t = landed
        rest_forces(X, C, CI, P, WP, grav, FG, e1, e2, d_a, dd_a, d, dd, f1, f2, m, r, k, ii, mode, fric)
        share(G, XI, 1, spent * h)
        ST[S_STEPS] += 1
        if not turning:
            ST[S_REST] += 1  # exact: a turning slide's intervals are not (their error is estimated)
        if record:
            KN, RC = record_step(KN, RC, CNT, G, GI, X, XI, C, CI, 1, 1, t, fl)
        if ST[S_STEPS] > fl[FL_MAXSTEPS]:
            ST[S_STATUS] = MAXSTEPS
            break
        if not record and not turning:
            t, lap, ring = rest_cycles(G, XI, X, C, CI, P, WP, t, W, n, grav, spin, planar, fp, mode, which, whole,
                                       bob, ends, snap, lap, snaps, marks, ring)
        if which == 0:
            return t, KN, RC, True
        if which > 0:
            # A stuck slip that can no longer be held slides on from its side of the band; one
            # whose hold force would turn round goes back into the band; a slip reaching the
            # band's edge is judged there, on the next interval's start.
            decided = False
            reached = which == 1 and mode != STICK
            if mode == STICK:
                mode = SLIDE if which == 1 else BAND
                decided = announce = True
                turning = mode == SLIDE and rest_turns(P)
    return t, KN, RC, False


@jit_inline
def rest_snapshot(G, XI, X, C, t, snap, value):
    """What `rest_repeat` compares and advances: t, position, orientation, dissipated work, the
    state that must recur (overlap, velocity, spin), and a slide's slip value."""
    snap[0] = t
    for i in range(3):
        snap[1 + i] = X[0, X_S + i]
        snap[9 + i] = X[0, X_V + i]
        snap[12 + i] = X[0, X_W + i]
    for i in range(4):
        snap[4 + i] = X[0, X_Q + i]
    snap[8] = G[XI[0], G_WK]
    snap[15] = C[0, C_DELTA]
    snap[16] = value


@jit_inline
def rest_repeat(G, XI, X, C, CI, WP, t, W, snap, depth, bob, normal, grav, spin, planar, event_tol, kind, value, spun):
    """Repeat a cycle: if the state now is the one in `snap` (taken at the same point of the
    motion: see rest_phase) but for a slow drift of the velocities (the band's dissipation), every
    cycle after is this one moved on: the bob's phase the same, the velocities and spins drifting
    by the cycle's change each cycle (and the displacement and turn with them), the same
    dissipated work and events. A cycle is whole periods of the bob (`bob`, s), its length taken
    as that, exactly, not as the events' times say (their phase recurs to the overlap's
    round-off).

    `kind`: REST_STILL, a period in the band or without friction, where nothing dissipates and
    the velocities recur but for round-off (not carried on: over 20 000 cycles it left 1e-12 in
    the energy); REST_DRIFTING, a cycle with stuck phases; REST_SLIDING, a slide along a fixed
    direction, whose friction (mu k delta, delta periodic) changes the velocities by the same
    each period, exactly. A slide's slip value (u.h - eps, `value` now) falls by the same each
    period, so it ends after value / fall periods, less a margin for the turned spin `spun` times
    the lever's swing (the bob's `depth`).

    The work each cycle dissipates is the measured cycle's, plus k times its change from one cycle
    to the next; that change is the energies' (m |Delta v|^2 + I |Delta w|^2 - m g . Delta v P,
    with the drifts extrapolated here), so that the energy balances over the cycles jumped. Taken
    from the friction's closed form instead, it carried the overlap's round-off (1e-9 of it at
    k = 1e9, from the centre's height) into the balance: 1.4e-11 off where the intervals leave
    1e-15.

    Jumps as many whole cycles as leave one at least before W to the intervals, and as keep what
    that leaves out within its share of the event tolerance: the drift's own change (REST_DRIFT);
    out of the plane, the turns' commutators. Returns the new t (t itself when the state did not
    recur), the geometry and springs (C, X_A) the moved state's."""
    measured = t - snap[0]
    periods = math.floor(measured / bob + 0.5)
    if not periods >= 1.0 or abs(measured - periods * bob) > REST_SLIP * measured:
        return t
    period = periods * bob
    ratio = period / measured  # the cycle's displacement, turn and work, over the bob's periods
    n = math.floor((W - t) / period) - 1.0
    if not n >= 1.0:
        return t
    r = X[0, X_R]
    # The velocities' change along the wall and the spins': the drift (across the wall the bob's
    # phase recurs, checked by the overlap).
    across = 0.0
    for i in range(3):
        across += (X[0, X_V + i] - snap[9 + i]) * normal[i]
    speed, moved = 0.0, 0.0
    for i in range(3):
        speed += abs(X[0, X_V + i]) + r * abs(X[0, X_W + i])
        moved += abs(X[0, X_V + i] - snap[9 + i] - across * normal[i]) + r * abs(X[0, X_W + i] - snap[12 + i])
    # The overlap recurs to the round-off of the position it is measured from.
    off = max(0.0, abs(C[0, C_DELTA] - snap[15]) - 16.0 * EPS64 * r) / depth if depth > 0.0 else 0.0
    drift = moved / speed if speed > 0.0 else 0.0
    if off > 0.0:
        return t
    carried = 0.0 if kind == REST_STILL else 1.0  # the drift, carried on or not
    if kind == REST_SLIDING:
        fall = snap[16] - value
        margin = 2.0 * abs(fall) + 2.0 * depth * spun
        if value <= margin:
            return t
        if fall > 0.0:
            n = min(n, math.floor((value - margin) / fall) - 1.0)
    else:
        if drift > REST_RECUR:
            return t
        # What is left out: still, the drift itself (round-off, or gravity along the wall at
        # round-off); drifting, the drift's own change.
        if drift > 0.0:
            left = REST_DRIFT * event_tol / drift if kind == REST_STILL else math.sqrt(REST_DRIFT * event_tol) / drift
            n = min(n, math.floor(left))
    # Out of the plane, the cycle's turn U as a rotation vector, and what the spins' drift adds
    # to it each cycle (g): k cycles on, the turn is about theta + k g. Taken as one rotation, n
    # of them leave out their commutators, n^3 |theta x g| / 12 (rad): within the event tolerance
    # (the orientation does not act back on the motion).
    tx, ty, tz, gx, gy, gz = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if spin and not planar:
        a, b, c, d = X[0, X_Q], X[0, X_Q + 1], X[0, X_Q + 2], X[0, X_Q + 3]
        e, f, g, h = snap[4], -snap[5], -snap[6], -snap[7]  # the snapshot's inverse
        u0 = a * e - b * f - c * g - d * h
        ux, uy, uz = a * f + b * e + c * h - d * g, a * g - b * h + c * e + d * f, a * h + b * g - c * f + d * e
        size = math.sqrt(ux * ux + uy * uy + uz * uz)
        if size > 0.0:
            angle = 2.0 * math.atan2(size, u0) / size
            tx, ty, tz = angle * ux, angle * uy, angle * uz
        gx, gy, gz = (carried * period * (X[0, X_W] - snap[12]), carried * period * (X[0, X_W + 1] - snap[13]),
                      carried * period * (X[0, X_W + 2] - snap[14]))
        cx, cy, cz = ty * gz - tz * gy, tz * gx - tx * gz, tx * gy - ty * gx
        left = math.sqrt(cx * cx + cy * cy + cz * cz)
        if left > 0.0:
            n = min(n, math.floor((12.0 * event_tol / left) ** (1.0 / 3.0)))
    if n < 1.0:
        return t
    # Cycle k after this one moves by this one's displacement plus k times the drift's, along
    # the wall: across it the bob's phase is exact, and its change over the cycle measured the
    # events' phase, not a drift.
    grow = 0.5 * n * (n + 1.0) * period
    ds = 0.0
    for i in range(3):
        ds += (X[0, X_S + i] - snap[1 + i]) * normal[i]
    grown = 0.0  # the work's change from one cycle to the next
    for i in range(3):
        drift = carried * (X[0, X_V + i] - snap[9 + i] - across * normal[i])
        dw = carried * (X[0, X_W + i] - snap[12 + i]) if spin else 0.0
        grown -= X[0, X_M] * drift * (drift - grav[i] * period) + X[0, X_I] * dw * dw
        X[0, X_S + i] += n * ratio * (X[0, X_S + i] - snap[1 + i] - ds * normal[i]) + grow * drift
        X[0, X_V + i] += n * drift
    if spin:
        if planar:
            X[0, X_Q] += n * ratio * (X[0, X_Q] - snap[4]) + grow * carried * (X[0, X_W + 2] - snap[14])
        else:
            tx = n * ratio * tx + grow / period * gx
            ty = n * ratio * ty + grow / period * gy
            tz = n * ratio * tz + grow / period * gz
            turn(X[0, X_Q:X_Q + 4], tx, ty, tz, 1.0, NO)
    for i in range(3):
        X[0, X_W + i] += n * carried * (X[0, X_W + i] - snap[12 + i])
    G[XI[0], G_WK] += n * ratio * (G[XI[0], G_WK] - snap[8]) + 0.5 * n * (n + 1.0) * grown
    geometry(X, C, CI, 1, WP, NO, NO)
    springs(X, C, CI, 1, 1, grav)
    return t + n * period


@jit_inline
def rest_put(X, P, dd, n, e1, e2, w_n):
    """The body's velocity and spin from the tangential pairs in P and the normal rate dd."""
    v1, v2, w1, w2 = P[RP_V], P[RP_V + 1], P[RP_TW], P[RP_TW + 1]
    for i in range(3):
        X[0, X_V + i] = v1 * e1[i] + v2 * e2[i] - n[i] * dd
        X[0, X_W + i] = rest_spin(n, e1, e2, w_n, w1, w2, i)
