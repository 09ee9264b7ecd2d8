"""Tangential force: the report's Coulomb slip, or a history spring (Cundall-Strack; Mindlin's
stiffness for Hertz) with LIGGGHTS' tangential damping.

The spring plus dashpot is capped at mu F_n (as LAMMPS' pair granular; LIGGGHTS 3.8 compares the
spring alone and drops the dashpot while sliding). After a slip the spring alone holds the capped
force (as LIGGGHTS); LAMMPS folds the dashpot's share into the stretch (-(F + gamma_t v_t) / k_t),
which with Hertz and damping made the outcome drift as dt shrank (2 % between 400 and 102 400
steps per contact, measured, and growing) instead of converging.
"""

from __future__ import annotations

import math

from collide.engine.dem.layout import H_KT, H_XI
from collide.engine.jit import jit_inline


@jit_inline
def spring_coefficients(kn, gn, ktr, ktr_root):
    """The spring's stiffness and dashpot from the normal ones: k_t = ratio k_n (Mindlin's for
    Hertz, whose k_n is dF/d delta), gamma_t = sqrt(ratio) gamma_n."""
    return ktr * kn, gn * ktr_root


@jit_inline
def friction_cap(mu, fn):
    """The largest friction force: mu times the normal force where it presses (none where it pulls)."""
    return mu * max(fn, 0.0)


@jit_inline
def spring_trial(hx, hy, hz, tx, ty, tz, kt, gt):
    """The spring plus dashpot before the cap: -k_t xi - gamma_t v_t (stretch xi, slip velocity v_t)."""
    return -kt * hx - gt * tx, -kt * hy - gt * ty, -kt * hz - gt * tz


@jit_inline
def slip_stretch(s, kt):
    """The stretch that holds the capped force s alone after a slip (module docstring)."""
    return -s * (1.0 / kt) if kt > 0.0 else 0.0


@jit_inline
def tangential_spring(hist, k, nx, ny, nz, tx, ty, tz, kt, gt, cap, dt):
    """History spring with dashpot, capped at `cap`: the friction force on i and its mode (2
    stick, 1 slip). The stretch is turned into the current tangent plane at its length; after a
    slip the spring alone holds the capped force (module docstring)."""
    hx, hy, hz = hist[k, H_XI], hist[k, H_XI + 1], hist[k, H_XI + 2]
    hn = hx * nx + hy * ny + hz * nz
    if hn != 0.0:
        before = hx * hx + hy * hy + hz * hz
        hx, hy, hz = hx - hn * nx, hy - hn * ny, hz - hn * nz
        after = hx * hx + hy * hy + hz * hz
        if after > 0.0:
            scale = math.sqrt(before / after)
            hx, hy, hz = hx * scale, hy * scale, hz * scale
    hx, hy, hz = hx + tx * dt, hy + ty * dt, hz + tz * dt
    sx, sy, sz = spring_trial(hx, hy, hz, tx, ty, tz, kt, gt)
    mag2 = sx * sx + sy * sy + sz * sz
    mode = 2.0
    if mag2 > cap * cap:
        mode = 1.0
        ratio = cap / math.sqrt(mag2)
        sx, sy, sz = sx * ratio, sy * ratio, sz * ratio
        hx, hy, hz = slip_stretch(sx, kt), slip_stretch(sy, kt), slip_stretch(sz, kt)
    hist[k, H_XI], hist[k, H_XI + 1], hist[k, H_XI + 2] = hx, hy, hz
    hist[k, H_KT] = kt
    return sx, sy, sz, mode


@jit_inline
def coulomb_slip(tx, ty, tz, cap, eps):
    """The report's law: cap against any slip faster than the dead band eps, else nothing."""
    slip = math.sqrt(tx * tx + ty * ty + tz * tz)
    if slip > eps and slip > 0.0:
        f = cap / slip
        return -f * tx, -f * ty, -f * tz, 1.0
    return 0.0, 0.0, 0.0, 0.0
