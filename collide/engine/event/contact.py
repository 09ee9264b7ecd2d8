"""Contact geometry of an island: each engaged contact's normal, overlap and arms (`geometry`),
its spring force (`springs`), the slip at the contact and its rate (`slip`, `slip_rate`), and a
candidate contact's overlap over its touching distance and whether it is engaged.
"""

from __future__ import annotations

import math

from collide.engine.dem.damping import dashpot, dashpot_slope
from collide.engine.dem.normal import normal_curvature, normal_elastic, normal_energy
from collide.engine.dem.tangential import friction_cap
from collide.engine.flight import free_state
from collide.engine.jit import jit_inline
from collide.engine.layout import (
    C_B,
    C_DELTA,
    C_DIST,
    C_ESTAR,
    C_FN,
    C_GAMMA,
    C_INV,
    C_K,
    C_LIF,
    C_LIS,
    C_LJF,
    C_LJS,
    C_MSTAR,
    C_MU,
    C_N,
    C_REACH,
    C_RSTAR,
    C_SH,
    C_ZETA,
    CI_I,
    CI_J,
    CI_PRESS,
    GI_LOC,
    LATE,
    Q_ENG,
    Q_I,
    Q_J,
    QF_REACH,
    QF_SH,
    TOUCH_TOL,
    X_A,
    X_FO,
    X_II,
    X_IM,
    X_R,
    X_S,
    X_V,
)


@jit_inline
def elastic(C, c):
    """Contact c's spring force and stiffness at its overlap C_DELTA: the DEM kernel's
    `normal_elastic`, the linear spring unclamped (smooth for a substep straying just outside
    the contact, whose end is a located event), Hertz (C_ESTAR > 0) none past touching (its
    force and stiffness are zero there)."""
    delta = C[c, C_DELTA]
    hertz = C[c, C_ESTAR] > 0.0
    if hertz and delta <= 0.0:
        return 0.0, 0.0
    return normal_elastic(hertz, C[c, C_K], C[c, C_ESTAR], C[c, C_RSTAR], delta)


@jit_inline
def stored(C, c):
    """The energy contact c's spring holds at its overlap (`normal_energy`; Hertz's none past
    touching)."""
    delta = C[c, C_DELTA]
    hertz = C[c, C_ESTAR] > 0.0
    if hertz and delta <= 0.0:
        return 0.0
    return normal_energy(hertz, C[c, C_K], C[c, C_ESTAR], C[c, C_RSTAR], delta)


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
            dx = X[j, X_S] - X[i, X_S] + C[c, C_SH]
            dy = X[j, X_S + 1] - X[i, X_S + 1] + C[c, C_SH + 1]
            dz = X[j, X_S + 2] - X[i, X_S + 2] + C[c, C_SH + 2]
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
        C[c, C_FN] = elastic(C, c)[0]


@jit_inline
def springs(X, C, CI, na, nc, grav):
    """Accelerations X_A from the springs (the elastic part of the normal force: a dashpot's
    depends on the velocities and goes with the friction, `dashpots`) and gravity."""
    for a in range(na):
        for d in range(3):
            X[a, X_FO + d] = 0.0
    for c in range(nc):
        i = CI[c, CI_I]
        j = CI[c, CI_J]
        fn = elastic(C, c)[0]
        for d in range(3):
            f = fn * C[c, C_N + d]
            X[i, X_FO + d] -= f
            if j >= 0:
                X[j, X_FO + d] += f
    for a in range(na):
        for d in range(3):
            X[a, X_A + d] = X[a, X_FO + d] * X[a, X_IM] + grav[d]


@jit_inline
def dashpots(X, C, CI, nc, vc, fa):
    """The restitution's dashpots at the velocities in column vc: each damped contact's normal
    force C_FN becomes the DEM kernel's, spring plus gamma times the overlap's rate (unclipped: it
    may pull as the contact ends, as there), and the dashpot's accelerations are added to column
    fa. Hertz's gamma follows the stiffness dF/d delta (the DEM kernel's `dashpot` at it), zero
    past touching. A dashpot's force lies along the line of centres: no torque."""
    for c in range(nc):
        gamma = C[c, C_GAMMA]
        if gamma == 0.0:
            continue
        spring, kn = elastic(C, c)
        if C[c, C_ESTAR] > 0.0:
            gamma = dashpot(C[c, C_ZETA], C[c, C_MSTAR], kn)
        i = CI[c, CI_I]
        j = CI[c, CI_J]
        nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
        rx, ry, rz = X[i, vc], X[i, vc + 1], X[i, vc + 2]
        if j >= 0:
            rx -= X[j, vc]
            ry -= X[j, vc + 1]
            rz -= X[j, vc + 2]
        damp = gamma * (rx * nx + ry * ny + rz * nz)  # the overlap's rate: > 0 while approaching
        C[c, C_FN] = spring + damp
        s = damp * X[i, X_IM]
        X[i, fa] -= s * nx
        X[i, fa + 1] -= s * ny
        X[i, fa + 2] -= s * nz
        if j >= 0:
            s = damp * X[j, X_IM]
            X[j, fa] += s * nx
            X[j, fa + 1] += s * ny
            X[j, fa + 2] += s * nz


@jit_inline
def press(X, C, CI, c, ac):
    """Damped contact c's pressing value, whose zero is its normal force's F_n = F_el(delta) +
    gamma(delta) delta' (C_FN, from `dashpots`), and the value's rate under the accelerations in
    column ac. delta'' is the accelerations' part along the line of centres less, for a pair,
    the line turning: |v_t|^2 / dist (a wall's normal does not turn).

    F_n's own rate is k delta' + gamma_delta delta'^2 + gamma delta'' (gamma_delta = d gamma /
    d delta, `dashpot_slope` of the curvature `normal_curvature`). Hertz's gamma grows as
    delta^(1/4): at the contact's end F_n comes back to zero with the overlap, as delta^(1/4),
    and its rate is unbounded (as delta^(-3/4)), which the root search's cubics and `foresee`'s
    parabolas cannot follow. The value is F_n / gamma(delta) = F_el / gamma + delta' instead, the
    same zero (gamma > 0 inside), smooth through the end (delta' there, and past it), with the
    rate (k - F_el gamma_delta / gamma) delta' / gamma + delta''; both in force units through
    the dashpot at the contact's stiffness C_GAMMA (Hertz's at its bound). The linear spring's
    gamma is that one: its value is F_n, its rate k delta' + gamma delta''. Returns (value,
    rate)."""
    i = CI[c, CI_I]
    j = CI[c, CI_J]
    nx, ny, nz = C[c, C_N], C[c, C_N + 1], C[c, C_N + 2]
    rx, ry, rz = X[i, X_V], X[i, X_V + 1], X[i, X_V + 2]
    ax, ay, az = X[i, ac], X[i, ac + 1], X[i, ac + 2]
    if j >= 0:
        rx, ry, rz = rx - X[j, X_V], ry - X[j, X_V + 1], rz - X[j, X_V + 2]
        ax, ay, az = ax - X[j, ac], ay - X[j, ac + 1], az - X[j, ac + 2]
    rn = rx * nx + ry * ny + rz * nz
    curve = (ax * nx + ay * ny + az * nz)
    if j >= 0:
        curve -= (rx * rx + ry * ry + rz * rz - rn * rn) * C[c, C_INV]
    top = C[c, C_GAMMA]
    spring, stiffness = elastic(C, c)
    hertz = C[c, C_ESTAR] > 0.0
    gamma = dashpot(C[c, C_ZETA], C[c, C_MSTAR], stiffness) if hertz else top
    if not gamma > 0.0:
        # Past Hertz's touching (a substep straying out): F_n / gamma's limit there.
        return top * rn, top * curve
    lean = 0.0
    if hertz:
        bend = normal_curvature(True, C[c, C_ESTAR], C[c, C_RSTAR], C[c, C_DELTA])
        lean = spring * dashpot_slope(C[c, C_ZETA], C[c, C_MSTAR], stiffness, bend) / gamma
    ratio = top / gamma
    return C[c, C_FN] * ratio, ratio * (stiffness - lean) * rn + top * curve


@jit_inline
def cap(C, CI, c):
    """Contact c's friction cap: with a dashpot the DEM kernel's, mu max(F_n, 0) (its F_n may pull
    as the contact ends), where a step's modes are decided (CI_PRESS 0); through the step the
    branch it started on, mu F_n or 0 (CI_PRESS 1, -1), smooth for the compositions' substeps
    that reach back past the start: the kink between is a located event (`mode_events`).
    Without a dashpot, mu F_n of the spring unclamped, smooth for a substep straying just
    outside the contact (its end is a located event)."""
    if C[c, C_GAMMA] > 0.0:
        side = CI[c, CI_PRESS]
        if side == 0:
            return friction_cap(C[c, C_MU], C[c, C_FN])
        return C[c, C_MU] * C[c, C_FN] if side > 0 else 0.0
    return C[c, C_MU] * C[c, C_FN]


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
        dx, dy, dz = qx - px + QF[k, QF_SH], qy - py + QF[k, QF_SH + 1], qz - pz + QF[k, QF_SH + 2]
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
