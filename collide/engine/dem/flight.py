"""Free flight: where nothing touches, the bodies fly in closed form (gravity included) as far as
no contact can begin, as in the event engine, instead of being stepped; and whether any contact
can ever begin again (a run with no end set stops when none can)."""

from __future__ import annotations

import math

from collide.engine.broad import BOX_ANY, nearest
from collide.engine.dem.geometry import wall_height
from collide.engine.dem.layout import B_R
from collide.engine.dem.records import frame
from collide.engine.flight import turn
from collide.engine.jit import jit


@jit
def free_time(X, V, Bd, PI, PJ, WL, WP, grav, n, skin, box):
    """How long every body can fly freely with no contact able to begin: until the fastest could
    have covered half the smallest gap (listed pairs, walls; an unlisted pair's gap is at least
    the skin, the lists being fresh), gravity included."""
    gap = skin
    for k in range(PI.shape[0]):
        i, j = PI[k], PJ[k]
        dx, dy, dz = X[j, 0] - X[i, 0], X[j, 1] - X[i, 1], X[j, 2] - X[i, 2]
        if box[BOX_ANY] != 0.0:
            dx, dy, dz = nearest(dx, dy, dz, box)
        gap = min(gap, math.sqrt(dx * dx + dy * dy + dz * dz) - Bd[i, B_R] - Bd[j, B_R])
    for m in range(WL.shape[0]):
        i, w = WL[m, 1], WL[m, 2]
        gap = min(gap, wall_height(X, WP, i, w) - Bd[i, B_R])
    if gap <= 0.0:
        return 0.0
    speed = 0.0
    for a in range(n):
        speed = max(speed, math.sqrt(V[a, 0] ** 2 + V[a, 1] ** 2 + V[a, 2] ** 2))
    g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
    reach = 0.5 * gap  # each of two bodies may close it by half
    if g > 0.0:
        return (-speed + math.sqrt(speed * speed + 2.0 * g * reach)) / g
    return reach / speed if speed > 0.0 else math.inf



@jit
def will_meet(X, V, Bd, WP, grav, n):
    """Whether any two spheres, or a sphere and a wall, may touch in free flight: a pair on
    straight lines (a uniform gravity cancels in their relative motion), a wall when a sphere
    heads for it or gravity pulls it back (conservative: any component)."""
    for i in range(n):
        for j in range(i + 1, n):
            dx, dy, dz = X[j, 0] - X[i, 0], X[j, 1] - X[i, 1], X[j, 2] - X[i, 2]
            ux, uy, uz = V[j, 0] - V[i, 0], V[j, 1] - V[i, 1], V[j, 2] - V[i, 2]
            closing = dx * ux + dy * uy + dz * uz
            if closing >= 0.0:
                continue
            speed2 = ux * ux + uy * uy + uz * uz
            # Nearest approach of two straight lines.
            tau = -closing / speed2
            cx, cy, cz = dx + ux * tau, dy + uy * tau, dz + uz * tau
            reach = Bd[i, B_R] + Bd[j, B_R]
            if cx * cx + cy * cy + cz * cz < reach * reach:
                return True
        for w in range(WP.shape[0]):
            if V[i, 0] * WP[w, 3] + V[i, 1] * WP[w, 4] + V[i, 2] * WP[w, 5] < 0.0:
                return True
            if grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5] < 0.0:
                return True
    return False




@jit
def may_meet(X, V, Bd, WP, grav, n, box):
    """`will_meet`, in a periodic box too: there two bodies moving apart meet again at another
    image unless they move together (conservative: any difference of velocities)."""
    if box[BOX_ANY] != 0.0:
        for i in range(1, n):
            if V[i, 0] != V[0, 0] or V[i, 1] != V[0, 1] or V[i, 2] != V[0, 2]:
                return True
    return will_meet(X, V, Bd, WP, grav, n)


@jit
def fly(X, V, W, Qo, F, Bd, WK, grav, tau, t, n, spin, planar, record, KN, nkn):
    """Every body flown freely from t for tau, in closed form; with a frame at each end if
    recorded (the one at t, which may be there already, marked as followed by free flight).
    Returns (KN, nkn)."""
    if record:
        if nkn >= n and KN[nkn - 1, 0] == t:
            for r in range(nkn - n, nkn):
                KN[r, 2] = 1.0
        else:
            KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 1.0)
    for a in range(n):
        for d in range(3):
            X[a, d] += V[a, d] * tau + 0.5 * grav[d] * tau * tau
            V[a, d] += grav[d] * tau
        if spin:
            turn(Qo[a], W[a, 0], W[a, 1], W[a, 2], tau, planar)
    if record:
        KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t + tau, n, 0.0)
    return KN, nkn
