"""Diagnostics of a run: conserved quantities, contacts and residuals (DESIGN sections 2 and 4).

Functions take states with any leading shape (..., B, N, D), so the same code serves a final
state (B, N, D) and a whole trajectory (S, B, N, D).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide.model import Model, State
from collide.physics import perp2
from collide.stepper import RunResult, Trajectory


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _cross_z(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angular momentum-like cross product: (..., 1) in 2D, (..., 3) in 3D."""
    if a.shape[-1] == 2:
        return (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])[..., None]
    return np.cross(a, b)


@dataclass
class Conserved:
    """Per-state totals; shapes (...,) for energies, (..., D) for P, (..., L) for L (L = 0 in 1D)."""

    kinetic: np.ndarray
    rotational: np.ndarray | None
    spring: np.ndarray
    gravitational: np.ndarray | None
    dissipated: np.ndarray | None
    momentum: np.ndarray
    angular_momentum: np.ndarray | None
    com: np.ndarray

    @property
    def total(self) -> np.ndarray:
        """Mechanical energy: kinetic + rotational + spring (+ gravitational)."""
        total = self.kinetic + self.spring
        if self.rotational is not None:
            total = total + self.rotational
        if self.gravitational is not None:
            total = total + self.gravitational
        return total

    @property
    def balance(self) -> np.ndarray:
        """Energy plus the work dissipated by friction: conserved by the model."""
        return self.total if self.dissipated is None else self.total + self.dissipated


def overlaps(model: Model, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overlap of every pair (..., P) and sphere-wall contact (..., W, N), positive in contact."""
    d = s[..., model.pair_j, :] - s[..., model.pair_i, :]
    dist = np.sqrt(_dot(d, d))
    pair = model.radius[:, model.pair_i] + model.radius[:, model.pair_j] - dist
    height = np.einsum("...nd,wd->...wn", s, model.wall_normal) - _dot(model.wall_point, model.wall_normal)[:, None]
    wall = model.radius[:, None, :] - height
    return pair, wall


def conserved(model: Model, t: np.ndarray, s: np.ndarray, v: np.ndarray, w: np.ndarray,
              work: np.ndarray) -> Conserved:
    """Energies, momentum, angular momentum about the origin and centre of mass."""
    m = model.mass
    kinetic = 0.5 * np.sum(m * _dot(v, v), axis=-1)
    rotational = 0.5 * np.sum(model.inertia * _dot(w, w), axis=-1) if w.shape[-1] else None
    pair, wall = overlaps(model, s)
    spring = 0.5 * np.sum(model.k_pair * np.maximum(pair, 0.0) ** 2, axis=-1)
    if model.n_walls:
        spring = spring + 0.5 * np.sum(model.k_wall[:, None, :] * np.maximum(wall, 0.0) ** 2, axis=(-1, -2))
    gravitational = None
    if model.gravity is not None:
        gravitational = -np.sum(m * _dot(s, model.gravity[:, None, :]), axis=-1)
    momentum = np.sum(m[..., None] * v, axis=-2)
    angular = None
    if model.dim > 1:
        angular = np.sum(_cross_z(s, m[..., None] * v), axis=-2)
        if w.shape[-1]:
            angular = angular + np.sum(model.inertia[..., None] * w, axis=-2)
    com = np.sum(m[..., None] * s, axis=-2) / m.sum(axis=-1)[..., None]
    return Conserved(kinetic, rotational, spring, gravitational, work if model.friction else None,
                     momentum, angular, com)


def trajectory_conserved(model: Model, traj: Trajectory) -> Conserved:
    return conserved(model, traj.t, traj.s, traj.v, traj.w, traj.work)


def state_conserved(model: Model, state: State) -> Conserved:
    return conserved(model, state.t, state.s, state.v, state.w, state.work)


# ---------------------------------------------------------------------------------------------
# Residuals (relative, dimensionless)


@dataclass
class Residuals:
    """Relative residuals (B,) of the final state against the start; NaN where none applies.

    energy: |E + W - E0| / E0 (W = work dissipated by friction, gravity's potential included);
    momentum: |P - P0 - M g t| / sum m|v|; angular_momentum: |L - L0 - gravity's torque| /
    sum |s x m v| + |I w| (largest of start and end). With walls, momentum and angular momentum
    are not conserved and their residuals are NaN (null in JSON).
    """

    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray


def _angular_scale(model: Model, s: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    terms = np.sqrt(_dot(_cross_z(s, model.mass[..., None] * v), _cross_z(s, model.mass[..., None] * v)))
    scale = terms.sum(axis=-1)
    if w.shape[-1]:
        scale = scale + np.sum(model.inertia * np.sqrt(_dot(w, w)), axis=-1)
    return scale


def residuals(result: RunResult) -> Residuals:
    model, a, b = result.model, result.initial, result.final
    c0, c1 = state_conserved(model, a), state_conserved(model, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        e0 = np.abs(c0.balance)
        energy = np.where(e0 > 0, np.abs(c1.balance - c0.balance) / e0, np.nan)
        elapsed = b.t - a.t
        total_mass = model.mass.sum(axis=1)
        dp = c1.momentum - c0.momentum
        dl = c1.angular_momentum - c0.angular_momentum if model.dim > 1 else None
        if model.gravity is not None:
            g = model.gravity
            dp = dp - total_mass[:, None] * g * elapsed[:, None]
            if dl is not None:
                # Gravity's torque about the origin, integrated along the free-falling centre of mass.
                arm = c0.com * elapsed[:, None] + 0.5 * (c0.momentum / total_mass[:, None]) * elapsed[:, None] ** 2
                dl = dl - _cross_z(arm, total_mass[:, None] * g)
        p_scale = np.maximum(np.sum(model.mass * np.sqrt(_dot(a.v, a.v)), -1),
                             np.sum(model.mass * np.sqrt(_dot(b.v, b.v)), -1))
        momentum = np.where(p_scale > 0, np.sqrt(_dot(dp, dp)) / p_scale, 0.0)
        if dl is None:
            angular = np.full(model.batch, np.nan)
        else:
            l_scale = np.maximum(_angular_scale(model, a.s, a.v, a.w), _angular_scale(model, b.s, b.v, b.w))
            angular = np.where(l_scale > 0, np.sqrt(_dot(dl, dl)) / l_scale, 0.0)
    if model.n_walls:
        momentum = np.full(model.batch, np.nan)
        angular = np.full(model.batch, np.nan)
    return Residuals(energy, momentum, angular)


# ---------------------------------------------------------------------------------------------
# Contacts along a trajectory


@dataclass
class ContactSeries:
    """Every contact at every step: pairs first, then sphere-wall contacts (C = P + W N).

    overlap (S, B, C) m; compression (S, B, C, 2) m, how much each of the two spheres is
    compressed (the wall's column is 0); point (S, B, C, D) m; normal_force (S, B, C, D) N and
    friction_force (S, B, C, D) N, both acting on the first body of the contact.
    """

    names: list[str]
    overlap: np.ndarray
    compression: np.ndarray
    point: np.ndarray
    normal_force: np.ndarray
    friction_force: np.ndarray | None


def contact_series(model: Model, traj: Trajectory) -> ContactSeries:
    s = traj.s
    d = s[..., model.pair_j, :] - s[..., model.pair_i, :]
    dist = np.sqrt(_dot(d, d))
    n = d / dist[..., None]
    ri, rj = model.radius[:, model.pair_i], model.radius[:, model.pair_j]
    overlap = ri + rj - dist
    pressed = np.maximum(overlap, 0.0)
    # Equal springs in series share the overlap equally.
    comp = np.stack((0.5 * pressed, 0.5 * pressed), axis=-1)
    point = s[..., model.pair_i, :] + (ri - 0.5 * pressed)[..., None] * n
    normal = -(model.k_pair * pressed)[..., None] * n
    _, wall_overlap = overlaps(model, s)
    wall_pressed = np.maximum(wall_overlap, 0.0)
    nw = model.wall_normal[:, None, :]
    wall_point = s[..., None, :, :] - (model.radius[:, None, :] - wall_pressed)[..., None] * nw
    wall_normal = (model.k_wall[:, None, :] * wall_pressed)[..., None] * nw
    lead = s.shape[:-2]
    flat = (*lead, model.n_walls * model.n_bodies)
    overlap = np.concatenate((overlap, wall_overlap.reshape(flat)), axis=-1)
    comp = np.concatenate((comp, np.stack((wall_pressed, np.zeros_like(wall_pressed)), -1).reshape(*flat, 2)), -2)
    point = np.concatenate((point, wall_point.reshape(*flat, model.dim)), axis=-2)
    normal = np.concatenate((normal, wall_normal.reshape(*flat, model.dim)), axis=-2)
    friction = None
    if traj.friction_pair is not None:
        friction = np.concatenate((traj.friction_pair, traj.friction_wall.reshape(*flat, model.dim)), axis=-2)
    return ContactSeries(model.contact_names(), overlap, comp, point, normal, friction)


# ---------------------------------------------------------------------------------------------
# Sampling a trajectory at any times (frames for recordings, CSV rows, the viewer's timeline)


def _quintic(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic Hermite basis at x in [0, 1] (for s0, h v0, h^2 a0, h^2 a1, h v1, s1) and its
    derivative."""
    x2, x3, x4, x5 = x * x, x**3, x**4, x**5
    basis = np.stack((1 - 10 * x3 + 15 * x4 - 6 * x5, x - 6 * x3 + 8 * x4 - 3 * x5,
                      0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5, 0.5 * x3 - x4 + 0.5 * x5,
                      -4 * x3 + 7 * x4 - 3 * x5, 10 * x3 - 15 * x4 + 6 * x5))
    deriv = np.stack((-30 * x2 + 60 * x3 - 30 * x4, 1 - 18 * x2 + 32 * x3 - 15 * x4,
                      x - 4.5 * x2 + 6 * x3 - 2.5 * x4, 1.5 * x2 - 4 * x3 + 2.5 * x4,
                      -12 * x2 + 28 * x3 - 15 * x4, 30 * x2 - 60 * x3 + 30 * x4))
    return basis, deriv


def _spring_accel(model: Model, s: np.ndarray) -> np.ndarray:
    """Accelerations (T, N, D) from the contact springs alone, for a batch-of-one model."""
    from collide import physics as ph

    c = ph.contact_geometry(model, s)
    fn, fw = ph.normal_forces(model, c)
    acc = ph.normal_accel(model, c, fn, fw)
    return acc - model.gravity[:, None, :] if model.gravity is not None else acc


def step_accelerations(model: Model, s: np.ndarray, v: np.ndarray, t: np.ndarray,
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations (S-1, N, D) at the start and end of each step: the springs' at the ends'
    positions, plus a constant rest (friction, gravity) chosen so that the step's velocity change
    comes out exactly: rest = (v1 - v0) / h - mean spring acceleration (Simpson's rule, the
    midpoint from a cubic Hermite)."""
    h = np.diff(t)[:, None, None]
    spring = _spring_accel(model, s)
    mid = 0.5 * (s[:-1] + s[1:]) + 0.125 * h * (v[:-1] - v[1:])
    spring_mid = _spring_accel(model, mid)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = np.where(h > 0, np.diff(v, axis=0) / np.where(h > 0, h, 1.0), 0.0)
    rest = mean - (spring[:-1] + 4 * spring_mid + spring[1:]) / 6
    return spring[:-1] + rest, spring[1:] + rest


def sample(model: Model, traj: Trajectory, times: np.ndarray, member: int = 0) -> State:
    """States of run `member` at the given times (T,), shaped (T, 1, N, D).

    Inside a free-flight segment the motion is exact (closed form). Inside a contact step,
    positions and velocities come from a quintic Hermite through both ends' positions,
    velocities and accelerations (a high-order step takes ten steps per contact: a cubic would
    make the energy wobble by per cent between them); spins and dissipated work are linear.
    Every step's end state is returned exactly.
    """
    from collide.model import select_model

    t = traj.t[:, member]
    times = np.clip(np.asarray(times, dtype=float), t[0], t[-1])
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2) if len(t) > 1 else \
        np.zeros(len(times), int)
    s0, v0, w0 = traj.s[k, member], traj.v[k, member], traj.w[k, member]
    q0, work0 = traj.q[k, member], traj.work[k, member]
    if len(t) == 1:
        return State(times, s0[:, None], v0[:, None], w0[:, None], q0[:, None], work0[:, None])
    k1 = k + 1
    h = t[k1] - t[k]
    tau = times - t[k]
    free = traj.free[k1, member]
    tb = tau[:, None, None]
    # Free flight: exact.
    s = s0 + v0 * tb
    v = v0.copy()
    if model.gravity is not None:
        g = model.gravity[member][None, None, :]
        s = s + 0.5 * g * tb * tb
        v = v0 + g * tb
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(h > 0, tau / np.where(h > 0, h, 1.0), 0.0)
    step = ~free & (h > 0)
    if step.any():
        one = select_model(model, member) if model.batch > 1 else model
        used = np.unique(np.concatenate((k[step], k[step] + 1)))
        a_start, a_end = step_accelerations(one, traj.s[:, member], traj.v[:, member], t) \
            if len(used) > 0.5 * len(t) else _local_accelerations(one, traj, member, k[step])
        ks = k[step]
        a0, a1 = (a_start[ks], a_end[ks]) if len(a_start) == len(t) - 1 else (a_start, a_end)
        hs = h[step][:, None, None]
        basis, deriv = _quintic(x[step])
        b, d = basis[:, :, None, None], deriv[:, :, None, None]
        terms = (s0[step], hs * v0[step], hs * hs * a0, hs * hs * a1, hs * traj.v[ks + 1, member],
                 traj.s[ks + 1, member])
        s[step] = sum(b[i] * term for i, term in enumerate(terms))
        v[step] = sum(d[i] * term for i, term in enumerate(terms)) / hs
    xb = x[:, None, None]
    w1 = traj.w[k1, member]
    w = np.where(free[:, None, None], w0, (1 - xb) * w0 + xb * w1)
    q = _orientation_between(traj.q[k, member], traj.q[k1, member], xb, w0, tau, free)
    work = (1 - x) * work0 + x * traj.work[k1, member]
    return State(times, s[:, None], v[:, None], w[:, None], q[:, None], work[:, None])


def _local_accelerations(model: Model, traj: Trajectory, member: int, ks: np.ndarray,
                         ) -> tuple[np.ndarray, np.ndarray]:
    """`step_accelerations` for the steps ks only (when few samples fall in a long run)."""
    idx = np.stack((ks, ks + 1), axis=1).ravel()
    s = traj.s[idx, member].reshape(len(ks), 2, *traj.s.shape[2:])
    v = traj.v[idx, member].reshape(len(ks), 2, *traj.v.shape[2:])
    t = traj.t[idx, member].reshape(len(ks), 2)
    h = (t[:, 1] - t[:, 0])[:, None, None]
    spring0, spring1 = _spring_accel(model, s[:, 0]), _spring_accel(model, s[:, 1])
    mid = 0.5 * (s[:, 0] + s[:, 1]) + 0.125 * h * (v[:, 0] - v[:, 1])
    spring_mid = _spring_accel(model, mid)
    rest = (v[:, 1] - v[:, 0]) / h - (spring0 + 4 * spring_mid + spring1) / 6
    return spring0 + rest, spring1 + rest


def _orientation_between(q0: np.ndarray, q1: np.ndarray, x: np.ndarray, w0: np.ndarray,
                         tau: np.ndarray, free: np.ndarray) -> np.ndarray:
    if q0.shape[-1] == 0:
        return q0
    if q0.shape[-1] == 1:
        return np.where(free[:, None, None], q0 + w0 * tau[:, None, None], (1 - x) * q0 + x * q1)
    from collide.physics import advance_orientation

    # Quaternions: free flight turns at constant w; inside a short step, normalised lerp.
    turned = advance_orientation(q0, w0, tau)
    lerp = (1 - x) * q0 + x * np.where(np.sum(q0 * q1, -1, keepdims=True) < 0, -q1, q1)
    lerp = lerp / np.linalg.norm(lerp, axis=-1, keepdims=True)
    return np.where(free[:, None, None], turned, lerp)


def frame_times(traj: Trajectory, fps: float, member: int = 0, stride: int = 1) -> np.ndarray:
    """Times of recording frames: every `stride`-th contact step, plus a steady `fps` in free
    flight; contact starts and ends are always frames."""
    t = traj.t[:, member]
    keep = np.ones(len(t), bool)
    keep[1:] = t[1:] > t[:-1]
    t, free = t[keep], traj.free[keep, member]
    steps = ~free[1:]
    contact_points = np.zeros(len(t), bool)
    contact_points[1:] |= steps
    contact_points[:-1] |= steps
    idx = np.flatnonzero(contact_points)
    if stride > 1 and len(idx):
        # Contact starts and ends stay frames whatever the stride.
        first = contact_points & ~np.roll(contact_points, 1)
        last = contact_points & ~np.roll(contact_points, -1)
        edges = np.flatnonzero(first | last)
        idx = np.union1d(idx[::stride], edges)
    grid = np.arange(t[0], t[-1], 1.0 / fps) if fps > 0 else np.empty(0)
    times = np.union1d(np.union1d(t[idx], grid), [t[0], t[-1]])
    return times


__all__ = ["Conserved", "ContactSeries", "Residuals", "conserved", "contact_series", "frame_times",
           "overlaps", "perp2", "residuals", "sample", "state_conserved",
           "trajectory_conserved"]
