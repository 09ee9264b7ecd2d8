"""One composite step for the commonest case, in plain Python floats: a single run (B = 1) of two
spheres in 1D or 2D with no walls (every built-in scene).

The equations are those of the numpy kernels, term by term: `physics.contact_geometry` and
`normal_accel`, and `friction.frame_kick`, `hold_rate` and `settle` for one pair in the plane.
numpy costs about a microsecond a call whatever the size, and a step here is a few dozen
operations on four numbers, so floats are some ten times faster. `tests/test_pairstep.py`
checks that both paths agree to round-off on every built-in and on random scenes.
"""

from __future__ import annotations

import math

import numpy as np

from collide import friction as fr
from collide.model import Model, State


def applies(model: Model) -> bool:
    """Whether `composite` can take this model's steps."""
    return model.batch == 1 and model.n_bodies == 2 and model.n_walls == 0 and model.dim <= 2


def composite(model: Model, state: State, h: float, weights: tuple[float, ...], engaged: bool,
              modes: fr.Modes | None) -> tuple[State, np.ndarray, tuple | None]:
    """A symmetric composition of Verlet substeps gamma h (see `integrators._composition`) from
    `state`; `engaged`: the pair is in its contact phase (smooth spring law); `modes`: its
    friction mode and side. Returns the new state, the pair's friction force at the end
    (1, 1, D) and, with friction, the modes' event values and rates there, unscaled (see
    `friction.frame_events`), each (1, 2)."""
    dim = model.dim
    spin = model.spin_dim > 0
    inv_m1, inv_m2 = (float(x) for x in model.inv_mass[0])
    inv_i1, inv_i2 = (float(x) for x in model.inv_inertia[0]) if spin else (0.0, 0.0)
    r1, r2 = (float(x) for x in model.radius[0])
    reach, k = float(model.pair_reach[0, 0]), float(model.k_pair[0, 0])
    inv_pair = float(model.pair_inv_mass[0, 0])
    gx, gy = (0.0, 0.0) if model.gravity is None else (float(model.gravity[0, 0]),
                                                        float(model.gravity[0, 1]) if dim == 2 else 0.0)
    friction = model.friction and modes is not None
    mode = int(modes.mode[0, 0]) if friction else fr.BAND
    side = float(modes.side[0, 0]) if friction else 1.0
    mu, eps, seed = float(model.mu[0]), float(model.eps[0]), model.seed_lever
    slide, stick = mode == fr.SLIDE, mode == fr.STICK

    s, v = state.s[0], state.v[0]
    x1, x2 = float(s[0, 0]), float(s[1, 0])
    y1, y2 = (float(s[0, 1]), float(s[1, 1])) if dim == 2 else (0.0, 0.0)
    u1, u2 = float(v[0, 0]), float(v[1, 0])
    v1, v2 = (float(v[0, 1]), float(v[1, 1])) if dim == 2 else (0.0, 0.0)
    w1, w2 = (float(state.w[0, 0, 0]), float(state.w[0, 1, 0])) if spin else (0.0, 0.0)
    q1, q2 = (float(state.q[0, 0, 0]), float(state.q[0, 1, 0])) if state.q.shape[-1] else (0.0, 0.0)
    work = 0.0
    force = (0.0, 0.0)

    def geometry() -> tuple:
        """Normal, tangent, arms, spring force and accelerations at the current positions."""
        dx, dy = x2 - x1, y2 - y1
        dist = math.sqrt(dx * dx + dy * dy)
        nx, ny = dx / dist, dy / dist
        overlap = reach - dist
        half = 0.5 * (overlap if engaged else max(overlap, 0.0))
        arm_i, arm_j = r1 - half, r2 - half
        fn = k * (2.0 * half)
        acc = (-fn * nx * inv_m1 + gx, -fn * ny * inv_m1 + gy, fn * nx * inv_m2 + gx, fn * ny * inv_m2 + gy)
        li, lj = (r1, r2) if seed else (arm_i, arm_j)
        response = inv_pair + li * arm_i * inv_i1 + lj * arm_j * inv_i2
        return nx, ny, -ny, nx, dist, arm_i, arm_j, li, lj, fn, acc, response

    def hold(geo: tuple) -> tuple[float, float]:
        """G along d and dG/dlam at the current velocities (friction.hold_rate, one pair)."""
        nx, ny, tx, ty, dist, arm_i, arm_j, _, _, _, (a1x, a1y, a2x, a2y), _ = geo
        dx_, dy_ = side * tx, side * ty
        rate = side * ((a1x * tx + a1y * ty) - (a2x * tx + a2y * ty))
        ux, uy = u2 - u1, v2 - v1
        un = ux * nx + uy * ny
        rate += un * (ux * dx_ + uy * dy_) / dist
        slope = un * inv_pair / dist
        if spin and not seed:
            lever_speed = 0.5 * un
            rate += (w1 + w2) * (nx * dy_ - ny * dx_) * lever_speed
            slope -= lever_speed * (arm_i * inv_i1 + arm_j * inv_i2)
        return rate, slope

    def kick(end: float | None, start: float | None) -> tuple:
        nonlocal u1, u2, v1, v2, w1, w2, work, force
        geo = geometry()
        _, _, tx, ty, _, arm_i, arm_j, li, lj, fn, (a1x, a1y, a2x, a2y), response = geo
        if not friction:
            for part in (end, start):
                if part is not None:
                    u1, v1, u2, v2 = u1 + a1x * part, v1 + a1y * part, u2 + a2x * part, v2 + a2y * part
            return geo
        slide_force = mu * fn if slide else 0.0

        def impulse(lam: float) -> None:
            """Friction impulse lam against the slip: -lam d on 1 at its arm, +lam d on 2."""
            nonlocal u1, u2, v1, v2, w1, w2, work
            c = lam * side
            i1x, i1y, i2x, i2y, j1, j2 = c * tx, c * ty, -c * tx, -c * ty, c * arm_i, c * arm_j
            d1x, d1y, d2x, d2y = -inv_m1 * i1x, -inv_m1 * i1y, -inv_m2 * i2x, -inv_m2 * i2y
            e1, e2 = -inv_i1 * j1, -inv_i2 * j2
            work += (i1x * (u1 + 0.5 * d1x) + i1y * (v1 + 0.5 * d1y) + i2x * (u2 + 0.5 * d2x)
                     + i2y * (v2 + 0.5 * d2y) + j1 * (w1 + 0.5 * e1) + j2 * (w2 + 0.5 * e2))
            u1, v1, u2, v2, w1, w2 = u1 + d1x, v1 + d1y, u2 + d2x, v2 + d2y, w1 + e1, w2 + e2

        rate = None
        if end is not None:
            u1, v1, u2, v2 = u1 + a1x * end, v1 + a1y * end, u2 + a2x * end, v2 + a2y * end
            lam = slide_force * end
            if stick:
                rate, slope = hold(geo)
                held = end * rate / (response - end * slope)
                lam += held
                rate += slope * held
            impulse(lam)
            if start is None:
                f = -lam / (end if end != 0 else 1.0)
                force = (f * side * tx, f * side * ty)
        if start is not None:
            lam = slide_force * start
            if stick:
                if rate is None:
                    rate = hold(geo)[0]
                lam += start * rate / response
            u1, v1, u2, v2 = u1 + a1x * start, v1 + a1y * start, u2 + a2x * start, v2 + a2y * start
            impulse(lam)
        if start is None and stick:
            # friction.settle: the stuck slip back on the band's edge after the whole step.
            slip = (u1 - u2) * tx + (v1 - v2) * ty + li * w1 + lj * w2
            impulse((side * slip - eps) / response)
        return geo

    steps = [gamma * h for gamma in weights]
    kick(None, 0.5 * steps[0])
    for i, hk in enumerate(steps):
        x1, y1, x2, y2 = x1 + u1 * hk, y1 + v1 * hk, x2 + u2 * hk, y2 + v2 * hk
        q1, q2 = q1 + w1 * hk, q2 + w2 * hk
        geo = kick(0.5 * hk, 0.5 * steps[i + 1] if i + 1 < len(steps) else None)
    speeds = None
    if friction:
        # friction.frame_events at the end state, unscaled: values and rates, two per contact.
        _, _, tx, ty, _, _, _, li, lj, fn, _, response = geo
        slip = (u1 - u2) * tx + (v1 - v2) * ty + li * w1 + lj * w2
        rate = hold(geo)[0]
        mu_fn = mu * fn
        nan = math.nan
        if slide:
            values, rates = (side * slip - eps, 1.0), (rate - response * mu_fn, 0.0)
        elif stick:
            values = ((mu_fn * response - rate) * fr.STICK_SCALE, rate * fr.STICK_SCALE)
            rates = (nan, nan)
        else:
            values, rates = (eps - slip, eps + slip), (-rate * side, rate * side)
        speeds = (np.array([values]), np.array([rates]))

    def pack(a: float, b: float, c: float, d: float) -> np.ndarray:
        return np.array([[[a, b], [c, d]]]) if dim == 2 else np.array([[[a], [c]]])

    new = State(state.t + h, pack(x1, y1, x2, y2), pack(u1, v1, u2, v2),
                np.array([[[w1], [w2]]]) if spin else state.w.copy(),
                np.array([[[q1], [q2]]]) if state.q.shape[-1] else state.q.copy(), state.work + work)
    return new, np.array([[force[:dim]]]), speeds
