"""Friction forces of an island's contacts for their modes: slide, mu F_n against the slip
(`slide_direction`); band, none; stick, the force that holds the slip on the band's edge,
solved for all stuck contacts together (`hold`: a stuck contact's hold force depends on its
neighbours'). `friction` applies them all.
"""

from __future__ import annotations

import math

from collide.engine.event.contact import (
    add_force,
    cap,
    dashpots,
    planar_velocity_terms,
    response,
    set_basis,
    slip,
    slip_rate,
)
from collide.engine.event.spring import spring_force
from collide.engine.jit import jit_call, jit_inline
from collide.engine.layout import (
    C_B,
    C_EPS,
    C_FF,
    C_GV,
    C_HELD,
    C_LIF,
    C_LIS,
    C_LJF,
    C_LJS,
    C_N,
    CI_I,
    CI_J,
    CI_MODE,
    FL_DAMPED,
    FL_PLANAR,
    FL_SEED,
    FL_SPIN,
    NO,
    SLIDE,
    SPRING,
    STICK,
    X_A,
    X_F,
    X_II,
    X_IM,
    X_L,
    X_SF,
    X_SL,
    X_T,
    YES,
)
from collide.engine.numerics import factor, solve_factored


@jit_inline
def _share(CI, c, a):
    """+1 if body a is contact c's first body, -1 if its second, 0 if neither."""
    if CI[c, CI_I] == a:
        return 1.0
    if CI[c, CI_J] == a:
        return -1.0
    return 0.0


@jit_inline
def couple_block(X, C, CI, c, d, a, spin, rows, A, row, col):
    """Add to A[row:row+rows, col:col+rows] what a friction force along d's tangents does to c's slip
    rate along c's tangents through their shared body a: a force f on it (sign s_d) moves it by
    s_d f / m_a and turns it by l_d (n_d x f) / I_a; c's slip sees s_c times the first and
    l_c (turn x n_c) of the second."""
    sc, sd = _share(CI, c, a), _share(CI, d, a)
    lc = C[c, C_LIS] if sc > 0 else C[c, C_LJS]
    ld = C[d, C_LIF] if sd > 0 else C[d, C_LJF]
    im, ii = X[a, X_IM], X[a, X_II]
    ncx, ncy, ncz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    ndx, ndy, ndz = C[d, C_N], C[d, C_N + 1], C[d, C_N + 2]
    if rows == 1:
        # In the plane each tangent is z x n and (n_d x e_d) x n_c is e_c: the block is
        # s_c s_d (n_c . n_d) / m_a + l_c l_d / I_a (a fifth of the general sums' work).
        A[row, col] += sc * sd * im * (ncx * ndx + ncy * ndy) + (lc * ii * ld if spin else 0.0)
        return
    for beta in range(rows):
        ex, ey, ez = C[d, C_B + 3 * beta], C[d, C_B + 3 * beta + 1], C[d, C_B + 3 * beta + 2]
        rx, ry, rz = sc * sd * im * ex, sc * sd * im * ey, sc * sd * im * ez
        if spin:
            k = lc * ii * ld
            # (n_d x e) x n_c
            tx, ty, tz = ndy * ez - ndz * ey, ndz * ex - ndx * ez, ndx * ey - ndy * ex
            rx += k * (ty * ncz - tz * ncy)
            ry += k * (tz * ncx - tx * ncz)
            rz += k * (tx * ncy - ty * ncx)
        for alpha in range(rows):
            A[row + alpha, col + beta] += (rx * C[c, C_B + 3 * alpha] + ry * C[c, C_B + 3 * alpha + 1]
                                           + rz * C[c, C_B + 3 * alpha + 2])


@jit_inline
def hold_matrix(X, C, CI, stuck, m, A, piv, spin, rows, seed):
    """Build and factor W (rows m x rows m) for the stuck contacts: block (c, d) is the rate of
    change of c's slip per unit friction force at d; a contact's own block is K times the
    identity (`response`), and contacts couple only through a body they share. `rows`: tangents
    per contact, 1 in the z = 0 plane (the e2 = z rows are zero there: W is block diagonal, and
    z holds no force). W is symmetric where the slip and force levers are one (not the seed's
    lever): then only its lower triangle is built, and factored by Cholesky. False if
    singular."""
    n = rows * m
    for r in range(n):
        for col in range(n if seed else r + 1):
            A[r, col] = 0.0
    for p in range(m):
        c = stuck[p]
        ci, cj = CI[c, CI_I], CI[c, CI_J]
        k = response(X, C, CI, c, spin)
        for alpha in range(rows):
            A[rows * p + alpha, rows * p + alpha] = k
        for q in range(m if seed else p):
            if q == p:
                continue
            d = stuck[q]
            for side in range(2):
                a = CI[d, CI_I] if side == 0 else CI[d, CI_J]
                if a >= 0 and (a == ci or a == cj):
                    couple_block(X, C, CI, c, d, a, spin, rows, A, rows * p, rows * q)
    return factor(A, piv, n, not seed)


@jit_call
def hold(X, C, CI, stuck, m, A, b, spin, seed, planar, fresh, fa, la):
    """Solve W f = b for the stuck contacts `stuck[:m]` (b in tangent coordinates, 2 per contact,
    and in the plane 1: the e1 = z x n one; see `hold_matrix`); with `fresh` W is built and
    factored here, else the factors in A from the last call at this geometry and these modes are
    used. Adds the forces (as accelerations) to columns (fa, la); they are also left in b.
    Returns False if W is singular."""
    piv = stuck[stuck.shape[0] // 3:]  # `stuck` holds the stuck contacts, then W's row swaps
    if planar:
        # In the plane W is m x m (its z rows hold nothing): an eighth of the factoring.
        if m == 1:
            b[0] /= response(X, C, CI, stuck[0], spin)
        else:
            if fresh and not hold_matrix(X, C, CI, stuck, m, A, piv, spin, 1, seed):
                return False
            solve_factored(A, piv, b, m, not seed)
        for k in range(m):
            c = stuck[k]
            add_force(X, C, CI, c, b[k] * C[c, C_B], b[k] * C[c, C_B + 1], 0.0, fa, la, spin, planar)
        return True
    if m == 1:
        k = response(X, C, CI, stuck[0], spin)
        b[0] /= k
        b[1] /= k
    else:
        if fresh and not hold_matrix(X, C, CI, stuck, m, A, piv, spin, 2, seed):
            return False
        solve_factored(A, piv, b, 2 * m, not seed)
    for k in range(m):
        c = stuck[k]
        f1, f2 = b[2 * k], b[2 * k + 1]
        add_force(X, C, CI, c, f1 * C[c, C_B] + f2 * C[c, C_B + 3], f1 * C[c, C_B + 1] + f2 * C[c, C_B + 4],
                  f1 * C[c, C_B + 2] + f2 * C[c, C_B + 5], fa, la, spin, planar)
    return True


@jit_inline
def slide_direction(X, C, CI, c, vc, wc, spin, span, planar):
    """The slip that sliding friction opposes at contact c, for the velocities in (vc, wc).

    `span` > 0: those velocities already hold this contact's own friction impulse over `span`
    seconds (C_FF), which is taken back out: the implicit kick's slip at the end is parallel to the
    slip before the contact's own impulse (s1 = s0 - span K mu F_n s1 / |s1|), so the direction is
    exact whatever the step (a fixed point on it would diverge once span K mu F_n > |slip|).

    While the slip's component a along the way it slid at the step's start (held) is above eps / 2,
    that slip itself, so friction follows the slip as it turns. At or below -eps / 2 the slip
    reversed: the slip's reverse. That is the implicit kick's other root, the one on the held
    side: where a substep's span is negative (kahan6) and the slip small (just after a stick to
    slide, where its direction is slaved to the other forces on a time scale of eps over its rate)
    the kick's slip before its own impulse points backwards, and its reverse is the direction the
    slide takes there; holding the direction at the step's start instead lost the order and made
    the error erratic in the step. Between, a C^1 blend: held times phi(a) = eps / 4 + a^2 / eps
    plus the rest of the slip times a / phi(a). In the plane all of these are the held side of
    the tangent z x n, whatever the slip: that, without the slip."""
    if planar:
        tx, ty = -C[c, C_N + 1], C[c, C_N]
        if tx * C[c, C_HELD] + ty * C[c, C_HELD + 1] < 0.0:
            return -tx, -ty, 0.0
        return tx, ty, 0.0
    sx, sy, sz = slip(X, C, CI, c, vc, wc, spin, False)
    nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    if span != 0.0:
        k = span * response(X, C, CI, c, spin)
        sx, sy, sz = sx - k * C[c, C_FF], sy - k * C[c, C_FF + 1], sz - k * C[c, C_FF + 2]
        # The impulse taken out acts in the tangent plane only. A normal part left in (C_FF from
        # another geometry, round-off) would come back amplified by span K mu F_n / |slip| at
        # every fixed-point pass of the kick, which exceeds 1 where a substep's span is
        # negative (kahan6) and the slip small: the friction turned into the normal and the
        # kick never settled (a symmetric rack's middle ball got spun).
        sn = sx * nx + sy * ny + sz * nz
        sx, sy, sz = sx - sn * nx, sy - sn * ny, sz - sn * nz
    hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
    a = sx * hx + sy * hy + sz * hz
    eps = C[c, C_EPS]
    if a >= 0.5 * eps:
        return sx, sy, sz
    if a <= -0.5 * eps:
        return -sx, -sy, -sz
    phi = 0.25 * eps + a * a / max(eps, 1e-300)
    rest = a / phi
    sx, sy, sz = phi * hx + rest * (sx - a * hx), phi * hy + rest * (sy - a * hy), phi * hz + rest * (sz - a * hz)
    sn = sx * nx + sy * ny + sz * nz
    return sx - sn * nx, sy - sn * ny, sz - sn * nz


@jit_call
def friction(X, C, CI, na, nc, vc, wc, stuck, A, b, fl, span, fresh):
    """Friction forces (C_FF, on body i) of every contact at the velocities in columns (vc, wc),
    by mode, and their accelerations (X_F, X_L); X_A holds everything else's. A sticking tangential
    spring's (SPRING) is its force at these velocities, with the slides'. Stuck contacts'
    slips stop changing: W f = -G, with G their slip rates under every other force. `span`: the
    velocities already hold the forces now in C_FF over that many seconds (see
    `slide_direction`); 0 when they hold none. `fresh`: the stuck contacts' matrix must be built
    (a new geometry or new modes), else the last one is reused. The slides' own (X_SF, X_SL)
    are kept apart: in the plane they are mu F_n on the held side whatever the velocities, and
    a kick's later passes there change only the stuck contacts' (see `repull`). The restitution's
dashpots (`dashpots`) are velocity-dependent forces too: they go in first, with the slides'."""
    spin, seed, planar = fl[FL_SPIN], fl[FL_SEED], fl[FL_PLANAR] == YES
    for a in range(na):
        for d in range(3):
            X[a, X_SF + d] = 0.0
            X[a, X_SL + d] = 0.0
    if fl[FL_DAMPED]:
        # The dashpots first: they set the normal forces that cap the friction.
        dashpots(X, C, CI, nc, vc, X_SF)
    m = 0
    for c in range(nc):
        if CI[c, CI_MODE] == SLIDE:
            sx, sy, sz = slide_direction(X, C, CI, c, vc, wc, spin, span, planar)
            # In the plane the direction is the unit tangent z x n.
            mag = 1.0 if planar else math.sqrt(sx * sx + sy * sy + sz * sz)
            C[c, C_FF] = 0.0
            C[c, C_FF + 1] = 0.0
            C[c, C_FF + 2] = 0.0
            if mag > 0.0:
                f = -cap(C, CI, c) / mag
                C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2] = f * sx, f * sy, f * sz
                add_force(X, C, CI, c, f * sx, f * sy, f * sz, X_SF, X_SL, spin, planar)
        elif CI[c, CI_MODE] == SPRING:
            # A sticking tangential spring: its force at these velocities (its dashpot's share
            # follows them, as a normal dashpot's does).
            f = spring_force(X, C, CI, c, vc, wc, spin)[0]
            fx, fy = -f * C[c, C_N + 1], f * C[c, C_N]
            C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2] = fx, fy, 0.0
            add_force(X, C, CI, c, fx, fy, 0.0, X_SF, X_SL, spin, planar)
        else:
            C[c, C_FF] = 0.0
            C[c, C_FF + 1] = 0.0
            C[c, C_FF + 2] = 0.0
            if CI[c, CI_MODE] == STICK:
                stuck[m] = c
                m += 1
    for a in range(na):
        for d in range(3):
            X[a, X_F + d] = X[a, X_SF + d]
            X[a, X_L + d] = X[a, X_SL + d]
            X[a, X_T + d] = X[a, X_A + d] + X[a, X_SF + d]
    if m == 0:
        return True
    for k in range(m):
        c = stuck[k]
        if fresh:
            set_basis(C, c, planar)  # else the one W was built in, at this geometry
        if planar:
            # The accelerations' part and the velocity terms apart: a later pass of the kick
            # changes only the second (see `repull`).
            gx, gy, gz = slip_rate(X, C, CI, c, vc, wc, X_T, X_L, spin, seed, NO, planar)
            vx, vy = planar_velocity_terms(X, C, CI, c, vc, wc, spin, seed)
            C[c, C_GV] = vx * C[c, C_B] + vy * C[c, C_B + 1]
            b[k] = -(gx * C[c, C_B] + gy * C[c, C_B + 1] + C[c, C_GV])
        else:
            gx, gy, gz = slip_rate(X, C, CI, c, vc, wc, X_T, X_L, spin, seed, YES, planar)
            b[2 * k] = -(gx * C[c, C_B] + gy * C[c, C_B + 1] + gz * C[c, C_B + 2])
            b[2 * k + 1] = -(gx * C[c, C_B + 3] + gy * C[c, C_B + 4] + gz * C[c, C_B + 5])
    if not hold(X, C, CI, stuck, m, A, b, spin, seed, planar, fresh, X_F, X_L):
        return False
    for k in range(m):
        c = stuck[k]
        if planar:
            C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2] = b[k] * C[c, C_B], b[k] * C[c, C_B + 1], 0.0
            continue
        f1, f2 = b[2 * k], b[2 * k + 1]
        for d in range(3):
            C[c, C_FF + d] = f1 * C[c, C_B + d] + f2 * C[c, C_B + 3 + d]
    return True


@jit_inline
def repull(X, C, CI, nc, stuck, A, b, fl, vc, wc):
    """A later pass of a kick's fixed point in the plane, at the velocities in (vc, wc): there
    the slides' forces and the stuck contacts' accelerations part stay (a geometry's), and only
    the hold rates' velocity terms (C_GV) change. Their change is solved with the factors the
    first pass left in A, and its forces added to C_FF and (X_F, X_L): a `friction` pass's
    numbers to round-off, without its passes over every contact and body."""
    spin, seed = fl[FL_SPIN], fl[FL_SEED]
    m = 0
    for c in range(nc):
        if CI[c, CI_MODE] == STICK:
            m += 1
    for k in range(m):
        c = stuck[k]
        vx, vy = planar_velocity_terms(X, C, CI, c, vc, wc, spin, seed)
        along = vx * C[c, C_B] + vy * C[c, C_B + 1]
        b[k] = C[c, C_GV] - along
        C[c, C_GV] = along
    if m == 1:
        b[0] /= response(X, C, CI, stuck[0], spin)
    elif m > 1:
        solve_factored(A, stuck[stuck.shape[0] // 3:], b, m, not seed)
    for k in range(m):
        c = stuck[k]
        fx, fy = b[k] * C[c, C_B], b[k] * C[c, C_B + 1]
        C[c, C_FF] += fx
        C[c, C_FF + 1] += fy
        add_force(X, C, CI, c, fx, fy, 0.0, X_F, X_L, spin, True)
