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
integrated over time. Every step is one of Dormand and Prince's explicit order-8 Runge-Kutta
(DOP853's 12 stages; measured on ten-bounce contacts, a third to a half of the evaluations that
3-stage Gauss-Legendre collocation, order 6, solved by fixed-point passes, took for the same
error). The largest overlap (delta' = 0) and
the largest force (dF/dt = 0) are landed by re-taking the step that contains them at the
length that puts the root at its end (secant steps), so they keep the step's order too.

The law and the stage evaluations are copied into the step (`jit_inline`), and the step, the
landing and the stop are called without reference counting (`jit_call`); each step's end is
evaluated once for the force and the watched rates, and the next step starts from it.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.dem.damping import dashpot
from collide.engine.dem.normal import normal_elastic
from collide.engine.jit import jit, jit_call, jit_inline
from collide.engine.numerics import illinois

# Dormand and Prince's explicit Runge-Kutta pair of order 8 (DOP853, Hairer, Norsett and Wanner,
# "Solving Ordinary Differential Equations I", section II.10): the 12 stages of its order-8
# solution, nodes RK_C, matrix RK_A (below the diagonal, row by row), weights RK_B.
RK_C = np.array([0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726,
                0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0])
RK_B = np.array([0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585,
                0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259])
_A_ROWS = (
    (),
    (0.05260015195876773,),
    (0.0197250569845379, 0.0591751709536137),
    (0.02958758547680685, 0.0, 0.08876275643042054),
    (0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792),
    (0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242),
    (0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125),
    (0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402,
     0.008273789163814023),
    (0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894,
     -43.48988418106996),
    (0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423,
     -33.28821096898486, -0.020331201708508627),
    (-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696,
     22.739487099350505, 2.4936055526796523, -3.0467644718982196),
    (2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996,
     -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636),
)
RK_A = np.zeros((12, 12))
for _i, _row in enumerate(_A_ROWS):
    RK_A[_i, :len(_row)] = _row
STAGES = 12
LAND = 40  # secant passes landing a root at a step's end
SWITCH = 0.25  # the ends' sigma phase reaches this part of the estimated largest overlap (measured:
# 0.5 left Hertz's ends ten times the error at the same steps, 0.1 the middle)
# The linear spring's end over sigma starts no deeper than delta omega (1 + 2 zeta) = FALL_UNIFORM |u|
# (`fall_depth`; measured on one impact at 8 steps per end: 0.25 to 1 leave the separation speed
# within 5e-13 at e = 0.01 to 0.3, 2 leaves 8e-8 at e = 0.01)
FALL_UNIFORM = 0.5
TIME, SIGMA = 0, 1  # the independent variable of a phase
# What an impact returns (OUT columns); `contact` adds how it ended and the state at a stop.
O_VOUT, O_TIME, O_DMAX, O_FMAX, O_WORK, O_STEPS, O_OK = 0, 1, 2, 3, 4, 5, 6
O_END, O_DELTA, O_U = 7, 8, 9
NOUT = 10
P_STOP = 8  # the law's parameters P: the time since touching at which `contact` stops (inf: none)
P_SPEED = 9  # ... and the round-off of the approach speed (set by `contact` and `impact`)
NP = 10
ENDED, STOPPED, FAILED = 1.0, 2.0, 0.0  # O_END: separated, stopped at P_STOP, not answered


@jit_inline
def law_stiff(P, delta, u):
    """(acceleration of delta, normal force, dashpot gamma, stiffness dF_el / d delta) at overlap
    delta and rate u. P: hertz flag, k, E*, R*, m*, zeta, a, p. Hertz past touching (a trial
    stage beyond the contact's end) has no force: NaN, which fails the step so that it is taken
    shorter."""
    if P[0] > 0.0 and delta < 0.0:
        return math.nan, math.nan, math.nan, math.nan
    elastic, kn = normal_elastic(P[0] > 0.0, P[1], P[2], P[3], delta)
    gamma = dashpot(P[5], P[4], kn) if P[5] > 0.0 else 0.0
    fn = elastic + gamma * u
    return P[6] - fn / P[4], fn, gamma, kn


@jit_inline
def law(P, delta, u):
    """`law_stiff` without the stiffness: (acceleration of delta, normal force, dashpot gamma)."""
    acc, fn, gamma, _ = law_stiff(P, delta, u)
    return acc, fn, gamma


@jit_inline
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


@jit_inline
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


@jit_call
def rk_step(P, phase, x, y0, y1, y2, h):
    """One step of h from (x, y) by DOP853's order-8 solution, its stages written out with the
    coefficients folded in (a loop over RK_A took 1.5 times as long: kernel time of ten bounces).
    Returns (y0, y1, y2, ok), ok False where a stage is not finite (Hertz past the contact's
    end), so that the step is taken shorter."""
    k0 = rhs(P, phase, x, y0, y1, y2)
    k1 = rhs(P, phase, x + RK_C[1] * h,
             y0 + h * (RK_A[1, 0] * k0[0]),
             y1 + h * (RK_A[1, 0] * k0[1]),
             y2 + h * (RK_A[1, 0] * k0[2]))
    k2 = rhs(P, phase, x + RK_C[2] * h,
             y0 + h * (RK_A[2, 0] * k0[0] + RK_A[2, 1] * k1[0]),
             y1 + h * (RK_A[2, 0] * k0[1] + RK_A[2, 1] * k1[1]),
             y2 + h * (RK_A[2, 0] * k0[2] + RK_A[2, 1] * k1[2]))
    k3 = rhs(P, phase, x + RK_C[3] * h,
             y0 + h * (RK_A[3, 0] * k0[0] + RK_A[3, 2] * k2[0]),
             y1 + h * (RK_A[3, 0] * k0[1] + RK_A[3, 2] * k2[1]),
             y2 + h * (RK_A[3, 0] * k0[2] + RK_A[3, 2] * k2[2]))
    k4 = rhs(P, phase, x + RK_C[4] * h,
             y0 + h * (RK_A[4, 0] * k0[0] + RK_A[4, 2] * k2[0] + RK_A[4, 3] * k3[0]),
             y1 + h * (RK_A[4, 0] * k0[1] + RK_A[4, 2] * k2[1] + RK_A[4, 3] * k3[1]),
             y2 + h * (RK_A[4, 0] * k0[2] + RK_A[4, 2] * k2[2] + RK_A[4, 3] * k3[2]))
    k5 = rhs(P, phase, x + RK_C[5] * h,
             y0 + h * (RK_A[5, 0] * k0[0] + RK_A[5, 3] * k3[0] + RK_A[5, 4] * k4[0]),
             y1 + h * (RK_A[5, 0] * k0[1] + RK_A[5, 3] * k3[1] + RK_A[5, 4] * k4[1]),
             y2 + h * (RK_A[5, 0] * k0[2] + RK_A[5, 3] * k3[2] + RK_A[5, 4] * k4[2]))
    k6 = rhs(P, phase, x + RK_C[6] * h,
             y0 + h * (RK_A[6, 0] * k0[0] + RK_A[6, 3] * k3[0] + RK_A[6, 4] * k4[0] + RK_A[6, 5] * k5[0]),
             y1 + h * (RK_A[6, 0] * k0[1] + RK_A[6, 3] * k3[1] + RK_A[6, 4] * k4[1] + RK_A[6, 5] * k5[1]),
             y2 + h * (RK_A[6, 0] * k0[2] + RK_A[6, 3] * k3[2] + RK_A[6, 4] * k4[2] + RK_A[6, 5] * k5[2]))
    k7 = rhs(P, phase, x + RK_C[7] * h,
             y0 + h * (RK_A[7, 0] * k0[0] + RK_A[7, 3] * k3[0] + RK_A[7, 4] * k4[0] + RK_A[7, 5] * k5[0] + RK_A[7, 6] *
                       k6[0]),
             y1 + h * (RK_A[7, 0] * k0[1] + RK_A[7, 3] * k3[1] + RK_A[7, 4] * k4[1] + RK_A[7, 5] * k5[1] + RK_A[7, 6] *
                       k6[1]),
             y2 + h * (RK_A[7, 0] * k0[2] + RK_A[7, 3] * k3[2] + RK_A[7, 4] * k4[2] + RK_A[7, 5] * k5[2] + RK_A[7, 6] *
                       k6[2]))
    k8 = rhs(P, phase, x + RK_C[8] * h,
             y0 + h * (RK_A[8, 0] * k0[0] + RK_A[8, 3] * k3[0] + RK_A[8, 4] * k4[0] + RK_A[8, 5] * k5[0] + RK_A[8, 6] *
                       k6[0] + RK_A[8, 7] * k7[0]),
             y1 + h * (RK_A[8, 0] * k0[1] + RK_A[8, 3] * k3[1] + RK_A[8, 4] * k4[1] + RK_A[8, 5] * k5[1] + RK_A[8, 6] *
                       k6[1] + RK_A[8, 7] * k7[1]),
             y2 + h * (RK_A[8, 0] * k0[2] + RK_A[8, 3] * k3[2] + RK_A[8, 4] * k4[2] + RK_A[8, 5] * k5[2] + RK_A[8, 6] *
                       k6[2] + RK_A[8, 7] * k7[2]))
    k9 = rhs(P, phase, x + RK_C[9] * h,
             y0 + h * (RK_A[9, 0] * k0[0] + RK_A[9, 3] * k3[0] + RK_A[9, 4] * k4[0] + RK_A[9, 5] * k5[0] + RK_A[9, 6] *
                       k6[0] + RK_A[9, 7] * k7[0] + RK_A[9, 8] * k8[0]),
             y1 + h * (RK_A[9, 0] * k0[1] + RK_A[9, 3] * k3[1] + RK_A[9, 4] * k4[1] + RK_A[9, 5] * k5[1] + RK_A[9, 6] *
                       k6[1] + RK_A[9, 7] * k7[1] + RK_A[9, 8] * k8[1]),
             y2 + h * (RK_A[9, 0] * k0[2] + RK_A[9, 3] * k3[2] + RK_A[9, 4] * k4[2] + RK_A[9, 5] * k5[2] + RK_A[9, 6] *
                       k6[2] + RK_A[9, 7] * k7[2] + RK_A[9, 8] * k8[2]))
    k10 = rhs(P, phase, x + RK_C[10] * h,
              y0 + h * (RK_A[10, 0] * k0[0] + RK_A[10, 3] * k3[0] + RK_A[10, 4] * k4[0] + RK_A[10, 5] * k5[0] +
                        RK_A[10, 6] * k6[0] + RK_A[10, 7] * k7[0] + RK_A[10, 8] * k8[0] + RK_A[10, 9] * k9[0]),
              y1 + h * (RK_A[10, 0] * k0[1] + RK_A[10, 3] * k3[1] + RK_A[10, 4] * k4[1] + RK_A[10, 5] * k5[1] +
                        RK_A[10, 6] * k6[1] + RK_A[10, 7] * k7[1] + RK_A[10, 8] * k8[1] + RK_A[10, 9] * k9[1]),
              y2 + h * (RK_A[10, 0] * k0[2] + RK_A[10, 3] * k3[2] + RK_A[10, 4] * k4[2] + RK_A[10, 5] * k5[2] +
                        RK_A[10, 6] * k6[2] + RK_A[10, 7] * k7[2] + RK_A[10, 8] * k8[2] + RK_A[10, 9] * k9[2]))
    k11 = rhs(P, phase, x + RK_C[11] * h,
              y0 + h * (RK_A[11, 0] * k0[0] + RK_A[11, 3] * k3[0] + RK_A[11, 4] * k4[0] + RK_A[11, 5] * k5[0] +
                        RK_A[11, 6] * k6[0] + RK_A[11, 7] * k7[0] + RK_A[11, 8] * k8[0] + RK_A[11, 9] * k9[0] +
                        RK_A[11, 10] * k10[0]),
              y1 + h * (RK_A[11, 0] * k0[1] + RK_A[11, 3] * k3[1] + RK_A[11, 4] * k4[1] + RK_A[11, 5] * k5[1] +
                        RK_A[11, 6] * k6[1] + RK_A[11, 7] * k7[1] + RK_A[11, 8] * k8[1] + RK_A[11, 9] * k9[1] +
                        RK_A[11, 10] * k10[1]),
              y2 + h * (RK_A[11, 0] * k0[2] + RK_A[11, 3] * k3[2] + RK_A[11, 4] * k4[2] + RK_A[11, 5] * k5[2] +
                        RK_A[11, 6] * k6[2] + RK_A[11, 7] * k7[2] + RK_A[11, 8] * k8[2] + RK_A[11, 9] * k9[2] +
                        RK_A[11, 10] * k10[2]))
    e0 = y0 + h * (RK_B[0] * k0[0] + RK_B[5] * k5[0] + RK_B[6] * k6[0] + RK_B[7] * k7[0] + RK_B[8] * k8[0] + RK_B[9] *
                   k9[0] + RK_B[10] * k10[0] + RK_B[11] * k11[0])
    e1 = y1 + h * (RK_B[0] * k0[1] + RK_B[5] * k5[1] + RK_B[6] * k6[1] + RK_B[7] * k7[1] + RK_B[8] * k8[1] + RK_B[9] *
                   k9[1] + RK_B[10] * k10[1] + RK_B[11] * k11[1])
    e2 = y2 + h * (RK_B[0] * k0[2] + RK_B[5] * k5[2] + RK_B[6] * k6[2] + RK_B[7] * k7[2] + RK_B[8] * k8[2] + RK_B[9] *
                   k9[2] + RK_B[10] * k10[2] + RK_B[11] * k11[2])
    return e0, e1, e2, math.isfinite(e0) and math.isfinite(e1) and math.isfinite(e2)


@jit_inline
def force_rate(P, delta, u):
    """(normal force, its rate dF/dt) at overlap delta and rate u, from one evaluation of the law
    (Hertz's dashpot grows as delta^(1/4): gamma' = gamma / (4 delta))."""
    acc, fn, gamma, kn = law_stiff(P, delta, u)
    slope = gamma / (4.0 * delta) if P[0] > 0.0 and delta > 0.0 else 0.0
    return fn, kn * u + slope * u * u + gamma * acc


@jit_inline
def watched(P, phase, x, y0, y1, which):
    """The watched function at a state: which 0, the overlap's rate; 1, the force's rate dF/dt;
    2, the time past the stop P_STOP."""
    if which == 2:
        return (x if phase == TIME else y0) - P[P_STOP]
    if which == 0:
        return y1
    return force_rate(P, y0 if phase == TIME else overlap(P, x), y1)[1]


@jit_inline
def probe(P, phase, x, y0, y1):
    """What `watch_step` reads at a step's end, and the next step takes at its start: (normal
    force, overlap's rate, force's rate)."""
    fn, rate = force_rate(P, y0 if phase == TIME else overlap(P, x), y1)
    return fn, y1, rate


@jit_inline
def force_at(P, phase, x, y0, y1):
    """The normal force at a state."""
    delta = y0 if phase == TIME else overlap(P, x)
    return law(P, delta, y1)[1]


@jit_call
def land(P, phase, x, y0, y1, y2, h, which, g0, g1):
    """The state where the watched function, g0 at the step's start and g1 at its end (of
    opposite signs), is zero, by secant (Illinois) steps on the step's length. Returns
    (x, y0, y1, y2, ok)."""
    lo, hi, glo, ghi = 0.0, h, g0, g1
    side = 0
    best = (x + h, y0, y1, y2)
    for _ in range(LAND):
        m = lo - glo * (hi - lo) / (ghi - glo)
        a0, a1, a2, ok = rk_step(P, phase, x, y0, y1, y2, m)
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
def watch_step(P, phase, x, y0, y1, y2, h, e0, e1, e2, at, peaks, trail):
    """After a step from (x, y) to (x + h, e), `at` the `probe` at its start: the largest force so
    far at its end, and where the overlap's rate (peaks[0]: the largest overlap) or the force's
    rate (peaks[1]) changes sign from + to - inside it, that peak landed and its state added to
    trail (in time order, before the step's end that the caller adds). Returns (ok, the probe at
    the step's end): each state is probed once, the law evaluated once there."""
    end = probe(P, phase, x + h, e0, e1)
    peaks[1] = max(peaks[1], end[0])
    if phase == SIGMA:
        peaks[0] = max(peaks[0], overlap(P, x + h))
    else:
        peaks[0] = max(peaks[0], e0)
    first = (math.inf, 0.0, 0.0, 0.0)
    second = (math.inf, 0.0, 0.0, 0.0)
    for which in range(2):
        g0 = at[1 + which]
        g1 = end[1 + which]
        if g0 > 0.0 and g1 < 0.0:
            lx, l0, l1, l2, ok = land(P, phase, x, y0, y1, y2, h, which, g0, g1)
            if not ok:
                return False, end
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
    return True, end


# How a phase ended (`rise`, `middle`, `fall`).
FAIL, DONE, STOP, TURNED = 0, 1, 2, 3


@jit_call
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
    at = probe(P, SIGMA, 0.0, t, u)
    for s in range(n):
        x = s * h
        e0, e1, e2, ok = rk_step(P, SIGMA, x, t, u, w, h)
        if not ok or not e1 > 0.25 * v_in:
            return x, t, u, w, s, FAIL
        lx, l0, l1, l2, ok, stopped = stop_inside(P, SIGMA, x, t, u, w, h, e0)
        if stopped:
            if not ok or not watch_step(P, SIGMA, x, t, u, w, lx - x, l0, l1, l2, at, peaks, trail)[0]:
                return x, t, u, w, s, FAIL
            trail.append((P[P_STOP], overlap(P, lx), l1, l2))
            return lx, P[P_STOP], l1, l2, s + 1, STOP
        ok, at = watch_step(P, SIGMA, x, t, u, w, h, e0, e1, e2, at, peaks, trail)
        if not ok:
            return x, t, u, w, s, FAIL
        t, u, w = e0, e1, e2
        trail.append((t, overlap(P, x + h), u, w))
    return sigma1, t, u, w, n, DONE


@jit_inline
def fall_depth(P, delta1, u):
    """The overlap below which the contact's end goes over sigma: delta1, and for the linear spring
    no deeper than where the separation is still about uniform over the rest of the overlap. A
    heavily damped contact separates slowly, and over sigma = delta its time's rate 1/u would
    change too much for the end's steps (measured on one impact at e = 0.01 from a quarter of
    the largest overlap: the separation speed off by 7e-4 at 8 steps, 2e-6 at 32)."""
    if P[0] > 0.0:
        return delta1
    omega = math.sqrt(P[1] / P[4])
    return min(delta1, FALL_UNIFORM * abs(u) / (omega * (1.0 + 2.0 * P[5])))


@jit
def middle(P, t, delta1, d, u, w, h, limit, peaks, trail):
    """Over time from delta = d until delta is back below `fall_depth` (separating), ending at no less
    than half of it, or the stop, within `limit` steps. Returns (t, delta, u, work, steps, how);
    FAIL where the limit is reached."""
    steps = 0
    size = h
    at = probe(P, TIME, t, d, u)
    while steps < limit:
        stopping = P[P_STOP] - t <= h
        step = P[P_STOP] - t if stopping else h
        e0, e1, e2, ok = rk_step(P, TIME, t, d, u, w, step)
        if not ok or (e1 < 0.0 and e0 < 0.5 * fall_depth(P, delta1, e1)):
            h *= 0.5  # too long a step for this part of the contact
            if h < 1e-12 * size:
                break
            continue
        steps += 1
        ok, at = watch_step(P, TIME, t, d, u, w, step, e0, e1, e2, at, peaks, trail)
        if not ok:
            break
        t, d, u, w = P[P_STOP] if stopping else t + step, e0, e1, e2
        trail.append((t, d, u, w))
        h = size
        if stopping:
            return t, d, u, w, steps, STOP
        if u < 0.0 and d < fall_depth(P, delta1, u):
            return t, d, u, w, steps, DONE
    return t, d, u, w, steps, FAIL


@jit
def fall(P, t, sigma, u, w, n, peaks, trail):
    """The contact's end over sigma, from delta = sigma^p (separating) to 0, or the stop. Returns
    (sigma, t, u, work, steps, how); TURNED (the state before the step that failed) where the
    separation stops before the overlap is gone."""
    h = -sigma / n
    at = probe(P, SIGMA, sigma, t, u)
    for s in range(n):
        x = sigma + s * h
        e0, e1, e2, ok = rk_step(P, SIGMA, x, t, u, w, h)
        if not ok or not e1 < 0.0:
            return x, t, u, w, s, TURNED
        lx, l0, l1, l2, ok, stopped = stop_inside(P, SIGMA, x, t, u, w, h, e0)
        if stopped:
            if not ok or not watch_step(P, SIGMA, x, t, u, w, lx - x, l0, l1, l2, at, peaks, trail)[0]:
                return x, t, u, w, s, TURNED
            trail.append((P[P_STOP], overlap(P, lx), l1, l2))
            return lx, P[P_STOP], l1, l2, s + 1, STOP
        ok, at = watch_step(P, SIGMA, x, t, u, w, h, e0, e1, e2, at, peaks, trail)
        if not ok:
            return x, t, u, w, s, TURNED
        t, u, w = e0, e1, e2
        trail.append((t, 0.0 if s == n - 1 else overlap(P, x + h), u, w))
    return 0.0, t, u, w, n, DONE


@jit_inline
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


# The error constants of `steps_for` (error about C / n^8 of the separation speed relative to
# the approach speed, of the contact time and of the largest overlap and force, relative), the
# ends' over sigma apart from the middle's over time: the most measured on single contacts at
# n = 6 to 24 (ends with the middle converged, and the other way round) over e = 0.05 to 1
# against the pressing acceleration's share g t_c / v from 0 to 1 (speeds 1e-3 to 100 m/s
# under gravity and without), padded about twofold. Hertz's ends grow with the damping: their
# largest, 6e-4 (e = 1), 1e-3 (e = 0.8), 2.9e-3 (e = 0.5), 6.7e-3 (e = 0.3), 5.7e-2 (e = 0.1),
# 6.9e-2 (e = 0.05, the contact time), about 6.4e-4 exp(8 zeta); its middle's 2e-2 at most
# (e = 0.8 to 0.99). The linear spring's are 1e-6 to 8e-5 at any e: its law is smooth at the
# ends and its error two to three orders below Hertz's.
HERTZ_END_C, HERTZ_END_GROWTH, HERTZ_MID_C = 1.5e-3, 8.0, 2.5e-2
LINEAR_C = 2e-4


def steps_for(tol: float, laws: np.ndarray) -> tuple[int, int]:
    """Steps over sigma at each end, and per contact time between, for a relative error tol of
    the separation speed, the contact time and the peaks under the laws P (one row, or one per
    wall: the costliest's, `impact_params`): order 8, error about C / n^8 at each end and in the
    middle, each given half of tol (the constants above; tests/engine/event/test_impact.py
    checks them over e and gravity's share)."""
    laws = np.asarray(laws)
    if (laws[..., 0] > 0.0).any():
        c_end = HERTZ_END_C * math.exp(HERTZ_END_GROWTH * float(laws[..., 5].max()))
        c_mid = HERTZ_MID_C
    else:
        c_end = c_mid = LINEAR_C
    n_end = max(4, math.ceil((2.0 * c_end / tol) ** (1.0 / 8.0)))
    n = max(4, math.ceil((2.0 * c_mid / tol) ** (1.0 / 8.0)))
    return n_end, 2 * n


def impact_params(*, hertz: bool, mstar: float, k: float = 0.0, estar: float = 0.0, rstar: float = 0.0,
                  zeta: float = 0.0, accel: float = 0.0) -> np.ndarray:
    """The law's parameters as `impact` takes them (P): the linear spring k, or Hertz with E* and
    R*; the dashpot's zeta (`collide.dem.damping_ratio`); m*; a constant acceleration pressing the
    contact (gravity's part along the normal into a wall)."""
    params = np.zeros(NP)
    params[:] = [1.0 if hertz else 0.0, k, estar, rstar, mstar, zeta, accel, 4.0 if hertz else 1.0, math.inf,
                       0.0]
    return params


def normal_impact(params: np.ndarray, v_in: float, tol: float) -> np.ndarray:
    """One contact at approach speed v_in, with the steps `steps_for(tol)`: the OUT row of
    `impact`."""
    out = np.zeros(NOUT)
    n_end, n_mid = steps_for(tol, params)
    impact(params, float(v_in), n_end, n_mid, out)
    return out
