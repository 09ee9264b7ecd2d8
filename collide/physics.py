"""Contact physics as small vectorised functions (DESIGN section 2).

Every function takes batched arrays (see `collide.model` for shapes). Friction and torque are
only computed when the model has friction; spin arrays have K = 0 components when nothing can
spin, so those terms vanish from the work, not just from the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide.model import Model, State

TOUCH_TOL = 1e-12  # relative overlap below which spheres count as just touching


_PERP = np.array([[0.0, 1.0], [-1.0, 0.0]])


def perp2(a: np.ndarray) -> np.ndarray:
    """Rotate 2D vectors by +90 degrees: z x a = (-a_y, a_x) (one matmul: cheapest here)."""
    return a @ _PERP


def spin_cross(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """w x a: velocity of a point at lever a on a body spinning at w (K = 1 or 3)."""
    if w.shape[-1] == 1:
        return w * perp2(a)
    return np.cross(w, a)


def torque(a: np.ndarray, f: np.ndarray) -> np.ndarray:
    """a x f with K components (the z-component in 2D); np.cross is slow on small arrays."""
    if a.shape[-1] == 2:
        return (a[..., 0] * f[..., 1] - a[..., 1] * f[..., 0])[..., None]
    return a[..., _ROLL1] * f[..., _ROLL2] - a[..., _ROLL2] * f[..., _ROLL1]


_ROLL1, _ROLL2 = np.array([1, 2, 0]), np.array([2, 0, 1])


_add = np.add.reduce


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis (np.add.reduce: the cheapest call on small arrays)."""
    return _add(a * b, -1)


def generalised_velocity(state: State) -> np.ndarray:
    """Velocities then spins of every body, flattened (B, N D + N K): what a friction impulse acts on."""
    b = state.v.shape[0]
    return np.concatenate((state.v.reshape(b, -1), state.w.reshape(b, -1)), axis=1)


def norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt(_add(a * a, -1))


@dataclass
class Engaged:
    """Contacts in the current contact phase: pairs (B, P) and walls (B, W, N), as floats 0/1."""

    pair: np.ndarray
    wall: np.ndarray


@dataclass
class Contacts:
    """Geometry of every pair and sphere-wall contact at one configuration.

    Pair arrays are (B, P[, D]); wall arrays are (B, W, N[, D]). `n` points from i to j for
    pairs and out of the wall for walls; `overlap` is positive in contact. The lever arms from
    each centre to the contact point are along -n / +n with lengths `arm_i`, `arm_j` (each
    sphere of a pair is compressed by half the overlap: equal springs in series).
    """

    n: np.ndarray
    overlap: np.ndarray
    arm_i: np.ndarray
    arm_j: np.ndarray
    wall_overlap: np.ndarray
    wall_arm: np.ndarray
    pressed: np.ndarray  # overlap where the spring acts (clamped, or smooth when engaged)
    wall_pressed: np.ndarray

    @property
    def lever_i(self) -> np.ndarray:
        return self.arm_i[..., None] * self.n

    @property
    def lever_j(self) -> np.ndarray:
        return -self.arm_j[..., None] * self.n


def contact_geometry(model: Model, s: np.ndarray, engaged: Engaged | None = None) -> Contacts:
    """Normals, overlaps and lever arms from positions s (B, N, D).

    `engaged` marks the contacts of the current contact phase: they use the smooth extension of
    the spring law (no clamp at zero overlap), so that a high-order step whose substeps stray
    just outside the contact sees a smooth force; the phase's start and end are located events.
    """
    d = model.pair_diff @ s
    dist = norm(d)
    n = d / dist[..., None]
    overlap = model.pair_reach - dist
    clamped = np.maximum(overlap, 0.0)
    # Contacts outside the phase (e.g. touching at rest) keep the clamped law.
    pressed = clamped if engaged is None else np.where(engaged.pair > 0, overlap, clamped)
    half = 0.5 * pressed
    arm_i = model.pair_ri - half
    arm_j = model.pair_rj - half
    if model.n_walls:
        height = np.einsum("bnd,wd->bwn", s, model.wall_normal) - dot(model.wall_point, model.wall_normal)[:, None]
        wall_overlap = model.radius[:, None, :] - height
        wall_clamped = np.maximum(wall_overlap, 0.0)
        wall_pressed = wall_clamped if engaged is None else np.where(engaged.wall > 0, wall_overlap, wall_clamped)
        wall_arm = model.radius[:, None, :] - wall_pressed
    else:
        wall_overlap = wall_arm = wall_pressed = _EMPTY_WALLS
    return Contacts(n, overlap, arm_i, arm_j, wall_overlap, wall_arm, 2.0 * half, wall_pressed)


_EMPTY_WALLS = np.zeros((1, 0, 1))


def normal_forces(model: Model, c: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Spring force magnitudes: pairs (B, P) and walls (B, W, N)."""
    fn = model.k_pair * c.pressed
    fw = model.k_wall[:, None, :] * c.wall_pressed if model.n_walls else c.wall_overlap
    return fn, fw


def normal_accel(model: Model, c: Contacts, fn: np.ndarray, fw: np.ndarray) -> np.ndarray:
    """Linear acceleration (B, N, D) from the normal springs and gravity."""
    # Force -F n on i and +F n on j: one product with the pair incidence matrix.
    force = model.pair_diff.T @ (fn[..., None] * c.n)
    if model.n_walls:
        force = force + np.einsum("bwn,wd->bnd", fw, model.wall_normal)
    acc = force * model.inv_mass[..., None]
    if model.gravity is not None:
        acc = acc + model.gravity[:, None, :]
    return acc


def _slip_arms(model: Model, c: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Lever lengths used to measure slip: the contact point, or the undeformed radius (seed)."""
    if model.seed_lever:
        return model.pair_ri, model.pair_rj
    return c.arm_i, c.arm_j


def pair_slip(model: Model, c: Contacts, v: np.ndarray, w: np.ndarray,
              arms: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Tangential velocity of i's surface relative to j's at each pair contact (B, P, D).

    u = v_i + w_i x a_i - v_j - w_j x a_j with a_i = l_i n, a_j = -l_j n.
    """
    li, lj = arms if arms is not None else _slip_arms(model, c)
    u = _sliding(model, c, v)
    if w.shape[-1]:
        u = u + _rolling(model, c, w, li, lj)
    return u


def _sliding(model: Model, c: Contacts, v: np.ndarray) -> np.ndarray:
    """Tangential part of v_i - v_j at each pair (B, P, D)."""
    rel = -(model.pair_diff @ v)
    return rel - dot(rel, c.n)[..., None] * c.n


def _rolling(model: Model, c: Contacts, w: np.ndarray, li: np.ndarray, lj: np.ndarray) -> np.ndarray:
    """Surface velocity from spin, (l_i w_i + l_j w_j) x n, at each pair (B, P, D)."""
    spin = (model.select_i @ w) * li[..., None] + (model.select_j @ w) * lj[..., None]
    return spin_cross(spin, c.n)


def wall_slip(model: Model, c: Contacts, v: np.ndarray, w: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """Tangential velocity of each sphere's surface on each wall (B, W, N, D); lever -arm n_w."""
    nw = model.wall_normal[None, :, None, :]
    vb = v[:, None]
    u = vb - dot(vb, nw)[..., None] * nw
    if w.shape[-1]:
        u = u - spin_cross(w[:, None] * arm[..., None], nw)
    return u


def _unit(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mag = norm(x)
    return x / np.where(mag > 0, mag, 1.0)[..., None], mag


def _wall_slip_arm(model: Model, c: Contacts) -> np.ndarray:
    return model.radius[:, None, :] * np.ones_like(c.wall_arm) if model.seed_lever else c.wall_arm


def coulomb_explicit(model: Model, c: Contacts, fn: np.ndarray, fw: np.ndarray,
                     v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Friction forces on i (pairs, B P D) and on spheres (walls, B W N D): the seed's law.

    mu F_n against the slip when the slip exceeds the dead band eps, otherwise none.
    """
    direction, mag = _unit(pair_slip(model, c, v, w))
    on = mag > model.eps[:, None]
    ft = -(model.mu[:, None] * fn * on)[..., None] * direction
    fwt = np.zeros((v.shape[0], model.n_walls, model.n_bodies, model.dim))
    if model.n_walls:
        wdir, wmag = _unit(wall_slip(model, c, v, w, _wall_slip_arm(model, c)))
        won = wmag > model.eps[:, None, None]
        fwt = -(model.mu[:, None, None] * fw * won)[..., None] * wdir
    return ft, fwt


def friction_response(model: Model, c: Contacts, ft: np.ndarray, fwt: np.ndarray,
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Force (B, N, D) and torque (B, N, K) on each body from friction forces on contacts.

    Pairs: +ft on i at lever a_i n, -ft on j at lever -a_j n; both torques are a n x ft.
    """
    force = -(model.pair_diff.T @ ft)
    nxf = torque(c.n, ft)
    tau = model.select_i.T @ (c.arm_i[..., None] * nxf) + model.select_j.T @ (c.arm_j[..., None] * nxf)
    if model.n_walls:
        force = force + fwt.sum(axis=1)
        nw = model.wall_normal[None, :, None, :]
        tau = tau - (c.wall_arm[..., None] * torque(np.broadcast_to(nw, fwt.shape), fwt)).sum(axis=1)
    return force, tau


def apply_friction(model: Model, c: Contacts, ft: np.ndarray, fwt: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Linear (B, N, D) and angular (B, N, K) accelerations from friction forces."""
    force, tau = friction_response(model, c, ft, fwt)
    return force * model.inv_mass[..., None], tau * model.inv_inertia[..., None]


def kinetic_energy(model: Model, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Translational plus rotational kinetic energy (B,) in J."""
    energy = 0.5 * _add(model.mass * dot(v, v), -1)
    if w.shape[-1]:
        energy = energy + 0.5 * _add(model.inertia * dot(w, w), -1)
    return energy


def advance_orientation(q: np.ndarray, w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Orientation after turning at constant w for h seconds (exact for a free sphere)."""
    if q.shape[-1] == 0:
        return q
    if q.shape[-1] == 1:
        return q + w * h[:, None, None]
    angle_rate = np.sqrt(np.sum(w * w, axis=-1, keepdims=True))
    half = 0.5 * angle_rate * h[:, None, None]
    axis = w / np.where(angle_rate > 0, angle_rate, 1.0)
    dq = np.concatenate((np.cos(half), np.sin(half) * axis), axis=-1)
    return quat_mul(dq, q)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack((aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw), axis=-1)


def free_flight(model: Model, state: State, tau: np.ndarray) -> State:
    """Advance every body tau (B,) seconds in closed form, with no contact."""
    out = state.copy()
    hb = tau[:, None, None]
    out.s = state.s + state.v * hb
    if model.gravity is not None:
        g = model.gravity[:, None, :]
        out.s = out.s + 0.5 * g * hb * hb
        out.v = state.v + g * hb
    out.q = advance_orientation(state.q, state.w, tau)
    out.t = state.t + tau
    return out


def _smallest_positive_root(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Smallest t > 0 with a t^2 + b t + c = 0 (inf if none); c > 0 here (not yet touching)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.maximum(disc, 0.0))
        # Stable forms of both roots.
        q = -0.5 * (b + np.copysign(sq, b))
        r1 = np.where(q != 0, c / q, np.inf)
        r2 = np.where(a != 0, q / np.where(a != 0, a, 1.0), np.inf)
        r1 = np.where(r1 > 0, r1, np.inf)
        r2 = np.where(r2 > 0, r2, np.inf)
        root = np.minimum(r1, r2)
        return np.where((disc >= 0) & np.isfinite(root), root, np.inf)


def contact_rates(model: Model, state: State, c: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Rates of change of the overlaps: pairs (B, P) and walls (B, W, N)."""
    pair_rate = -dot(model.pair_diff @ state.v, c.n)
    if not model.n_walls:
        return pair_rate, c.wall_overlap
    return pair_rate, -np.einsum("bnd,wd->bwn", state.v, model.wall_normal)


def active_contacts(model: Model, state: State, c: Contacts | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Contacts that are pressing, or touching and approaching: pairs (B, P), walls (B, W, N)."""
    c = c or contact_geometry(model, state.s)
    pair_rate, wall_rate = contact_rates(model, state, c)
    tol = TOUCH_TOL * model.pair_reach
    pair = (c.overlap > tol) | ((c.overlap > -tol) & (pair_rate > 0))
    if not model.n_walls:
        return pair, c.wall_overlap > 0
    wtol = TOUCH_TOL * model.radius[:, None, :]
    approaching = wall_rate > 0
    if model.gravity is not None:
        # Resting on a wall at zero normal speed: gravity presses it in at the next instant.
        into = (model.gravity @ model.wall_normal.T)[:, :, None] < 0
        approaching = approaching | ((wall_rate == 0) & into)
    wall = (c.wall_overlap > wtol) | ((c.wall_overlap > -wtol) & approaching)
    return pair, wall


def time_to_contact(model: Model, state: State) -> np.ndarray:
    """Time (B,) until the next contact begins in free flight: 0 if one is active, inf if none."""
    c = contact_geometry(model, state.s)
    pair_active, wall_active = active_contacts(model, state, c)
    active = pair_active.any(axis=1) | wall_active.any(axis=(1, 2))
    d = model.pair_diff @ state.s
    u = model.pair_diff @ state.v  # gravity cancels in relative motion
    reach = model.pair_reach
    a = dot(u, u)
    b = 2 * dot(d, u)
    cc = dot(d, d) - reach * reach
    approaching = b < 0
    t_pair = np.where(approaching, _smallest_positive_root(a, b, np.maximum(cc, 0.0)), np.inf)
    tau = t_pair.min(axis=1, initial=np.inf)
    if model.n_walls:
        gap = -c.wall_overlap  # height above the wall minus radius
        rate = np.einsum("bnd,wd->bwn", state.v, model.wall_normal)
        acc = np.zeros_like(rate) if model.gravity is None else \
            np.einsum("bd,wd->bw", model.gravity, model.wall_normal)[..., None] * np.ones_like(rate)
        t_wall = _smallest_positive_root(0.5 * acc, rate, np.maximum(gap, 0.0))
        tau = np.minimum(tau, t_wall.min(axis=(1, 2), initial=np.inf))
    return np.where(active, 0.0, tau)
