"""A contact's geometry: the bodies' effective (reduced) quantities, a sphere's height over a
wall, and the relative velocity of the surfaces at the contact point."""

from __future__ import annotations

from collide.engine.jit import jit_inline


@jit_inline
def reduced(a, b):
    """The effective mass, radius or inertia of two bodies in contact: a b / (a + b)."""
    return a * b / (a + b)


@jit_inline
def wall_height(X, WP, i, w):
    """Body i's centre's height over wall w (WP rows: a point, then the unit normal)."""
    return ((X[i, 0] - WP[w, 0]) * WP[w, 3] + (X[i, 1] - WP[w, 1]) * WP[w, 4]
            + (X[i, 2] - WP[w, 2]) * WP[w, 5])


@jit_inline
def surface_velocity(V, W, i, j, nx, ny, nz, ai, aj, spin):
    """The velocity of i's surface at the contact point minus j's (j < 0: a wall, at rest); n
    points from i into j, ai and aj are the lever arms from the centres."""
    vx, vy, vz = V[i, 0], V[i, 1], V[i, 2]
    if spin:
        vx += W[i, 1] * nz * ai - W[i, 2] * ny * ai
        vy += W[i, 2] * nx * ai - W[i, 0] * nz * ai
        vz += W[i, 0] * ny * ai - W[i, 1] * nx * ai
    if j >= 0:
        vx -= V[j, 0]
        vy -= V[j, 1]
        vz -= V[j, 2]
        if spin:
            vx += W[j, 1] * nz * aj - W[j, 2] * ny * aj
            vy += W[j, 2] * nx * aj - W[j, 0] * nz * aj
            vz += W[j, 0] * ny * aj - W[j, 1] * nx * aj
    return vx, vy, vz
