"""A sphere's contact with a wall under friction with a tangential spring (Cundall-Strack; Mindlin's
stiffness for Hertz), at full order: the normal contact of `impact` coupled with the spring, the
slip of the contact point and the spin, each stick and slip located as an event.

The force is the DEM kernel's (`collide.engine.dem.tangential`: `spring_coefficients`,
`spring_trial`, `friction_cap`, `slip_stretch`), taken to the limit of a vanishing step:

* stick: xi' = v_c, F = -k_t xi - gamma_t v_c, while |F| <= mu F_n;
* slip: F = s mu F_n (s the slip's sign), the stretch the one that holds it alone
  (xi = -F / k_t, as the DEM kernel keeps it). With a tangential dashpot the slip lasts while the
  contact point slides against F (s v_c < 0); without one, while the stretch is pushed past the
  cap: -s v_c > c' with c = mu F_n / k_t (the DEM kernel's update, its step to zero).

Reaching the cap in stick is an event: the stretch is set to hold the capped force (the DEM
kernel's rule), and the contact slips, or sticks on where the point moves along the force (the
dashpot's share then lowers the force below the cap). Slip ending is an event too.

Where stick and slip would alternate without end, the law's limit is one of two motions:

* without a dashpot, Filippov's sliding on the cap, and the slip is it: on s xi = -c the stick
  drives the force past the cap at the rate k_t (-s v_c - c'), the slip's own condition times
  k_t, so the slip lasts exactly while the stick would leave the cap (the two fields differ only
  in xi', and the one that keeps xi on the surface is the slip's). No alternation is left;
* with one, the slip ends at v_c = 0 and, where the cap falls faster there than the dashpot's
  share lowers the stick's force (mu F_n' + gamma_t s v_c' < 0), the stick leaves the cap at
  once. This limit is not a motion on a surface but a saw: each return to the cap drops the
  dashpot's share (the stretch set to hold the cap alone), the force falls to s mu F_n -
  gamma_t v_c and sticks until the falling cap meets it again, and those sticks grow from zero
  length, each longer by a fixed ratio (a few percent) as the point moves along the force.
  HOLD takes the saw's start: the force held at the cap, as in slip, until s v_c reaches
  T_HOLD (about 1e-14 n_mid of the approach speed; an event located as the others), where the
  sticks are long enough to be located one by one. While it holds the law's force lies between
  the cap and the cap less gamma_t s v_c, a change of the outcome below round-off. But the saw's
  phase (where its sticks fall on a log scale) is not fixed by the law: it is set where the saw
  starts (in the DEM kernel, by its step), and the outcome moves with it, by up to 1e-4 of the
  speed in cases measured. T_HOLD is by the steps, so the run at a tenth of --tol that confirms
  every oblique contact starts its saw at another phase and the measured error holds that
  spread: a saw whose phase matters more than --tol is refused, not answered.

HOLD is entered where the alternation shows: a stick that does not hold from its start (its
switch function below zero at once) whose point barely moves (|v_c| <= T_HOLD). What still
alternates beyond CHANGES mode changes in one contact is CHATTER. All events are
located by secant steps on the step's length, as `impact.land` lands a peak, so the composition
keeps the step's order (Gauss-Legendre, three stages, order 6; over sigma = delta^(1/p) near the
ends, as `impact` integrates Hertz's singular start and end).

Two spheres alone (no walls, `pair`) take the same contact in their relative coordinate: the
reduced mass, one sphere's spin as the wall's sphere's and the other's as a second spin, each
lever its radius less half the overlap (the DEM kernel's contact point), and the line of
centres turning with the relative velocity across it (its centripetal and Coriolis terms; the
stretch, along the turning tangent, turns with it as the DEM kernel's projection keeps it).

The tangential motion must stay in one line of the wall (the contact point's slip, the centre's
velocity along the wall and gravity's part along it parallel, no spin about that line): always so
in a 2D scene. In 3D a contact that is not such is DEM's so far (`frame`). A contact that does
not separate (a ball held on the wall, rolling) goes on over time, as `impact.contact`'s does.

Rolling resistance (T_ROLL = mu_r) is a second mode beside stick and slip, the DEM kernel's
law (`collide.engine.dem.rolling`: `rolling_cap`, `rolling_torque`) at the vanishing step:
rolling, the torque mu_r R* max(F_n, 0) against the relative spin's sign (T_RS); held (T_RS =
0), the relative spin locked, the torque that holds it within that cap. At a wall the spin is the
sphere's, R* its radius and the holding torque -(r - delta) F; between two spheres (`pair`) it is
their spins' difference (the DEM kernel's w_i - w_j, the torque on one and its reverse on the
other), R* their reduced radius; held, both spins turn together at (a_1 + a_2) F / (I_1 + I_2)
(a_k the levers), held so by the torque I_1 times that rate less a_1 F on the first. The
relative spin reaching zero (then held where the cap holds it, else rolling on the other way;
the spins made equal with their angular momentum kept) and the held torque reaching the cap are
events, landed as the others.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.dem.geometry import reduced
from collide.engine.dem.normal import normal_elastic
from collide.engine.dem.rolling import rolling_cap, rolling_torque
from collide.engine.dem.tangential import friction_cap, slip_stretch, spring_coefficients, spring_trial
from collide.engine.event.impact import (
    ENDED,
    FAILED,
    LAND,
    O_DELTA,
    O_END,
    O_OK,
    O_STEPS,
    O_TIME,
    O_U,
    O_VOUT,
    O_WORK,
    P_SPEED,
    P_STOP,
    SIGMA,
    STOPPED,
    SWITCH,
    TIME,
    estimate,
    law,
)
from collide.engine.jit import jit
from collide.engine.numerics import dot3, illinois

# T, the spring's parameters: mu, k_t / k_n, its root, the sphere's mass, inertia and radius,
# gravity along the line e, the slip's sign s (set as the contact goes); the lever's share of
# delta (1 at a wall, 1/2 between spheres), the other sphere's inertia and radius (a wall: inf
# and 0), the line of centres' length at touching (a wall: 0, no turning), HOLD's end speed
# (set by `rub`), the rolling resistance mu_r (0: none; a wall's R* is the sphere's radius) and
# its mode: the spin's sign while rolling, 0 while held (set as the contact goes)
T_MU, T_KTR, T_ROOT, T_M, T_I, T_R, T_G, T_S, T_LEVER, T_I2, T_R2, T_D, T_HOLD, T_ROLL, T_RS = range(15)
NT = 15
# y, the state: delta over time (the time over sigma), delta's rate, the dashpot's work, the
# stretch xi, the centre's velocity along e, the spin about b = -N x e, friction's work, the
# centre's way along e (two spheres: the angle the line of centres turned), the angle turned
# about b, the other sphere's spin about b and its angle turned
Y0, YU, YWN, YXI, YVT, YWB, YWT, YP, YTH, YW2, YTH2 = range(11)
NY = 11
STICK, SLIP, HOLD = 0, 1, 2
# HOLD lasts until the point moves along the force at this many times P_SPEED times n_mid (about
# 1e-14 n_mid of the approach speed; by the steps, so that a run and its confirmation at a tenth of
# the tolerance start the saw at different phases: module docstring)
HOLD_SPEED = 1e3
SWITCHES = 1000  # mode changes inside one step before the step counts as failed
CHATTER = 5.0  # O_END beyond impact's: modes alternating beyond CHANGES (module docstring)
CHANGES = 64  # stick-slip changes in one contact beyond which it counts as CHATTER
# Gauss-Legendre, three stages (order 6): nodes _C, matrix _A, weights _B.
_R15 = math.sqrt(15.0)
_A = np.array([[5.0 / 36.0, 2.0 / 9.0 - _R15 / 15.0, 5.0 / 36.0 - _R15 / 30.0],
               [5.0 / 36.0 + _R15 / 24.0, 2.0 / 9.0, 5.0 / 36.0 - _R15 / 24.0],
               [5.0 / 36.0 + _R15 / 30.0, 2.0 / 9.0 + _R15 / 15.0, 5.0 / 36.0]])
_B = np.array([5.0 / 18.0, 4.0 / 9.0, 5.0 / 18.0])
_C = np.array([0.5 - _R15 / 10.0, 0.5, 0.5 + _R15 / 10.0])
ITERATIONS = 80  # fixed-point passes of a collocation step before it counts as failed


@jit
def overlap(P, phase, x, y):
    """(delta, d t / d x) at a state: over time x is t; over sigma delta = x^p."""
    if phase == TIME:
        return y[Y0], 1.0
    p = P[7]
    if p == 4.0:
        x2 = x * x
        return x2 * x2, 4.0 * x2 * x / y[YU]
    if p == 1.0:
        return x, 1.0 / y[YU]
    return x ** p, p * x ** (p - 1.0) / y[YU]


@jit
def forces(P, T, mode, delta, y):
    """(normal acceleration, F_n, gamma_n, friction F along e, contact point's slip v_c, k_t,
    gamma_t, cap, k_n) at overlap delta: in stick the spring's force before the cap (so that a
    step past the cap stays smooth and the event is found), in slip the cap."""
    acc, fn, gamma = law(P, delta, y[YU])
    if not math.isfinite(acc):
        return acc, acc, acc, acc, acc, acc, acc, acc, acc
    _, kn = normal_elastic(P[0] > 0.0, P[1], P[2], P[3], delta)
    kt, gt = spring_coefficients(kn, gamma, T[T_KTR], T[T_ROOT])
    cap = friction_cap(T[T_MU], fn)
    vc = y[YVT] + (T[T_R] - T[T_LEVER] * delta) * y[YWB] + (T[T_R2] - T[T_LEVER] * delta) * y[YW2]
    if mode == STICK:
        f = spring_trial(y[YXI], 0.0, 0.0, vc, 0.0, 0.0, kt, gt)[0]
    else:
        f = T[T_S] * cap
    return acc, fn, gamma, f, vc, kt, gt, cap, kn


@jit
def rolled(T, fn, ft, delta, y):
    """(rolling resistance's torque about b on the sphere (the other's its reverse), the torque
    that would hold the relative spin, its cap, the rate of both spins while held): the cap
    against the relative spin while rolling (`rolling_torque` at the vanishing step's limit);
    held, the holding torque itself (the relative spin locked). A wall's R* is the sphere's
    radius and its spin none; two spheres' R* is their reduced radius (the DEM kernel's)."""
    if T[T_ROLL] == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    a1, a2 = T[T_R] - T[T_LEVER] * delta, T[T_R2] - T[T_LEVER] * delta
    cap = rolling_cap(T[T_ROLL], T[T_R] if T[T_D] == 0.0 else reduced(T[T_R], T[T_R2]), fn)
    common = (a1 + a2) * ft / (T[T_I] + T[T_I2])  # held: both spins' rate (a wall's inertia inf: none)
    need = T[T_I] * common - a1 * ft
    if T[T_RS] == 0.0:
        return need, need, cap, common
    # against the mode's sign: a trial stage past the spin's zero keeps the mode's torque (so the
    # step stays smooth and the zero is found as an event)
    return rolling_torque(cap, math.inf, T[T_RS], 0.0, 0.0)[0], need, cap, common


@jit
def rhs(P, T, phase, mode, x, y, f):
    """The derivatives of y over the phase's variable into f."""
    delta, scale = overlap(P, phase, x, y)
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, delta, y)
    u = y[YU]
    # Two spheres: the line of centres (length d) turns at v / d, v the relative velocity along e
    turning = y[YVT] / (T[T_D] - delta) if T[T_D] > 0.0 else 0.0
    f[Y0] = u if phase == TIME else scale
    f[YU] = (acc - y[YVT] * turning) * scale
    f[YWN] = gamma * u * u * scale
    f[YXI] = vc * scale if mode == STICK else 0.0
    f[YVT] = (ft / T[T_M] + T[T_G] + u * turning) * scale
    tr, _, _, common = rolled(T, fn, ft, delta, y)
    held = T[T_ROLL] > 0.0 and T[T_RS] == 0.0
    f[YWB] = (common if held else ((T[T_R] - T[T_LEVER] * delta) * ft + tr) / T[T_I]) * scale
    f[YWT] = (-ft * vc - (0.0 if held else tr * (y[YWB] - y[YW2]))) * scale
    f[YP] = (turning if T[T_D] > 0.0 else y[YVT]) * scale
    f[YTH] = y[YWB] * scale
    f[YW2] = (common if held else ((T[T_R2] - T[T_LEVER] * delta) * ft - tr) / T[T_I2]) * scale
    f[YTH2] = y[YW2] * scale


@jit
def gl_step(P, T, phase, mode, x, y, h, e, ws, floors):
    """One Gauss-Legendre step of h from (x, y) into e (each part's change relative to its own
    size, round-off below floors; its stages solved by fixed-point iteration). Returns ok."""
    K, N, ys, f0 = ws[0:3], ws[3:6], ws[6], ws[7]
    rhs(P, T, phase, mode, x, y, f0)
    for i in range(3):
        for c in range(NY):
            K[i, c] = f0[c]
    last = math.inf
    for _ in range(ITERATIONS):
        for i in range(3):
            for c in range(NY):
                ys[c] = y[c] + h * (_A[i, 0] * K[0, c] + _A[i, 1] * K[1, c] + _A[i, 2] * K[2, c])
            rhs(P, T, phase, mode, x + _C[i] * h, ys, N[i])
        change = 0.0
        for c in range(NY):
            d = abs(N[0, c] - K[0, c]) + abs(N[1, c] - K[1, c]) + abs(N[2, c] - K[2, c])
            floor = floors[c] + (abs(h * P[6]) if c == YU else 0.0)
            part = abs(h) * d / (abs(y[c]) + abs(h * f0[c]) + floor)
            if not part <= change:  # (NaN too: Hertz past the contact's end fails the step)
                change = part
        for i in range(3):
            for c in range(NY):
                K[i, c] = N[i, c]
        if change <= 1e-16 or (change <= 1e-13 and change >= 0.5 * last):
            for c in range(NY):
                e[c] = y[c] + h * (_B[0] * K[0, c] + _B[1] * K[1, c] + _B[2] * K[2, c])
            return True
        if not math.isfinite(change):
            break
        last = change
    return False


@jit
def watched(P, T, phase, mode, x, y, which):
    """which 0: the mode's own switch function (> 0 while it lasts); 1: the time past P_STOP; 2:
    the normal force (where it changes sign the cap mu max(F_n, 0) has a kink); 3: rolling
    resistance's mode's (rolling: the spin along its sign; held: the cap less the torque that
    holds it)."""
    if which == 1:
        return (x if phase == TIME else y[Y0]) - P[P_STOP]
    delta, _ = overlap(P, phase, x, y)
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, delta, y)
    if which == 2:
        return fn
    if which == 3:
        if T[T_RS] != 0.0:
            return T[T_RS] * (y[YWB] - y[YW2])
        _, need, cap_r, _ = rolled(T, fn, ft, delta, y)
        return cap_r - abs(need)
    if mode == STICK:
        return cap - abs(ft)
    if mode == HOLD:
        return T[T_HOLD] - T[T_S] * vc
    if gt > 0.0:
        return -T[T_S] * vc
    # c' = d/dt (mu F_n / k_t), F_n elastic alone here (no dashpot): Hertz's k_n' = k_n / (2 delta)
    # (at touching, kn = 0, its limit: F_n k_n' / k_n = k_n / 3)
    if kt > 0.0:
        slope = kn / (2.0 * delta) if P[0] > 0.0 else 0.0
        rate = T[T_MU] * y[YU] * (kn - fn * slope / kn) / kt
    else:
        rate = T[T_MU] * y[YU] * (2.0 / 3.0 if P[0] > 0.0 else 1.0) / T[T_KTR]
    return -T[T_S] * vc - rate


@jit
def switch(P, T, phase, mode, x, y, at_once):
    """The mode after a located switch from `mode` at (x, y) (at_once: the mode did not hold from
    there); sets the stretch and the slip's sign."""
    delta, _ = overlap(P, phase, x, y)
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, delta, y)
    if mode != STICK:
        y[YXI] = slip_stretch(T[T_S] * cap, kt)
        return STICK
    T[T_S] = 1.0 if ft > 0.0 or (ft == 0.0 and vc < 0.0) else -1.0
    y[YXI] = slip_stretch(T[T_S] * cap, kt)
    if at_once and gt > 0.0 and abs(vc) <= T[T_HOLD]:
        return HOLD  # neither slip nor stick lasts from here: the force held at the cap (module docstring)
    if gt > 0.0 and T[T_S] * vc >= 0.0:
        # the point moves along the force: the dashpot's share may hold the spring below the cap
        held = spring_trial(y[YXI], 0.0, 0.0, vc, 0.0, 0.0, kt, gt)[0]
        if abs(held) <= cap:
            return STICK
        T[T_S] = 1.0 if held > 0.0 else -1.0
    return SLIP


@jit
def changed(P, T, phase, mode, x, y, count, at_once):
    """`switch`, counting changes of mode in count[1]: (mode, ok), ok False beyond CHANGES."""
    after = switch(P, T, phase, mode, x, y, at_once)
    if after != mode:
        count[1] += 1
    return after, count[1] <= CHANGES


@jit
def roll_switch(P, T, phase, mode, x, y, count):
    """Rolling resistance's mode after a located switch at (x, y): from rolling (the spin reached
    zero), held where the cap can hold it, else rolling on the other way; from held (the torque
    that holds the spin reached the cap), rolling the way the rest of the torque turns it. Counts
    the change in count[1]; ok False beyond CHANGES."""
    delta, _ = overlap(P, phase, x, y)
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, delta, y)
    if T[T_RS] != 0.0:
        # the spins made equal (a wall's: none), their angular momentum about b kept
        y[YWB] = y[YW2] if T[T_D] == 0.0 else (T[T_I] * y[YWB] + T[T_I2] * y[YW2]) / (T[T_I] + T[T_I2])
        y[YW2] = y[YWB]
        T[T_RS] = 0.0
        _, need, cap, _ = rolled(T, fn, ft, delta, y)
        if abs(need) > cap:
            T[T_RS] = -1.0 if need > 0.0 else 1.0
    else:
        _, need, cap, _ = rolled(T, fn, ft, delta, y)
        T[T_RS] = -1.0 if need > 0.0 else 1.0
    count[1] += 1
    return count[1] <= CHANGES


@jit
def first_roll(P, T, v_in, dmax, mode, y):
    """Rolling resistance's mode at touching: rolling the spin's way, or with no spin held if its
    cap holds the torque a little way in (both vanish at touching), else rolling the torque's way."""
    if T[T_ROLL] == 0.0:
        return
    if y[YWB] != y[YW2]:
        T[T_RS] = 1.0 if y[YWB] > y[YW2] else -1.0
        return
    T[T_RS] = 0.0
    d = 1e-8 * dmax
    vc = y[YVT] + (T[T_R] - T[T_LEVER] * d) * y[YWB] + (T[T_R2] - T[T_LEVER] * d) * y[YW2]
    y[YXI] = vc * d / v_in if mode == STICK else 0.0
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, d, y)
    y[YXI] = 0.0
    _, need, cap, _ = rolled(T, fn, ft, d, y)
    if abs(need) > cap:
        T[T_RS] = -1.0 if need > 0.0 else 1.0


@jit
def land(P, T, phase, mode, x, y, h, which, g0, g1, e, ws, floors):
    """The step's length from (x, y) that puts the watched function (g0 at 0, g1 at h) at zero, by
    secant (Illinois) steps, its end state in e. Returns (length, ok)."""
    lo, hi, glo, ghi = 0.0, h, g0, g1
    side = 0
    m = h
    for _ in range(LAND):
        m = lo - glo * (hi - lo) / (ghi - glo)
        if not gl_step(P, T, phase, mode, x, y, m, e, ws, floors):
            return m, False
        g = watched(P, T, phase, mode, x + m, e, which)
        if g == 0.0 or abs(hi - lo) <= 4e-16 * abs(h):
            break
        lo, hi, glo, ghi, side = illinois(lo, hi, glo, ghi, side, m, g)
    # the mode's side of the root: a switch landed just past it would start the next mode early
    if (which == 0 or which == 3) and watched(P, T, phase, mode, x + m, e, which) < 0.0 and lo > 0.0:
        m = lo
        if not gl_step(P, T, phase, mode, x, y, m, e, ws, floors):
            return m, False
    return m, True


@jit
def keep(P, T, phase, mode, x, y, trail):
    """The state after a step into the trail: (time, delta, rate, work, way, velocity, angle, spin,
    F_n, F, mode, the other sphere's spin and angle)."""
    delta, _ = overlap(P, phase, x, y)
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, mode, delta, y)
    trail.append((x if phase == TIME else y[Y0], delta, y[YU], y[YWN] + y[YWT], y[YP], y[YVT], y[YTH], y[YWB],
                  fn, ft, 2.0 if mode == STICK else 1.0, y[YW2], y[YTH2]))


@jit
def advance(P, T, phase, mode, x, end, y, ws, floors, trail, count):
    """Step y (in place) from x to end, each mode switch and each kink of the cap (F_n through
    zero, where a damped force would pull) inside landed and the rest taken on from there; stops
    at P_STOP. Returns (x, mode, how): how 0 done, 1 failed, 2 stopped."""
    e = ws[8]
    at_kink = False
    for _ in range(SWITCHES):
        h = end - x
        if not gl_step(P, T, phase, mode, x, y, h, e, ws, floors):
            return x, mode, 1
        count[0] += 1
        kink = False
        if not at_kink:
            n0, n1 = watched(P, T, phase, mode, x, y, 2), watched(P, T, phase, mode, x + h, e, 2)
            if (n0 > 0.0 and n1 <= 0.0) or (n0 < 0.0 and n1 >= 0.0):
                h, ok = land(P, T, phase, mode, x, y, h, 2, n0, n1, e, ws, floors)
                if not ok:
                    return x, mode, 1
                kink = True
        g1 = watched(P, T, phase, mode, x + h, e, 0)
        r1 = watched(P, T, phase, mode, x + h, e, 3) if T[T_ROLL] > 0.0 else 1.0
        switched, rolls = False, False
        if g1 < 0.0 or r1 < 0.0:
            g0 = watched(P, T, phase, mode, x, y, 0)
            r0 = watched(P, T, phase, mode, x, y, 3) if T[T_ROLL] > 0.0 else 1.0
            if g1 < 0.0 and g0 <= 0.0:  # the mode does not hold from here (at touch, or just switched): the other
                mode, ok = changed(P, T, phase, mode, x, y, count, True)
                if not ok:
                    return x, mode, 4
                at_kink = False
                continue
            if r1 < 0.0 and r0 <= 0.0:  # so for rolling resistance's
                if not roll_switch(P, T, phase, mode, x, y, count):
                    return x, mode, 4
                at_kink = False
                continue
            if g1 < 0.0:
                h, ok = land(P, T, phase, mode, x, y, h, 0, g0, g1, e, ws, floors)
                if not ok:
                    return x, mode, 1
                switched, kink = True, False
                if T[T_ROLL] > 0.0:
                    r1 = watched(P, T, phase, mode, x + h, e, 3)
            if r1 < 0.0:  # rolling resistance's switch, first of the two
                h, ok = land(P, T, phase, mode, x, y, h, 3, r0, r1, e, ws, floors)
                if not ok:
                    return x, mode, 1
                switched, rolls, kink = False, True, False
        stopped = False
        t1 = x + h if phase == TIME else e[Y0]
        if t1 > P[P_STOP]:
            t0 = x if phase == TIME else y[Y0]
            h, ok = land(P, T, phase, mode, x, y, h, 1, t0 - P[P_STOP], t1 - P[P_STOP], e, ws, floors)
            if not ok:
                return x, mode, 1
            stopped = True
        for c in range(NY):
            y[c] = e[c]
        x += h
        keep(P, T, phase, mode, x, y, trail)
        if stopped:
            return x, mode, 2
        if switched:
            mode, ok = changed(P, T, phase, mode, x, y, count, False)
            if not ok:
                return x, mode, 4
        elif rolls:
            if not roll_switch(P, T, phase, mode, x, y, count):
                return x, mode, 4
        elif not kink:
            return end, mode, 0
        at_kink = kink
    return x, mode, 1


@jit
def first_mode(P, T, v_in, dmax, y):
    """The mode at touching (xi = 0): the spring's force against the cap a little way in (both
    vanish at touching under Hertz; their ratio settles at once)."""
    d = 1e-8 * dmax
    y[YU] = v_in
    acc, fn, gamma, ft, vc, kt, gt, cap, kn = forces(P, T, STICK, d, y)
    y[YXI] = vc * d / v_in
    ft = spring_trial(y[YXI], 0.0, 0.0, vc, 0.0, 0.0, kt, gt)[0]
    y[YXI] = 0.0
    if abs(ft) <= cap:
        return STICK
    T[T_S] = -1.0 if vc > 0.0 else 1.0
    return SLIP


@jit
def sigma_steps(P, T, mode, x, end, n, y, ws, floors, trail, count, v_in):
    """n steps over sigma from x to end (the rise: failed where the approach slows below a
    quarter; the fall: turned where the separation stops). Returns (x, mode, how): how 0 done,
    1 failed, 2 stopped, 3 turned, 4 chattering."""
    h = (end - x) / n
    start = x
    save = np.empty(NY)
    for s in range(n):
        for c in range(NY):
            save[c] = y[c]
        x0, mode0, sign, rolling, kept = x, mode, T[T_S], T[T_RS], len(trail)
        x, mode, how = advance(P, T, SIGMA, mode, x, end if s == n - 1 else start + (s + 1) * h, y, ws, floors,
                               trail, count)
        if how == 4:
            return x, mode, 4
        if how == 1 or (h > 0.0 and not y[YU] > 0.25 * v_in):
            return x, mode, 1
        if h < 0.0 and not y[YU] < 0.0:
            # turned: back to the state before this step (its steps over sigma pass 1/u = inf)
            for c in range(NY):
                y[c] = save[c]
            T[T_S], T[T_RS] = sign, rolling
            while len(trail) > kept:
                trail.pop()
            return x0, mode0, 3
        if how == 2:
            return x, mode, 2
    return x, mode, 0


@jit
def middle(P, T, mode, t, delta1, h, limit, y, ws, floors, trail, count):
    """Over time from y (delta in Y0) until delta is back below delta1 (separating), ending at no
    less than half of it, or the stop, within `limit` steps (`impact.middle`). Returns (t, mode,
    how) as `sigma_steps`."""
    size = h
    save = np.empty(NY)
    while count[0] < limit:
        for c in range(NY):
            save[c] = y[c]
        sign, rolling, kept = T[T_S], T[T_RS], len(trail)
        x, after, how = advance(P, T, TIME, mode, t, t + h, y, ws, floors, trail, count)
        if how == 4:
            return t, mode, 4
        if how == 1 or (y[YU] < 0.0 and y[Y0] < 0.5 * delta1):
            for c in range(NY):  # too long a step for this part of the contact
                y[c] = save[c]
            T[T_S], T[T_RS] = sign, rolling
            while len(trail) > kept:
                trail.pop()
            h *= 0.5
            if h < 1e-12 * size:
                return t, mode, 1
            continue
        t, mode, h = x, after, size
        if how == 2:
            return t, mode, 2
        if y[YU] < 0.0 and y[Y0] < delta1:
            return t, mode, 0
    return t, mode, 1


@jit
def rub(P, T, v_in, n_end, n_mid, limit, out, trail, y):
    """One contact from touching at approach speed v_in > 0 until it separates or P_STOP comes
    (`impact.contact`'s steps: n_end over sigma at each end, a contact time over n_mid between),
    with friction; y (NY) holds the tangential state at touching (YVT, YWB) and gets the state at
    the end. out (impact's NOUT): the speed of separation, the time, the work of the dashpot and
    friction, the steps, O_END (ENDED; STOPPED, with O_DELTA and O_U; FAILED; CHATTER); the peaks
    are left to `impact.contact`. trail gets `keep`'s row after every step."""
    dmax, span = estimate(P, v_in)
    P[P_SPEED] = 1e-300 + 1e-17 * v_in
    T[T_HOLD] = HOLD_SPEED * P[P_SPEED] * n_mid
    ws = np.zeros((9, NY))
    floors = np.full(NY, 1e-300)
    floors[YU] = floors[YVT] = P[P_SPEED]
    floors[YWB] = floors[YW2] = P[P_SPEED] / T[T_R]
    floors[YXI] = floors[YP] = P[P_SPEED] * span
    floors[YTH] = floors[YTH2] = floors[YXI] / T[T_R]
    if T[T_D] > 0.0:
        floors[YP] /= T[T_D]
    floors[YWN] = floors[YWT] = 1e-17 * T[T_M] * v_in * v_in
    y0 = y.copy()
    count = np.zeros(2, np.int64)
    frac, how, delta1, mode, x = SWITCH, 1, 0.0, STICK, 0.0
    for _ in range(10):  # the rise, its switch to time steps halved while the approach slows too much
        while len(trail) > 0:
            trail.pop()
        for c in range(NY):
            y[c] = y0[c]
        mode = first_mode(P, T, v_in, dmax, y)
        first_roll(P, T, v_in, dmax, mode, y)
        y[Y0], y[YU] = 0.0, v_in
        delta1 = frac * dmax
        x, mode, how = sigma_steps(P, T, mode, 0.0, delta1 ** (1.0 / P[7]), n_end, y, ws, floors, trail, count,
                                   v_in)
        if how != 1:
            break
        frac *= 0.5
        count[1] = 0
    t, d = y[Y0], x ** P[7]
    while how == 0:
        y[Y0] = d
        t, mode, how = middle(P, T, mode, t, delta1, span / n_mid, limit, y, ws, floors, trail, count)
        d = y[Y0]
        if how != 0:
            break
        y[Y0] = t
        x, mode, how = sigma_steps(P, T, mode, d ** (1.0 / P[7]), 0.0, n_end, y, ws, floors, trail, count,
                                   v_in)
        t, d = y[Y0], x ** P[7]
        if how == 0:  # separated
            break
        if how == 3:
            # Held on the wall (or the separation too slow for sigma's steps): over time again, back
            # to the end's sigma only if it goes on well below here (as `impact.contact`).
            delta1, how = 0.25 * d, 0
    out[O_VOUT], out[O_TIME], out[O_WORK], out[O_STEPS] = -y[YU], t, y[YWN] + y[YWT], count[0]
    out[O_DELTA], out[O_U] = d, y[YU]
    out[O_END] = (ENDED, FAILED, STOPPED, FAILED, CHATTER)[how]  # (how 3, turned, goes on over time above)
    out[O_OK] = 1.0 if how == 0 else 0.0


@jit
def frame(N, v, w, g, r):
    """The line e of the wall (normal N, out of it) along which the contact's tangential motion
    stays, b = -N x e the spin's axis, for a sphere at v spinning at w under g; ok False where
    the motion is not in one line (module docstring)."""
    vn, gn = v[0] * N[0] + v[1] * N[1] + v[2] * N[2], g[0] * N[0] + g[1] * N[1] + g[2] * N[2]
    vt, gt, slip = np.empty(3), np.empty(3), np.empty(3)
    for d in range(3):
        vt[d], gt[d] = v[d] - vn * N[d], g[d] - gn * N[d]
    wxn = np.array([N[1] * w[2] - N[2] * w[1], N[2] * w[0] - N[0] * w[2], N[0] * w[1] - N[1] * w[0]])  # w x -N
    for d in range(3):
        slip[d] = vt[d] + r * wxn[d]
    # Loops and dot3, not numpy's reductions: a cached kernel using those makes every process that
    # loads it import numba's array maths (tests/test_startup.py).
    e = np.zeros(3)
    for cand in (slip, vt, gt):
        size = math.sqrt(dot3(cand, cand))
        if size > 0.0:
            for d in range(3):
                e[d] = cand[d] / size
            break
    if dot3(e, e) == 0.0:  # head-on, no spin, no gravity along the wall: any line of it
        axis = 0
        for d in range(1, 3):
            if abs(N[d]) < abs(N[axis]):
                axis = d
        e[axis] = 1.0
        en = dot3(e, N)
        for d in range(3):
            e[d] -= en * N[d]
        size = math.sqrt(dot3(e, e))
        for d in range(3):
            e[d] /= size
    b = np.array([N[2] * e[1] - N[1] * e[2], N[0] * e[2] - N[2] * e[0], N[1] * e[0] - N[0] * e[1]])
    scale = math.sqrt(dot3(v, v)) + r * math.sqrt(dot3(w, w)) + 1e-300
    off = 0.0
    for vec, size in ((vt, scale), (gt, math.sqrt(dot3(g, g)) + 1e-300), (slip, scale)):
        along = dot3(vec, e)
        across = 0.0
        for d in range(3):
            across += (vec[d] - along * e[d]) ** 2
        off = max(off, math.sqrt(across) / size)
    off = max(off, r * abs(dot3(w, e)) / scale)
    return e, b, off <= 1e-12


def rub_steps(tol: float) -> tuple[int, int]:
    """`impact.steps_for` for `rub`'s order-6 steps (before the spring's factor in
    `alone.take_rubbing`): error about 3e-3 / n^6."""
    n = max(4, math.ceil((3e-3 / tol) ** (1.0 / 6.0)))
    return n, 2 * n

