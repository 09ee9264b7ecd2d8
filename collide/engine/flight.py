"""Bodies in free flight: a body's state at any time from its base state (gravity only, spin
turning its orientation), and when free flights meet (a body and a wall, two bodies).
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import BOX_ANY, join, near_pairs, nearest, root_of
from collide.engine.jit import jit, jit_inline
from collide.engine.layout import CN_IVALS, FL_PLANAR, FL_SPIN, G_Q, G_R, G_S, G_TB, G_V, G_W, V_I, V_J
from collide.engine.numerics import smallest_positive_root


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


@jit
def touch_time(G, i, j, t, WP, grav, box):
    """Time from t until body i touches body j (or wall -1 - j) in free flight (inf: never). In a
    periodic box, j's nearest image at t: the callers look no further ahead than a body can
    cross to another image."""
    px, py, pz, ux, uy, uz = free_state(G, i, t, grav)
    if j >= 0:
        qx, qy, qz, wx, wy, wz = free_state(G, j, t, grav)
        dx, dy, dz = qx - px, qy - py, qz - pz
        if box[BOX_ANY] != 0.0:
            dx, dy, dz = nearest(dx, dy, dz, box)
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
def positions_at(G, n, t, grav, P, V):
    for i in range(n):
        px, py, pz, ux, uy, uz = free_state(G, i, t, grav)
        P[i, 0], P[i, 1], P[i, 2] = px, py, pz
        V[i, 0], V[i, 1], V[i, 2] = ux, uy, uz


@jit_inline
def approaches(P, V, i, j, slow, floor, scale, box):
    """Whether bodies i and j close along their line of centres faster than `slow` times their
    speed scales (`speed_scales`: round-off of the speeds the pair itself carries, never of the
    scene's fastest body, beside which a slow pair would pass through unseen) and than `floor`
    (m/s)."""
    dx, dy, dz = P[j, 0] - P[i, 0], P[j, 1] - P[i, 1], P[j, 2] - P[i, 2]
    if box[BOX_ANY] != 0.0:
        dx, dy, dz = nearest(dx, dy, dz, box)
    closing = -((V[j, 0] - V[i, 0]) * dx + (V[j, 1] - V[i, 1]) * dy + (V[j, 2] - V[i, 2]) * dz)
    return closing > max(slow * (scale[i] + scale[j]), floor) * math.sqrt(dx * dx + dy * dy + dz * dz)


@jit
def account_contacts(IV, CNT, parent, count, seen):
    """Fold the contact intervals opened since the last call (`seen[0]` of them were folded) into
    `parent`, a union-find of the bodies that exchanged momentum, directly or through others, and
    `count`, each body's contacts. Incremental, so that a jump costs the bodies, not every contact
    of the run so far (a 1D stack bouncing for two hours: 190 000 contacts, each jump scanning
    them all). A window redone since (fewer intervals now) starts again from none."""
    if seen[0] > CNT[CN_IVALS]:
        for i in range(parent.shape[0]):
            parent[i] = i
            count[i] = 0.0
        seen[0] = 0
    for k in range(seen[0], CNT[CN_IVALS]):
        i, j = int(IV[k, V_I]), int(IV[k, V_J])
        if i >= 0 and j >= 0:
            join(parent, i, j)
        if i >= 0:
            count[i] += 1.0
        if j >= 0:
            count[j] += 1.0
    seen[0] = CNT[CN_IVALS]


@jit
def speed_scales(V, n, parent):
    """Each body's speed scale for round-off: the fastest speed now among the bodies it has
    exchanged momentum with, directly or through others (`parent`, see `account_contacts`),
    itself included (a ball a Newton's cradle left at rest keeps the round-off of the speed it
    passed on, not a speed of its own)."""
    top = np.zeros(n)
    for i in range(n):
        r = root_of(parent, i)
        top[r] = max(top[r], math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2))
    out = np.empty(n)
    for i in range(n):
        out[i] = top[root_of(parent, i)]
    return out


@jit
def next_contact(G, P, V, n, t, WP, grav, dim, horizon, every_pair, slow, scale, box):
    """The earliest contact start after t, looking `horizon` ahead (every pair if asked). Two
    bodies closing at under `slow` times their speed scales are taken as not approaching: what is
    left of a perfect exchange of velocities, round-off, would otherwise meet again billions of
    seconds later."""
    best = math.inf
    if every_pair:
        for i in range(n):
            for j in range(i + 1, n):
                if approaches(P, V, i, j, slow, 0.0, scale, box):
                    best = min(best, touch_time(G, i, j, t, WP, grav, box))
    else:
        g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
        margin = np.empty(n)
        for i in range(n):
            margin[i] = math.sqrt(V[i, 0] ** 2 + V[i, 1] ** 2 + V[i, 2] ** 2) * horizon + 0.5 * g * horizon ** 2
        pairs = near_pairs(P, G[:, G_R], margin, n, dim, box)
        for p in range(pairs.shape[0]):
            i, j = pairs[p, 0], pairs[p, 1]
            if approaches(P, V, i, j, slow, 0.0, scale, box):
                best = min(best, touch_time(G, i, j, t, WP, grav, box))
    for w in range(WP.shape[0]):
        for i in range(n):
            best = min(best, touch_time(G, i, -1 - w, t, WP, grav, box))
    return best


@jit
def meets_again(G, P, V, n, t, WP, grav, count, slow, resolved, within, scale, box):
    """Whether a wall or a pair meets again after t, a pair only if it closes faster than its
    velocities are known: each contact a body took part in left it with the run's resolved
    velocity error at most (`resolved`, m/s), so a pair whose bodies had c_i and c_j contacts
    closes by error alone below (c_i + c_j) resolved (a Newton's cradle at tol 1e-7: its middle
    balls, two contacts each, parted at 8e-8 m/s and closed at 1.07e-7, met again 7.8 hours on).
    A pair that closes slower than that but meets `within` (before the run would end) meets:
    ended without it, the two would end the run inside each other. `count`: each body's contacts
    (`account_contacts`)."""
    for i in range(n):
        for j in range(i + 1, n):
            if not approaches(P, V, i, j, slow, 0.0, scale, box):
                continue
            tau = touch_time(G, i, j, t, WP, grav, box)
            floor = (count[i] + count[j]) * resolved
            if tau <= within or (tau < math.inf and approaches(P, V, i, j, slow, floor, scale, box)):
                return True
    for w in range(WP.shape[0]):
        for i in range(n):
            if touch_time(G, i, -1 - w, t, WP, grav, box) < math.inf:
                return True
    return False
