"""Damping for a restitution e: gamma = 2 zeta sqrt(m* k), zeta = -ln e / sqrt(ln^2 e + pi^2)
(zeta is taken once a table, by `collide.dem.damping_ratio`).

k is the normal stiffness dF/d delta: the linear spring-dashpot formula, and for Hertz LIGGGHTS'
and LAMMPS' 2 sqrt(5/6) beta sqrt(S_n m*), the same number. The normal force is not clipped at
zero, so a contact may pull as it ends; with that choice e_out = e exactly for both laws. The
tangential dashpot is this one scaled by sqrt(k_t / k_n) (LIGGGHTS).
"""

from __future__ import annotations

import math

from collide.engine.jit import jit_inline


@jit_inline
def dashpot(zeta, mstar, k):
    """The dashpot for the restitution with a spring of stiffness k: 2 zeta sqrt(m* k)."""
    return 2.0 * zeta * math.sqrt(mstar * k)


@jit_inline
def dashpot_slope(zeta, mstar, k, dk):
    """How `dashpot`'s gamma changes as its spring's stiffness k changes by dk: zeta sqrt(m* / k)
    dk (Hertz's stiffness grows with the overlap, and its gamma with it, as delta^(1/4))."""
    return zeta * math.sqrt(mstar / k) * dk
