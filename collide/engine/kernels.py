"""The compiled engine: contact mechanics, friction modes, events, islands and the run loop.

One module of small numba functions over a few packed arrays, because numba's compile time
grows with the number of arguments, array accesses and specialisations (measured: a function
of 200 array statements compiles in 10-20 s here; the same code split and packed, in a tenth
of that) and its cache loads in proportion to the code. Everything is 3D inside: a 1D or 2D
scene lives in the z = 0 plane with spin about z, so one path serves every dimension.

Tables (float64 unless noted; columns named by the constants below):

====  ===========  ========================================================================
name  shape        rows, columns
====  ===========  ========================================================================
G     (N, NG)      bodies: state s, v, w, q at base time tb; dissipated work share; 1/m,
                   1/I, radius, m, I, material
GI    (N, 2) int   bodies: local row in the running island (-1), last knot row
X     (A, NX)      an island's bodies: state, start state, accelerations, scratch; constants
XI    (A,) int     an island's bodies: global row
C     (K, NC)      an island's engaged contacts: normal, overlap, arms, normal force,
                   parameters, held slip direction, friction force, tangent basis
CI    (K, NCI) int contacts: local i, local j (or -1 - wall), global i, global j, mode, ...
Q     (K, 3) int   an island's candidate contacts: global i, j (or -1 - wall), engaged
QF    (K, NQF)     candidates: touching distance, overlaps and rates at trial ends
E     (2K, NE)     friction mode events: values and rates at a step's start, a trial's end
                   and the longest trial at whose end none had crossed
WP    (W, 6)       walls: a point and the outward unit normal
====  ===========  ========================================================================

Friction (the report's law as dt -> 0; README "Friction as events"): slide: mu F_n against the
slip; band: none; stick: the force that holds the slip on the band's edge, for all stuck
contacts of an island together (a stuck contact's hold force depends on its neighbours'). Slide
and stick forces depend on the velocities, so a substep's closing kick is implicit (a fixed
point, a few iterations) and the next one's opening kick explicit: each substep is symmetric
and the compositions keep their order in every mode, in 3D as in 2D.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.jit import jit, jit_inline
from collide.engine.layout import (
    AIM,
    BAND,
    C_B,
    C_DELTA,
    C_DIST,
    C_EPS,
    C_FF,
    C_FN,
    C_GV,
    C_HELD,
    C_INV,
    C_K,
    C_LIF,
    C_LIS,
    C_LJF,
    C_LJS,
    C_MU,
    C_N,
    C_REACH,
    CI_EDGE,
    CI_FLIPPED,
    CI_GI,
    CI_GJ,
    CI_GRAZE,
    CI_I,
    CI_J,
    CI_MODE,
    CI_Q,
    CI_RETRIED,
    CN_IVALS,
    CN_KNOTS,
    CN_OPEN,
    CN_RECS,
    CONTRACTION_SAFETY,
    CREEP_LIMIT,
    DIP_SAMPLES,
    E_FORCED,
    E_R0,
    E_R1,
    E_RC,
    E_V0,
    E_V1,
    E_VC,
    EDGE_TOL,
    ENERGY,
    EPS64,
    EVENT_RES,
    F_DT_MIN,
    F_MAX_FORCE,
    F_MAX_OVERLAP,
    F_STATUS_A,
    F_STATUS_B,
    F_STATUS_T,
    F_UNLOCATED_T,
    FIXED_POINT,
    FL_AUTO,
    FL_DIM,
    FL_FRICTION,
    FL_MAXSTEPS,
    FL_PLANAR,
    FL_RECORD,
    FL_SEED,
    FL_SPIN,
    FL_TURNS,
    FLIP,
    FLIP_SAFETY,
    FLIP_SHARE,
    FORESEE_SPAN,
    FP_DT,
    FP_END_SLOW,
    FP_EVENT_TOL,
    FP_NOW,
    FP_NOW_STEPS,
    FP_OMEGA_H,
    FP_SCALE,
    FP_SLOW,
    FP_TAIL,
    FP_TEND,
    G_I,
    G_II,
    G_IM,
    G_M,
    G_MAT,
    G_Q,
    G_R,
    G_S,
    G_TB,
    G_V,
    G_W,
    G_WK,
    GI_KNOT,
    GI_LOC,
    GRAZE_SHARE,
    ISLAND_SLACK,
    K_A,
    K_AN,
    K_BODY,
    K_FREE,
    K_Q,
    K_S,
    K_T,
    K_V,
    K_W,
    K_WORK,
    KAHAN6_ERROR,
    LATE,
    LATE_SAFETY,
    LONE_WINDOW_STEPS,
    MAX_RETRIES,
    MAXSTEPS,
    MODE_TOL,
    NC,
    NCI,
    NE,
    NF,
    NG,
    NK,
    NO,
    NO_CONTACT_TAIL,
    NONFINITE,
    NQF,
    NR,
    NS,
    NUDGE_SHARE,
    NX,
    OK,
    Q_ENG,
    Q_I,
    Q_J,
    QF_D0,
    QF_D1,
    QF_DB,
    QF_DP,
    QF_R0,
    QF_R1,
    QF_RB,
    QF_REACH,
    QF_RP,
    R_DELTA,
    R_FN,
    R_FX,
    R_FY,
    R_FZ,
    R_I,
    R_J,
    R_MODE,
    R_T,
    S_ATTEMPTS,
    S_CONTACTS,
    S_JUMPS,
    S_REST,
    S_RETRIES,
    S_STATUS,
    S_STEPS,
    S_UNLOCATED,
    S_WINDOWS,
    SHORT_SHARE,
    SINGULAR,
    SIXTH7,
    SIXTH7_ERROR,
    SLIDE,
    STALL,
    STALL_LIMIT,
    STICK,
    STICK_SCALE,
    STIFF_SLIDE_IMPULSES,
    STIFF_SLIDE_POWER,
    STIFF_SLIDE_SPAN,
    SUZUKI,
    SUZUKI_ERROR,
    TINY_LIMIT,
    TOUCH_TOL,
    TP_EPS,
    TP_K,
    TP_MU,
    TRIALS,
    V_END,
    V_I,
    V_J,
    V_START,
    VERLET,
    VERLET_ERROR,
    WINDOW_SAFETY,
    WINDOW_STEPS,
    X_A,
    X_F,
    X_F0,
    X_FO,
    X_FP,
    X_HP,
    X_I,
    X_II,
    X_IM,
    X_L,
    X_L0,
    X_LP,
    X_M,
    X_Q,
    X_R,
    X_S,
    X_S0,
    X_SF,
    X_SL,
    X_T,
    X_UA,
    X_UL,
    X_V,
    X_V0,
    X_V1,
    X_VB,
    X_W,
    X_W0,
    X_W1,
    X_WB,
    YES,
    YOSHIDA,
    YOSHIDA_ERROR,
)

# ---------------------------------------------------------------------------------------------
# Contact mechanics of an island


@jit_inline
def geometry(X, C, CI, nc, WP, seed, fric):
    """Normals, overlaps, lever arms and spring forces of the engaged contacts at X's positions;
    with `fric`, the pairs' 1 / distance too (for the slip rates).

    Engaged contacts use the spring law unclamped, so that a substep straying just outside the
    contact sees a smooth force; the contact's start and end are located events."""
    for c in range(nc):
        i = CI[c, CI_I]
        j = CI[c, CI_J]
        r = X[i, X_R]
        if j >= 0:
            dx = X[j, X_S] - X[i, X_S]
            dy = X[j, X_S + 1] - X[i, X_S + 1]
            dz = X[j, X_S + 2] - X[i, X_S + 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if fric:
                C[c, C_INV] = 1.0 / dist
            C[c, C_N] = dx / dist
            C[c, C_N + 1] = dy / dist
            C[c, C_N + 2] = dz / dist
            delta = C[c, C_REACH] - dist
            # Equal springs in series share the overlap: each sphere is pressed by half of it.
            C[c, C_LIF] = r - 0.5 * delta
            C[c, C_LJF] = X[j, X_R] - 0.5 * delta
            C[c, C_LIS] = r if seed else C[c, C_LIF]
            C[c, C_LJS] = X[j, X_R] if seed else C[c, C_LJF]
        else:
            k = -1 - j
            dist = ((X[i, X_S] - WP[k, 0]) * WP[k, 3] + (X[i, X_S + 1] - WP[k, 1]) * WP[k, 4]
                    + (X[i, X_S + 2] - WP[k, 2]) * WP[k, 5])
            C[c, C_N] = -WP[k, 3]
            C[c, C_N + 1] = -WP[k, 4]
            C[c, C_N + 2] = -WP[k, 5]
            delta = r - dist
            C[c, C_LIF] = r - delta  # the wall is rigid: the sphere takes all of the overlap
            C[c, C_LJF] = 0.0
            C[c, C_LIS] = r if seed else C[c, C_LIF]
            C[c, C_LJS] = 0.0
        C[c, C_DELTA] = delta
        C[c, C_DIST] = dist
        C[c, C_FN] = C[c, C_K] * delta


@jit_inline
def springs(X, C, CI, na, nc, grav):
    """Accelerations X_A from the springs and gravity."""
    for a in range(na):
        for d in range(3):
            X[a, X_FO + d] = 0.0
    for c in range(nc):
        i = CI[c, CI_I]
        j = CI[c, CI_J]
        for d in range(3):
            f = C[c, C_FN] * C[c, C_N + d]
            X[i, X_FO + d] -= f
            if j >= 0:
                X[j, X_FO + d] += f
    for a in range(na):
        for d in range(3):
            X[a, X_A + d] = X[a, X_FO + d] * X[a, X_IM] + grav[d]


@jit_inline
def planar_relative(X, i, j, col):
    """The x, y parts of body i's column col (a velocity, an acceleration) less body j's (a wall
    has none)."""
    x, y = X[i, col], X[i, col + 1]
    if j >= 0:
        x -= X[j, col]
        y -= X[j, col + 1]
    return x, y


@jit_inline
def planar_levers(X, C, c, i, j, col):
    """l_i times body i's column col's z part (a spin, an angular acceleration), plus l_j times
    body j's, with contact c's slip levers."""
    z = C[c, C_LIS] * X[i, col + 2]
    if j >= 0:
        z += C[c, C_LJS] * X[j, col + 2]
    return z


@jit_inline
def slip(X, C, CI, c, vc, wc, spin, planar):
    """Slip of i's surface relative to j's (or the wall's) at contact c, at the velocities in
    columns vc, wc: P_t (v_i - v_j) + (l_i w_i + l_j w_j) x n, with the slip lever arms.
    `planar`: in the z = 0 plane (z parts and in-plane spins exactly zero), the same sums
    without their zero terms (the same numbers)."""
    i = CI[c, CI_I]
    j = CI[c, CI_J]
    nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    if planar:
        rx, ry = planar_relative(X, i, j, vc)
        rn = rx * nx + ry * ny
        sx, sy = rx - rn * nx, ry - rn * ny
        if spin:
            lz = planar_levers(X, C, c, i, j, wc)
            sx -= lz * ny
            sy += lz * nx
        return sx, sy, 0.0
    rx, ry, rz = X[i, vc], X[i, vc + 1], X[i, vc + 2]
    if j >= 0:
        rx -= X[j, vc]
        ry -= X[j, vc + 1]
        rz -= X[j, vc + 2]
    rn = rx * nx + ry * ny + rz * nz
    sx, sy, sz = rx - rn * nx, ry - rn * ny, rz - rn * nz
    if spin:
        li = C[c, C_LIS]
        lx, ly, lz = li * X[i, wc], li * X[i, wc + 1], li * X[i, wc + 2]
        if j >= 0:
            lj = C[c, C_LJS]
            lx += lj * X[j, wc]
            ly += lj * X[j, wc + 1]
            lz += lj * X[j, wc + 2]
        sx += ly * nz - lz * ny
        sy += lz * nx - lx * nz
        sz += lx * ny - ly * nx
    return sx, sy, sz


@jit_inline
def planar_velocity_terms(X, C, CI, c, vc, wc, spin, seed):
    """In the plane, the terms of contact c's slip rate that the velocities in (vc, wc) make (see
    `slip_rate`): the line of centres turning, -n' (n . (v_i - v_j)), and the arms shortening,
    (l_i' w_i + l_j' w_j) x n."""
    i, j = CI[c, CI_I], CI[c, CI_J]
    nx, ny = C[c, C_N], C[c, C_N + 1]
    rx, ry = planar_relative(X, i, j, vc)
    rn = rx * nx + ry * ny
    vx, vy = 0.0, 0.0
    if j >= 0:
        inv = C[c, C_INV]
        vx, vy = (rx - rn * nx) * inv * rn, (ry - rn * ny) * inv * rn
    if spin and not seed:
        ld = -0.5 * rn if j >= 0 else -rn
        pz = ld * X[i, wc + 2]
        if j >= 0:
            pz += ld * X[j, wc + 2]
        vx -= pz * ny
        vy += pz * nx
    return vx, vy


@jit_inline
def slip_rate(X, C, CI, c, vc, wc, ac, lc, spin, seed, velocity_terms, planar):
    """Rate of change of contact c's tangential slip at velocities (vc, wc) under linear and
    angular accelerations in columns (ac, lc); the hold rate G when those leave out stuck
    friction. Without `velocity_terms`, only the accelerations' part. `planar`: as `slip`
    (there L lies along z, normal to n: the turning term is zero).

    G = P_t (a_i - a_j) - n' (n . (v_i - v_j)) + (l_i' w_i + l_j' w_j) x n + (l_i alpha_i +
    l_j alpha_j) x n + (L . n)(n x n'), with L = l_i w_i + l_j w_j, the line of centres turning
    at n' = -P_t (v_i - v_j) / dist (a wall's normal does not turn), and with the contact lever
    the arms shortening as the overlap grows (pairs l' = -delta' / 2 each, a wall l' = -delta')."""
    i = CI[c, CI_I]
    j = CI[c, CI_J]
    nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    if planar:
        ax, ay = planar_relative(X, i, j, ac)
        an = ax * nx + ay * ny
        gx, gy = ax - an * nx, ay - an * ny
        if spin:
            pz = planar_levers(X, C, c, i, j, lc)  # (l_i alpha_i + l_j alpha_j) . z
            gx -= pz * ny
            gy += pz * nx
        if velocity_terms:
            vx, vy = planar_velocity_terms(X, C, CI, c, vc, wc, spin, seed)
            gx += vx
            gy += vy
        return gx, gy, 0.0
    ax, ay, az = X[i, ac], X[i, ac + 1], X[i, ac + 2]
    if j >= 0:
        ax -= X[j, ac]
        ay -= X[j, ac + 1]
        az -= X[j, ac + 2]
    an = ax * nx + ay * ny + az * nz
    gx, gy, gz = ax - an * nx, ay - an * ny, az - an * nz
    px, py, pz = 0.0, 0.0, 0.0  # l_i alpha_i + l_j alpha_j (+ l' w terms)
    li, lj = C[c, C_LIS], C[c, C_LJS]
    if spin:
        px, py, pz = li * X[i, lc], li * X[i, lc + 1], li * X[i, lc + 2]
        if j >= 0:
            px += lj * X[j, lc]
            py += lj * X[j, lc + 1]
            pz += lj * X[j, lc + 2]
    if velocity_terms:
        rx, ry, rz = X[i, vc], X[i, vc + 1], X[i, vc + 2]
        if j >= 0:
            rx -= X[j, vc]
            ry -= X[j, vc + 1]
            rz -= X[j, vc + 2]
        rn = rx * nx + ry * ny + rz * nz
        tx, ty, tz = 0.0, 0.0, 0.0  # n'
        if j >= 0:
            inv = C[c, C_INV]
            tx, ty, tz = -(rx - rn * nx) * inv, -(ry - rn * ny) * inv, -(rz - rn * nz) * inv
            gx -= tx * rn
            gy -= ty * rn
            gz -= tz * rn
        if spin:
            lx, ly, lz = li * X[i, wc], li * X[i, wc + 1], li * X[i, wc + 2]
            if j >= 0:
                lx += lj * X[j, wc]
                ly += lj * X[j, wc + 1]
                lz += lj * X[j, wc + 2]
            if not seed:
                # Arms shorten as the overlap grows: pairs by half its rate each, a wall by all.
                ld = -0.5 * rn if j >= 0 else -rn
                px += ld * X[i, wc]
                py += ld * X[i, wc + 1]
                pz += ld * X[i, wc + 2]
                if j >= 0:
                    px += ld * X[j, wc]
                    py += ld * X[j, wc + 1]
                    pz += ld * X[j, wc + 2]
            ln = lx * nx + ly * ny + lz * nz
            gx += ln * (ny * tz - nz * ty)
            gy += ln * (nz * tx - nx * tz)
            gz += ln * (nx * ty - ny * tx)
    if spin:
        gx += py * nz - pz * ny
        gy += pz * nx - px * nz
        gz += px * ny - py * nx
    return gx, gy, gz


@jit_inline
def response(X, C, CI, c, spin):
    """K: the change of contact c's slip per unit tangential impulse on it, the same in every
    tangent direction for spheres: 1/m_i + 1/m_j + l_i a_i / I_i + l_j a_j / I_j."""
    i = CI[c, CI_I]
    j = CI[c, CI_J]
    k = X[i, X_IM]
    if spin:
        k += C[c, C_LIS] * C[c, C_LIF] * X[i, X_II]
    if j >= 0:
        k += X[j, X_IM]
        if spin:
            k += C[c, C_LJS] * C[c, C_LJF] * X[j, X_II]
    return k


@jit_inline
def add_force(X, C, CI, c, fx, fy, fz, ac, lc, spin, planar):
    """Add to columns (ac, lc) the accelerations of friction force f on i (and -f on j) at
    contact c: torques l_i (n x f) on i and l_j (n x f) on j (both arms reach the contact).
    `planar`: f and n in the z = 0 plane, the torque along z (as `slip`)."""
    i = CI[c, CI_I]
    j = CI[c, CI_J]
    if planar:
        X[i, ac] += fx * X[i, X_IM]
        X[i, ac + 1] += fy * X[i, X_IM]
        if j >= 0:
            X[j, ac] -= fx * X[j, X_IM]
            X[j, ac + 1] -= fy * X[j, X_IM]
        if spin:
            cz = C[c, C_N] * fy - C[c, C_N + 1] * fx
            X[i, lc + 2] += C[c, C_LIF] * X[i, X_II] * cz
            if j >= 0:
                X[j, lc + 2] += C[c, C_LJF] * X[j, X_II] * cz
        return
    X[i, ac] += fx * X[i, X_IM]
    X[i, ac + 1] += fy * X[i, X_IM]
    X[i, ac + 2] += fz * X[i, X_IM]
    if j >= 0:
        X[j, ac] -= fx * X[j, X_IM]
        X[j, ac + 1] -= fy * X[j, X_IM]
        X[j, ac + 2] -= fz * X[j, X_IM]
    if spin:
        nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
        cx, cy, cz = ny * fz - nz * fy, nz * fx - nx * fz, nx * fy - ny * fx
        s = C[c, C_LIF] * X[i, X_II]
        X[i, lc] += s * cx
        X[i, lc + 1] += s * cy
        X[i, lc + 2] += s * cz
        if j >= 0:
            s = C[c, C_LJF] * X[j, X_II]
            X[j, lc] += s * cx
            X[j, lc + 1] += s * cy
            X[j, lc + 2] += s * cz


@jit_inline
def set_basis(C, c, planar):
    """Two unit tangents (e1, e2 = n x e1) of contact c's normal. In the z = 0 plane only e1 =
    z x n, a 2D scene's tangent: a unit vector as n is, to round-off (normalising it cost a
    square root and three divisions per stuck contact per solve); e2 = z holds no force there."""
    nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    if planar:
        C[c, C_B], C[c, C_B + 1], C[c, C_B + 2] = -ny, nx, 0.0
        return
    if abs(nz) < 0.9:
        ex, ey, ez = -ny, nx, 0.0
    else:
        ex, ey, ez = 0.0, nz, -ny
    m = math.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / m, ey / m, ez / m
    C[c, C_B], C[c, C_B + 1], C[c, C_B + 2] = ex, ey, ez
    C[c, C_B + 3], C[c, C_B + 4], C[c, C_B + 5] = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex


@jit_inline
def factor(A, piv, m, symmetric):
    """Factor A[:m, :m] in place: `symmetric` (and positive definite, as W is where it is
    symmetric) as L D L^T, L unit lower triangular below the diagonal and 1 / D on it, half the
    work of LU and no pivoting (Cholesky: 0.21 against 0.38 us at m = 10, 0.68 against 1.57 at
    16), and no square root, nor a division in the solves, whose chains wait on each; the upper
    triangle holds L D while factoring. Else LU with partial pivoting (row swaps in
    piv). False if singular."""
    if symmetric:
        for k in range(m):
            for p in range(k):
                s = A[k, p]
                for q in range(p):
                    s -= A[q, k] * A[p, q]
                A[p, k] = s  # L[k, p] D[p]
            d = A[k, k]
            for p in range(k):
                lkp = A[p, k] * A[p, p]
                A[k, p] = lkp
                d -= A[p, k] * lkp
            if not d > 0.0:
                return False
            A[k, k] = 1.0 / d
        return True
    for k in range(m):
        p = k
        for r in range(k + 1, m):
            if abs(A[r, k]) > abs(A[p, k]):
                p = r
        piv[k] = p
        if A[p, k] == 0.0:
            return False
        if p != k:
            for col in range(m):
                A[k, col], A[p, col] = A[p, col], A[k, col]
        for r in range(k + 1, m):
            A[r, k] /= A[k, k]
            f = A[r, k]
            if f != 0.0:
                for col in range(k + 1, m):
                    A[r, col] -= f * A[k, col]
    return True


@jit_inline
def solve_factored(A, piv, b, m, symmetric):
    """Solve with the factors from `factor`; b holds the solution."""
    if symmetric:
        for k in range(m):
            s = b[k]
            for col in range(k):
                s -= A[k, col] * b[col]
            b[k] = s
        for k in range(m - 1, -1, -1):
            s = b[k] * A[k, k]
            for r in range(k + 1, m):
                s -= A[r, k] * b[r]
            b[k] = s
        return
    for k in range(m):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for k in range(m):
        s = b[k]
        for col in range(k):
            s -= A[k, col] * b[col]
        b[k] = s
    for k in range(m - 1, -1, -1):
        s = b[k]
        for col in range(k + 1, m):
            s -= A[k, col] * b[col]
        b[k] = s / A[k, k]


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


@jit_inline
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


@jit_inline
def friction(X, C, CI, na, nc, vc, wc, stuck, A, b, fl, span, fresh):
    """Friction forces (C_FF, on body i) of every contact at the velocities in columns (vc, wc),
    by mode, and their accelerations (X_F, X_L); X_A holds everything else's. Stuck contacts'
    slips stop changing: W f = -G, with G their slip rates under every other force. `span`: the
    velocities already hold the forces now in C_FF over that many seconds (see
    `slide_direction`); 0 when they hold none. `fresh`: the stuck contacts' matrix must be built
    (a new geometry or new modes), else the last one is reused. The slides' own (X_SF, X_SL)
    are kept apart: in the plane they are mu F_n on the held side whatever the velocities, and
    a kick's later passes there change only the stuck contacts' (see `repull`)."""
    spin, seed, planar = fl[FL_SPIN], fl[FL_SEED], fl[FL_PLANAR] == YES
    for a in range(na):
        for d in range(3):
            X[a, X_SF + d] = 0.0
            X[a, X_SL + d] = 0.0
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
                f = -C[c, C_MU] * C[c, C_FN] / mag
                C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2] = f * sx, f * sy, f * sz
                add_force(X, C, CI, c, f * sx, f * sy, f * sz, X_SF, X_SL, spin, planar)
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
    Taken once a step: within one it changes by a share of the step's impulse, which
    CONTRACTION_SAFETY covers (computed at each kick, it took three square roots per stuck
    contact every time)."""
    pull = 0.0
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
    return pull


@jit_inline
def kick_start(CI, nc, planar):
    """How a step's closing kicks start, from its modes: (warm, one pass). Warm: from the last
    kick's friction (C_FF and its accelerations), which differs from this one's by a substep's
    change, a pass fewer than from none; not with a slide out of the plane, whose kick can have
    two roots (see slide_direction): a start off the one the kick's own impulse defines can
    settle on the other (measured: a random 3D scene stopped converging with the tolerance).
    One pass: in the plane a slide's friction is mu F_n on the held side whatever the
    velocities, so with nothing stuck one pass is the fixed point."""
    warm, one_pass = True, planar
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
            if it > 0 and planar:
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


@jit_inline
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
def turn(q, w0, w1, w2, tau, planar):
    """Orientation q (4,) after turning at constant w for tau seconds (exact for a free sphere);
    in the plane q[0] is the angle about z."""
    if planar:
        q[0] += w2 * tau
        return
    x2 = 0.25 * tau * tau * (w0 * w0 + w1 * w1 + w2 * w2)  # (half the angle turned)^2
    if x2 == 0.0:
        return
    # A small turn (every body, every DEM step): cos and sin(x)/x by their series, exact to
    # round-off (the terms left out are below 3e-17), without sqrt, sin, cos and a division,
    # which were a tenth of the DEM kernel's time; to x^4 for the smallest (a DEM step's).
    if x2 < 1e-5:
        dw = 1.0 - x2 * (1.0 / 2.0 - x2 * (1.0 / 24.0))
        s = 0.5 * tau * (1.0 - x2 * (1.0 / 6.0 - x2 * (1.0 / 120.0)))
    elif x2 < 0.01:
        dw = 1.0 - x2 * (1.0 / 2.0 - x2 * (1.0 / 24.0 - x2 * (1.0 / 720.0 - x2 * (1.0 / 40320.0))))
        s = 0.5 * tau * (1.0 - x2 * (1.0 / 6.0 - x2 * (1.0 / 120.0 - x2 * (1.0 / 5040.0 - x2 * (1.0 / 362880.0)))))
    else:
        rate = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        half = 0.5 * rate * tau
        s = math.sin(half) / rate
        dw = math.cos(half)
    dx, dy, dz = s * w0, s * w1, s * w2
    a, b, c, d = q[0], q[1], q[2], q[3]
    q[0] = dw * a - dx * b - dy * c - dz * d
    q[1] = dw * b + dx * a + dy * d - dz * c
    q[2] = dw * c - dx * d + dy * a + dz * b
    q[3] = dw * d + dx * c - dy * b + dz * a


@jit_inline
def step(X, C, CI, na, nc, h, weights, WP, grav, stuck, A, b, fl, restart, exact, pull_rate, warm, one_pass):
    """One step of h from the start state (X_S0..., its friction accelerations in X_F0, X_L0), or
    with `restart` NO from the state now in (X_S...), its geometry in C and X_A and its friction
    in (X_F, X_L) (a trial's end, whose mode values solved it there): a symmetric composition of
    Verlet (kick-drift-kick) substeps gamma h (`weights`); the kicks between two substeps share
    one geometry. Stuck slips go back on the band's edge only once the step is taken (`settle`,
    by the event search): a trial's end is off it by the kicks' fixed-point tolerance. The end
    state is left in (X_S...) with its geometry in C and its accelerations in X_A, X_F. `exact`,
    `pull_rate`, `warm`, `one_pass`: the kicks' (see `kick`), the same for every trial of a
    step. Returns (work, ok)."""
    spin, fric, seed, planar = fl[FL_SPIN], fl[FL_FRICTION], fl[FL_SEED], fl[FL_PLANAR]
    if restart:
        for a in range(na):
            for d in range(13):
                X[a, X_S + d] = X[a, X_S0 + d]
            for d in range(3 if fric else 0):
                X[a, X_F + d], X[a, X_L + d] = X[a, X_F0 + d], X[a, X_L0 + d]
        geometry(X, C, CI, nc, WP, seed, fric)
        springs(X, C, CI, na, nc, grav)
    n = weights.shape[0]
    work = 0.0
    ok = True
    first = 0.5 * weights[0] * h
    if fric:
        work, ok = kick(X, C, CI, na, nc, 0.0, first, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
    else:
        for a in range(na):
            for d in range(3):
                X[a, X_V + d] += first * X[a, X_A + d]
    for k in range(n):
        hk = weights[k] * h
        for a in range(na):
            for d in range(3):
                X[a, X_S + d] += X[a, X_V + d] * hk
            if spin:
                turn(X[a, X_Q:X_Q + 4], X[a, X_W], X[a, X_W + 1], X[a, X_W + 2], hk, planar)
        geometry(X, C, CI, nc, WP, seed, fric)
        springs(X, C, CI, na, nc, grav)
        close = 0.5 * hk
        opening = 0.5 * weights[k + 1] * h if k + 1 < n else 0.0
        if fric:
            done, good = kick(X, C, CI, na, nc, close, opening, stuck, A, b, fl, exact, pull_rate, warm, one_pass)
            work += done
            ok = ok and good
        else:
            # Two adds, as with friction: a sweep mixing mu = 0 with mu > 0 matches single runs.
            for a in range(na):
                for d in range(3):
                    X[a, X_V + d] += close * X[a, X_A + d]
                    if opening != 0.0:
                        X[a, X_V + d] += opening * X[a, X_A + d]
    return work, ok


# ---------------------------------------------------------------------------------------------
# Friction modes and their events


@jit_inline
def mode_events(X, C, CI, E, na, nc, vcol, rcol, stuck, A, b, fl, scale, fresh, known):
    """Friction mode event values (2C) into E[:, vcol] and their rates into E[:, rcol], in speed
    units over `scale`, at the state in X (geometry in C, X_A set). Slide: |slip| - eps; band:
    eps - |slip|; stick: the margin to mu F_n and the hold force's component against the held
    slip, as the slip change they would make over STICK_SCALE (rates NaN: no closed form).
    The stuck contacts' hold system is built with `fresh`, else it is the one in A: a state that
    ends a step or a decision, whose `settle` built it at this geometry and these modes. Leaves
    the friction forces in C_FF. With `known`, those forces (C_FF, X_F, X_L) are already this
    state's: a step's end, whose closing kick solved them at its velocities (the settling of
    stuck slips after it moves them by the kick's fixed-point tolerance: a mode value by 1e-12,
    far below MODE_TOL), and the solve is skipped. Returns False if the hold system is singular."""
    spin, seed, planar = fl[FL_SPIN], fl[FL_SEED], fl[FL_PLANAR] == YES
    if not known and not friction(X, C, CI, na, nc, X_V, X_W, stuck, A, b, fl, 0.0, fresh):
        return False
    for a in range(na):
        for d in range(3):
            X[a, X_T + d] = X[a, X_A + d] + X[a, X_F + d]
    for c in range(nc):
        second = nc + c
        if CI[c, CI_MODE] == STICK:
            k = response(X, C, CI, c, spin) * STICK_SCALE / scale
            fx, fy, fz = C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2]
            fmag = math.sqrt(fx * fx + fy * fy + fz * fz)
            E[c, vcol] = (C[c, C_MU] * C[c, C_FN] - fmag) * k
            E[second, vcol] = -(fx * C[c, C_HELD] + fy * C[c, C_HELD + 1] + fz * C[c, C_HELD + 2]) * k
            E[c, rcol] = math.nan
            E[second, rcol] = math.nan
            continue
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar)
        gx, gy, gz = slip_rate(X, C, CI, c, X_V, X_W, X_T, X_L, spin, seed, YES, planar)
        if CI[c, CI_MODE] == SLIDE:
            # |slip| - eps, with |slip| counted negative once the slip points against the way it
            # slid at the step's start: a slip reversing through the band within a step then
            # still changes sign, and one that turns as it slows lands where |slip| = eps.
            hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
            mag = math.sqrt(sx * sx + sy * sy + sz * sz)
            along = sx * hx + sy * hy + sz * hz
            outward = (sx * gx + sy * gy + sz * gz) / mag if mag > 0 else 0.0
            if planar:
                sign = 1.0 if along >= 0 else -1.0
                E[c, vcol] = (sign * mag - C[c, C_EPS]) / scale
                E[c, rcol] = sign * outward / scale
            else:
                # Out of the plane a slip near the band can turn past a right angle off the way
                # it slid without slowing to the band (its direction slaved to the other forces):
                # the signed |slip| jumped there, and the root search bisected the jump to the
                # clock (40 trials, in a pile of 27 spheres). (|slip| + slip . held) / 2, that is
                # |slip| cos^2 of half the turn, is continuous, |slip| while the slip keeps its
                # way and 0 reversed: a reversal still changes sign, and a slip that turns as it
                # slows lands a little before |slip| = eps, where it slides on, redirected.
                E[c, vcol] = (0.5 * (mag + along) - C[c, C_EPS]) / scale
                E[c, rcol] = 0.5 * (outward + gx * hx + gy * hy + gz * hz) / scale
            E[second, vcol] = 1.0
            E[second, rcol] = 0.0
        elif planar:
            # In the plane the band is a segment along the tangent e = z x n, its edges where
            # the slip along e is eps and -eps: values smooth in the slip. eps - |slip| has a
            # kink at zero slip: a slip crossing the band made it rise and fall back with the
            # far edge's, and a root search on it crept (11 trials for one event).
            ex, ey = -C[c, C_N + 1], C[c, C_N]
            along, rate = sx * ex + sy * ey, gx * ex + gy * ey
            E[c, vcol] = (C[c, C_EPS] - along) / scale
            E[c, rcol] = -rate / scale
            E[second, vcol] = (C[c, C_EPS] + along) / scale
            E[second, rcol] = rate / scale
        else:
            # Any edge: eps - |slip| (|slip|' = slip . slip' / |slip|, friction included); it
            # starts at zero when the band is entered from its edge, so the far edge is watched
            # too: eps + the slip along its direction at the step's start.
            mag = math.sqrt(sx * sx + sy * sy + sz * sz)
            hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
            E[c, vcol] = (C[c, C_EPS] - mag) / scale
            E[c, rcol] = -(sx * gx + sy * gy + sz * gz) / mag / scale if mag > 0 else 0.0
            E[second, vcol] = (C[c, C_EPS] + sx * hx + sy * hy + sz * hz) / scale
            E[second, rcol] = (gx * hx + gy * hy + gz * hz) / scale
    return True


@jit_inline
def decide(X, C, CI, na, nc, stuck, A, b, fl, scale):
    """Modes of the engaged contacts at this state (at a phase start and after every step).

    Outside the band: slide; inside: band; on its edge (within the event tolerance, so that a
    step landed on a mode change switches): stick if the force that holds the slip there (solved
    with the other stuck contacts) is within mu F_n and against the slip, else slide (beyond
    mu F_n) or band (not against it). A stuck slip is held along its hold force's reverse; in 3D
    a slip that reaches the edge off that direction is turned onto it (the limit of the fast
    turning along the edge that the law gives there). Returns (work dissipated, ok, whether the
    hold system left in A is not these modes': 3D edge contacts that slide on were settled held,
    whether the friction forces left are this state's: see `mode_events`' `known`)."""
    spin, planar, seed = fl[FL_SPIN], fl[FL_PLANAR], fl[FL_SEED]
    tol = EDGE_TOL * scale
    edges = 0
    flipped_any = False
    for c in range(nc):
        CI[c, CI_RETRIED] = NO
        CI[c, CI_FLIPPED] = NO
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar == YES)
        mag = math.sqrt(sx * sx + sy * sy + sz * sz)
        if mag > 0:
            C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2] = sx / mag, sy / mag, sz / mag
        flip = CI[c, CI_EDGE] == FLIP
        CI[c, CI_EDGE] = 0
        if abs(mag - C[c, C_EPS]) <= tol:
            CI[c, CI_MODE] = STICK
            CI[c, CI_EDGE] = 1
            edges += 1
            if flip:
                # Its slip goes to the band's other edge (settled there below) and is held
                # there: the hold force goes on through zero, now against the reversed slip.
                for d in range(3):
                    C[c, C_HELD + d] = -C[c, C_HELD + d]
                CI[c, CI_FLIPPED] = YES
                flipped_any = True
        elif mag > C[c, C_EPS]:
            CI[c, CI_MODE] = SLIDE
        else:
            CI[c, CI_MODE] = BAND
    solved = False  # the last friction solve was at the final modes: its hold system is settle's
    for _ in range(2 * nc + 2):
        if not friction(X, C, CI, na, nc, X_V, X_W, stuck, A, b, fl, 0.0, YES):
            return 0.0, False, False, False
        changed = False
        # An edge contact that another's change left sliding with its slip heading into the band,
        # or in the band with its slip heading out, is in no consistent mode: it is held again
        # (once) and judged by its hold force with the others' modes as they now are. Left so,
        # the slide crossed the band unseen within the step (its value starts at zero) and the
        # outcome moved by 1e-3 between tolerances (two balls and a floor changing at once).
        if edges:
            for a in range(na):
                for d in range(3):
                    X[a, X_T + d] = X[a, X_A + d] + X[a, X_F + d]
            limit = tol / STICK_SCALE
            for c in range(nc):
                if CI[c, CI_EDGE] != 1 or CI[c, CI_MODE] == STICK or CI[c, CI_RETRIED]:
                    continue
                sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar == YES)
                gx, gy, gz = slip_rate(X, C, CI, c, X_V, X_W, X_T, X_L, spin, seed, YES, planar == YES)
                mag = math.sqrt(sx * sx + sy * sy + sz * sz)
                outward = (sx * gx + sy * gy + sz * gz) / mag if mag > 0 else 0.0
                if (CI[c, CI_MODE] == SLIDE and outward < -limit) or (CI[c, CI_MODE] == BAND and outward > limit):
                    CI[c, CI_MODE] = STICK
                    CI[c, CI_RETRIED] = YES
                    changed = True
        if changed:
            continue
        for c in range(nc):
            if CI[c, CI_MODE] != STICK:
                continue
            force_tol = tol / (response(X, C, CI, c, spin) * STICK_SCALE)
            fx, fy, fz = C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2]
            fmag = math.sqrt(fx * fx + fy * fy + fz * fz)
            need = -(fx * C[c, C_HELD] + fy * C[c, C_HELD + 1] + fz * C[c, C_HELD + 2])
            if not planar and need > 0:
                need = fmag
            if need <= force_tol and not (CI[c, CI_FLIPPED] and need > -force_tol):
                CI[c, CI_MODE] = BAND
                changed = True
            elif fmag >= C[c, C_MU] * C[c, C_FN] - force_tol:
                CI[c, CI_MODE] = SLIDE
                changed = True
            if not planar and fmag > 0 and CI[c, CI_MODE] != BAND:
                C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2] = -fx / fmag, -fy / fmag, -fz / fmag
        if not changed:
            solved = True
            break
    # Stuck slips onto the edge along their held direction; in 3D an edge contact that slides on
    # starts along its hold force's reverse: its slip is turned there with the stuck ones.
    turned = False
    for c in range(nc):
        if not planar and CI[c, CI_EDGE] == 1 and CI[c, CI_MODE] == SLIDE:
            CI[c, CI_MODE] = STICK
            CI[c, CI_EDGE] = 2
            turned = True
    work, ok = settle(X, C, CI, na, nc, stuck, A, b, fl, NO if solved and not turned else YES)
    for c in range(nc):
        if CI[c, CI_EDGE] == 2:
            CI[c, CI_MODE] = SLIDE
    # The friction its last solve left (C_FF, X_F, X_L) is this state's unless settling moved a
    # slip by more than a step's drift: a flip moves one by 2 eps (a mode value by 3e-8 in the break).
    return work, ok, turned, solved and not turned and not flipped_any


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
def hermite_root(d0, d1, r0, r1):
    """Root in (0, 1) of the cubic Hermite through (0, d0, r0) and (1, d1, r1) (r per step), by
    safeguarded Newton on the cubic, kept inside the bracket."""
    c2 = 3.0 * (d1 - d0) - 2.0 * r0 - r1
    c3 = 2.0 * (d0 - d1) + r0 + r1
    theta = min(max(d0 / (d0 - d1 if d0 != d1 else 1.0), 0.0), 1.0)
    if (d0 > 0) == (d1 > 0):
        return theta
    lo, hi = 0.0, 1.0
    positive = d0 > 0
    for _ in range(60):
        p = d0 + theta * (r0 + theta * (c2 + theta * c3))
        dp = r0 + theta * (2.0 * c2 + 3.0 * c3 * theta)
        if (p > 0) == positive:
            lo = theta
        else:
            hi = theta
        newton = theta - p / dp if dp != 0 else math.inf
        nxt = newton if lo <= newton <= hi else 0.5 * (lo + hi)
        done = abs(nxt - theta) <= 1e-15
        theta = nxt
        if done:
            break
    return theta


@jit_inline
def bracketed_root(lo, f_lo, hi, f_hi, a, fa, b, fb, c, fc):
    """Next estimate of a root bracketed in [lo, hi] (f_lo >= 0 > f_hi) from the latest three
    trials (c the latest): inverse quadratic interpolation through them, else the secant through
    the latest two; where that leaves the bracket, false position nudged off its ends."""
    est = math.nan
    if fa == fa and fa != fb and fa != fc and fb != fc:
        est = (a * fb * fc / ((fa - fb) * (fa - fc)) + b * fa * fc / ((fb - fa) * (fb - fc))
               + c * fa * fb / ((fc - fa) * (fc - fb)))
    if not (lo < est < hi) and fb == fb and fc != fb:
        est = c - fc * (c - b) / (fc - fb)
    if lo < est < hi:
        return est
    width = hi - lo
    if f_lo != f_hi:
        return min(max(lo + width * f_lo / (f_lo - f_hi), lo + 0.01 * width), hi - 0.01 * width)
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------------------------------------
# Bodies in free flight and candidate contacts


@jit_inline
def free_state(G, i, t, grav):
    """Position and velocity of body i at time t in free flight from its base state."""
    tau = t - G[i, G_TB]
    return (G[i, G_S] + G[i, G_V] * tau + 0.5 * grav[0] * tau * tau,
            G[i, G_S + 1] + G[i, G_V + 1] * tau + 0.5 * grav[1] * tau * tau,
            G[i, G_S + 2] + G[i, G_V + 2] * tau + 0.5 * grav[2] * tau * tau,
            G[i, G_V] + grav[0] * tau, G[i, G_V + 1] + grav[1] * tau, G[i, G_V + 2] + grav[2] * tau)


@jit
def bring(G, i, t, grav, fl):
    """Move body i's base state to time t along its free flight."""
    tau = t - G[i, G_TB]
    if tau == 0.0:
        return
    px, py, pz, ux, uy, uz = free_state(G, i, t, grav)
    if fl[FL_SPIN]:
        turn(G[i, G_Q:G_Q + 4], G[i, G_W], G[i, G_W + 1], G[i, G_W + 2], tau, fl[FL_PLANAR])
    G[i, G_S], G[i, G_S + 1], G[i, G_S + 2] = px, py, pz
    G[i, G_V], G[i, G_V + 1], G[i, G_V + 2] = ux, uy, uz
    G[i, G_TB] = t


@jit_inline
def body_pv(G, GI, X, i, t, grav):
    """Body i at time t: from its island's step if it is being stepped, else in free flight."""
    a = GI[i, GI_LOC]
    if a >= 0:
        return X[a, X_S], X[a, X_S + 1], X[a, X_S + 2], X[a, X_V], X[a, X_V + 1], X[a, X_V + 2]
    return free_state(G, i, t, grav)


@jit_inline
def overlap(G, GI, X, Q, QF, k, t, WP, grav):
    """Candidate k's overlap over its touching distance, and that ratio's rate."""
    i, j = Q[k, Q_I], Q[k, Q_J]
    px, py, pz, ux, uy, uz = body_pv(G, GI, X, i, t, grav)
    reach = QF[k, QF_REACH]
    if j >= 0:
        qx, qy, qz, wx, wy, wz = body_pv(G, GI, X, j, t, grav)
        dx, dy, dz = qx - px, qy - py, qz - pz
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        return (reach - dist) / reach, ((ux - wx) * dx + (uy - wy) * dy + (uz - wz) * dz) / (dist * reach)
    w = -1 - j
    h = (px - WP[w, 0]) * WP[w, 3] + (py - WP[w, 1]) * WP[w, 4] + (pz - WP[w, 2]) * WP[w, 5]
    return (reach - h) / reach, -(ux * WP[w, 3] + uy * WP[w, 4] + uz * WP[w, 5]) / reach


@jit_inline
def engaged(Q, k, d, r, WP, grav):
    """A contact is engaged when pressing, or touching and approaching (or, on a wall, resting
    with gravity pressing it in), or touching and not separating if it was engaged already (a
    contact of a Newton's cradle, engaged when a step found it pressing from touching)."""
    if d > TOUCH_TOL:
        return True
    if d < -TOUCH_TOL:
        return False
    # A contact found pressing late (within a step that began with it touching) stays engaged
    # while it touches, whatever its rate: otherwise it would be found late again, forever.
    if r > 0 or (Q[k, Q_ENG] > 0 and r == 0) or Q[k, Q_ENG] == LATE:
        return True
    j = Q[k, Q_J]
    if j < 0 and r == 0:
        w = -1 - j
        return grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5] < 0
    return False


@jit
def smallest_positive_root(a, b, c):
    """Smallest t > 0 with a t^2 + b t + c = 0 (inf if none); c >= 0 (not yet touching)."""
    disc = b * b - 4.0 * a * c
    if disc < 0:
        return math.inf
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    r1 = c / q if q != 0 else math.inf
    r2 = q / a if a != 0 else math.inf
    best = math.inf
    if r1 > 0:
        best = r1
    if 0 < r2 < best:
        best = r2
    return best


@jit
def touch_time(G, i, j, t, WP, grav):
    """Time from t until body i touches body j (or wall -1 - j) in free flight (inf: never)."""
    px, py, pz, ux, uy, uz = free_state(G, i, t, grav)
    if j >= 0:
        qx, qy, qz, wx, wy, wz = free_state(G, j, t, grav)
        dx, dy, dz = qx - px, qy - py, qz - pz
        ex, ey, ez = wx - ux, wy - uy, wz - uz  # gravity cancels in relative motion
        b = 2.0 * (dx * ex + dy * ey + dz * ez)
        if b >= 0:
            return math.inf
        reach = G[i, G_R] + G[j, G_R]
        return smallest_positive_root(ex * ex + ey * ey + ez * ez, b,
                                      max(dx * dx + dy * dy + dz * dz - reach * reach, 0.0))
    w = -1 - j
    gap = (px - WP[w, 0]) * WP[w, 3] + (py - WP[w, 1]) * WP[w, 4] + (pz - WP[w, 2]) * WP[w, 5] - G[i, G_R]
    rate = ux * WP[w, 3] + uy * WP[w, 4] + uz * WP[w, 5]
    acc = grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5]
    return smallest_positive_root(0.5 * acc, rate, max(gap, 0.0))


@jit
def grow(buf, n):
    """`buf` with room for row n (doubled when full)."""
    if n < buf.shape[0]:
        return buf
    # At least row n: a caller may ask for many rows at once (an island's new contacts).
    out = np.empty((max(2 * buf.shape[0] + 16, n + 1), buf.shape[1]))
    out[:buf.shape[0]] = buf
    return out


@jit
def grow_int(buf, n):
    if n < buf.shape[0]:
        return buf
    out = np.empty((max(2 * buf.shape[0] + 16, n + 1), buf.shape[1]), np.int64)
    out[:buf.shape[0]] = buf
    return out


# ---------------------------------------------------------------------------------------------
# Broad phase: a uniform cell grid, so that finding contacts follows the bodies, not the pairs


@jit
def near_pairs(P, rad, margin, n, dim):
    """Pairs (i < j) with |s_i - s_j| <= r_i + r_j + margin_i + margin_j, shape (K, 2), from
    positions P (N, 3). A body whose reach is far above the rest's (a fast one) is checked
    against every body instead of setting the cell size for all."""
    out = np.empty((max(16, 4 * n), 2), np.int64)
    m = 0
    if n < 2:
        return out[:0]
    mean = 0.0
    for i in range(n):
        mean += rad[i] + margin[i]
    mean /= n
    size = 0.0
    for i in range(n):
        b = rad[i] + margin[i]
        if b <= 4.0 * mean:
            size = max(size, b)
    size *= 2.0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(n):
        for d in range(dim):
            lo[d] = min(lo[d], P[i, d])
            hi[d] = max(hi[d], P[i, d])
    cells = np.ones(3, np.int64)
    while True:
        total = 1
        for d in range(dim):
            cells[d] = min(int((hi[d] - lo[d]) / size) + 1, 1 << 20) if size > 0 else 1
            total *= cells[d]
        if total <= 4 * n + 64:
            break
        size *= 1.5
    head = np.full(cells[0] * cells[1] * cells[2], -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    cell = np.zeros((n, 3), np.int64)
    for i in range(n):
        if rad[i] + margin[i] > 4.0 * mean:
            continue
        for d in range(dim):
            cell[i, d] = min(max(int((P[i, d] - lo[d]) / size) if size > 0 else 0, 0), cells[d] - 1)
        key = (cell[i, 0] * cells[1] + cell[i, 1]) * cells[2] + cell[i, 2]
        nxt[i] = head[key]
        head[key] = i
    for i in range(n):
        bi = rad[i] + margin[i]
        if bi > 4.0 * mean:
            # Against everyone (another outlier only once, from the lower index).
            for j in range(n):
                if j == i or (j < i and rad[j] + margin[j] > 4.0 * mean):
                    continue
                if _close(P, i, j, bi + rad[j] + margin[j]):
                    out = grow_int(out, m)
                    out[m, 0], out[m, 1] = min(i, j), max(i, j)
                    m += 1
            continue
        a0, a1 = max(cell[i, 0] - 1, 0), min(cell[i, 0] + 1, cells[0] - 1)
        b0, b1 = max(cell[i, 1] - 1, 0), min(cell[i, 1] + 1, cells[1] - 1)
        c0, c1 = max(cell[i, 2] - 1, 0), min(cell[i, 2] + 1, cells[2] - 1)
        for a in range(a0, a1 + 1):
            for b in range(b0, b1 + 1):
                for c in range(c0, c1 + 1):
                    j = head[(a * cells[1] + b) * cells[2] + c]
                    while j >= 0:
                        if j > i and _close(P, i, j, bi + rad[j] + margin[j]):
                            out = grow_int(out, m)
                            out[m, 0], out[m, 1] = i, j
                            m += 1
                        j = nxt[j]
    return out[:m]


@jit
def _close(P, i, j, reach):
    dx = P[j, 0] - P[i, 0]
    dy = P[j, 1] - P[i, 1]
    dz = P[j, 2] - P[i, 2]
    return dx * dx + dy * dy + dz * dz <= reach * reach


@jit
def root_of(parent, i):
    """Union-find root, with path halving."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@jit
def join(parent, i, j):
    a, b = root_of(parent, i), root_of(parent, j)
    if a != b:
        parent[max(a, b)] = min(a, b)


# ---------------------------------------------------------------------------------------------
# Recording


@jit
def add_knot(KN, CNT, t, g, free, X, a, sc, vc, wc, qc, acc, work):
    """Append body g's state at t from row a of X (or of G, with the columns given)."""
    KN = grow(KN, CNT[CN_KNOTS])
    r = CNT[CN_KNOTS]
    KN[r, K_T] = t
    KN[r, K_BODY] = g
    KN[r, K_FREE] = free
    for d in range(3):
        KN[r, K_S + d] = X[a, sc + d]
        KN[r, K_V + d] = X[a, vc + d]
        KN[r, K_W + d] = X[a, wc + d]
        KN[r, K_A + d] = acc[d]
        KN[r, K_AN + d] = acc[d]
    for d in range(4):
        KN[r, K_Q + d] = X[a, qc + d]
    KN[r, K_WORK] = work
    CNT[CN_KNOTS] += 1
    return KN


@jit
def intervals(Q, nq, t, IV, OP, CNT, ST):
    """Open an interval for every newly engaged candidate, close the island's that ended.
    OP holds the rows of open intervals (CNT[CN_OPEN] of them). Returns the grown buffers."""
    IV = grow(IV, CNT[CN_IVALS] + nq)
    if CNT[CN_OPEN] + nq >= OP.shape[0]:
        more = np.empty(2 * OP.shape[0] + nq + 16, np.int64)
        more[:OP.shape[0]] = OP
        OP = more
    k = 0
    while k < CNT[CN_OPEN]:
        row = OP[k]
        gi, gj = int(IV[row, V_I]), int(IV[row, V_J])
        close = False
        for q in range(nq):
            if Q[q, Q_I] == gi and Q[q, Q_J] == gj:
                close = Q[q, Q_ENG] == 0
                break
        if close:
            IV[row, V_END] = t
            CNT[CN_OPEN] -= 1
            OP[k] = OP[CNT[CN_OPEN]]
        else:
            k += 1
    for q in range(nq):
        if Q[q, Q_ENG] == 0:
            continue
        found = False
        for k in range(CNT[CN_OPEN]):
            row = OP[k]
            if int(IV[row, V_I]) == Q[q, Q_I] and int(IV[row, V_J]) == Q[q, Q_J]:
                found = True
                break
        if found:
            continue
        row = CNT[CN_IVALS]
        IV[row, V_I] = Q[q, Q_I]
        IV[row, V_J] = Q[q, Q_J]
        IV[row, V_START] = t
        IV[row, V_END] = math.nan
        OP[CNT[CN_OPEN]] = row
        CNT[CN_OPEN] += 1
        CNT[CN_IVALS] += 1
        ST[S_CONTACTS] += 1
    return IV, OP


# ---------------------------------------------------------------------------------------------
# An island


@jit
def gather(G, GI, X, XI, C, CI, Q, QF, nq, bodies_params):
    """Set up the island's engaged contacts (C, CI) and their bodies (X, XI) from the engaged
    candidates; returns (bodies, contacts)."""
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
        else:
            C[nc, C_K], C[nc, C_MU], C[nc, C_EPS] = wtab[mi, TP_K], wtab[mi, TP_MU], wtab[mi, TP_EPS]
        C[nc, C_REACH] = QF[k, QF_REACH]
        nc += 1
    return na, nc


@jit_inline
def island_omega(X, C, CI, na, nc):
    """The stiffest frequency of the engaged contacts: exact for one contact, otherwise a
    Gershgorin bound on the mass-symmetrised stiffness matrix (rows k/m_i + k/sqrt(m_i m_j))."""
    if nc == 1:
        i, j = CI[0, CI_I], CI[0, CI_J]
        return math.sqrt(C[0, C_K] * (X[i, X_IM] + (X[j, X_IM] if j >= 0 else 0.0)))
    for a in range(na):
        X[a, X_FO] = 0.0
    for c in range(nc):
        i, j = CI[c, CI_I], CI[c, CI_J]
        k = C[c, C_K]
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
    """Kinetic, rotational, gravitational and spring energy of the island's stepped bodies."""
    e = 0.0
    for a in range(na):
        for d in range(3):
            e += 0.5 * X[a, X_M] * X[a, X_V + d] ** 2 - X[a, X_M] * grav[d] * X[a, X_S + d]
            if spin:
                e += 0.5 * X[a, X_I] * X[a, X_W + d] ** 2
    for c in range(nc):
        e += 0.5 * C[c, C_K] * C[c, C_DELTA] ** 2
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
        e += 0.5 * C[c, C_K] * C[c, C_DELTA] ** 2
    return e


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
        if CI[c, CI_MODE] != SLIDE or C[c, C_MU] * C[c, C_FN] * response(X, C, CI, c, fl[FL_SPIN]) * h <= negligible:
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
        rate = C[c, C_MU] * C[c, C_FN] * response(X, C, CI, c, spin)
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
def hermite_dip(e0, e1, r0, r1, floor):
    """The first of DIP_SAMPLES points in (0, 1) where the cubic Hermite through (0, e0, r0) and
    (1, e1, r1) (r per step) is below `floor`: a value above it at both ends that dips between.
    inf if none (or if the rates make it a hump)."""
    if r0 >= 0.0 and r1 <= 0.0:
        return math.inf
    # The cubic is e0, e1's blend plus r0 u (1 - u)^2 - r1 u^2 (1 - u), each term at most 4/27 of
    # its rate: no sample can dip below this bound (0.15 over 4/27 and the 1e-12 cover the
    # samples' rounding), and most values of a trial stay above it (their 15 samples skipped).
    reach = max(-r0, 0.0) + max(r1, 0.0)
    if min(e0, e1) - 0.15 * reach - 1e-12 * (abs(e0) + abs(e1) + reach) > floor:
        return math.inf
    for i in range(1, DIP_SAMPLES):
        u = i / DIP_SAMPLES
        u2, u3 = u * u, u * u * u
        p = (2 * u3 - 3 * u2 + 1) * e0 + (u3 - 2 * u2 + u) * r0 + (3 * u2 - 2 * u3) * e1 + (u3 - u2) * r1
        if p < floor:
            return u
    return math.inf


@jit_inline
def first_root(e0, r0, curve):
    """The first positive root of e0 + r0 t + curve t^2 / 2 (e0 > 0), in the form without
    cancellation; inf if none."""
    disc = r0 * r0 - 2.0 * curve * e0
    if disc >= 0.0:
        denominator = -r0 + math.sqrt(disc)
        if denominator > 0.0:
            return 2.0 * e0 / denominator
    return math.inf


@jit_inline
def foresee(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full, WP, grav, stuck, A, b, fl, scale):
    """The first time (from the step's start) at which a contact is foreseen to start or end or a
    friction mode to change: where the parabola through a value's start, rate and rate of change
    reaches zero. The rates of change, and a stuck contact's rate (its values have no closed
    form; theirs is a line), are differences to a state FORESEE_SPAN of the step on by the
    start's velocities and accelerations (the bodies are left there: the step restarts; its mode
    values in E[:, E_V1:]). inf if nothing is foreseen."""
    span = FORESEE_SPAN * h_full
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
def flips(C, CI, E, nc, c, h, omega, scale):
    """Whether stuck contact c's hold force, come to zero in a trial of h (from above: E_V0 and
    E_V1 its values at the trial's ends), crosses the band quickly enough to be taken as the
    impulse that flips its slip to the band's other edge, at the trial's end: the bodies that
    impulse moves by 2 eps over the crossing's length and over how late the trial's end is
    (both from the line through the two values) stray, times omega (FLIP_SAFETY over), within
    FLIP_SHARE of the event tolerance as a speed (EDGE_TOL scale: the mode values' unit)."""
    k = nc + c
    v0, v1 = E[k, E_V0], E[k, E_V1]
    if CI[c, CI_MODE] != STICK or not (v0 > MODE_TOL and v1 <= MODE_TOL and E[c, E_V1] > MODE_TOL):
        return False
    rate = (v0 - v1) / h * scale / STICK_SCALE  # of the slip's acceleration
    crossing = 2.0 * math.sqrt(C[c, C_EPS] / rate)
    late = h * max(-v1, 0.0) / (v0 - v1)
    return FLIP_SAFETY * omega * C[c, C_EPS] * (crossing + 2.0 * late) <= FLIP_SHARE * EDGE_TOL * scale


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
        force = C[c, C_MU] * C[c, C_FN] * response(X, C, CI, c, spin)
        if force * rate > 0.0:
            nudge = min(nudge, (12.0 * NUDGE_SHARE * negligible / (force * rate)) ** (1.0 / 3.0))
            reach = min(reach, (NUDGE_SHARE * negligible / (YOSHIDA_ERROR * force * rate * rate)) ** 0.2)
    return nudge, reach


@jit
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
    h = h_full
    limited = -1
    tol = TOUCH_TOL
    # The kicks' start and their hold forces' pull, from the step's start (its modes hold through
    # the step; the pull is a bound with CONTRACTION_SAFETY's margin, which a trial's share of
    # the step's impulse stays within), before `foresee` moves the bodies on.
    pull_rate, warm, one_pass = 0.0, True, False
    if fl[FL_FRICTION]:
        warm, one_pass = kick_start(CI, nc, fl[FL_PLANAR] == YES)
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
    if not ok:
        return h, work, False, limited, -1, True
    # A contact touching at the start with no approach speed that presses by the end began with
    # the step: it is engaged from the start and the step taken again (a Newton's cradle).
    for k in range(nq):
        if Q[k, Q_ENG] == 0 and -tol <= QF[k, QF_D0] <= tol:
            d1, r1 = overlap(G, GI, X, Q, QF, k, t + h, WP, grav)
            if d1 > tol:
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
        crossing_aim = theta
        best = -1
        if modes:
            if not mode_events(X, C, CI, E, na, nc, E_V1, E_R1, stuck, A, b, fl, scale, NO, YES):
                return h, work, False, limited, -1, True
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
            fresh = best >= 0 and (not pending or best != col)
            if fresh:
                col = best
                start = clear if clear < frac else 0.0  # a value back below zero before it: a dip
                at_v, at_r = (E[col, E_VC], E[col, E_RC]) if start > 0.0 else (E[col, E_V0], E[col, E_R0])
                lo, f_lo, hi, f_hi = start, at_v, frac, E[col, E_V1]
                s_lo, s_hi = at_r * h_full, E[col, E_R1] * h_full
                ta, fa, tb, fb = math.nan, math.nan, start, at_v
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
                if flip or late_ok or (abs(f) <= MODE_TOL and (best < 0 or best == col)):
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
                    widths = (widths[1], abs(f))
                    theta = min(theta, estimate)
                    ta, fa, tb, fb = tb, fb, frac, f
            if short and not pending and abs(frac - passed_at) <= 1e-12 * frac:
                # Landed just past a jump, short of a contact's crossing: the step ends here, as
                # at a root (aimed on at the crossing, the search ran out of trials in a pile).
                theta = math.inf
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
        if modes and not pending:
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
        if not (theta < math.inf and abs(theta - frac) > 1e-12 * max(frac, 1e-300)):
            located = True
            break
        aimed = theta == crossing_aim
        # Never shorter than a few ticks of the clock: an event closer than that is taken as passed.
        h_next = max(h_full * max(theta, 1e-12), shortest)
        near_nudge, near_reach = nudge, reach
        if nudge > 0.0 and abs(h_next - h) <= reach and fl[FL_FRICTION] and fl[FL_PLANAR] != YES:
            # Out of the plane, as far as the slips turning at this trial's end allow.
            near_nudge, near_reach = turning_nudges(X, C, CI, na, nc, fl, nudge, reach, negligible, abs(h_next - h),
                                                    X_V, X_W, X_F, X_L)
        if nudge > 0.0 and abs(h_next - h) <= near_reach:
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


@jit
def record_step(KN, RC, CNT, G, GI, X, XI, C, CI, na, nc, t, fl):
    """Knots of the stepped bodies and records of the engaged contacts at the end of a step."""
    acc = np.empty(3)
    for a in range(na):
        g = XI[a]
        for d in range(3):
            acc[d] = X[a, X_A + d] + (X[a, X_F + d] if fl[FL_FRICTION] else 0.0)
        KN = add_knot(KN, CNT, t, g, 0.0, X, a, X_S, X_V, X_W, X_Q, acc, G[g, G_WK])
        GI[g, GI_KNOT] = CNT[CN_KNOTS] - 1
    for c in range(nc):
        RC = grow(RC, CNT[CN_RECS])
        r = CNT[CN_RECS]
        RC[r, R_T] = t
        RC[r, R_I] = CI[c, CI_GI]
        RC[r, R_J] = CI[c, CI_GJ]
        RC[r, R_DELTA] = C[c, C_DELTA]
        RC[r, R_FN] = C[c, C_FN]
        for d in range(3):
            RC[r, R_FX + d] = C[c, C_FF + d] if fl[FL_FRICTION] else 0.0
        RC[r, R_MODE] = CI[c, CI_MODE] if fl[FL_FRICTION] else 0.0
        CNT[CN_RECS] += 1
    return KN, RC


# ---------------------------------------------------------------------------------------------
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
GL8_S = np.array([[np.polynomial.Polynomial.fit(GL8_X, np.eye(8)[j], 7, domain=[0, 1], window=[0, 1]).integ()(x)
                   for j in range(8)] for x in GL8_X])
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
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


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
    """Whether this contact phase runs in closed form: one sphere on one wall, the contact's own
    step (dt auto) and the true lever."""
    return fl[FL_AUTO] and nq == 1 and na == 1 and nc == 1 and CI[0, CI_J] < 0 and not fl[FL_SEED]


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
    if planar:
        e1[0], e1[1] = n[1], -n[0]  # n x z: the in-plane tangent (e2 = -z)
    else:
        # n x the axis least along n.
        a = 0 if abs(n[0]) <= min(abs(n[1]), abs(n[2])) else (1 if abs(n[1]) <= abs(n[2]) else 2)
        e1[(a + 1) % 3], e1[(a + 2) % 3] = n[(a + 2) % 3], -n[(a + 1) % 3]
        e1 /= math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    e2 = np.array([n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]])
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
    # Nothing here depends on the position along the wall or the orientation: once the state
    # recurs (the bob's phase, the velocities, the mode), the motion repeats (a ball resting,
    # rolling or sliding straight). A cycle is looked for between two events of the same kind, or over a period of
    # the bob without events, and repeated in one go (`rest_repeat`). Not when recording, whose
    # knots every interval gives.
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
                decided = announce = True
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
        # The positions, angle and friction's work over the interval by Gauss-Legendre (the work
        # from its force and the slip, not from the energies: a check).
        d, dd, v1, v2, w1, w2, f1, f2 = rest_at(P, mode, h)
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
        if spin:
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
        P[RP_V], P[RP_V + 1], P[RP_TW], P[RP_TW + 1] = v1, v2, w1, w2
        rest_put(X, P, dd, n, e1, e2, w_n)
        t = landed
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


@jit
def run_island(G, GI, Q, QF, T, W, tables, WP, grav, weights, fl, fp, bufs, CNT, ST, FG):
    """Advance the island of candidate contacts Q (N_Q, 3) from T to W: free flight in closed
    form while nothing is engaged, event-located steps of the bodies with engaged contacts while
    something is. Returns the (grown) recording buffers; problems go to ST[S_STATUS]."""
    KN, RC, IV, OP = bufs
    spin, fric, record = fl[FL_SPIN], fl[FL_FRICTION], fl[FL_RECORD]
    scale = fp[FP_SCALE]
    nq = Q.shape[0]
    size = 0
    for k in range(nq):
        size += 1 if Q[k, Q_J] < 0 else 2
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
    while t < W and ST[S_STATUS] == OK:
        n_eng = 0
        for k in range(nq):
            d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
            # Contacts found late keep that mark through the restarts at this time: re-marked as
            # ordinary ones, touching contacts easing apart in a rack dropped out and were found
            # late again, one after another, until the run stalled. A step taken clears it.
            on = engaged(Q, k, d, r, WP, grav)
            Q[k, Q_ENG] = (LATE if Q[k, Q_ENG] == LATE else 1) if on else 0
            n_eng += 1 if on else 0
        IV, OP = intervals(Q, nq, t, IV, OP, CNT, ST)
        if n_eng == 0:
            tau = math.inf
            for k in range(nq):
                tau = min(tau, touch_time(G, Q[k, Q_I], Q[k, Q_J], t, WP, grav))
            if t + tau >= W:
                break
            # A touch closer than the clock resolves lands on its next tick (late by less than one:
            # the clock's resolution at t), where it is found touching; a float clock's ticks
            # grow with t (5.7e-14 s at 256 s), and a bounce landed on time to within a tick came
            # down just short of the floor, over and over. The same touch met at every tick is
            # still a stall.
            stalled = stalled + 1 if t + tau == t else 0
            if stalled > STALL_LIMIT:
                ST[S_STATUS] = STALL
                FG[F_STATUS_T], FG[F_STATUS_A] = t, 2.0
                break
            t = t + tau if stalled == 0 else np.nextafter(t, math.inf)
            continue
        # A contact phase: the bodies of the engaged contacts are stepped.
        for k in range(nq):
            for side in range(2):
                g = Q[k, Q_I] if side == 0 else Q[k, Q_J]
                if g >= 0 and Q[k, Q_ENG]:
                    bring(G, g, t, grav, fl)
        na, nc = gather(G, GI, X, XI, C, CI, Q, QF, nq, tables)
        if 2 * nc > A.shape[0] and fric:
            A = np.zeros((2 * nc, 2 * nc))
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
        grown = math.inf
        turner = -1  # the contact whose turning last limited a step
        FG[F_DT_MIN] = min(FG[F_DT_MIN], dt)
        geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
        springs(X, C, CI, na, nc, grav)
        e_start = energy(X, C, na, nc, grav, spin)
        t_phase = t
        e_room = max(abs(e_start), energy_scale(X, C, na, nc, grav, spin))
        if record:
            # Where a body's free flight ends and its steps begin.
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
            if carried:
                # The last step met no mode's edge: decide would keep every mode (in the plane a
                # held direction counts by its side only) and settle nothing (the step's end
                # did), and its mode values at the end are this step's at the start.
                for k in range(2 * nc):
                    E[k, E_V0], E[k, E_R0] = E[k, E_V1], E[k, E_R1]
            elif fric:
                if not stepped:
                    geometry(X, C, CI, nc, WP, fl[FL_SEED], fl[FL_FRICTION])
                    springs(X, C, CI, na, nc, grav)
                done, ok, turned, solved = decide(X, C, CI, na, nc, stuck, A, b, fl, scale)
                share(G, XI, na, done)
                if not ok or not mode_events(X, C, CI, E, na, nc, E_V0, E_R0, stuck, A, b, fl, scale,
                                             YES if turned else NO, YES if solved else NO):
                    ST[S_STATUS] = SINGULAR
                    FG[F_STATUS_T] = t
                    break
                for c in range(nc):
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
            h, work, ok, limited, late, located = step_events(G, GI, X, C, CI, Q, QF, E, na, nc, nq, t, h_full,
                                                              weights, WP, grav, stuck, A, b, fl, scale, max_turn,
                                                              negligible,
                                                              nudge, reach, briefs, exact, ST, omega)
            if not located:
                if ST[S_UNLOCATED] == 0:
                    FG[F_UNLOCATED_T] = t
                ST[S_UNLOCATED] += 1
            if late >= 0:
                # Engage it from here: back to the step's start, and a new phase.
                for a in range(na):
                    for d in range(13):
                        X[a, X_S + d] = X[a, X_S0 + d]
                Q[late, Q_ENG] = LATE
                changed = True
                restarts += 1
                if restarts > STALL_LIMIT:
                    ST[S_STATUS] = STALL
                    FG[F_STATUS_T], FG[F_STATUS_A] = t, 3.0
                break
            restarts = 0
            for k in range(nq):
                if Q[k, Q_ENG] == LATE:
                    Q[k, Q_ENG] = 1
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
                # A band value counted as just inside that this step landed at once, no further
                # from its edge than it started (within MODE_TOL): a slip grazing the band's edge,
                # heading in at first and turning out again within MODE_TOL of it. Counted as
                # just inside again, it was landed again a step on, each step shorter, until the
                # run stalled (a pile of 27 spheres: 20 000 steps at t = 0.394634 s). The next
                # step leaves its value as it is (CI_GRAZE): over it the slip strays from the edge
                # by no more than the event tolerance allows a landing.
                for k in range(2 * nc):
                    if E[k, E_FORCED] == YES and abs(E[k, E_V1]) <= MODE_TOL and CI[k % nc, CI_MODE] == BAND:
                        CI[k % nc, CI_GRAZE] = YES
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
            for a in range(na):
                for d in range(6):
                    if not math.isfinite(X[a, X_S + d]):
                        ST[S_STATUS] = NONFINITE
            if ST[S_STEPS] > fl[FL_MAXSTEPS]:
                ST[S_STATUS] = MAXSTEPS
            if ST[S_STATUS] != OK:
                FG[F_STATUS_T] = t
                break
            for c in range(nc):
                FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], C[c, C_DELTA])
                FG[F_MAX_FORCE] = max(FG[F_MAX_FORCE], C[c, C_FN])
            if record:
                KN, RC = record_step(KN, RC, CNT, G, GI, X, XI, C, CI, na, nc, t, fl)
            for k in range(nq):
                d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
                if engaged(Q, k, d, r, WP, grav) != Q[k, Q_ENG]:
                    changed = True
            # Every mode value clear of its edge at the step's end, by twice what decide counts as
            # on it (its own closing trial evaluated them there, at these modes).
            carried = fric and located and fl[FL_PLANAR] == YES
            for k in range(2 * nc if carried else 0):
                if not E[k, E_V1] > 2.0 * EDGE_TOL:
                    carried = False
                    break
            if fric and located and not carried and not changed and fl[FL_PLANAR] == YES and h > 0.0:
                # A stuck contact whose hold force came to zero here (from above, over this step)
                # and would cross the band quickly enough: `decide` flips it to the other edge.
                for c in range(nc):
                    if flips(C, CI, E, nc, c, h, omega, scale):
                        CI[c, CI_EDGE] = FLIP
        # The phase ends here: the stepped bodies go back to base states at t.
        e_end = energy(X, C, na, nc, grav, spin)
        # Phases that end where they began, over and over, are a stall, never a hang.
        idle = idle + 1 if t == t_phase else 0
        if idle > STALL_LIMIT and ST[S_STATUS] == OK:
            ST[S_STATUS] = STALL
            FG[F_STATUS_T] = t
        # An unstable step multiplies the energy every step: half the scale is reached in a few.
        if e_end - e_start > 0.5 * e_room + 1e-300 and ST[S_STATUS] == OK:
            ST[S_STATUS] = ENERGY
            FG[F_STATUS_T], FG[F_STATUS_A], FG[F_STATUS_B] = t, e_start, e_end
        for a in range(na):
            g = XI[a]
            for d in range(13):
                G[g, G_S + d] = X[a, X_S + d]
            G[g, G_TB] = t
            GI[g, GI_LOC] = -1
        if record and changed:
            # Bodies whose every contact has ended fly freely from their last knot.
            for a in range(na):
                g = XI[a]
                still = False
                for k in range(nq):
                    if Q[k, Q_I] == g or Q[k, Q_J] == g:
                        d, r = overlap(G, GI, X, Q, QF, k, t, WP, grav)
                        still = still or engaged(Q, k, d, r, WP, grav)
                if not still and GI[g, GI_KNOT] >= 0:
                    KN[GI[g, GI_KNOT], K_FREE] = 1.0
    return KN, RC, IV, OP


@jit
def share(G, XI, na, work):
    """An island step's dissipated work, shared among its stepped bodies (their sum is exact at
    the step's end, where every one of them has a knot)."""
    if work != 0.0 and na > 0:
        for a in range(na):
            G[XI[a], G_WK] += work / na


# ---------------------------------------------------------------------------------------------
# A run: windows of islands


@jit
def positions_at(G, n, t, grav, P, V):
    for i in range(n):
        px, py, pz, ux, uy, uz = free_state(G, i, t, grav)
        P[i, 0], P[i, 1], P[i, 2] = px, py, pz
        V[i, 0], V[i, 1], V[i, 2] = ux, uy, uz


@jit
def engaged_now(G, P, V, n, WP, grav, dim):
    """Contacts engaged at positions P and velocities V: (K, 2), walls as (i, -1 - wall)."""
    margin = np.zeros(n)
    for i in range(n):
        margin[i] = 2.0 * TOUCH_TOL * G[i, G_R]
    pairs = near_pairs(P, G[:, G_R], margin, n, dim)
    out = np.empty((pairs.shape[0] + n * WP.shape[0] + 1, 2), np.int64)
    m = 0
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        reach = G[i, G_R] + G[j, G_R]
        d = (reach - dist) / reach
        r = (V[i, 0] - V[j, 0]) * dx + (V[i, 1] - V[j, 1]) * dy + (V[i, 2] - V[j, 2]) * dz
        if d > TOUCH_TOL or (d >= -TOUCH_TOL and r > 0):
            out[m, 0], out[m, 1] = i, j
            m += 1
    for w in range(WP.shape[0]):
        into = grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5] < 0
        for i in range(n):
            h = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + (P[i, 2] - WP[w, 2]) * WP[w, 5]
            d = (G[i, G_R] - h) / G[i, G_R]
            r = -(V[i, 0] * WP[w, 3] + V[i, 1] * WP[w, 4] + V[i, 2] * WP[w, 5])
            if d > TOUCH_TOL or (d >= -TOUCH_TOL and (r > 0 or (r == 0 and into))):
                out[m, 0], out[m, 1] = i, -1 - w
                m += 1
    return out[:m]


@jit_inline
def approaches(P, V, i, j, slow, floor, scale):
    """Whether bodies i and j close along their line of centres faster than `slow` times their
    speed scales (`speed_scales`: round-off of the speeds the pair itself carries, never of the
    scene's fastest body, beside which a slow pair would pass through unseen) and than `floor`
    (m/s)."""
    dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
    closing = -((V[j, 0] - V[i, 0]) * dx + (V[j, 1] - V[i, 1]) * dy + (V[j, 2] - V[i, 2]) * dz)
    return closing > max(slow * (scale[i] + scale[j]), floor) * math.sqrt(dx * dx + dy * dy + dz * dz)


@jit
def speed_scales(V, n, IV, CNT):
    """Each body's speed scale for round-off: the fastest speed now among the bodies it has
    exchanged momentum with, directly or through others, itself included (a ball a Newton's
    cradle left at rest keeps the round-off of the speed it passed on, not a speed of its own)."""
    parent = np.arange(n)
    for k in range(CNT[CN_IVALS]):
        i, j = int(IV[k, V_I]), int(IV[k, V_J])
        if i >= 0 and j >= 0:
            join(parent, i, j)
    top = np.zeros(n)
    for i in range(n):
        r = root_of(parent, i)
        top[r] = max(top[r], math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2))
    out = np.empty(n)
    for i in range(n):
        out[i] = top[root_of(parent, i)]
    return out


@jit
def next_contact(G, P, V, n, t, WP, grav, dim, horizon, every_pair, slow, scale):
    """The earliest contact start after t, looking `horizon` ahead (every pair if asked). Two
    bodies closing at under `slow` times their speed scales are taken as not approaching: what is
    left of a perfect exchange of velocities, round-off, would otherwise meet again billions of
    seconds later."""
    best = math.inf
    if every_pair:
        for i in range(n):
            for j in range(i + 1, n):
                if approaches(P, V, i, j, slow, 0.0, scale):
                    best = min(best, touch_time(G, i, j, t, WP, grav))
    else:
        g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
        margin = np.empty(n)
        for i in range(n):
            margin[i] = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) * horizon + 0.5 * g * horizon ** 2
        pairs = near_pairs(P, G[:, G_R], margin, n, dim)
        for p in range(pairs.shape[0]):
            i, j = pairs[p, 0], pairs[p, 1]
            if approaches(P, V, i, j, slow, 0.0, scale):
                best = min(best, touch_time(G, i, j, t, WP, grav))
    for w in range(WP.shape[0]):
        for i in range(n):
            best = min(best, touch_time(G, i, -1 - w, t, WP, grav))
    return best


@jit
def meets_again(G, P, V, n, t, WP, grav, IV, CNT, slow, resolved, within, scale):
    """Whether a wall or a pair meets again after t, a pair only if it closes faster than its
    velocities are known: each contact a body took part in left it with the run's resolved
    velocity error at most (`resolved`, m/s), so a pair whose bodies had c_i and c_j contacts
    closes by error alone below (c_i + c_j) resolved (a Newton's cradle at tol 1e-7: its middle
    balls, two contacts each, parted at 8e-8 m/s and closed at 1.07e-7, met again 7.8 hours on).
    A pair that closes slower than that but meets `within` (before the run would end) meets:
    ended without it, the two would end the run inside each other."""
    count = np.zeros(n)
    for k in range(CNT[CN_IVALS]):
        for col in (V_I, V_J):
            b = int(IV[k, col])
            if b >= 0:
                count[b] += 1.0
    for i in range(n):
        for j in range(i + 1, n):
            if not approaches(P, V, i, j, slow, 0.0, scale):
                continue
            tau = touch_time(G, i, j, t, WP, grav)
            floor = (count[i] + count[j]) * resolved
            if tau <= within or (tau < math.inf and approaches(P, V, i, j, slow, floor, scale)):
                return True
    for w in range(WP.shape[0]):
        for i in range(n):
            if touch_time(G, i, -1 - w, t, WP, grav) < math.inf:
                return True
    return False


@jit
def window_candidates(G, P, V, n, eng, tables, horizon, safety, WP, grav, dim):
    """Contacts that may go on or start within the window: pairs and walls whose gap could close
    within `horizon`, each body's speed bounded by the energy its engaged cluster holds (spin
    included: friction can turn it into motion), plus gravity's pull. (K, 2), and each body's
    margin (how far it was taken to move)."""
    ptab, wtab = tables
    parent = np.arange(n)
    for p in range(eng.shape[0]):
        if eng[p, 1] >= 0:
            join(parent, eng[p, 0], eng[p, 1])
    pool = np.zeros(n)
    clustered = np.zeros(n, np.bool_)
    for p in range(eng.shape[0]):
        i, j = eng[p, 0], eng[p, 1]
        mi = int(G[i, G_MAT])
        if j >= 0:
            k = ptab[mi, int(G[j, G_MAT]), TP_K]
            dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
            delta = G[i, G_R] + G[j, G_R] - math.sqrt(dx * dx + dy * dy + dz * dz)
            clustered[j] = True
        else:
            w = -1 - j
            k = wtab[mi, TP_K]
            delta = G[i, G_R] - ((P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4]
                                 + (P[i, 2] - WP[w, 2]) * WP[w, 5])
        clustered[i] = True
        pool[root_of(parent, i)] += 0.5 * k * max(delta, 0.0) ** 2
    for i in range(n):
        if clustered[i]:
            pool[root_of(parent, i)] += 0.5 * G[i, G_M] * (V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) + \
                0.5 * G[i, G_I] * (G[i, G_W] ** 2 + G[i, G_W + 1] ** 2 + G[i, G_W + 2] ** 2)
    g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
    margin = np.empty(n)
    for i in range(n):
        speed = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2)
        if clustered[i]:
            speed = max(speed, math.sqrt(2.0 * pool[root_of(parent, i)] / G[i, G_M]))
        margin[i] = safety * (speed * horizon + 0.5 * g * horizon * horizon) + 2.0 * TOUCH_TOL * G[i, G_R]
    pairs = near_pairs(P, G[:, G_R], margin, n, dim)
    out = np.empty((pairs.shape[0] + n * WP.shape[0], 2), np.int64)
    m = 0
    for p in range(pairs.shape[0]):
        out[m, 0], out[m, 1] = pairs[p, 0], pairs[p, 1]
        m += 1
    for w in range(WP.shape[0]):
        for i in range(n):
            gap = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + \
                (P[i, 2] - WP[w, 2]) * WP[w, 5] - G[i, G_R]
            if gap <= margin[i]:
                out[m, 0], out[m, 1] = i, -1 - w
                m += 1
    return out[:m], margin


@jit
def missed_contact(G, P, V, n, t, cand, WP, grav, dim, P0, margin):
    """Whether bodies (or a body and a wall) overlap at t without having been candidates, or
    went through each other since the window's start (positions P0)."""
    positions_at(G, n, t, grav, P, V)
    # Each body's candidates, for a quick lookup (CSR).
    start = np.zeros(n + 1, np.int64)
    for k in range(cand.shape[0]):
        start[cand[k, 0] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start.copy()
    other = np.empty(cand.shape[0], np.int64)
    for k in range(cand.shape[0]):
        other[fill[cand[k, 0]]] = cand[k, 1]
        fill[cand[k, 0]] += 1
    eng = engaged_now(G, P, V, n, WP, grav, dim)
    for p in range(eng.shape[0]):
        i, j = eng[p, 0], eng[p, 1]
        if j >= 0:
            dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
            reach = G[i, G_R] + G[j, G_R]
            deep = reach - math.sqrt(dx * dx + dy * dy + dz * dz) > 1e-9 * reach
        else:
            w = -1 - j
            h = (P[i, 0] - WP[w, 0]) * WP[w, 3] + (P[i, 1] - WP[w, 1]) * WP[w, 4] + (P[i, 2] - WP[w, 2]) * WP[w, 5]
            deep = G[i, G_R] - h > 1e-9 * G[i, G_R]
        if not deep:
            continue
        found = False
        for k in range(start[i], start[i + 1]):
            if other[k] == j:
                found = True
                break
        if not found:
            return True
    return crossed(P0, P, G, n, start, other, margin)


@jit
def crossed(P0, P, G, n, start, other, margin):
    """Whether two bodies, neither the other's candidate, went through each other between P0 and
    P. Only a body that moved past its margin can have (a speed bound that failed: a body at rest
    sent on by a candidate within the window, in a row of spheres, went through the next one
    whole, touching it at neither end). Their relative motion taken straight from P0 to P; in 1D
    exact: their order flipped."""
    for i in range(n):
        mx, my, mz = P[i, 0] - P0[i, 0], P[i, 1] - P0[i, 1], P[i, 2] - P0[i, 2]
        if mx * mx + my * my + mz * mz <= margin[i] * margin[i]:
            continue
        for j in range(n):
            if j == i or listed(start, other, i, j) or listed(start, other, j, i):
                continue
            ax, ay, az = P0[j, 0] - P0[i, 0], P0[j, 1] - P0[i, 1], P0[j, 2] - P0[i, 2]
            ux = P[j, 0] - P[i, 0] - ax
            uy = P[j, 1] - P[i, 1] - ay
            uz = P[j, 2] - P[i, 2] - az
            uu = ux * ux + uy * uy + uz * uz
            s = min(max(-(ax * ux + ay * uy + az * uz) / uu, 0.0), 1.0) if uu > 0.0 else 0.0
            cx, cy, cz = ax + ux * s, ay + uy * s, az + uz * s
            reach = G[i, G_R] + G[j, G_R]
            if cx * cx + cy * cy + cz * cz < reach * reach:
                return True
    return False


@jit_inline
def listed(start, other, i, j):
    """Whether j is among i's candidates (CSR)."""
    for k in range(start[i], start[i + 1]):
        if other[k] == j:
            return True
    return False


@jit
def tail_after(tail, IV, CNT):
    """After the last separation, keep going long enough to see the bodies part."""
    if tail == tail:
        return tail
    first, last = math.inf, -math.inf
    for k in range(CNT[CN_IVALS]):
        first = min(first, IV[k, V_START])
        if IV[k, V_END] == IV[k, V_END]:
            last = max(last, IV[k, V_END])
    if last == -math.inf:
        return NO_CONTACT_TAIL
    return max(2.0 * (last - first), 0.1 * last)


@jit
def largest_set(parent, n):
    size = np.zeros(n, np.int64)
    big = 0
    for i in range(n):
        r = root_of(parent, i)
        size[r] += 1
        big = max(big, size[r])
    return big


@jit
def lone_on_walls(cand, eng, n):
    """Whether a window's candidates are its engaged contacts and each a body alone on one wall
    (a ball resting or rolling on a floor): nothing else can come in, and its rest phase may
    repeat its cycles over a long window."""
    if cand.shape[0] != eng.shape[0]:
        return False
    seen = np.zeros(n, np.int64)
    for k in range(cand.shape[0]):
        if cand[k, 1] >= 0 or seen[cand[k, 0]]:
            return False
        seen[cand[k, 0]] = 1
    return True


@jit
def windows(G, GI, tables, WP, grav, weights, fl, fp, bufs, CNT, ST, FG):
    """Advance every body to the run's end (see the README's engine notes): jump to the next
    contact start while nothing touches; otherwise a window of islands. Returns the buffers and
    the final time."""
    KN, RC, IV, OP = bufs
    n = G.shape[0]
    dim = fl[FL_DIM]
    P = np.zeros((n, 3))
    V = np.zeros((n, 3))
    t = 0.0
    t_end = fp[FP_TEND]
    search = math.inf
    span = float(WINDOW_STEPS)  # the next window's length, in steps of its stiffest contact
    ticks = 0  # jumps in a row to a contact due within the clock's resolution
    while ST[S_STATUS] == OK and t < t_end:
        fp[FP_NOW] = t
        fp[FP_NOW_STEPS] = ST[S_STEPS]
        positions_at(G, n, t, grav, P, V)
        eng = engaged_now(G, P, V, n, WP, grav, dim)
        if eng.shape[0] == 0:
            small = YES if n <= 64 else NO
            scale = speed_scales(V, n, IV, CNT)
            if (t_end == math.inf and small == YES and CNT[CN_IVALS] > 0 and fp[FP_END_SLOW] > 0.0
                    and not meets_again(G, P, V, n, t, WP, grav, IV, CNT, fp[FP_SLOW], fp[FP_END_SLOW],
                                        run_end(t, fp, IV, CNT) - t, scale)):
                # What still approaches closes slower than the run resolves velocities (its
                # tolerance): the step's error, not a contact to come (a Newton's cradle at k =
                # 1e6, tol 1e-7, left its balls at 1e-8 m/s and met them again 11 hours later).
                t = t_end = run_end(t, fp, IV, CNT)
                ST[S_JUMPS] += 1
                break
            # Nothing touches: jump to the next contact start (nothing to record in free flight).
            if search == math.inf:
                fastest = 0.0
                for i in range(n):
                    fastest = max(fastest, math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2))
                search = 4.0 * G[0, G_R] / fastest if fastest > 0 else 1.0
            horizon = min(search, t_end - t)
            tau = next_contact(G, P, V, n, t, WP, grav, dim, horizon, small, fp[FP_SLOW], scale)
            if tau <= horizon or (small == YES and tau < math.inf):
                if not min(t + tau, t_end) > t:
                    # A contact due closer than the clock resolves lands on its next tick (see
                    # run_island); one that still does not engage tick after tick (bodies far
                    # from the origin, where positions are coarse) is refused, never a hang.
                    ticks += 1
                    if ticks > STALL_LIMIT:
                        ST[S_STATUS] = STALL
                        FG[F_STATUS_T] = t
                        break
                    t = np.nextafter(t, math.inf)
                    ST[S_JUMPS] += 1
                    continue
                ticks = 0
                t = min(t + tau, t_end)
                ST[S_JUMPS] += 1
                search = 2.0 * tau if tau > 0 else search
                continue
            ST[S_JUMPS] += 1
            if t_end < math.inf:
                t = min(t + horizon, t_end)
                search *= 2.0
                continue
            tau = next_contact(G, P, V, n, t, WP, grav, dim, horizon, YES, fp[FP_SLOW], scale)
            if tau < math.inf:
                t += tau
                continue
            t = t_end = run_end(t, fp, IV, CNT)  # no contact ahead
            break
        # A window: islands of the bodies that may meet within it.
        omega = 0.0
        ptab, wtab = tables
        for p in range(eng.shape[0]):
            i, j = eng[p, 0], eng[p, 1]
            mi = int(G[i, G_MAT])
            k = ptab[mi, int(G[j, G_MAT]), TP_K] if j >= 0 else wtab[mi, TP_K]
            omega = max(omega, math.sqrt(k * (G[i, G_IM] + (G[j, G_IM] if j >= 0 else 0.0))))
        step_est = fp[FP_OMEGA_H] / omega if fl[FL_AUTO] else fp[FP_DT]
        horizon = min(span * step_est, t_end - t)
        saved_G = G.copy()
        saved_GI = GI.copy()
        saved_CNT = CNT.copy()
        saved_OP = OP[:CNT[CN_OPEN]].copy()
        saved_flags = np.zeros(n)
        for i in range(n):
            if GI[i, GI_KNOT] >= 0:
                saved_flags[i] = KN[GI[i, GI_KNOT], K_FREE]
        # The largest cluster of touching bodies: islands much bigger than it mean the window
        # is long enough for free bodies to chain up, and every step would cost the chain.
        parent = np.arange(n)
        for p in range(eng.shape[0]):
            if eng[p, 1] >= 0:
                join(parent, eng[p, 0], eng[p, 1])
        touching = largest_set(parent, n)
        retries = 0
        safety = WINDOW_SAFETY
        halved = False
        P0 = P.copy()
        while True:
            cand, margin = window_candidates(G, P, V, n, eng, tables, horizon, safety, WP, grav, dim)
            parent = np.arange(n)
            for k in range(cand.shape[0]):
                if cand[k, 1] >= 0:
                    join(parent, cand[k, 0], cand[k, 1])
            if largest_set(parent, n) > max(ISLAND_SLACK * touching, 16) and horizon > 4.0 * step_est:
                horizon *= 0.5
                halved = True
                continue
            # Not recorded: a recording's residuals are drawn where every body has a knot, at
            # window ends among others (two balls on a floor, apart: 8 such in 0.3 s, not 94).
            # A lone body stepped (a slip turning too fast for the closed form) then takes other
            # steps recorded than not: the two differ by the stepped path's own error. With a
            # given dt nothing repeats.
            lone = fl[FL_AUTO] and not fl[FL_RECORD] and lone_on_walls(cand, eng, n)
            if not lone and horizon > WINDOW_STEPS * step_est:
                # A window grown past WINDOW_STEPS while its bodies were each alone on a wall: now
                # something may come in.
                horizon = min(WINDOW_STEPS * step_est, t_end - t)
                halved = True
                continue
            # Bucket the candidates by island (counting sort on the island's root).
            count = np.zeros(n + 1, np.int64)
            for k in range(cand.shape[0]):
                count[root_of(parent, cand[k, 0]) + 1] += 1
            for i in range(n):
                count[i + 1] += count[i]
            fill = count.copy()
            order = np.empty(cand.shape[0], np.int64)
            for k in range(cand.shape[0]):
                r = root_of(parent, cand[k, 0])
                order[fill[r]] = k
                fill[r] += 1
            for r in range(n):
                k0, k1 = count[r], count[r + 1]
                if k1 == k0:
                    continue
                Q = np.zeros((k1 - k0, 3), np.int64)
                QF = np.zeros((k1 - k0, NQF))
                for k in range(k0, k1):
                    i, j = cand[order[k], 0], cand[order[k], 1]
                    Q[k - k0, Q_I], Q[k - k0, Q_J] = i, j
                    QF[k - k0, QF_REACH] = G[i, G_R] + (G[j, G_R] if j >= 0 else 0.0)
                KN, RC, IV, OP = run_island(G, GI, Q, QF, t, t + horizon, tables, WP, grav, weights, fl, fp,
                                            (KN, RC, IV, OP), CNT, ST, FG)
                if ST[S_STATUS] != OK:
                    break
            if ST[S_STATUS] != OK or not missed_contact(G, P, V, n, t + horizon, cand, WP, grav, dim, P0, margin):
                break
            # A contact between islands: a speed bound failed. Redo the window, shorter and safer.
            ST[S_RETRIES] += 1
            retries += 1
            if retries > MAX_RETRIES:
                ST[S_STATUS] = STALL
                FG[F_STATUS_T], FG[F_STATUS_A] = t, 1.0
                break
            for i in range(n):
                for d in range(NG):
                    G[i, d] = saved_G[i, d]
                GI[i, 0], GI[i, 1] = saved_GI[i, 0], saved_GI[i, 1]
            for d in range(4):
                CNT[d] = saved_CNT[d]
            for k in range(CNT[CN_OPEN]):
                OP[k] = saved_OP[k]
                IV[OP[k], V_END] = math.nan
            for i in range(n):
                if GI[i, GI_KNOT] >= 0:
                    KN[GI[i, GI_KNOT], K_FREE] = saved_flags[i]
            horizon *= 0.25
            safety *= 2.0
            positions_at(G, n, t, grav, P, V)
        t += horizon
        ST[S_WINDOWS] += 1
        search = math.inf
        # The next window starts from this one's length, or twice it if it was not cut: the
        # candidates of a window far too long cost most of a dense run (gas-box: 64 steps, its
        # islands spanning the box, halved to 16 in each of its windows, 3 candidate searches).
        span = min(LONE_WINDOW_STEPS if lone else WINDOW_STEPS,
                   horizon / step_est * (1.0 if halved or retries > 0 else 2.0))
    return KN, RC, IV, OP, t


@jit
def run_end(t, fp, IV, CNT):
    """When a run that ends by itself ends: a tail after the last separation (free flight since),
    or after t if nothing ever touched."""
    tail = tail_after(fp[FP_TAIL], IV, CNT)
    if CNT[CN_IVALS] == 0:
        return t + tail
    last = 0.0
    for k in range(CNT[CN_IVALS]):
        if IV[k, V_END] == IV[k, V_END]:
            last = max(last, IV[k, V_END])
    return last + tail


@jit
def simulate(G, tables, WP, grav, weights, fl, fp):
    """Run one scene from the state in G (base time 0) to its end. Returns (final time, knots,
    contact records, contact intervals, counters, figures); G holds the final state."""
    n = G.shape[0]
    GI = np.full((n, 2), -1, np.int64)
    KN = np.empty((max(64, 4 * n), NK))
    RC = np.empty((64, NR))
    IV = np.empty((16, 4))
    OP = np.empty(16, np.int64)
    CNT = np.zeros(4, np.int64)
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = math.inf
    acc = np.zeros(3)
    for d in range(3):
        acc[d] = grav[d]
    if fl[FL_RECORD]:
        for i in range(n):
            KN = add_knot(KN, CNT, 0.0, i, 1.0, G, i, G_S, G_V, G_W, G_Q, acc, 0.0)
            GI[i, GI_KNOT] = i
    KN, RC, IV, OP, t = windows(G, GI, tables, WP, grav, weights, fl, fp, (KN, RC, IV, OP), CNT, ST, FG)
    for i in range(n):
        bring(G, i, t, grav, fl)
        if fl[FL_RECORD] and not (GI[i, GI_KNOT] >= 0 and KN[GI[i, GI_KNOT], K_T] == t):
            KN = add_knot(KN, CNT, t, i, 1.0, G, i, G_S, G_V, G_W, G_Q, acc, G[i, G_WK])
            GI[i, GI_KNOT] = CNT[CN_KNOTS] - 1
    for k in range(CNT[CN_OPEN]):
        IV[OP[k], V_END] = t
    return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG


# ---------------------------------------------------------------------------------------------
# The report's own update (section III), on its fixed grid


@jit
def seed_forces(G, pairs, WP, grav, tables, fl, force, facc, alp, RC, CNT, t_rec):
    """The report's forces at the bodies' base states: springs clamped at zero overlap, and
    friction mu F_n against the slip when it exceeds eps (explicit), the slip measured with the
    slip lever and the torque applied at the contact point. Fills force (springs), facc
    (friction, as accelerations) and alp, records each pressed contact at t_rec (when
    recording); returns the largest overlap and the records."""
    ptab, wtab = tables
    n = G.shape[0]
    seed, spin, fric = fl[FL_SEED], fl[FL_SPIN], fl[FL_FRICTION]
    for i in range(n):
        for d in range(3):
            force[i, d] = 0.0
            facc[i, d] = 0.0
            alp[i, d] = 0.0
    top = 0.0
    npair = pairs.shape[0]
    for p in range(npair + n * WP.shape[0]):
        if p < npair:
            i, j = pairs[p, 0], pairs[p, 1]
        else:
            i, j = (p - npair) % n, -1 - (p - npair) // n
        r = G[i, G_R]
        mi = int(G[i, G_MAT])
        if j >= 0:
            dx, dy, dz = G[j, G_S] - G[i, G_S], G[j, G_S + 1] - G[i, G_S + 1], G[j, G_S + 2] - G[i, G_S + 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            nx, ny, nz = dx / dist, dy / dist, dz / dist
            delta = r + G[j, G_R] - dist
            mj = int(G[j, G_MAT])
            k, mu, eps = ptab[mi, mj, TP_K], ptab[mi, mj, TP_MU], ptab[mi, mj, TP_EPS]
            half = 0.5 * delta
        else:
            w = -1 - j
            dist = (G[i, G_S] - WP[w, 0]) * WP[w, 3] + (G[i, G_S + 1] - WP[w, 1]) * WP[w, 4] + \
                (G[i, G_S + 2] - WP[w, 2]) * WP[w, 5]
            nx, ny, nz = -WP[w, 3], -WP[w, 4], -WP[w, 5]
            delta = r - dist
            k, mu, eps = wtab[mi, TP_K], wtab[mi, TP_MU], wtab[mi, TP_EPS]
            half = delta
        if delta <= 0.0:
            continue
        top = max(top, delta)
        fn = k * delta
        if fl[FL_RECORD]:
            RC = grow(RC, CNT[CN_RECS])
            row = CNT[CN_RECS]
            RC[row, R_T], RC[row, R_I], RC[row, R_J] = t_rec, i, j
            RC[row, R_DELTA], RC[row, R_FN] = delta, fn
            RC[row, R_FX], RC[row, R_FY], RC[row, R_FZ], RC[row, R_MODE] = 0.0, 0.0, 0.0, 0.0
            CNT[CN_RECS] += 1
        force[i, 0] -= fn * nx
        force[i, 1] -= fn * ny
        force[i, 2] -= fn * nz
        if j >= 0:
            force[j, 0] += fn * nx
            force[j, 1] += fn * ny
            force[j, 2] += fn * nz
        if not fric:
            continue
        lif = r - half
        ljf = G[j, G_R] - half if j >= 0 else 0.0
        lis = r if seed else lif
        ljs = (G[j, G_R] if seed else ljf) if j >= 0 else 0.0
        rx, ry, rz = G[i, G_V], G[i, G_V + 1], G[i, G_V + 2]
        lx, ly, lz = lis * G[i, G_W], lis * G[i, G_W + 1], lis * G[i, G_W + 2]
        if j >= 0:
            rx, ry, rz = rx - G[j, G_V], ry - G[j, G_V + 1], rz - G[j, G_V + 2]
            lx, ly, lz = lx + ljs * G[j, G_W], ly + ljs * G[j, G_W + 1], lz + ljs * G[j, G_W + 2]
        rn = rx * nx + ry * ny + rz * nz
        sx = rx - rn * nx + ly * nz - lz * ny
        sy = ry - rn * ny + lz * nx - lx * nz
        sz = rz - rn * nz + lx * ny - ly * nx
        mag = math.sqrt(sx * sx + sy * sy + sz * sz)
        if not mag > eps:
            continue
        f = -mu * fn / mag
        fx, fy, fz = f * sx, f * sy, f * sz
        if fl[FL_RECORD]:
            row = CNT[CN_RECS] - 1
            RC[row, R_FX], RC[row, R_FY], RC[row, R_FZ], RC[row, R_MODE] = fx, fy, fz, SLIDE
        cx, cy, cz = ny * fz - nz * fy, nz * fx - nx * fz, nx * fy - ny * fx
        facc[i, 0] += fx * G[i, G_IM]
        facc[i, 1] += fy * G[i, G_IM]
        facc[i, 2] += fz * G[i, G_IM]
        if spin:
            alp[i, 0] += lif * G[i, G_II] * cx
            alp[i, 1] += lif * G[i, G_II] * cy
            alp[i, 2] += lif * G[i, G_II] * cz
        if j >= 0:
            facc[j, 0] -= fx * G[j, G_IM]
            facc[j, 1] -= fy * G[j, G_IM]
            facc[j, 2] -= fz * G[j, G_IM]
            if spin:
                alp[j, 0] += ljf * G[j, G_II] * cx
                alp[j, 1] += ljf * G[j, G_II] * cy
                alp[j, 2] += ljf * G[j, G_II] * cz
    return top, RC


@jit
def seed_run(G, tables, WP, grav, fl, fp):
    """The report's update on its grid of dt: forces from the current state, then w += alpha dt,
    s += v dt + a dt^2 / 2, v += a dt (first order; it reproduces the report's tables). Free
    flight between contacts jumps whole steps in closed form, so every step lands on the grid.
    Returns what `simulate` returns."""
    n = G.shape[0]
    dim = fl[FL_DIM]
    dt = fp[FP_DT]
    spin, planar, record = fl[FL_SPIN], fl[FL_PLANAR], fl[FL_RECORD]
    KN = np.empty((max(64, 4 * n), NK))
    RC = np.empty((64, NR))
    IV = np.empty((16, 4))
    CNT = np.zeros(4, np.int64)
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = dt
    P = np.zeros((n, 3))
    V = np.zeros((n, 3))
    force = np.zeros((n, 3))
    facc = np.zeros((n, 3))
    alp = np.zeros((n, 3))
    acc = np.zeros((n, 3))
    g3 = np.zeros(3)
    for d in range(3):
        g3[d] = grav[d]
    knot_of = np.zeros(n, np.int64)
    if record:
        for i in range(n):
            KN = add_knot(KN, CNT, 0.0, i, 1.0, G, i, G_S, G_V, G_W, G_Q, g3, 0.0)
            knot_of[i] = i
    t = 0.0
    t_end = fp[FP_TEND]
    in_contact = False

    while t < t_end * (1 - 1e-15) and ST[S_STATUS] == OK:
        fp[FP_NOW] = t
        fp[FP_NOW_STEPS] = ST[S_STEPS]
        positions_at(G, n, t, grav, P, V)
        margin = np.zeros(n)
        for i in range(n):
            margin[i] = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) * dt + 1e-12 * G[i, G_R]
        pairs = near_pairs(P, G[:, G_R], margin, n, dim)
        for i in range(n):
            bring(G, i, t, grav, fl)
        top, RC = seed_forces(G, pairs, WP, grav, tables, fl, force, facc, alp, RC, CNT, t + dt)
        if top > 0.0:
            if not in_contact:
                in_contact = True

                IV = grow(IV, CNT[CN_IVALS])
                IV[CNT[CN_IVALS], V_I] = -1.0
                IV[CNT[CN_IVALS], V_J] = -1.0
                IV[CNT[CN_IVALS], V_START] = t
                IV[CNT[CN_IVALS], V_END] = math.nan
                CNT[CN_IVALS] += 1
                ST[S_CONTACTS] += 1
            FG[F_MAX_OVERLAP] = max(FG[F_MAX_OVERLAP], top)
            before = 0.0
            after = 0.0
            for i in range(n):
                for d in range(3):
                    acc[i, d] = force[i, d] * G[i, G_IM] + grav[d] + facc[i, d]
            # Work against friction: what the friction kick removes at the start of the step.
            for i in range(n):
                for d in range(3):
                    vm = G[i, G_V + d] + facc[i, d] * dt
                    before += 0.5 * G[i, G_M] * G[i, G_V + d] ** 2
                    after += 0.5 * G[i, G_M] * vm * vm
                    if spin:
                        before += 0.5 * G[i, G_I] * G[i, G_W + d] ** 2
                        after += 0.5 * G[i, G_I] * (G[i, G_W + d] + alp[i, d] * dt) ** 2
            work = before - after
            if record:
                # A knot where the step starts (within a seed step the motion is exactly
                # quadratic: the step's acceleration on both of its sides).
                for i in range(n):
                    last = knot_of[i]
                    if KN[last, K_T] < t:
                        KN = add_knot(KN, CNT, t, i, 0.0, G, i, G_S, G_V, G_W, G_Q, g3, G[i, G_WK])
                        last = CNT[CN_KNOTS] - 1
                        knot_of[i] = last
                    KN[last, K_FREE] = 0.0
                    for d in range(3):
                        KN[last, K_AN + d] = acc[i, d]
            for i in range(n):
                w0x, w0y, w0z = G[i, G_W], G[i, G_W + 1], G[i, G_W + 2]
                for d in range(3):
                    G[i, G_W + d] += alp[i, d] * dt
                    G[i, G_S + d] += G[i, G_V + d] * dt + 0.5 * acc[i, d] * dt * dt
                    G[i, G_V + d] += acc[i, d] * dt
                if spin:
                    turn(G[i, G_Q:G_Q + 4], 0.5 * (w0x + G[i, G_W]), 0.5 * (w0y + G[i, G_W + 1]),
                         0.5 * (w0z + G[i, G_W + 2]), dt, planar)
                G[i, G_WK] += work / n
                G[i, G_TB] = t + dt
            t += dt
            ST[S_STEPS] += 1
            if ST[S_STEPS] > fl[FL_MAXSTEPS]:
                ST[S_STATUS] = MAXSTEPS
            for i in range(n):
                for d in range(6):
                    if not math.isfinite(G[i, G_S + d]):
                        ST[S_STATUS] = NONFINITE
            if record:
                for i in range(n):
                    KN = add_knot(KN, CNT, t, i, 0.0, G, i, G_S, G_V, G_W, G_Q, acc[i], G[i, G_WK])
                    knot_of[i] = CNT[CN_KNOTS] - 1
            continue
        if in_contact:
            in_contact = False
            IV[CNT[CN_IVALS] - 1, V_END] = t
            if record:
                for i in range(n):
                    KN[knot_of[i], K_FREE] = 1.0
                    for d in range(3):
                        KN[knot_of[i], K_AN + d] = grav[d]
        # Free flight: whole steps in closed form, up to the step in which a contact begins.
        positions_at(G, n, t, grav, P, V)
        tau = next_contact(G, P, V, n, t, WP, grav, dim, math.inf, YES, fp[FP_SLOW],
                           speed_scales(V, n, IV, CNT))
        if tau == math.inf and t_end == math.inf:
            t_end = t + math.ceil(tail_after(fp[FP_TAIL], IV, CNT) / dt) * dt
        jump = min(math.floor(tau / dt) * dt if tau < math.inf else math.inf, t_end - t)
        if jump <= 0.0:
            jump = dt  # a contact begins within this step: take it with the spring clamped
            for i in range(n):
                bring(G, i, t + dt, grav, fl)
        t += jump
    for i in range(n):
        bring(G, i, t, grav, fl)
        if record and KN[knot_of[i], K_T] < t:
            KN = add_knot(KN, CNT, t, i, 1.0, G, i, G_S, G_V, G_W, G_Q, g3, G[i, G_WK])
    if in_contact:
        IV[CNT[CN_IVALS] - 1, V_END] = t
    return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG
