"""Steps and friction modes for the commonest case, in plain Python floats: a single run (B = 1)
of two spheres in 1D or 2D with no walls (every built-in scene).

The equations are those of the numpy kernels, term by term: `physics.contact_geometry` and
`normal_accel`, and `friction.frame_kick`, `hold_rate`, `settle`, `decide_modes` and
`frame_events` for one pair in the plane. numpy costs about a microsecond a call whatever the
size, and a step here is a few dozen operations on four numbers, so floats are some ten times
faster. `tests/test_pairstep.py` checks that both paths agree to round-off on every built-in, on
random scenes, and step by step in every friction mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from collide import friction as fr
from collide.model import Model, State


def applies(model: Model) -> bool:
    """Whether this module can take the model's steps."""
    return model.batch == 1 and model.n_bodies == 2 and model.n_walls == 0 and model.dim <= 2


@dataclass(frozen=True)
class Pair:
    """The model's constants as floats."""

    dim: int
    spin: bool
    inv_m1: float
    inv_m2: float
    inv_i1: float
    inv_i2: float
    r1: float
    r2: float
    reach: float
    k: float
    inv_pair: float
    gx: float
    gy: float
    mu: float
    eps: float
    seed: bool
    friction: bool

    @classmethod
    def of(cls, model: Model) -> Pair:
        """The model's constants, built once per model (a run asks for them at every step)."""
        key = id(model)
        cached = _PAIRS.get(key)
        if cached is not None and cached[0] is model:
            return cached[1]
        pair = cls._build(model)
        if len(_PAIRS) > 16:
            _PAIRS.clear()
        _PAIRS[key] = (model, pair)
        return pair

    @classmethod
    def _build(cls, model: Model) -> Pair:
        spin = model.spin_dim > 0
        g = (0.0, 0.0) if model.gravity is None else \
            (float(model.gravity[0, 0]), float(model.gravity[0, 1]) if model.dim == 2 else 0.0)
        i1, i2 = (float(x) for x in model.inv_inertia[0]) if spin else (0.0, 0.0)
        m1, m2 = (float(x) for x in model.inv_mass[0])
        r1, r2 = (float(x) for x in model.radius[0])
        return cls(model.dim, spin, m1, m2, i1, i2, r1, r2, float(model.pair_reach[0, 0]),
                   float(model.k_pair[0, 0]), float(model.pair_inv_mass[0, 0]), g[0], g[1],
                   float(model.mu[0]), float(model.eps[0]), model.seed_lever, model.friction)


_PAIRS: dict[int, tuple[Model, Pair]] = {}  # id -> (the model itself, so the id is not reused, its Pair)


def _geometry(p: Pair, x1: float, y1: float, x2: float, y2: float, engaged: bool) -> tuple:
    """Normal, tangent, distance, arms, slip levers, spring force, accelerations and the slip's
    response to a friction impulse at these positions."""
    dx, dy = x2 - x1, y2 - y1
    dist = math.sqrt(dx * dx + dy * dy)
    nx, ny = dx / dist, dy / dist
    overlap = p.reach - dist
    half = 0.5 * (overlap if engaged else max(overlap, 0.0))
    arm_i, arm_j = p.r1 - half, p.r2 - half
    fn = p.k * (2.0 * half)
    acc = (-fn * nx * p.inv_m1 + p.gx, -fn * ny * p.inv_m1 + p.gy, fn * nx * p.inv_m2 + p.gx, fn * ny * p.inv_m2 + p.gy)
    li, lj = (p.r1, p.r2) if p.seed else (arm_i, arm_j)
    response = p.inv_pair + li * arm_i * p.inv_i1 + lj * arm_j * p.inv_i2
    return nx, ny, -ny, nx, dist, arm_i, arm_j, li, lj, fn, acc, response


def _hold(p: Pair, geo: tuple, side: float, vel: tuple) -> tuple[float, float]:
    """G along d = side t and dG/dlam at velocities (u1, v1, u2, v2, w1, w2): friction.hold_rate."""
    nx, ny, tx, ty, dist, arm_i, arm_j, _, _, _, (a1x, a1y, a2x, a2y), _ = geo
    u1, v1, u2, v2, w1, w2 = vel
    dx_, dy_ = side * tx, side * ty
    rate = side * ((a1x * tx + a1y * ty) - (a2x * tx + a2y * ty))
    ux, uy = u2 - u1, v2 - v1
    un = ux * nx + uy * ny
    rate += un * (ux * dx_ + uy * dy_) / dist
    slope = un * p.inv_pair / dist
    if p.spin and not p.seed:
        lever_speed = 0.5 * un
        rate += (w1 + w2) * (nx * dy_ - ny * dx_) * lever_speed
        slope -= lever_speed * (arm_i * p.inv_i1 + arm_j * p.inv_i2)
    return rate, slope


def _slip(geo: tuple, vel: tuple) -> float:
    """The slip along t (surface of 1 relative to surface of 2)."""
    _, _, tx, ty, _, _, _, li, lj, _, _, _ = geo
    u1, v1, u2, v2, w1, w2 = vel
    return (u1 - u2) * tx + (v1 - v2) * ty + li * w1 + lj * w2


def _events(p: Pair, geo: tuple, mode: int, side: float, vel: tuple, positions: tuple,
            engaged: bool) -> tuple[tuple, tuple]:
    """friction.frame_events for the pair, unscaled: two values and their rates. The stuck
    contact's rates, which have no closed form, come from a central difference along its motion
    (numpy's path leaves them unknown and brackets instead)."""
    slip = _slip(geo, vel)
    rate = _hold(p, geo, side, vel)[0]
    response, mu_fn = geo[11], p.mu * geo[9]
    if mode == fr.SLIDE:
        return (side * slip - p.eps, 1.0), (rate - response * mu_fn, 0.0)
    if mode == fr.STICK:
        values = ((mu_fn * response - rate) * fr.STICK_SCALE, rate * fr.STICK_SCALE)
        return values, _stick_rates(p, geo, side, vel, positions, engaged, rate)
    return (p.eps - slip, p.eps + slip), (-rate * side, rate * side)


def _stick_rates(p: Pair, geo: tuple, side: float, vel: tuple, positions: tuple, engaged: bool,
                 rate: float) -> tuple[float, float]:
    """Time derivatives of a stuck contact's event values: central differences over +-delta
    along the motion (springs, gravity and the hold force G / K), delta = 1e-4 / omega, so the
    truncation error is about 1e-9 and rounding about 1e-12, relative."""
    _, _, tx, ty, _, arm_i, arm_j, _, _, _, (a1x, a1y, a2x, a2y), response = geo
    c = side * rate / response  # the hold force along d, as an impulse per unit time
    accel = (a1x - p.inv_m1 * c * tx, a1y - p.inv_m1 * c * ty, a2x + p.inv_m2 * c * tx,
             a2y + p.inv_m2 * c * ty, -p.inv_i1 * c * arm_i, -p.inv_i2 * c * arm_j)
    delta = 1e-4 / math.sqrt(p.k * p.inv_pair)
    u1, v1, u2, v2 = vel[:4]
    out = []
    for sign in (1.0, -1.0):
        d = sign * delta
        x1, y1, x2, y2 = positions
        moved = _geometry(p, x1 + d * u1, y1 + d * v1, x2 + d * u2, y2 + d * v2, engaged)
        w = tuple(a + d * b for a, b in zip(vel, accel))
        g = _hold(p, moved, side, w)[0]
        out.append((p.mu * moved[9] * moved[11] - g, g))
    scale = fr.STICK_SCALE / (2.0 * delta)
    return (out[0][0] - out[1][0]) * scale, (out[0][1] - out[1][1]) * scale


def _unpack(state: State, dim: int) -> tuple[list[float], list[float]]:
    s, v = state.s[0], state.v[0]
    positions = [float(s[0, 0]), float(s[0, 1]) if dim == 2 else 0.0,
                 float(s[1, 0]), float(s[1, 1]) if dim == 2 else 0.0]
    w = (float(state.w[0, 0, 0]), float(state.w[0, 1, 0])) if state.w.shape[-1] else (0.0, 0.0)
    velocities = [float(v[0, 0]), float(v[0, 1]) if dim == 2 else 0.0, float(v[1, 0]),
                  float(v[1, 1]) if dim == 2 else 0.0, *w]
    return positions, velocities


def decide(model: Model, state: State, engaged: bool, scale: float) -> tuple[fr.Modes, tuple]:
    """friction.decide_modes for the pair: its mode at this state, and the mode's event values
    and rates there, unscaled (each (1, 2))."""
    p = Pair.of(model)
    (x1, y1, x2, y2), vel = _unpack(state, p.dim)
    geo = _geometry(p, x1, y1, x2, y2, engaged)
    slip = _slip(geo, vel)
    side = 1.0 if slip >= 0 else -1.0
    along = side * slip
    response, fn = geo[11], geo[9]
    need = _hold(p, geo, side, vel)[0] / response
    tol = fr.EDGE_TOL * scale
    force_tol = tol / (response * fr.STICK_SCALE)
    if not engaged:
        mode = fr.BAND
    elif abs(along - p.eps) <= tol:
        mode = fr.BAND if need <= force_tol else (fr.STICK if need < p.mu * fn - force_tol else fr.SLIDE)
    else:
        mode = fr.SLIDE if along > p.eps else fr.BAND
    values, rates = _events(p, geo, mode, side, vel, (x1, y1, x2, y2), engaged)
    modes = fr.Modes(np.full((1, 1), mode, np.int8), np.full((1, 1), side), np.zeros((1, 1, 2)))
    return modes, (np.array([values]), np.array([rates]))


def composite(model: Model, state: State, h: float, weights: tuple[float, ...], engaged: bool,
              modes: fr.Modes | None) -> tuple[State, np.ndarray, tuple | None]:
    """A symmetric composition of Verlet substeps gamma h (see `integrators._composition`) from
    `state`; `engaged`: the pair is in its contact phase (smooth spring law); `modes`: its
    friction mode and side. Returns the new state, the pair's friction force at the end
    (1, 1, D) and, with friction, the mode's event values and rates there, unscaled (see
    `friction.frame_events`), each (1, 2)."""
    p = Pair.of(model)
    friction = p.friction and modes is not None
    mode = int(modes.mode[0, 0]) if friction else fr.BAND
    side = float(modes.side[0, 0]) if friction else 1.0
    slide, stick = mode == fr.SLIDE, mode == fr.STICK
    (x1, y1, x2, y2), (u1, v1, u2, v2, w1, w2) = _unpack(state, p.dim)
    q1, q2 = (float(state.q[0, 0, 0]), float(state.q[0, 1, 0])) if state.q.shape[-1] else (0.0, 0.0)
    work = 0.0
    force = (0.0, 0.0)

    def kick(end: float | None, start: float | None) -> tuple:
        nonlocal u1, u2, v1, v2, w1, w2, work, force
        geo = _geometry(p, x1, y1, x2, y2, engaged)
        _, _, tx, ty, _, arm_i, arm_j, li, lj, fn, (a1x, a1y, a2x, a2y), response = geo
        if not friction:
            for part in (end, start):
                if part is not None:
                    u1, v1, u2, v2 = u1 + a1x * part, v1 + a1y * part, u2 + a2x * part, v2 + a2y * part
            return geo
        slide_force = p.mu * fn if slide else 0.0

        def impulse(lam: float) -> None:
            """Friction impulse lam against the slip: -lam d on 1 at its arm, +lam d on 2."""
            nonlocal u1, u2, v1, v2, w1, w2, work
            c = lam * side
            i1x, i1y, i2x, i2y, j1, j2 = c * tx, c * ty, -c * tx, -c * ty, c * arm_i, c * arm_j
            d1x, d1y, d2x, d2y = -p.inv_m1 * i1x, -p.inv_m1 * i1y, -p.inv_m2 * i2x, -p.inv_m2 * i2y
            e1, e2 = -p.inv_i1 * j1, -p.inv_i2 * j2
            work += (i1x * (u1 + 0.5 * d1x) + i1y * (v1 + 0.5 * d1y) + i2x * (u2 + 0.5 * d2x)
                     + i2y * (v2 + 0.5 * d2y) + j1 * (w1 + 0.5 * e1) + j2 * (w2 + 0.5 * e2))
            u1, v1, u2, v2, w1, w2 = u1 + d1x, v1 + d1y, u2 + d2x, v2 + d2y, w1 + e1, w2 + e2

        rate = None
        if end is not None:
            u1, v1, u2, v2 = u1 + a1x * end, v1 + a1y * end, u2 + a2x * end, v2 + a2y * end
            lam = slide_force * end
            if stick:
                rate, slope = _hold(p, geo, side, (u1, v1, u2, v2, w1, w2))
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
                    rate = _hold(p, geo, side, (u1, v1, u2, v2, w1, w2))[0]
                lam += start * rate / response
            u1, v1, u2, v2 = u1 + a1x * start, v1 + a1y * start, u2 + a2x * start, v2 + a2y * start
            impulse(lam)
        if start is None and stick:
            # friction.settle: the stuck slip back on the band's edge after the whole step.
            slip = (u1 - u2) * tx + (v1 - v2) * ty + li * w1 + lj * w2
            impulse((side * slip - p.eps) / response)
        return geo

    steps = [gamma * h for gamma in weights]
    kick(None, 0.5 * steps[0])
    for i, hk in enumerate(steps):
        x1, y1, x2, y2 = x1 + u1 * hk, y1 + v1 * hk, x2 + u2 * hk, y2 + v2 * hk
        q1, q2 = q1 + w1 * hk, q2 + w2 * hk
        geo = kick(0.5 * hk, 0.5 * steps[i + 1] if i + 1 < len(steps) else None)
    speeds = None
    if friction:
        values, rates = _events(p, geo, mode, side, (u1, v1, u2, v2, w1, w2), (x1, y1, x2, y2), engaged)
        speeds = (np.array([values]), np.array([rates]))

    def pack(a: float, b: float, c: float, d: float) -> np.ndarray:
        return np.array([[[a, b], [c, d]]]) if p.dim == 2 else np.array([[[a], [c]]])

    new = State(state.t + h, pack(x1, y1, x2, y2), pack(u1, v1, u2, v2),
                np.array([[[w1], [w2]]]) if p.spin else state.w.copy(),
                np.array([[[q1], [q2]]]) if state.q.shape[-1] else state.q.copy(), state.work + work)
    return new, np.array([[force[:p.dim]]]), speeds
