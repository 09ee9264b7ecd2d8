"""One step of an island: a symmetric composition of kick-drift-kick substeps (`step`). Slide and
stick forces depend on the velocities, so a substep's closing kick is implicit (a fixed point,
a few iterations: `kick`) and the next one's opening kick explicit: each substep is symmetric
and the compositions keep their order in every mode, in 3D as in 2D.
"""

from __future__ import annotations

import math

from collide.engine.event.contact import geometry, response, set_basis, slip, springs
from collide.engine.event.forces import friction, hold, repull
from collide.engine.event.spring import spring_law, stretch_drift, stretch_start
from collide.engine.flight import turn
from collide.engine.jit import jit_call, jit_inline
from collide.engine.layout import (
    C_B,
    C_DIST,
    C_EPS,
    C_GAMMA,
    C_HELD,
    C_LIS,
    C_LJS,
    C_N,
    CI_I,
    CI_J,
    CI_MODE,
    CONTRACTION_SAFETY,
    EPS64,
    FIXED_POINT,
    FL_DAMPED,
    FL_FRICTION,
    FL_PLANAR,
    FL_SEED,
    FL_SPIN,
    FL_SPRING,
    MAP_BOTH,
    MAP_NONE,
    MAP_START,
    NO,
    SLIDE,
    SPRING,
    STICK,
    X_A,
    X_F,
    X_F0,
    X_FP,
    X_HP,
    X_I,
    X_IM,
    X_L,
    X_L0,
    X_LP,
    X_M,
    X_MD,
    X_MH,
    X_MK,
    X_MO,
    X_MP,
    X_MR,
    X_MU,
    X_Q,
    X_R,
    X_S,
    X_S0,
    X_UA,
    X_UL,
    X_V,
    X_V1,
    X_VB,
    X_W,
    X_W1,
    X_WB,
    YES,
)


@jit_inline
def take_velocities(X, na, vc, wc, spin, planar):
    """Make the velocities in (vc, wc) the bodies' (X_V, X_W); returns the kinetic energy lost.
    `planar`: only the parts in the plane (the velocities' x, y, the spins' z: the others are
    zero and stay so), the same sums."""
    moves, turns = (2, 2) if planar else (3, 0)
    e = 0.0
    for a in range(na):
        for d in range(moves):
            v, u = X[a, X_V + d], X[a, vc + d]
            e += 0.5 * X[a, X_M] * (v * v - u * u)
            X[a, X_V + d] = u
        for d in range(turns, 3):
            w, u = X[a, X_W + d], X[a, wc + d]
            if spin:
                e += 0.5 * X[a, X_I] * (w * w - u * u)
            X[a, X_W + d] = u
    return e


@jit_inline
def friction_kick(X, na, h, then, spin, planar):
    """Add h times the friction accelerations (X_F, X_L) to the velocities and then, unless 0,
    `then` times the others' (X_A); returns the kinetic energy the friction took: one pass over
    the bodies where `take_velocities` of stored velocities made two. `planar`: as there."""
    moves, turns = (2, 2) if planar else (3, 0)
    e = 0.0
    for a in range(na):
        for d in range(moves):
            v = X[a, X_V + d]
            u = v + h * X[a, X_F + d]
            e += 0.5 * X[a, X_M] * (v * v - u * u)
            X[a, X_V + d] = u + then * X[a, X_A + d] if then != 0.0 else u
        for d in range(turns, 3):
            w = X[a, X_W + d]
            u = w + h * X[a, X_L + d]
            if spin:
                e += 0.5 * X[a, X_I] * (w * w - u * u)
            X[a, X_W + d] = u
    return e


@jit_inline
def close_and_open(X, na, h, spin, planar):
    """`take_velocities` of (X_V1, X_W1), then `friction_kick` over h with the springs' after it,
    in one pass over the bodies; returns the kinetic energy each took. `planar`: as there."""
    moves, turns = (2, 2) if planar else (3, 0)
    closed, opened = 0.0, 0.0
    for a in range(na):
        m, i = 0.5 * X[a, X_M], 0.5 * X[a, X_I]
        for d in range(moves):
            v, u = X[a, X_V + d], X[a, X_V1 + d]
            n = u + h * X[a, X_F + d]
            closed += m * (v * v - u * u)
            opened += m * (u * u - n * n)
            X[a, X_V + d] = n + h * X[a, X_A + d]
        for d in range(turns, 3):
            w, u = X[a, X_W + d], X[a, X_W1 + d]
            n = u + h * X[a, X_L + d]
            if spin:
                closed += i * (w * w - u * u)
                opened += i * (u * u - n * n)
            X[a, X_W + d] = n
    return closed, opened


@jit_inline
def hold_pull(X, C, CI, nc):
    """How fast the stuck contacts' hold forces follow the velocities, |dG/dv| (1/s): the frame
    turning at the relative speed over the distance and with the spins, the arms with the spins.
    With the dashpots' (gamma over the reduced mass, summed). Taken once a step: within one it
    changes by a share of the step's impulse, which
    CONTRACTION_SAFETY covers (computed at each kick, it took three square roots per stuck
    contact every time)."""
    pull = 0.0
    for c in range(nc):
        # A dashpot's force follows the velocities at gamma (1/m_i + 1/m_j); several on a body add.
        gamma = C[c, C_GAMMA]
        if gamma > 0.0:
            i, j = CI[c, CI_I], CI[c, CI_J]
            pull += gamma * (X[i, X_IM] + (X[j, X_IM] if j >= 0 else 0.0))
        if CI[c, CI_MODE] == SPRING:
            # A sticking spring's dashpot follows the slip at gamma_t K.
            pull += spring_law(C, c)[1] * response(X, C, CI, c, True)
    damped, pull = pull, 0.0
    for c in range(nc):
        if CI[c, CI_MODE] == STICK:
            i, j = CI[c, CI_I], CI[c, CI_J]
            rel, wi, wj = 0.0, 0.0, 0.0
            for d in range(3):
                u = X[i, X_V + d] - (X[j, X_V + d] if j >= 0 else 0.0)
                rel += u * u
                wi += X[i, X_W + d] ** 2
                if j >= 0:
                    wj += X[j, X_W + d] ** 2
            wi, wj = math.sqrt(wi), math.sqrt(wj)
            arm = C[c, C_DIST] if j >= 0 else C[c, C_LIS]
            pull = max(pull, (math.sqrt(rel) + C[c, C_LIS] * wi + C[c, C_LJS] * wj) / arm + wi + wj)
    return damped + pull


@jit_inline
def kick_start(CI, nc, planar, damped):
    """How a step's closing kicks start, from its modes: (warm, one pass). Warm: from the last
    kick's friction (C_FF and its accelerations), which differs from this one's by a substep's
    change, a pass fewer than from none; not with a slide out of the plane, whose kick can have
    two roots (see slide_direction): a start off the one the kick's own impulse defines can
    settle on the other (measured: a random 3D scene stopped converging with the tolerance).
    One pass: in the plane a slide's friction is mu F_n on the held side whatever the
    velocities, so with nothing stuck one pass is the fixed point, unless a dashpot (`damped`)
    makes F_n follow them."""
    warm, one_pass = True, planar and not damped
    for c in range(nc):
        if CI[c, CI_MODE] == STICK:
            one_pass = False
        elif CI[c, CI_MODE] == SLIDE and not planar:
            warm = False
    return warm, one_pass


@jit_inline
def kick(X, C, CI, na, nc, h_end, h_start, stuck, A, b, fl, exact, pull_rate, warm, one_pass):
    """The kicks at one geometry between two Verlet substeps, on (X_V, X_W): the close of one
    (springs over h_end, then friction at the end velocities: implicit) and the opening of the
    next (friction at those velocities, then springs over h_start); either span may be 0 (a
    step's first kick, h_end 0, opens with the friction already in X_F, X_L: see `step`).
    `exact`: the change, relative to the fastest velocity, that the closing kick's fixed point may
    leave undone; `pull_rate`: `hold_pull` at the step's start; `warm`, `one_pass`:
    `kick_start` of the step's modes (they hold through a step). Returns (work dissipated, ok);
    friction forces at the closing velocities stay in C_FF."""
    spin = fl[FL_SPIN]
    planar = fl[FL_PLANAR] == YES
    damped = fl[FL_DAMPED]
    work = 0.0
    if h_end != 0.0:
        if one_pass:
            # Nothing depends on the velocities: the closing kick is explicit, in one pass.
            for a in range(na):
                for d in range(3):
                    X[a, X_V + d] += h_end * X[a, X_A + d]
            X[0, X_HP] = h_end
            if not friction(X, C, CI, na, nc, X_V, X_W, stuck, A, b, fl, h_end, YES):
                return work, False
            work += friction_kick(X, na, h_end, 0.0, spin, planar)
            if h_start != 0.0:
                work += friction_kick(X, na, h_start, h_start, spin, planar)
            return work, True
        start = h_end if warm else 0.0
        # The friction extrapolated along the step from the last two kicks' (same modes, a smooth
        # function of time): the first pass starts closer to the fixed point.
        lean = h_end / X[0, X_HP] if X[0, X_HP] != 0.0 and warm and planar else 0.0
        for a in range(na):
            for d in range(3):
                X[a, X_V + d] += h_end * X[a, X_A + d]
                f, l = X[a, X_F + d], X[a, X_L + d]
                X[a, X_V1 + d] = X[a, X_V + d] + start * (f + lean * (f - X[a, X_FP + d]))
                X[a, X_W1 + d] = X[a, X_W + d] + start * (l + lean * (l - X[a, X_LP + d]))
                X[a, X_FP + d], X[a, X_LP + d] = f, l
        X[0, X_HP] = h_end
        # How fast the hold forces follow the velocities: a pass shrinks the change by about
        # h |dG/dv| (see CONTRACTION_SAFETY); with it, one pass can be enough.
        pull = CONTRACTION_SAFETY * abs(h_end) * pull_rate  # 0 unless warm (see step_events)
        # In the plane the velocities' z parts and the spins' x, y parts are zero and stay so.
        moves, turns = (2, 2) if planar else (3, 0)
        last = math.inf
        for it in range(FIXED_POINT):
            if it > 0 and planar and not damped:
                repull(X, C, CI, nc, stuck, A, b, fl, X_V1, X_W1)
            # Each pass but a cold first takes each contact's own friction in V1 back out.
            elif not friction(X, C, CI, na, nc, X_V1, X_W1, stuck, A, b, fl, h_end if warm or it > 0 else 0.0,
                              YES if it == 0 else NO):
                return work, False
            change = 0.0
            size = 0.0
            for a in range(na):
                for d in range(moves):
                    nv = X[a, X_V + d] + h_end * X[a, X_F + d]
                    change = max(change, abs(nv - X[a, X_V1 + d]))
                    size = max(size, abs(nv))
                    X[a, X_V1 + d] = nv
                for d in range(turns, 3):
                    nw = X[a, X_W + d] + h_end * X[a, X_L + d]
                    change = max(change, abs(nw - X[a, X_W1 + d]) * X[a, X_R])
                    size = max(size, abs(nw) * X[a, X_R])
                    X[a, X_W1 + d] = nw
            # Done when what is left is round-off or below `exact`: the change itself, or the next
            # one as the last two passes of the same map predict it (a stuck contact's hold force
            # follows the velocities as the contact frame turns, ratio about h v / dist: one pass
            # fewer), or after a warm first pass, as its bound `pull` predicts it.
            predicted = (it == 0 and warm and pull * change <= exact * size) or (
                (it >= 1 if warm else it >= 2) and change < 0.5 * last and change * change <= exact * size * last)
            if change <= 4.0 * EPS64 * size or predicted:
                break
            last = change
        if h_start != 0.0:
            closed, opened = close_and_open(X, na, h_start, spin, planar)
            return work + closed + opened, True
        work += take_velocities(X, na, X_V1, X_W1, spin, planar)
    else:
        X[0, X_HP] = 0.0  # a step's first kick: no kick before it at these modes
    if h_start != 0.0:
        work += friction_kick(X, na, h_start, h_start, spin, planar)
    return work, True


@jit_call
def settle(X, C, CI, na, nc, stuck, A, b, fl, fresh):
    """Put stuck slips on the band's edge, at eps along their held direction (carried onto the
    tangent plane), with the impulses that do exactly that, solved together. `fresh`: the hold
    system is built here, else the one in A (and the tangent bases) from the last friction solve
    at this geometry and these modes is used. Returns (work, ok)."""
    spin, planar = fl[FL_SPIN], fl[FL_PLANAR] == YES
    m = 0
    for c in range(nc):
        if CI[c, CI_MODE] == STICK:
            stuck[m] = c
            m += 1
    if m == 0:
        return 0.0, True
    for k in range(m):
        c = stuck[k]
        if fresh:
            set_basis(C, c, planar)
        nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
        hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
        hn = hx * nx + hy * ny + hz * nz
        hx, hy, hz = hx - hn * nx, hy - hn * ny, hz - hn * nz
        hm = math.sqrt(hx * hx + hy * hy + hz * hz)
        if hm > 0.0:
            hm = C[c, C_EPS] / hm
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar)
        # A friction impulse changes the slip as its force changes the slip's rate: W J = s* - s.
        dx, dy, dz = hm * hx - sx, hm * hy - sy, hm * hz - sz
        if planar:
            b[k] = dx * C[c, C_B] + dy * C[c, C_B + 1]
        else:
            b[2 * k] = dx * C[c, C_B] + dy * C[c, C_B + 1] + dz * C[c, C_B + 2]
            b[2 * k + 1] = dx * C[c, C_B + 3] + dy * C[c, C_B + 4] + dz * C[c, C_B + 5]
    for a in range(na):
        for d in range(3):
            X[a, X_UA + d] = 0.0
            X[a, X_UL + d] = 0.0
    if not hold(X, C, CI, stuck, m, A, b, spin, fl[FL_SEED], planar, fresh, X_UA, X_UL):
        return 0.0, False
    for a in range(na):
        for d in range(3):
            X[a, X_VB + d] = X[a, X_V + d] + X[a, X_UA + d]
            X[a, X_WB + d] = X[a, X_W + d] + X[a, X_UL + d]
    return take_velocities(X, na, X_VB, X_WB, spin, planar), True


@jit_inline
def drift(X, C, CI, na, nc, hk, WP, grav, fl):
    """A substep's drift over hk (the sticking springs' stretches with the positions), then the
    geometry and spring accelerations at its end."""
    spin, planar = fl[FL_SPIN], fl[FL_PLANAR]
    if fl[FL_SPRING]:
        stretch_drift(X, C, CI, nc, hk, WP, spin, fl[FL_SEED])
    for a in range(na):
        for d in range(3):
            X[a, X_S + d] += X[a, X_V + d] * hk
        if spin:
            turn(X[a, X_Q:X_Q + 4], X[a, X_W], X[a, X_W + 1], X[a, X_W + 2], hk, planar)
    geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
    springs(X, C, CI, na, nc, grav)


@jit_inline
def kicks(X, C, CI, na, nc, close, opening, stuck, A, b, fl, exact, pull_rate, warm, one_pass):
    """The kicks between two substeps (see `kick`): with friction or dashpots `kick`, else the
    springs' over close then opening. Returns (work, ok)."""
    if fl[FL_FRICTION]:
        return kick(X, C, CI, na, nc, close, opening, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
    # Two adds, as with friction: a sweep mixing mu = 0 with mu > 0 matches single runs.
    for a in range(na):
        for d in range(3):
            if close != 0.0:
                X[a, X_V + d] += close * X[a, X_A + d]
            if opening != 0.0:
                X[a, X_V + d] += opening * X[a, X_A + d]
    return 0.0, True


@jit_call
def step(X, C, CI, na, nc, h, weights, WP, grav, stuck, A, b, fl, restart, exact, pull_rate, warm, one_pass):
    """One step of h from the start state (X_S0..., its friction accelerations in X_F0, X_L0), or
    with `restart` NO from the state now in (X_S...), its geometry in C and X_A and its friction
    in (X_F, X_L) (a trial's end, whose mode values solved it there): a symmetric composition of
    Verlet (kick-drift-kick) substeps gamma h (`weights`); the kicks between two substeps share
    one geometry. Stuck slips go back on the band's edge only once the step is taken (`settle`,
    by the event search): a trial's end is off it by the kicks' fixed-point tolerance. The end
    state is left in (X_S...) with its geometry in C and its accelerations in X_A, X_F. `exact`,
    `pull_rate`, `warm`, `one_pass`: the kicks' (see `kick`), the same for every trial of a
    step. Where the step's map of time (X_MK) is set, `mapped_step` takes it. Returns (work, ok)."""
    fric = fl[FL_FRICTION]
    if restart:
        for a in range(na):
            for d in range(13):
                X[a, X_S + d] = X[a, X_S0 + d]
            for d in range(3 if fric else 0):
                X[a, X_F + d], X[a, X_L + d] = X[a, X_F0 + d], X[a, X_L0 + d]
        stretch_start(C, nc, True)
        geometry(X, C, CI, nc, WP, fl[FL_SEED], fric)
        springs(X, C, CI, na, nc, grav)
    start = 0.0 if restart else X[0, X_MO]
    X[0, X_MO] = start + h
    n = weights.shape[0]
    # (One Verlet substep integrates a map of time exactly only where it is linear in s: P = 2 at
    # one end.)
    if X[0, X_MK] != MAP_NONE and (n > 1 or (X[0, X_MP] <= 2.0 and X[0, X_MK] != MAP_BOTH)):
        return mapped_step(X, C, CI, na, nc, h, start, weights, WP, grav, stuck, A, b, fl, exact, pull_rate, warm,
                           one_pass)
    first = 0.5 * weights[0] * h
    work, ok = kicks(X, C, CI, na, nc, 0.0, first, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
    for k in range(n):
        hk = weights[k] * h
        drift(X, C, CI, na, nc, hk, WP, grav, fl)
        opening = 0.5 * weights[k + 1] * h if k + 1 < n else 0.0
        done, good = kicks(X, C, CI, na, nc, 0.5 * hk, opening, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
        work += done
        ok = ok and good
    return work, ok


@jit_inline
def offset(X, kind, sa, sb, h, sigma):
    """The time past a mapped call's start at sigma in [0, 1] over it, and its rate d t / d sigma:
    MAP_START t = t_s + H s^P, s from sa to sb (t_s the Hertz contact's start); MAP_END the call
    ends on the contact's end, t_end - t = h (1 - sigma)^P; MAP_BOTH both (a contact starting
    at the call's start, another ending at its end)."""
    p = X[0, X_MP]
    if kind == MAP_START:
        big = X[0, X_MH]
        s = sa + sigma * (sb - sa)
        return big * (s ** p - sa ** p), big * p * s ** (p - 1.0) * (sb - sa)
    rest = 1.0 - sigma
    if kind == MAP_BOTH:
        # Singular at both ends: 3 s^2 - 2 s^3 (P = 2), or 35 s^4 - 84 s^5 + 70 s^6 - 20 s^7.
        if p > 2.0:
            return (h * sigma ** 4 * (35.0 - sigma * (84.0 - sigma * (70.0 - 20.0 * sigma))),
                    140.0 * h * (sigma * rest) ** 3)
        return h * sigma * sigma * (3.0 - 2.0 * sigma), 6.0 * h * sigma * rest
    return h * (1.0 - rest ** p), h * p * rest ** (p - 1.0)


@jit_call
def mapped_step(X, C, CI, na, nc, h, start, weights, WP, grav, stuck, A, b, fl, exact, pull_rate, warm, one_pass):
    """`step` over s instead of t, where a Hertz contact starts or ends (its force's derivatives are
    singular at delta = 0; over s every force is smooth, see MAP_SHARE): the composition over s
    in as many runs as bring the longest substep to about the phase's step (X_MD). In the extended
    phase space (s a coordinate) the kicks advance s, each by the exact time span between its two
    s (a constant force, gravity, kicks exactly), and the drifts, at fixed s, move the bodies by
    dt/ds times their s span (exact for the map's polynomial, of degree P - 1 below the
    composition's order): both parts' flows are exact, so the composition keeps its order in s.
    `start`: the call's start's time past the step's start (a nudge's). Returns (work, ok)."""
    kind, p = X[0, X_MK], X[0, X_MP]
    sa, sb = 0.0, 1.0
    if kind == MAP_START:
        big, u = X[0, X_MH], X[0, X_MU]
        sa = (max(u + start, 0.0) / big) ** (1.0 / p)
        sb = (max(u + start + h, 0.0) / big) ** (1.0 / p)
        runs = int(math.ceil(abs(sb - sa) * p * big / X[0, X_MD]))
    else:
        runs = int(math.ceil(p * abs(h) / X[0, X_MD]))
    # Near an end the step's own length sets the map's scale in s, not the phase's step: its
    # error goes as (the change of velocity over it) / runs^order, and that change as
    # (omega h)^2.5 (with Hertz's dashpot, ~ delta^(1/4), as (omega h)^1.25): at least
    # (omega dt)^(-3/4) runs (damped (omega dt)^-1) bring it to a regular step's (omega dt)^7.
    least = (0.75 if p > 2.0 else 0.5) * p * (X[0, X_MD] / X[0, X_MR]) ** (-1.0 if p > 2.0 else -0.75)
    runs = max(runs, int(math.ceil(least)), 1)
    n = weights.shape[0]
    total = runs * n
    sigma = 0.0
    first = offset(X, kind, sa, sb, h, 0.5 * weights[0] / runs)[0]
    work, ok = kicks(X, C, CI, na, nc, 0.0, first, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
    for k in range(total):
        w = weights[k % n] / runs
        mid, rate = offset(X, kind, sa, sb, h, sigma + 0.5 * w)
        drift(X, C, CI, na, nc, rate * w, WP, grav, fl)
        end = offset(X, kind, sa, sb, h, sigma + w)[0]
        opening = 0.0
        if k + 1 < total:
            opening = offset(X, kind, sa, sb, h, sigma + w + 0.5 * weights[(k + 1) % n] / runs)[0] - end
        done, good = kicks(X, C, CI, na, nc, end - mid, opening, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
        work += done
        ok = ok and good
        sigma += w
    return work, ok
