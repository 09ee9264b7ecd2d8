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


def perp2(a: np.ndarray) -> np.ndarray:
    """Rotate 2D vectors by +90 degrees: z x a."""
    return np.stack((-a[..., 1], a[..., 0]), axis=-1)


def spin_cross(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """w x a: velocity of a point at lever a on a body spinning at w (K = 1 or 3)."""
    if w.shape[-1] == 1:
        return w * perp2(a)
    return np.cross(w, a)


def torque(a: np.ndarray, f: np.ndarray) -> np.ndarray:
    """a x f with K components (the z-component in 2D)."""
    if a.shape[-1] == 2:
        return (a[..., 0] * f[..., 1] - a[..., 1] * f[..., 0])[..., None]
    return np.cross(a, f)


@dataclass
class Contacts:
    """Geometry of every pair and sphere-wall contact at one configuration.

    Pair arrays are (B, P[, D]); wall arrays are (B, W, N[, D]). `n` points from i to j for
    pairs and out of the wall for walls; `overlap` is positive in contact.
    """

    n: np.ndarray
    overlap: np.ndarray
    lever_i: np.ndarray  # centre of i to the contact point
    lever_j: np.ndarray
    wall_overlap: np.ndarray
    wall_lever: np.ndarray


def contact_geometry(model: Model, s: np.ndarray) -> Contacts:
    """Normals, overlaps and lever arms from positions s (B, N, D)."""
    d = s[:, model.pair_j] - s[:, model.pair_i]
    dist = np.sqrt(np.einsum("bpd,bpd->bp", d, d))
    n = d / dist[..., None]
    ri = model.radius[:, model.pair_i]
    rj = model.radius[:, model.pair_j]
    overlap = ri + rj - dist
    # Springs in series share the overlap in proportion to the other's constant (equal k: half).
    half = 0.5 * np.maximum(overlap, 0.0)
    lever_i = (ri - half)[..., None] * n
    lever_j = -(rj - half)[..., None] * n
    if model.n_walls:
        height = np.einsum("bnd,wd->bwn", s, model.wall_normal) - np.einsum(
            "wd,wd->w", model.wall_point, model.wall_normal)[None, :, None]
        wall_overlap = model.radius[:, None, :] - height
        wall_lever = -(model.radius[:, None, :] - np.maximum(wall_overlap, 0.0))[..., None] * \
            model.wall_normal[None, :, None, :]
    else:
        wall_overlap = np.zeros((s.shape[0], 0, model.n_bodies))
        wall_lever = np.zeros((s.shape[0], 0, model.n_bodies, model.dim))
    return Contacts(n, overlap, lever_i, lever_j, wall_overlap, wall_lever)


def scatter_pairs(model: Model, f_i: np.ndarray, f_j: np.ndarray) -> np.ndarray:
    """Sum per-pair quantities (B, P, X) onto bodies (B, N, X)."""
    return model.pair_to_body_i @ f_i + model.pair_to_body_j @ f_j


def normal_forces(model: Model, c: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Spring force magnitudes: pairs (B, P) and walls (B, W, N)."""
    fn = model.k_pair * np.maximum(c.overlap, 0.0)
    fw = model.k_wall[:, None, :] * np.maximum(c.wall_overlap, 0.0)
    return fn, fw


def normal_accel(model: Model, c: Contacts, fn: np.ndarray, fw: np.ndarray) -> np.ndarray:
    """Linear acceleration (B, N, D) from the normal springs and gravity."""
    f_pair = fn[..., None] * c.n
    force = scatter_pairs(model, -f_pair, f_pair)
    if model.n_walls:
        force = force + np.einsum("bwn,wd->bnd", fw, model.wall_normal)
    acc = force * model.inv_mass[..., None]
    if model.gravity is not None:
        acc = acc + model.gravity[:, None, :]
    return acc


def slip_levers(model: Model, c: Contacts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lever arms used to measure slip: the contact point, or the undeformed radius (seed)."""
    if not model.seed_lever:
        return c.lever_i, c.lever_j, c.wall_lever
    ri = model.radius[:, model.pair_i][..., None]
    rj = model.radius[:, model.pair_j][..., None]
    wall = -model.radius[:, None, :, None] * model.wall_normal[None, :, None, :]
    return ri * c.n, -rj * c.n, wall


def tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - np.sum(u * n, axis=-1, keepdims=True) * n


def pair_slip(model: Model, c: Contacts, v: np.ndarray, w: np.ndarray, levers) -> np.ndarray:
    """Tangential velocity of i's surface relative to j's at each pair contact (B, P, D)."""
    li, lj, _ = levers
    ui = v[:, model.pair_i] + spin_cross(w[:, model.pair_i], li)
    uj = v[:, model.pair_j] + spin_cross(w[:, model.pair_j], lj)
    return tangential(ui - uj, c.n)


def wall_slip(model: Model, c: Contacts, v: np.ndarray, w: np.ndarray, levers) -> np.ndarray:
    """Tangential velocity of each sphere's surface on each wall (B, W, N, D)."""
    _, _, lw = levers
    u = v[:, None] + spin_cross(w[:, None], lw)
    return tangential(u, model.wall_normal[None, :, None, :])


def _unit(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mag = np.sqrt(np.sum(x * x, axis=-1))
    safe = np.where(mag > 0, mag, 1.0)
    return x / safe[..., None], mag


def coulomb_explicit(model: Model, c: Contacts, fn: np.ndarray, fw: np.ndarray,
                     v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Friction forces on i (pairs, B P D) and on spheres (walls, B W N D): the seed's law.

    mu F_n against the slip when the slip exceeds the dead band eps, otherwise none.
    """
    levers = slip_levers(model, c)
    direction, mag = _unit(pair_slip(model, c, v, w, levers))
    on = mag > model.eps[:, None]
    ft = -(model.mu[:, None] * fn * on)[..., None] * direction
    wdir, wmag = _unit(wall_slip(model, c, v, w, levers))
    won = wmag > model.eps[:, None, None]
    fwt = -(model.mu[:, None, None] * fw * won)[..., None] * wdir
    return ft, fwt


def apply_friction(model: Model, c: Contacts, ft: np.ndarray, fwt: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Linear (B, N, D) and angular (B, N, K) accelerations from friction forces."""
    force = scatter_pairs(model, ft, -ft)
    tau = scatter_pairs(model, torque(c.lever_i, ft), torque(c.lever_j, -ft))
    if model.n_walls:
        force = force + fwt.sum(axis=1)
        tau = tau + torque(c.wall_lever, fwt).sum(axis=1)
    return force * model.inv_mass[..., None], tau * model.inv_inertia[..., None]


def friction_kick(model: Model, c: Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
                  hk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply a friction impulse over hk seconds, implicitly (backward Euler in the slip).

    The impulse is the one that brings the slip to the edge of the dead band, capped at
    mu F_n hk: this is Coulomb's law with the band's sliding mode treated exactly, so there is
    no chatter on the band edge (DESIGN section 8). Impulses are equal and opposite at one
    contact point, so momentum and angular momentum stay at round-off. Adds the work done
    against friction to `state.work`. Returns the friction forces (for display).
    """
    levers = slip_levers(model, c)
    i, j = model.pair_i, model.pair_j
    mi, mj = model.inv_mass[:, i], model.inv_mass[:, j]
    ii, ij = model.inv_inertia[:, i], model.inv_inertia[:, j]
    li = np.sqrt(np.sum(levers[0] ** 2, -1))
    lj = np.sqrt(np.sum(levers[1] ** 2, -1))
    ai = np.sqrt(np.sum(c.lever_i ** 2, -1))
    aj = np.sqrt(np.sum(c.lever_j ** 2, -1))
    # Slip change per unit tangential impulse (spheres: isotropic, so along the impulse).
    k_slip = mi + mj + li * ai * ii + lj * aj * ij
    direction, slip = _unit(pair_slip(model, c, state.v, state.w, levers))
    hkp = hk[:, None]
    cap = model.mu[:, None] * fn * np.abs(hkp)
    impulse = np.minimum(cap, np.maximum(slip - model.eps[:, None], 0.0) / k_slip)
    ji = -impulse[..., None] * direction
    dv = scatter_pairs(model, ji, -ji) * model.inv_mass[..., None]
    dw = scatter_pairs(model, torque(c.lever_i, ji), torque(c.lever_j, -ji)) * model.inv_inertia[..., None]
    safe_h = np.where(hkp != 0, hkp, 1.0)
    ft = ji / safe_h[..., None]
    fwt = np.zeros(c.wall_lever.shape)
    if model.n_walls:
        wm = model.inv_mass[:, None, :]
        wi = model.inv_inertia[:, None, :]
        lw = np.sqrt(np.sum(levers[2] ** 2, -1))
        aw = np.sqrt(np.sum(c.wall_lever ** 2, -1))
        wdir, wslip = _unit(wall_slip(model, c, state.v, state.w, levers))
        wcap = model.mu[:, None, None] * fw * np.abs(hk)[:, None, None]
        wimp = np.minimum(wcap, np.maximum(wslip - model.eps[:, None, None], 0.0) / (wm + lw * aw * wi))
        jw = -wimp[..., None] * wdir
        dv = dv + jw.sum(axis=1) * model.inv_mass[..., None]
        dw = dw + torque(c.wall_lever, jw).sum(axis=1) * model.inv_inertia[..., None]
        fwt = jw / np.where(hk != 0, hk, 1.0)[:, None, None, None]
    # The work done against friction is the kinetic energy these impulses remove.
    before = kinetic_energy(model, state.v, state.w)
    state.v += dv
    state.w += dw
    state.work += before - kinetic_energy(model, state.v, state.w)
    return ft, fwt


def kinetic_energy(model: Model, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Translational plus rotational kinetic energy (B,) in J."""
    energy = 0.5 * np.sum(model.mass * np.sum(v * v, -1), -1)
    if w.shape[-1]:
        energy = energy + 0.5 * np.sum(model.inertia * np.sum(w * w, -1), -1)
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
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
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
    u = state.v[:, model.pair_j] - state.v[:, model.pair_i]
    pair_rate = -np.sum(u * c.n, axis=-1)
    wall_rate = -np.einsum("bnd,wd->bwn", state.v, model.wall_normal)
    return pair_rate, wall_rate


def active_contacts(model: Model, state: State, c: Contacts | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Contacts that are pressing, or touching and approaching: pairs (B, P), walls (B, W, N)."""
    c = c or contact_geometry(model, state.s)
    pair_rate, wall_rate = contact_rates(model, state, c)
    scale = model.radius[:, model.pair_i] + model.radius[:, model.pair_j]
    tol = TOUCH_TOL * scale
    pair = (c.overlap > tol) | ((c.overlap > -tol) & (pair_rate > 0))
    wtol = TOUCH_TOL * model.radius[:, None, :]
    wall = (c.wall_overlap > wtol) | ((c.wall_overlap > -wtol) & (wall_rate > 0))
    return pair, wall


def time_to_contact(model: Model, state: State) -> np.ndarray:
    """Time (B,) until the next contact begins in free flight: 0 if one is active, inf if none."""
    c = contact_geometry(model, state.s)
    pair_active, wall_active = active_contacts(model, state, c)
    active = pair_active.any(axis=1) | wall_active.any(axis=(1, 2))
    d = state.s[:, model.pair_j] - state.s[:, model.pair_i]
    u = state.v[:, model.pair_j] - state.v[:, model.pair_i]  # gravity cancels in relative motion
    reach = model.radius[:, model.pair_i] + model.radius[:, model.pair_j]
    a = np.sum(u * u, -1)
    b = 2 * np.sum(d * u, -1)
    cc = np.sum(d * d, -1) - reach * reach
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
