"""The integrator: velocity Verlet at a fixed step (half kick, drift, forces, half kick: LIGGGHTS'
`nve/sphere`), with forces from the positions after the drift and the half-step velocities. A
kick also books the work each part of the contact forces did (damping, friction, rolling), so
the energy balance stays a check on the stepping."""

from __future__ import annotations

from collide.engine.dem.layout import B_I, B_II, B_IM, B_M, PT_DAMP, PT_FRIC, PT_ROLL
from collide.engine.flight import turn
from collide.engine.jit import jit, jit_inline


@jit_inline
def kinetic_parts(Bd, a, v0, v1, v2, w0, w1, w2):
    """Body a's kinetic energy at velocity v and spin w: (translation, rotation), added to a sum
    in that order."""
    return 0.5 * Bd[a, B_M] * (v0 ** 2 + v1 ** 2 + v2 ** 2), 0.5 * Bd[a, B_I] * (w0 ** 2 + w1 ** 2 + w2 ** 2)


@jit_inline
def _half_kick(WK, a, h2, im, ii, spins, F, T, PT, rolling, vb0, vb1, vb2, wb0, wb1, wb2):
    """Body a's half kick as `kick` makes it (the same operations in the same order), its work
    booked in WK; returns the velocity and spin after it."""
    tx, ty, tz = T[a, 0], T[a, 1], T[a, 2]
    rx, ry, rz = 0.0, 0.0, 0.0
    if rolling:
        rx, ry, rz = PT[a, PT_ROLL], PT[a, PT_ROLL + 1], PT[a, PT_ROLL + 2]
    va0, va1, va2 = vb0 + h2 * F[a, 0] * im, vb1 + h2 * F[a, 1] * im, vb2 + h2 * F[a, 2] * im
    wa0, wa1, wa2 = wb0 + h2 * tx * ii, wb1 + h2 * ty * ii, wb2 + h2 * tz * ii
    v0, v1, v2 = 0.5 * (vb0 + va0), 0.5 * (vb1 + va1), 0.5 * (vb2 + va2)
    w0, w1, w2 = 0.5 * (wb0 + wa0), 0.5 * (wb1 + wa1), 0.5 * (wb2 + wa2)
    WK[a, 0] -= h2 * (PT[a, PT_DAMP] * v0 + PT[a, PT_DAMP + 1] * v1 + PT[a, PT_DAMP + 2] * v2)
    WK[a, 1] -= h2 * (PT[a, PT_FRIC] * v0 + PT[a, PT_FRIC + 1] * v1 + PT[a, PT_FRIC + 2] * v2
                      + ((tx - rx) * w0 + (ty - ry) * w1 + (tz - rz) * w2) * spins)
    if rolling:
        WK[a, 2] -= h2 * (rx * w0 + ry * w1 + rz * w2) * spins
    return va0, va1, va2, wa0, wa1, wa2


@jit_inline
def _drift_body(X, X0, Qo, a, v0, v1, v2, w0, w1, w2, h, spin, planar):
    """Body a moved and turned for h at velocity v and spin w. Returns its squared distance from
    where the neighbour lists were built (X0)."""
    X[a, 0] += h * v0
    X[a, 1] += h * v1
    X[a, 2] += h * v2
    if spin:
        turn(Qo[a], w0, w1, w2, h, planar)
    ddx, ddy, ddz = X[a, 0] - X0[a, 0], X[a, 1] - X0[a, 1], X[a, 2] - X0[a, 2]
    return ddx * ddx + ddy * ddy + ddz * ddz


@jit
def kick(V, W, F, T, PT, Bd, h2, n, WK, rolling, energy):
    """A half kick of h2, and the work each part of the contact forces did in it, from the
    kinetic energy it changed: F . (v_before + v_after) / 2 h2 per body (exact for a kick, and
    additive over the parts). WK (N, 3) gathers minus that: damping, friction (with what the
    tangential springs hold), rolling resistance (if the scene has it). Returns the kinetic
    energy after the kick if asked (`energy`), else 0."""
    e = 0.0
    for a in range(n):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h2, im, ii, spins, F, T, PT, rolling,
                                            V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        if energy:
            lin, rot = kinetic_parts(Bd, a, v0, v1, v2, w0, w1, w2)
            e += lin
            e += rot
    return e


@jit
def drift(X, X0, V, W, Qo, h, n, spin, planar):
    """Move and turn every body for h at its velocity and spin. Returns the largest squared
    distance a body is from where the neighbour lists were built (X0)."""
    moved = 0.0
    for a in range(n):
        moved = max(moved, _drift_body(X, X0, Qo, a, V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2], h,
                                       spin, planar))
    return moved


@jit
def kick_kick_drift(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, lo, hi, rolling, spin, planar):
    """One step's closing half kick (h_close), the next step's opening half kick (h_open) and its
    drift (h) in one pass over bodies lo..hi, each body's numbers as `kick`, `kick` and `drift`
    make them (bit for bit): as three passes they took 1.2-1.3 times as long (1 000 bodies). The
    one-thread loop and each thread's share (`threads.kick_share`) run this same pass. Returns (the
    kinetic energy between the kicks, summed body by body as `kick` sums it; `drift`'s moved)."""
    e = 0.0
    moved = 0.0
    for a in range(lo, hi):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_close, im, ii, spins, F, T, PT, rolling,
                                            V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        lin, rot = kinetic_parts(Bd, a, v0, v1, v2, w0, w1, w2)
        e += lin
        e += rot
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_open, im, ii, spins, F, T, PT, rolling, v0, v1, v2, w0, w1, w2)
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        moved = max(moved, _drift_body(X, X0, Qo, a, v0, v1, v2, w0, w1, w2, h, spin, planar))
    return e, moved


@jit
def kinetic(V, W, Bd, n):
    """The bodies' kinetic energy."""
    e = 0.0
    for a in range(n):
        lin, rot = kinetic_parts(Bd, a, V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        e += lin
        e += rot
    return e
