"""A tangential spring in an island (in the plane): the DEM kernel's law (`collide.engine.dem.
tangential`: `spring_coefficients`, `spring_trial`, `friction_cap`, `slip_stretch`) taken to a
vanishing step, as `oblique` takes it for a sphere alone or two spheres:

* SPRING (stick): the stretch xi along the tangent e = z x n is a state, xi' = the slip along e
  (the drifts integrate it: `stretch_drift`), and the force on i is F = -k_t xi - gamma_t v_e, a
  smooth force of the positions, the stretch and (its dashpot) the velocities, in the kicks with
  the normal dashpots; the event is |F| reaching mu F_n (`mode_events`' first value).
* SLIDE: F = s mu F_n (s the side, kept as the held slip -s e), the stretch the one that holds it
  alone (xi = -F / k_t). With a tangential dashpot the slip lasts while the contact point slides
  against F (s v_e < 0); without one while the stretch is pushed past the cap, -s v_e > c' with
  c = mu F_n / k_t (`slide_value`; its zero is the event).

Reaching the cap (`spring_mode`, as `oblique.switch`): the stretch is set to hold the capped
force, and the contact slips, or sticks on where the point moves along the force. The stretch
stays with its pair across phases and windows (the N x (N + W) table SP, at most 64 bodies:
`load_stretches`, `keep_stretches`); a contact that ends loses it, as the DEM kernel's history
does. The stretch keeps its length as the normal turns (the DEM kernel's projection): in the plane
it is the scalar along e.
"""

from __future__ import annotations

import math

from collide.engine.dem.damping import dashpot
from collide.engine.dem.tangential import friction_cap, slip_stretch, spring_coefficients, spring_trial
from collide.engine.event.contact import elastic, engaged, overlap, planar_levers, planar_relative, response
from collide.engine.jit import jit_call, jit_inline
from collide.engine.layout import (
    C_ESTAR,
    C_FN,
    C_GAMMA,
    C_HELD,
    C_KTR,
    C_MSTAR,
    C_MU,
    C_N,
    C_REACH,
    C_SH,
    C_XI,
    C_XI0,
    C_ZETA,
    CI_EDGE,
    CI_GI,
    CI_GJ,
    CI_I,
    CI_J,
    CI_MODE,
    CI_Q,
    Q_ENG,
    Q_I,
    Q_J,
    SLIDE,
    SPRING,
    STICK_SCALE,
    TOOTH,
    X_R,
    X_S,
    X_V,
    X_W,
)

# Gauss-Legendre, three nodes: the drifts' integral of the slip (exact to degree five in the
# drift's time; the slip along e is analytic in it, its scale the pair's distance over its speed).
_R15 = math.sqrt(15.0)
_NODES = (0.5 - _R15 / 10.0, 0.5, 0.5 + _R15 / 10.0)
_WEIGHTS = (5.0 / 18.0, 4.0 / 9.0, 5.0 / 18.0)


@jit_inline
def spring_law(C, c):
    """(k_t, gamma_t) at contact c's overlap: `spring_coefficients` of its normal stiffness dF/d
    delta and dashpot (Hertz's at that stiffness, as `contact.dashpots`)."""
    kn = elastic(C, c)[1]
    gamma = C[c, C_GAMMA]
    if gamma > 0.0 and C[c, C_ESTAR] > 0.0:
        gamma = dashpot(C[c, C_ZETA], C[c, C_MSTAR], kn)
    return spring_coefficients(kn, gamma, C[c, C_KTR], math.sqrt(C[c, C_KTR]))


@jit_inline
def slip_along(X, C, CI, c, vc, wc, spin):
    """Contact c's slip along e = z x n at the velocities in columns (vc, wc) (`contact.slip`'s)."""
    i, j = CI[c, CI_I], CI[c, CI_J]
    rx, ry = planar_relative(X, i, j, vc)
    v = -rx * C[c, C_N + 1] + ry * C[c, C_N]
    if spin:
        v += planar_levers(X, C, c, i, j, wc)
    return v


@jit_inline
def spring_force(X, C, CI, c, vc, wc, spin):
    """The spring's force on i along e at the velocities in (vc, wc), before the cap: (F, v_e)."""
    kt, gt = spring_law(C, c)
    v = slip_along(X, C, CI, c, vc, wc, spin)
    return spring_trial(C[c, C_XI], 0.0, 0.0, v, 0.0, 0.0, kt, gt)[0], v


@jit_inline
def slide_sign(C, c):
    """A spring's slide's side s (F = s mu F_n along e): its held slip is -s e."""
    return -1.0 if -C[c, C_N + 1] * C[c, C_HELD] + C[c, C_N] * C[c, C_HELD + 1] >= 0.0 else 1.0


@jit_inline
def set_slide(C, c, s):
    """Hold the slide on side s, the stretch the one that holds its force (`slip_stretch`)."""
    C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2] = s * C[c, C_N + 1], -s * C[c, C_N], 0.0
    C[c, C_XI] = slip_stretch(s * friction_cap(C[c, C_MU], C[c, C_FN]), spring_law(C, c)[0])


@jit_inline
def closing_rate(X, CI, C, c):
    """delta' (> 0 while approaching) at the bodies' velocities."""
    rx, ry = planar_relative(X, CI[c, CI_I], CI[c, CI_J], X_V)
    return rx * C[c, C_N] + ry * C[c, C_N + 1]


@jit_inline
def slide_value(X, C, CI, c, s, v):
    """A spring's slide's value (> 0 while it lasts), at slip v along e: with a tangential dashpot
    -s v; without, -s v - c', c' = mu delta' (1 - F_n k_n' / k_n^2) / ratio (Hertz's bracket 2/3)."""
    if C[c, C_GAMMA] > 0.0:
        return -s * v
    bracket = 2.0 / 3.0 if C[c, C_ESTAR] > 0.0 else 1.0
    return -s * v - C[c, C_MU] * closing_rate(X, CI, C, c) * bracket / C[c, C_KTR]


@jit_inline
def weighted(X, C, CI, c, f, v, limit, force_tol):
    """(F, cap, tolerance) as `spring_mode` compares them. Under Hertz's dashpot both F and the cap
    vanish at touching as gamma does (delta^(1/4)): they are compared over gamma (the tolerance
    over its bound C_GAMMA), and where gamma is zero by their limits there, -sqrt(ratio) v_e and
    mu max(delta', 0) (the spring's share and the elastic force vanish faster)."""
    if not (C[c, C_GAMMA] > 0.0 and C[c, C_ESTAR] > 0.0):
        return f, limit, force_tol
    gamma = dashpot(C[c, C_ZETA], C[c, C_MSTAR], elastic(C, c)[1])
    tol = force_tol / C[c, C_GAMMA]
    if gamma > 0.0:
        return f / gamma, limit / gamma, tol
    return -math.sqrt(C[c, C_KTR]) * v, C[c, C_MU] * max(closing_rate(X, CI, C, c), 0.0), tol


@jit_inline
def spring_mode(X, C, CI, c, spin, tol):
    """Contact c's mode at this state (C_FN this state's): SPRING while the spring's force is
    within the cap; at or past it (within the event tolerance `tol`, a speed) the stretch is set
    to hold the capped force, and the contact slides unless its point moves along the force and
    the spring then holds within the cap (`oblique.switch`). A slide's stretch is not stepped:
    it is first set to the one that holds its force here."""
    if CI[c, CI_MODE] == SLIDE:
        set_slide(C, c, slide_sign(C, c))
    f, v = spring_force(X, C, CI, c, X_V, X_W, spin)
    force_tol = tol / (response(X, C, CI, c, spin) * STICK_SCALE)
    f, limit, force_tol = weighted(X, C, CI, c, f, v, friction_cap(C[c, C_MU], C[c, C_FN]), force_tol)
    if abs(f) < limit - force_tol:
        CI[c, CI_MODE] = SPRING
        return
    s = 1.0 if f > 0.0 or (f == 0.0 and v < 0.0) else -1.0
    for _ in range(2):
        set_slide(C, c, s)
        if slide_value(X, C, CI, c, s, v) > tol:
            CI[c, CI_MODE] = SLIDE
            return
        held = spring_force(X, C, CI, c, X_V, X_W, spin)[0]
        held = weighted(X, C, CI, c, held, v, 0.0, 0.0)[0]
        if abs(held) <= limit + force_tol or C[c, C_GAMMA] == 0.0:
            break
        # The dashpot's share carries the force past the cap on the other side: a slide there.
        s = 1.0 if held > 0.0 else -1.0
    if CI[c, CI_MODE] == SPRING and C[c, C_GAMMA] > 0.0:
        # A damped spring that sticks on at the cap it reached: a tooth of the sawtooth (SAWTOOTH).
        CI[c, CI_EDGE] = TOOTH
    CI[c, CI_MODE] = SPRING


@jit_inline
def stretch_drift(X, C, CI, nc, hk, WP, spin, seed):
    """A drift's share of each sticking spring's stretch: the integral of its slip along e over
    hk at the bodies' fixed velocities, the positions moving (Gauss-Legendre, three nodes; call
    before the positions move)."""
    for c in range(nc):
        if CI[c, CI_MODE] != SPRING:
            continue
        i, j = CI[c, CI_I], CI[c, CI_J]
        total = 0.0
        for k in range(3):
            tau = _NODES[k] * hk
            xi, yi = X[i, X_S] + X[i, X_V] * tau, X[i, X_S + 1] + X[i, X_V + 1] * tau
            if j >= 0:
                dx = X[j, X_S] + X[j, X_V] * tau - xi + C[c, C_SH]
                dy = X[j, X_S + 1] + X[j, X_V + 1] * tau - yi + C[c, C_SH + 1]
                dist = math.sqrt(dx * dx + dy * dy)
                nx, ny = dx / dist, dy / dist
                half = 0.5 * (C[c, C_REACH] - dist)
                li = X[i, X_R] if seed else X[i, X_R] - half
                lj = X[j, X_R] if seed else X[j, X_R] - half
                rx, ry = X[i, X_V] - X[j, X_V], X[i, X_V + 1] - X[j, X_V + 1]
                lz = li * X[i, X_W + 2] + lj * X[j, X_W + 2]
            else:
                w = -1 - j
                nx, ny = -WP[w, 3], -WP[w, 4]
                dist = (xi - WP[w, 0]) * WP[w, 3] + (yi - WP[w, 1]) * WP[w, 4] - WP[w, 2] * WP[w, 5]
                li = X[i, X_R] if seed else dist
                rx, ry = X[i, X_V], X[i, X_V + 1]
                lz = li * X[i, X_W + 2]
            total += _WEIGHTS[k] * (-rx * ny + ry * nx + (lz if spin else 0.0))
        C[c, C_XI] += hk * total


@jit_inline
def stretch_rows(SP, CI, c, n):
    """Contact c's row and column in the stretch table (a wall w's column n + w)."""
    gj = CI[c, CI_GJ]
    return CI[c, CI_GI], gj if gj >= 0 else n - 1 - gj


@jit_call
def load_stretches(SP, C, CI, Q, nq, nc, n, spring):
    """The engaged contacts' stretches from the table (none without a spring); a candidate not
    engaged has none (a contact that ended lost it)."""
    for c in range(nc):
        C[c, C_XI] = 0.0
        if spring:
            r, col = stretch_rows(SP, CI, c, n)
            C[c, C_XI] = SP[r, col]
    if spring:
        for k in range(nq):
            if Q[k, Q_ENG] == 0:
                gj = Q[k, Q_J]
                SP[Q[k, Q_I], gj if gj >= 0 else n - 1 - gj] = 0.0


@jit_call
def keep_stretches(G, GI, X, SP, C, CI, Q, QF, nc, t, WP, grav, n):
    """The phase's stretches back to the table at its end t (a slide's the one that holds its
    force); a contact no longer engaged there keeps none."""
    for c in range(nc):
        if CI[c, CI_MODE] == SLIDE:
            set_slide(C, c, slide_sign(C, c))
        k = CI[c, CI_Q]
        d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
        row, col = stretch_rows(SP, CI, c, n)
        SP[row, col] = C[c, C_XI] if engaged(Q, k, d, r, WP, grav) else 0.0


@jit_call
def sawtooth(CI, nc, spring):
    """Whether a damped spring stuck on at a cap it reached (`spring_mode`'s TOOTH)."""
    for c in range(nc if spring else 0):
        if CI[c, CI_EDGE] == TOOTH:
            return True
    return False


@jit_inline
def stretch_start(C, nc, back):
    """The stretches at the step's start kept (`back` False) or restored (True)."""
    for c in range(nc):
        if back:
            C[c, C_XI] = C[c, C_XI0]
        else:
            C[c, C_XI0] = C[c, C_XI]


@jit_inline
def held(C, c):
    """The energy contact c's tangential spring holds, k_t xi^2 / 2 (none without one)."""
    if C[c, C_KTR] == 0.0:
        return 0.0
    return 0.5 * spring_law(C, c)[0] * C[c, C_XI] ** 2
