"""One normal contact at full order: the overlap delta of a sphere on a rigid wall, or of two
spheres head-on, from touching to separating, under the normal laws of docs/design.md section 9
(the linear spring or Hertz, with the dashpot of a restitution), taken from the DEM kernel's own
definitions (`collide.engine.dem.normal`, `collide.engine.dem.damping`) so the two cannot
disagree.

    m* delta'' = -F_n(delta, delta') + m* a,   F_n = F_el(delta) + gamma(delta) delta'

(a: a constant acceleration pressing the contact, gravity's part along the normal). The force is
not clipped at zero (as in the DEM kernel): the contact ends where delta returns to 0.

Hertz's force, delta^1.5, and its dashpot, gamma ~ delta^(1/4), have singular derivatives at
delta = 0, so a step in time that starts or ends there loses its order. Near both ends the
overlap grows or shrinks monotonically, and there the contact is integrated over
sigma = delta^(1/p) (p = 4 for Hertz, 1 for the linear spring) instead of time: in sigma every
term is a polynomial (delta^1.5 = sigma^6, gamma ~ sigma), so the solution is smooth and the
step keeps its order. Between the two ends (where delta' passes through zero) the contact is
integrated over time. Every step is a 3-stage Gauss-Legendre collocation step (order 6,
symmetric), its stages solved by fixed-point iteration. The largest overlap (delta' = 0) and
the largest force (dF/dt = 0) are landed by re-taking the step that contains them at the
length that puts the root at its end (secant steps), so they keep the step's order too.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.dem.damping import dashpot
from collide.engine.dem.normal import normal_elastic
from collide.engine.jit import jit
from collide.engine.numerics import illinois

# Gauss-Legendre, three stages (order 6): nodes C, matrix A, weights B.
_R15 = math.sqrt(15.0)
GL_C0, GL_C1, GL_C2 = 0.5 - _R15 / 10.0, 0.5, 0.5 + _R15 / 10.0
GL_A00, GL_A01, GL_A02 = 5.0 / 36.0, 2.0 / 9.0 - _R15 / 15.0, 5.0 / 36.0 - _R15 / 30.0
GL_A10, GL_A11, GL_A12 = 5.0 / 36.0 + _R15 / 24.0, 2.0 / 9.0, 5.0 / 36.0 - _R15 / 24.0
GL_A20, GL_A21, GL_A22 = 5.0 / 36.0 + _R15 / 30.0, 2.0 / 9.0 + _R15 / 15.0, 5.0 / 36.0
GL_B0, GL_B1, GL_B2 = 5.0 / 18.0, 4.0 / 9.0, 5.0 / 18.0

ITERATIONS = 80  # fixed-point passes of a collocation step before it counts as failed
LAND = 40  # secant passes landing a root at a step's end
SWITCH = 0.25  # the ends' sigma phase reaches this part of the estimated largest overlap (measured:
# 0.5 left Hertz's ends ten times the error at the same steps, 0.1 the middle)
TIME, SIGMA = 0, 1  # the independent variable of a phase
# What an impact returns (OUT columns); `contact` adds how it ended and the state at a stop.
O_VOUT, O_TIME, O_DMAX, O_FMAX, O_WORK, O_STEPS, O_OK = 0, 1, 2, 3, 4, 5, 6
O_END, O_DELTA, O_U = 7, 8, 9
NOUT = 10
P_STOP = 8  # the law's parameters P: the time since touching at which `contact` stops (inf: none)
P_SPEED = 9  # ... and the round-off of the approach speed (set by `contact` and `impact`)
P_WARM = 10  # ... and the last converged step (x, h, phase, kept, its 9 stages): `warm_start`
P_CONVERGED = P_WARM + 13  # ... and the change at which a step's fixed-point passes stop (`converged`)
NP = P_WARM + 14
ENDED, STOPPED, FAILED = 1.0, 2.0, 0.0  # O_END: separated, stopped at P_STOP, not answered


@jit
def law(P, delta, u):
    """(acceleration of delta, normal force, dashpot gamma) at overlap delta and rate u. P: hertz
    flag, k, E*, R*, m*, zeta, a, p. Hertz past touching (a trial stage beyond the contact's
    end) has no force: NaN, which fails the step so that it is taken shorter."""
    if P[0] > 0.0 and delta < 0.0:
        return math.nan, math.nan, math.nan
    elastic, kn = normal_elastic(P[0] > 0.0, P[1], P[2], P[3], delta)
    gamma = dashpot(P[5], P[4], kn) if P[5] > 0.0 else 0.0
    fn = elastic + gamma * u
    return P[6] - fn / P[4], fn, gamma


@jit
def overlap(P, x):
    """delta = x^p at sigma = x: by products for Hertz's 4 and the linear spring's 1 (a power with
    a float exponent cost more than the rest of an evaluation, measured)."""
    p = P[7]
    if p == 4.0:
        x2 = x * x
        return x2 * x2
    if p == 1.0:
        return x
    return x ** p


@jit
def rhs(P, phase, x, y0, y1, y2):
    """The derivatives over the phase's variable x. TIME: y = (delta, u, work); SIGMA:
    y = (t, u, work) at delta = x^p."""
    if phase == TIME:
        acc, _, gamma = law(P, y0, y1)
        return y1, acc, gamma * y1 * y1
    p = P[7]
    # delta = x^p (`overlap`) and d delta / d sigma
    if p == 4.0:
        x2 = x * x
        delta, jac = x2 * x2, 4.0 * x2 * x
    elif p == 1.0:
        delta, jac = x, 1.0
    else:
        delta, jac = x ** p, p * x ** (p - 1.0)
    acc, _, gamma = law(P, delta, y1)
    return jac / y1, acc * jac / y1, gamma * y1 * jac


@jit
def _lagrange(c, a, b, d):
    """The quadratic through (GL_C0, a), (GL_C1, b), (GL_C2, d) at c."""
    return (a * (c - GL_C1) * (c - GL_C2) / ((GL_C0 - GL_C1) * (GL_C0 - GL_C2))
            + b * (c - GL_C0) * (c - GL_C2) / ((GL_C1 - GL_C0) * (GL_C1 - GL_C2))
            + d * (c - GL_C0) * (c - GL_C1) / ((GL_C2 - GL_C0) * (GL_C2 - GL_C1)))


@jit
def converged(n_end):
    """The change at which a step's fixed-point passes stop, for n_end steps over sigma at each
    end: a thousandth of the steps' error (`steps_for`), round-off (1e-16) at most, 1e-13 at
    least (measured on ten-bounce contacts, Hertz and the linear spring: stopping there left the
    separation speed, the peaks and the contact time as at round-off, with 15 % fewer passes)."""
    return max(1e-16, min(1e-13, 3e-6 / float(n_end) ** 6))


@jit
def warm_start(P, phase, x, h, f0, f1, f2):
    """The first guess of a step's stages (k00, k01, k02, k10, ...): the last converged step's
    stage polynomial (kept in P by `keep_stages`) where it is of this phase and near, its error
    O(h^3) rather than the O(h) of the start's derivatives (f0, f1, f2), which are the guess
    otherwise (measured: about 5 fixed-point passes a step instead of 7)."""
    if P[P_WARM + 3] == 0.0 or P[P_WARM + 2] != phase or P[P_WARM + 1] == 0.0:
        return f0, f1, f2, f0, f1, f2, f0, f1, f2
    c0 = (x + GL_C0 * h - P[P_WARM]) / P[P_WARM + 1]
    c1 = (x + GL_C1 * h - P[P_WARM]) / P[P_WARM + 1]
    c2 = (x + GL_C2 * h - P[P_WARM]) / P[P_WARM + 1]
    if not (abs(c0) <= 3.0 and abs(c2) <= 3.0):  # too far to extrapolate (a step after landing)
        return f0, f1, f2, f0, f1, f2, f0, f1, f2
    K = P[P_WARM + 4:P_WARM + 13]
    return (_lagrange(c0, K[0], K[3], K[6]), _lagrange(c0, K[1], K[4], K[7]), _lagrange(c0, K[2], K[5], K[8]),
            _lagrange(c1, K[0], K[3], K[6]), _lagrange(c1, K[1], K[4], K[7]), _lagrange(c1, K[2], K[5], K[8]),
            _lagrange(c2, K[0], K[3], K[6]), _lagrange(c2, K[1], K[4], K[7]), _lagrange(c2, K[2], K[5], K[8]))


@jit
def keep_stages(P, phase, x, h, k00, k01, k02, k10, k11, k12, k20, k21, k22):
    """Keep a converged step's stages in P for the next step's `warm_start`."""
    P[P_WARM], P[P_WARM + 1], P[P_WARM + 2], P[P_WARM + 3] = x, h, phase, 1.0
    K = P[P_WARM + 4:P_WARM + 13]
    K[0], K[1], K[2], K[3], K[4], K[5], K[6], K[7], K[8] = k00, k01, k02, k10, k11, k12, k20, k21, k22


@jit
def gl_step(P, phase, x, y0, y1, y2, h):
    """One Gauss-Legendre step of h from (x, y); returns (y0, y1, y2, ok)."""
    f0, f1, f2 = rhs(P, phase, x, y0, y1, y2)
    k00, k01, k02, k10, k11, k12, k20, k21, k22 = warm_start(P, phase, x, h, f0, f1, f2)
    last = math.inf
    for _ in range(ITERATIONS):
        n00, n01, n02 = rhs(P, phase, x + GL_C0 * h, y0 + h * (GL_A00 * k00 + GL_A01 * k10 + GL_A02 * k20),
                            y1 + h * (GL_A00 * k01 + GL_A01 * k11 + GL_A02 * k21),
                            y2 + h * (GL_A00 * k02 + GL_A01 * k12 + GL_A02 * k22))
        n10, n11, n12 = rhs(P, phase, x + GL_C1 * h, y0 + h * (GL_A10 * k00 + GL_A11 * k10 + GL_A12 * k20),
                            y1 + h * (GL_A10 * k01 + GL_A11 * k11 + GL_A12 * k21),
                            y2 + h * (GL_A10 * k02 + GL_A11 * k12 + GL_A12 * k22))
        n20, n21, n22 = rhs(P, phase, x + GL_C2 * h, y0 + h * (GL_A20 * k00 + GL_A21 * k10 + GL_A22 * k20),
                            y1 + h * (GL_A20 * k01 + GL_A21 * k11 + GL_A22 * k21),
                            y2 + h * (GL_A20 * k02 + GL_A21 * k12 + GL_A22 * k22))
        # Each part's change relative to its own size (the parts have different units; the rate's
        # at least what the step makes of the pressing acceleration, which a ball held at rest
        # balances: its rate is round-off of that, or of the approach speed).
        change = abs(h) * max((abs(n00 - k00) + abs(n10 - k10) + abs(n20 - k20)) / (abs(y0) + abs(h * f0) + 1e-300),
                              (abs(n01 - k01) + abs(n11 - k11) + abs(n21 - k21))
                              / (abs(y1) + abs(h * f1) + abs(h * P[6]) + P[P_SPEED]),
                              (abs(n02 - k02) + abs(n12 - k12) + abs(n22 - k22)) / (abs(y2) + abs(h * f2) + 1e-300))
        k00, k01, k02, k10, k11, k12, k20, k21, k22 = n00, n01, n02, n10, n11, n12, n20, n21, n22
        # Done below P_CONVERGED (`converged`), or with the next pass's change forecast below it from
        # this pass's contraction (change / last), or no longer shrinking near round-off.
        done = P[P_CONVERGED]
        forecast = change <= 1e-8 and last < math.inf and change <= 0.5 * last and change * change <= done * last
        if change <= done or forecast or (change <= 1e-13 and change >= 0.5 * last):
            keep_stages(P, phase, x, h, k00, k01, k02, k10, k11, k12, k20, k21, k22)
            return (y0 + h * (GL_B0 * k00 + GL_B1 * k10 + GL_B2 * k20),
                    y1 + h * (GL_B0 * k01 + GL_B1 * k11 + GL_B2 * k21),
                    y2 + h * (GL_B0 * k02 + GL_B1 * k12 + GL_B2 * k22), True)
        if not math.isfinite(change):
            break
        last = change
    return y0, y1, y2, False


@jit
def watched(P, phase, x, y0, y1, which):
    """The watched function at a state: which 0, the overlap's rate; 1, the force's rate dF/dt
    (Hertz's dashpot grows as delta^(1/4): gamma' = gamma / (4 delta)); 2, the time past the
    stop P_STOP."""
    if which == 2:
        return (x if phase == TIME else y0) - P[P_STOP]
    delta, u = (y0, y1) if phase == TIME else (overlap(P, x), y1)
    if which == 0:
        return u
    acc, _, gamma = law(P, delta, u)
    _, kn = normal_elastic(P[0] > 0.0, P[1], P[2], P[3], delta)
    slope = gamma / (4.0 * delta) if P[0] > 0.0 and delta > 0.0 else 0.0
    return kn * u + slope * u * u + gamma * acc


@jit
def force_at(P, phase, x, y0, y1):
    """The normal force at a state."""
    delta = y0 if phase == TIME else overlap(P, x)
    return law(P, delta, y1)[1]


@jit
def land(P, phase, x, y0, y1, y2, h, which, g0, g1):
    """The state where the watched function, g0 at the step's start and g1 at its end (of
    opposite signs), is zero, by secant (Illinois) steps on the step's length. Returns
    (x, y0, y1, y2, ok)."""
    lo, hi, glo, ghi = 0.0, h, g0, g1
    side = 0
    best = (x + h, y0, y1, y2)
    for _ in range(LAND):
        m = lo - glo * (hi - lo) / (ghi - glo)
        a0, a1, a2, ok = gl_step(P, phase, x, y0, y1, y2, m)
        if not ok:
            return x, y0, y1, y2, False
        g = watched(P, phase, x + m, a0, a1, which)
        best = (x + m, a0, a1, a2)
        if g == 0.0 or abs(hi - lo) <= 4e-16 * abs(h):
            break
        lo, hi, glo, ghi, side = illinois(lo, hi, glo, ghi, side, m, g)
        # A peak (which 0, 1) is stationary: landed within 1e-8 of the step its value is off by
        # the square of that, round-off; the next secant point's move bounds the miss.
        if which < 2 and abs(lo - glo * (hi - lo) / (ghi - glo) - m) <= 1e-8 * abs(h):
            break
    return best[0], best[1], best[2], best[3], True


@jit
def watch_step(P, phase, x, y0, y1, y2, h, e0, e1, e2, peaks, trail):
    """After a step from (x, y) to (x + h, e): the largest force so far at its end, and where the
    overlap's rate (peaks[0]: the largest overlap) or the force's rate (peaks[1]) changes sign
    from + to - inside it, that peak landed and its state added to trail (in time order, before
    the step's end that the caller adds). Returns ok."""
    peaks[1] = max(peaks[1], force_at(P, phase, x + h, e0, e1))
    if phase == SIGMA:
        peaks[0] = max(peaks[0], overlap(P, x + h))
    else:
        peaks[0] = max(peaks[0], e0)
    first = (math.inf, 0.0, 0.0, 0.0)
    second = (math.inf, 0.0, 0.0, 0.0)
    for which in range(2):
        g0 = watched(P, phase, x, y0, y1, which)
        g1 = watched(P, phase, x + h, e0, e1, which)
        if g0 > 0.0 and g1 < 0.0:
            lx, l0, l1, l2, ok = land(P, phase, x, y0, y1, y2, h, which, g0, g1)
            if not ok:
                return False
            if which == 0:
                peaks[0] = max(peaks[0], l0 if phase == TIME else overlap(P, lx))
            else:
                peaks[1] = max(peaks[1], force_at(P, phase, lx, l0, l1))
            state = (lx, l0, l1, l2) if phase == TIME else (l0, overlap(P, lx), l1, l2)
            if state[0] < first[0]:
                first, second = state, first
            else:
                second = state
    if first[0] < math.inf:
        trail.append(first)
    if second[0] < math.inf:
        trail.append(second)
    return True


# How a phase ended (`rise`, `middle`, `fall`).
FAIL, DONE, STOP, TURNED = 0, 1, 2, 3


@jit
def stop_inside(P, phase, x, y0, y1, y2, h, e0):
    """Whether a step from (x, y) of h passes the stop P_STOP: then the state there (landed on
    it by secant steps), as (x, y0, y1, y2, ok, True); else (..., True, False)."""
    t0 = x if phase == TIME else y0
    t1 = x + h if phase == TIME else e0
    if not t1 > P[P_STOP]:
        return x, y0, y1, y2, True, False
    lx, l0, l1, l2, ok = land(P, phase, x, y0, y1, y2, h, 2, t0 - P[P_STOP], t1 - P[P_STOP])
    return lx, l0, l1, l2, ok, True


@jit
def rise(P, v_in, sigma1, n, peaks, trail):
    """The contact's start over sigma, from touching to delta = sigma1^p (or the stop). Returns
    (sigma, t, u, work, steps, how); FAIL where the approach slows below a quarter (the switch
    lies too deep)."""
    h = sigma1 / n
    t, u, w = 0.0, v_in, 0.0
    for s in range(n):
        x = s * h
        e0, e1, e2, ok = gl_step(P, SIGMA, x, t, u, w, h)
        if not ok or not e1 > 0.25 * v_in:
            return x, t, u, w, s, FAIL
        lx, l0, l1, l2, ok, stopped = stop_inside(P, SIGMA, x, t, u, w, h, e0)
        if stopped:
            if not ok or not watch_step(P, SIGMA, x, t, u, w, lx - x, l0, l1, l2, peaks, trail):
                return x, t, u, w, s, FAIL
            trail.append((P[P_STOP], overlap(P, lx), l1, l2))
            return lx, P[P_STOP], l1, l2, s + 1, STOP
        if not watch_step(P, SIGMA, x, t, u, w, h, e0, e1, e2, peaks, trail):
            return x, t, u, w, s, FAIL
        t, u, w = e0, e1, e2
        trail.append((t, overlap(P, x + h), u, w))
    return sigma1, t, u, w, n, DONE


@jit
def middle(P, t, delta1, d, u, w, h, limit, peaks, trail):
    """Over time from delta = d until delta is back below delta1 (separating), ending at no less
    than half of it, or the stop, within `limit` steps. Returns (t, delta, u, work, steps, how);
    FAIL where the limit is reached."""
    steps = 0
    size = h
    while steps < limit:
        stopping = P[P_STOP] - t <= h
        step = P[P_STOP] - t if stopping else h
        e0, e1, e2, ok = gl_step(P, TIME, t, d, u, w, step)
        if not ok or (e1 < 0.0 and e0 < 0.5 * delta1):
            h *= 0.5  # too long a step for this part of the contact
            if h < 1e-12 * size:
                break
            continue
        steps += 1
        if not watch_step(P, TIME, t, d, u, w, step, e0, e1, e2, peaks, trail):
            break
        t, d, u, w = P[P_STOP] if stopping else t + step, e0, e1, e2
        trail.append((t, d, u, w))
        h = size
        if stopping:
            return t, d, u, w, steps, STOP
        if u < 0.0 and d < delta1:
            return t, d, u, w, steps, DONE
    return t, d, u, w, steps, FAIL


@jit
def fall(P, t, sigma, u, w, n, peaks, trail):
    """The contact's end over sigma, from delta = sigma^p (separating) to 0, or the stop. Returns
    (sigma, t, u, work, steps, how); TURNED (the state before the step that failed) where the
    separation stops before the overlap is gone."""
    h = -sigma / n
    for s in range(n):
        x = sigma + s * h
        e0, e1, e2, ok = gl_step(P, SIGMA, x, t, u, w, h)
        if not ok or not e1 < 0.0:
            return x, t, u, w, s, TURNED
        lx, l0, l1, l2, ok, stopped = stop_inside(P, SIGMA, x, t, u, w, h, e0)
        if stopped:
            if not ok or not watch_step(P, SIGMA, x, t, u, w, lx - x, l0, l1, l2, peaks, trail):
                return x, t, u, w, s, TURNED
            trail.append((P[P_STOP], overlap(P, lx), l1, l2))
            return lx, P[P_STOP], l1, l2, s + 1, STOP
        if not watch_step(P, SIGMA, x, t, u, w, h, e0, e1, e2, peaks, trail):
            return x, t, u, w, s, TURNED
        t, u, w = e0, e1, e2
        trail.append((t, 0.0 if s == n - 1 else overlap(P, x + h), u, w))
    return 0.0, t, u, w, n, DONE


@jit
def estimate(P, v_in):
    """The largest overlap and the contact time without damping or the pressing acceleration:
    Hertz's closed forms (the time 2 delta_max / v times the integral of (1 - x^2.5)^(-1/2)
    over [0, 1]) or the linear spring's half period."""
    if P[0] > 0.0:
        dmax = (15.0 * P[4] * v_in * v_in / (16.0 * P[2] * math.sqrt(P[3]))) ** 0.4
        return dmax, 2.9432 * dmax / v_in
    omega = math.sqrt(P[1] / P[4])
    return v_in / omega, math.pi / omega


@jit
def start(P, v_in, n_end, peaks, trail):
    """The rise, its switch to time steps at a quarter of the estimated largest overlap (halved
    while the approach slows too much before it). Returns (delta1, sigma, t, u, work, steps,
    how)."""
    dmax, _ = estimate(P, v_in)
    frac = SWITCH
    for _ in range(10):
        peaks[0], peaks[1] = 0.0, law(P, 0.0, v_in)[1]
        delta1 = frac * dmax
        while len(trail) > 0:  # a deeper switch's attempt
            trail.pop()
        x, t, u, w, s1, how = rise(P, v_in, delta1 ** (1.0 / P[7]), n_end, peaks, trail)
        if how != FAIL:
            return delta1, x, t, u, w, s1, how
        frac *= 0.5
    return delta1, x, t, u, w, s1, FAIL


@jit
def contact(P, v_in, n_end, n_mid, limit, out, trail):
    """One contact from touching at approach speed v_in > 0 until it separates or P_STOP (time
    since touching) comes, n_end steps over sigma at each end and steps of a contact time over
    n_mid between, at most `limit` steps over time. A contact whose separation stops before the
    overlap is gone (gravity holds a slow, damped ball) goes on over time. out (NOUT): the speed
    of separation, the time, the largest overlap and force, the dashpot's work, the steps, O_OK,
    and O_END (ENDED, STOPPED: O_DELTA and O_U the overlap and its rate at the stop; FAILED).
    trail (a list, emptied first) gets (time, overlap, its rate, work) after every step taken."""
    while len(trail) > 0:
        trail.pop()
    _, span = estimate(P, v_in)
    P[P_SPEED] = 1e-300 + 1e-17 * v_in
    P[P_WARM + 3] = 0.0
    P[P_CONVERGED] = converged(n_end)
    peaks = [0.0, 0.0]
    for c in range(NOUT):
        out[c] = 0.0
    delta1, x, t, u, w, steps, how = start(P, v_in, n_end, peaks, trail)
    d = delta1 if how == DONE else overlap(P, x)
    ended = False
    while how == DONE:
        t, d, u, w, s2, how = middle(P, t, delta1, d, u, w, span / n_mid, limit - steps, peaks, trail)
        steps += s2
        if how != DONE:
            break
        x, t, u, w, s3, how = fall(P, t, d ** (1.0 / P[7]), u, w, n_end, peaks, trail)
        steps += s3
        d = overlap(P, x)
        if how == DONE:
            ended = True
            break
        if how == TURNED:
            # Held on the wall (or the separation too slow for sigma's steps): over time again,
            # back to the end's sigma only if it goes on well below here.
            delta1, how = 0.25 * d, DONE
    out[O_VOUT], out[O_TIME], out[O_DMAX], out[O_FMAX], out[O_WORK] = -u, t, peaks[0], peaks[1], w
    out[O_STEPS] = steps
    out[O_END] = ENDED if ended else (STOPPED if how == STOP else FAILED)
    out[O_OK] = 1.0 if ended else 0.0
    out[O_DELTA], out[O_U] = d, u


@jit
def impact(P, v_in, n_end, n_mid, out):
    """One contact from touching at approach speed v_in > 0 to separating, n_end steps over sigma
    at each end and steps of a contact time over n_mid between. out (NOUT): the speed of
    separation, the contact time, the largest overlap and force, the dashpot's work, the steps
    taken, and 1 where every part converged (0: the contact does not separate as an impact, or a
    step failed)."""
    _, span = estimate(P, v_in)
    peaks = [0.0, 0.0]
    for c in range(NOUT):
        out[c] = 0.0
    P[P_SPEED] = 1e-300 + 1e-17 * v_in
    P[P_WARM + 3] = 0.0
    P[P_CONVERGED] = converged(n_end)
    trail = [(0.0, 0.0, 0.0, 0.0)]  # (the states after each step: `contact`'s callers keep them)
    delta1, x, t, u, w, s1, how = start(P, v_in, n_end, peaks, trail)
    if how != DONE:
        return
    t, d, u, w, s2, how = middle(P, t, delta1, delta1, u, w, span / n_mid, 50 * n_mid, peaks, trail)
    if how != DONE:
        return
    x, t, u, w, s3, how = fall(P, t, d ** (1.0 / P[7]), u, w, n_end, peaks, trail)
    out[O_VOUT], out[O_TIME], out[O_DMAX], out[O_FMAX], out[O_WORK] = -u, t, peaks[0], peaks[1], w
    out[O_STEPS] = s1 + s2 + s3
    out[O_OK] = 1.0 if how == DONE else 0.0
    out[O_END] = ENDED if how == DONE else FAILED


def steps_for(tol: float) -> tuple[int, int]:
    """Steps over sigma at each end, and per contact time between, for a relative error tol of
    the separation speed, the contact time and the peaks: order 6, error about 3e-3 / n^6 (measured
    on Hertz and the linear spring with and without damping: tests/engine/event/test_impact.py)."""
    n = max(4, math.ceil((3e-3 / tol) ** (1.0 / 6.0)))
    return n, 2 * n


def impact_params(*, hertz: bool, mstar: float, k: float = 0.0, estar: float = 0.0, rstar: float = 0.0,
                  zeta: float = 0.0, accel: float = 0.0) -> np.ndarray:
    """The law's parameters as `impact` takes them (P): the linear spring k, or Hertz with E* and
    R*; the dashpot's zeta (`collide.dem.damping_ratio`); m*; a constant acceleration pressing the
    contact (gravity's part along the normal into a wall)."""
    params = np.zeros(NP)
    params[:P_WARM] = [1.0 if hertz else 0.0, k, estar, rstar, mstar, zeta, accel, 4.0 if hertz else 1.0, math.inf,
                       0.0]
    return params


def normal_impact(params: np.ndarray, v_in: float, tol: float) -> np.ndarray:
    """One contact at approach speed v_in, with the steps `steps_for(tol)`: the OUT row of
    `impact`."""
    out = np.zeros(NOUT)
    n_end, n_mid = steps_for(tol)
    impact(params, float(v_in), n_end, n_mid, out)
    return out
