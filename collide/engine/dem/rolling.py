"""Rolling resistance: a torque mu_r R* F_n against the relative rotation (rolling and twisting),
capped by a viscous torque that would stop it in ROLL_STEPS steps (so that a ball at rest does
not chatter, and a sphere with many contacts does not overshoot).

The law's two parts are defined once here: its cap (`rolling_cap`) and the torque against the
rotation up to a bound (`rolling_torque`). The DEM kernel bounds it by the viscous torque of its
step; the event engine (`collide.engine.event.oblique`) takes the vanishing step's limit, no
bound: rolling (the cap against the rotation) or held (the rotation locked, the torque that
holds it within the cap), the switch between them located as an event."""

from __future__ import annotations

import math

import numpy as np

from collide.engine.dem.geometry import reduced
from collide.engine.dem.layout import B_I, PT_ROLL
from collide.engine.jit import jit_inline

# Below mu_r R* F_n, rolling resistance is a viscous torque that would stop the relative rolling
# in this many steps: more than the 12 contacts a sphere can have, so that together they never
# overshoot (a cap of one step each made a sphere in a pile spin up, measured).
ROLL_STEPS = np.int64(16)


@jit_inline
def rolling_cap(mu_r, rstar, fn):
    """The largest rolling-resistance torque: mu_r R* times the normal force where it presses
    (none where a damped force pulls)."""
    return mu_r * rstar * max(fn, 0.0)


@jit_inline
def rolling_torque(cap, bound, wx, wy, wz):
    """The torque against the relative rotation w: the cap, or `bound` if smaller (inf: the cap
    alone, the rolling mode of the event engine); none where w is zero."""
    rate = math.sqrt(wx * wx + wy * wy + wz * wz)
    if rate == 0.0:
        return 0.0, 0.0, 0.0
    g = min(cap, bound) / rate
    return -g * wx, -g * wy, -g * wz


@jit_inline
def rolling_resistance(W, Ti, PTi, oi, Tj, PTj, oj, Bd, i, j, cap, dt):
    """Torque up to `cap` against the relative rotation (rolling and twisting alike: LAMMPS
    composes a twisting model, here it shares mu_r, since a sphere left spinning about its
    contact normal would never stop), below it a viscous torque that would stop the rotation
    in ROLL_STEPS steps. i's share goes to row oi of Ti and PTi, j's to row oj of Tj and PTj."""
    wx, wy, wz = W[i, 0], W[i, 1], W[i, 2]
    ieff = Bd[i, B_I]
    if j >= 0:
        wx, wy, wz = wx - W[j, 0], wy - W[j, 1], wz - W[j, 2]
        ieff = reduced(Bd[i, B_I], Bd[j, B_I])
    rate = math.sqrt(wx * wx + wy * wy + wz * wz)
    if rate == 0.0:
        return
    tx, ty, tz = rolling_torque(cap, ieff * rate / (ROLL_STEPS * dt), wx, wy, wz)
    for d, td in ((0, tx), (1, ty), (2, tz)):
        Ti[oi, d] += td
        PTi[oi, PT_ROLL + d] += td
        if j >= 0:
            Tj[oj, d] -= td
            PTj[oj, PT_ROLL + d] -= td
