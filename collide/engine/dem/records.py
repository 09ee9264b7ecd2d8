"""What a run records: frames of every body's state (knots, as the event engine's), and the
energy taken out by each part of the contact forces and held by the tangential springs."""

from __future__ import annotations

from collide.engine.dem.layout import B_IM, EP_DAMP, EP_STORED, EP_T, H_KT, H_XI
from collide.engine.jit import jit, jit_inline
from collide.engine.numerics import grow


@jit
def stored(PS, HS, WH):
    """The energy the tangential springs hold: 1/2 k_t |xi|^2 each, the pairs' (history rows HS
    at slots PS) in the list's order, then the wall contacts'."""
    total = 0.0
    for k in range(PS.shape[0]):
        if PS[k] >= 0:
            total += _spring(HS, PS[k])
    for k in range(WH.shape[0]):
        total += _spring(WH, k)
    return total


@jit_inline
def _spring(H, k):
    hx, hy, hz = H[k, H_XI], H[k, H_XI + 1], H[k, H_XI + 2]
    return 0.5 * H[k, H_KT] * (hx * hx + hy * hy + hz * hz)


@jit_inline
def work_total(WK, n, c):
    """The work of part c (damping, friction, rolling) summed over the bodies."""
    s = 0.0
    for a in range(n):
        s += WK[a, c]
    return s


@jit
def frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, free):
    """Every body's state at t (knots); `free`: free flight follows, in closed form."""
    KN = grow(KN, nkn + n)
    for a in range(n):
        r = nkn + a
        KN[r, 0], KN[r, 1], KN[r, 2] = t, a, free
        for d in range(3):
            KN[r, 3 + d] = X[a, d]
            KN[r, 6 + d] = V[a, d]
            KN[r, 9 + d] = W[a, d]
            acc = F[a, d] * Bd[a, B_IM]
            KN[r, 16 + d] = acc
            KN[r, 19 + d] = acc
        for d in range(4):
            KN[r, 12 + d] = Qo[a, d]
        KN[r, 22] = WK[a, 0] + WK[a, 1] + WK[a, 2]
    return KN, nkn + n


@jit
def energy_row(EP, nep, t, WK, PS, HS, WH, n):
    """The energy parts at t: work of damping, friction and rolling, and what the springs hold.
    Returns (EP, nep)."""
    EP = grow(EP, nep)
    EP[nep, EP_T] = t
    for c in range(3):
        EP[nep, EP_DAMP + c] = work_total(WK, n, c)
    EP[nep, EP_STORED] = stored(PS, HS, WH)
    return EP, nep + 1
