"""One contact's forces: the laws a scene uses, composed (flags fixed when the scene is
compiled), as LAMMPS' pair_style granular composes sub-models: normal (`normal`), damping
(`damping`), tangential (`tangential`), rolling resistance (`rolling`)."""

from __future__ import annotations

from collide.engine.dem.damping import dashpot
from collide.engine.dem.geometry import reduced, surface_velocity
from collide.engine.dem.layout import (
    B_M,
    B_R,
    F_HERTZ,
    F_SPIN,
    F_TSPRING,
    PT_DAMP,
    PT_FRIC,
    T_EPS,
    T_ESTAR,
    T_K,
    T_KTR,
    T_KTR_ROOT,
    T_MU,
    T_ROLL,
    T_ZETA,
)
from collide.engine.dem.normal import normal_elastic
from collide.engine.dem.rolling import rolling_cap, rolling_resistance
from collide.engine.dem.tangential import coulomb_slip, friction_cap, spring_coefficients, tangential_spring
from collide.engine.jit import jit_inline


@jit_inline
def contact_force(X, V, W, F, T, PT, Bd, i, j, nx, ny, nz, delta, tabs, mi, mj, hist, k, fl, dt, out):
    """Add contact (i, j)'s forces and torques (j < 0: a rigid wall along -n) to F, T, and by
    part to PT. n points from i into j; the law's coefficients are tabs[mi, mj]. Returns the normal
    force; `out` gets the friction force on i (3) and the mode."""
    return contact_into(X, V, W, F, T, T, PT, i, F, T, T, PT, j, Bd, i, j, nx, ny, nz, delta, tabs, mi, mj, hist, k,
                        fl, dt, out)


@jit_inline
def contact_into(X, V, W, Fi, Ti, TRi, PTi, oi, Fj, Tj, TRj, PTj, oj, Bd, i, j, nx, ny, nz, delta, tabs, mi, mj, hist,
                 k, fl, dt, out):
    """`contact_force` adding i's share to row oi of Fi, Ti and PTi (its rolling torque to TRi)
    and j's to row oj of Fj, Tj, TRj and PTj: the threaded force pass keeps i's share of a
    contact between two threads' bodies apart, each element of its row receiving at most one
    addition (`collide.engine.dem.threads`)."""
    tspring, spin = fl[F_TSPRING], fl[F_SPIN]
    ri = Bd[i, B_R]
    if j >= 0:
        rj = Bd[j, B_R]
        ai, aj = ri - 0.5 * delta, rj - 0.5 * delta
        mstar = reduced(Bd[i, B_M], Bd[j, B_M])
        rstar = reduced(ri, rj)
    else:
        ai, aj = ri - delta, 0.0
        mstar = Bd[i, B_M]
        rstar = ri
    vx, vy, vz = surface_velocity(V, W, i, j, nx, ny, nz, ai, aj, spin)
    vn = vx * nx + vy * ny + vz * nz  # the overlap's rate: > 0 while approaching
    tx, ty, tz = vx - vn * nx, vy - vn * ny, vz - vn * nz
    elastic, kn = normal_elastic(fl[F_HERTZ], tabs[mi, mj, T_K], tabs[mi, mj, T_ESTAR], rstar, delta)
    zeta = tabs[mi, mj, T_ZETA]
    gn = dashpot(zeta, mstar, kn) if zeta > 0.0 else 0.0
    damp = gn * vn
    fn = elastic + damp
    press = max(fn, 0.0)
    fx, fy, fz = -fn * nx, -fn * ny, -fn * nz  # on i
    mode = 0.0
    sx, sy, sz = 0.0, 0.0, 0.0  # friction on i
    mu = tabs[mi, mj, T_MU]
    if spin and (mu > 0.0 or tspring):
        if tspring:
            kt, gt = spring_coefficients(kn, gn, tabs[mi, mj, T_KTR], tabs[mi, mj, T_KTR_ROOT])
            sx, sy, sz, mode = tangential_spring(hist, k, nx, ny, nz, tx, ty, tz, kt, gt, friction_cap(mu, fn), dt)
        else:
            sx, sy, sz, mode = coulomb_slip(tx, ty, tz, friction_cap(mu, fn), tabs[mi, mj, T_EPS])
        fx += sx
        fy += sy
        fz += sz
        friction_torque(Ti, PTi, oi, Tj, PTj, oj, nx, ny, nz, ai, aj, sx, sy, sz)
    roll = tabs[mi, mj, T_ROLL]
    if spin and roll > 0.0 and press > 0.0:
        rolling_resistance(W, TRi, PTi, oi, TRj, PTj, oj, Bd, i, j, rolling_cap(roll, rstar, fn), dt)
    Fi[oi, 0] += fx
    Fi[oi, 1] += fy
    Fi[oi, 2] += fz
    dx, dy, dz = -damp * nx, -damp * ny, -damp * nz
    PTi[oi, PT_DAMP] += dx
    PTi[oi, PT_DAMP + 1] += dy
    PTi[oi, PT_DAMP + 2] += dz
    if j >= 0:
        Fj[oj, 0] -= fx
        Fj[oj, 1] -= fy
        Fj[oj, 2] -= fz
        PTj[oj, PT_DAMP] -= dx
        PTj[oj, PT_DAMP + 1] -= dy
        PTj[oj, PT_DAMP + 2] -= dz
    out[0], out[1], out[2], out[3] = sx, sy, sz, mode
    return fn


@jit_inline
def friction_torque(Ti, PTi, oi, Tj, PTj, oj, nx, ny, nz, ai, aj, sx, sy, sz):
    """The friction force s on i (and -s on j) at the contact point: its torque a x s with
    a = ai n on i, -aj n on j, and its share of the parts (i's in row oi of Ti and PTi, j's in
    row oj of Tj and PTj; none for a wall, oj < 0)."""
    cx, cy, cz = ny * sz - nz * sy, nz * sx - nx * sz, nx * sy - ny * sx
    for d, c in ((0, cx), (1, cy), (2, cz)):
        Ti[oi, d] += ai * c
        if oj >= 0:
            Tj[oj, d] += aj * c
    PTi[oi, PT_FRIC] += sx
    PTi[oi, PT_FRIC + 1] += sy
    PTi[oi, PT_FRIC + 2] += sz
    if oj >= 0:
        PTj[oj, PT_FRIC] -= sx
        PTj[oj, PT_FRIC + 1] -= sy
        PTj[oj, PT_FRIC + 2] -= sz
