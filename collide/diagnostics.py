"""Diagnostics of a run: conserved quantities, contacts and residuals (docs/design.md sections 2 and 4).

Functions take states with any leading shape (..., B, N, D), so the same code serves a final
state (B, N, D) and frames of a trajectory (T, 1, N, D). Contacts are lists (C, 2) of body
pairs (i, j), a wall as j = -1 - wall: nothing here grows with the number of possible pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide.contact_forces import RecordedForces
from collide.engine.broad import near_pairs
from collide.model import TABLE_ESTAR, Model, State
from collide.periodic import kernel_box, nearest_image
from collide.results import RunResult
from collide.trajectory import Trajectory, body_knots, sample, settled

# Contacts whose spring energy `conserved` works out at once.
CONTACT_CHUNK = 16384


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


def all_contacts(model: Model) -> np.ndarray:
    """Every possible contact (C, 2) of a small scene: all pairs, then every sphere on every wall."""
    i, j = np.triu_indices(model.n_bodies, k=1)
    out = np.concatenate((np.stack((i, j), axis=1), _wall_contacts(model)))
    return out.astype(np.int64)


def _wall_contacts(model: Model) -> np.ndarray:
    """(n_walls * N, 2): every sphere on the first wall, then on the second, ... (j = -1 - wall)."""
    n, walls = model.n_bodies, model.n_walls
    return np.stack((np.tile(np.arange(n, dtype=np.int64), walls),
                     np.repeat(-1 - np.arange(walls, dtype=np.int64), n)), axis=1)


def contacts_near(model: Model, s: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Contacts (C, 2) whose gap is at most `margin` (relative to the radii) in any of the
    states s (..., N, D) of member 0: all of them for a few bodies, a cell grid for many."""
    if model.n_bodies <= 64:
        return all_contacts(model)
    flat = s.reshape(-1, model.n_bodies, model.dim)
    found = [np.zeros((0, 2), np.int64)]
    radius = model.radius[0]
    for frame in flat:
        pos = np.zeros((model.n_bodies, 3))
        pos[:, :model.dim] = frame
        found.append(near_pairs(pos, radius, margin * radius + 1e-12 * radius, model.n_bodies, model.dim,
                                kernel_box(model.period)).astype(np.int64).reshape(-1, 2))
    pairs = np.unique(np.concatenate(found), axis=0)  # sorted by (i, j)
    return np.concatenate((pairs, _wall_contacts(model)))


def contact_geometry(model: Model, s: np.ndarray, contacts: np.ndarray) -> tuple[np.ndarray, ...]:
    """Normal n (from i towards j or into the wall, (..., C, D)), overlap (..., C) and distance
    (..., C) of the contacts at positions s (..., N, D)."""
    i, j = contacts[:, 0], contacts[:, 1]
    pair = j >= 0
    si = s[..., i, :]
    jj = np.where(pair, j, 0)
    d = nearest_image(s[..., jj, :] - si, model.period)  # (positions are unwrapped in a periodic box)
    dist = np.sqrt(_dot(d, d))
    with np.errstate(invalid="ignore", divide="ignore"):
        n = d / dist[..., None]
    r = model.radius[..., i]
    reach = r + np.where(pair, model.radius[..., jj], 0.0)
    if model.n_walls:
        w = np.where(pair, 0, -1 - j)
        normal = model.wall_normal[w]
        height = _dot(si - model.wall_point[w], normal)
        n = np.where(pair[:, None], n, -normal)
        dist = np.where(pair, dist, height)
    overlap = reach - dist
    return n, overlap, dist


def stiffness(model: Model, contacts: np.ndarray) -> np.ndarray:
    """Spring constant (B, C) of each contact."""
    i, j = contacts[:, 0], contacts[:, 1]
    k = model.pair_stiffness(i, np.where(j >= 0, j, 0))
    if model.n_walls:
        k = np.where(j >= 0, k, model.wall_stiffness()[:, i])
    return k


def elastic_energy(model: Model, contacts: np.ndarray, overlap: np.ndarray) -> np.ndarray:
    """Energy (..., C) the normal springs of `contacts` hold at these overlaps: k delta^2 / 2
    (linear), 8/15 E* sqrt(R*) delta^2.5 (Hertz)."""
    if not model.hertz:
        return 0.5 * stiffness(model, contacts) * overlap**2
    i, j = contacts[:, 0], contacts[:, 1]
    pair = j >= 0
    jj = np.where(pair, j, 0)
    e_star = model.pair_column(i, jj, TABLE_ESTAR)
    ri, rj = model.radius[:, i], model.radius[:, jj]
    r_star = np.where(pair, ri * rj / (ri + rj), ri)
    if model.n_walls:
        e_star = np.where(pair, e_star, model.wall_column(TABLE_ESTAR)[:, i])
    return 8.0 / 15.0 * e_star * np.sqrt(r_star) * overlap**2.5


def conserved(model: Model, t: np.ndarray, s: np.ndarray, v: np.ndarray, w: np.ndarray,
              work: np.ndarray, contacts: np.ndarray | None = None, stored: np.ndarray | None = None) -> Conserved:
    """Energies, momentum, angular momentum about the origin and centre of mass. The spring
    energy sums over `contacts` (default: every possible contact of a small scene, those near at
    these states for a large one)."""
    m = model.mass
    kinetic = 0.5 * np.sum(m * _dot(v, v), axis=-1)
    rotational = 0.5 * np.sum(model.inertia * _dot(w, w), axis=-1) if w.shape[-1] else None
    if contacts is None:
        contacts = contacts_near(model, s)
    if len(contacts):
        # Each contact's energy a chunk of contacts at a time, then summed as one array (the sum
        # as taken whole): a settling box of 100 000 spheres lists every sphere on every wall,
        # and its geometry whole took 100 MB at once.
        energy = np.empty(s.shape[:-2] + (len(contacts),))
        for lo in range(0, len(contacts), CONTACT_CHUNK):
            part = contacts[lo:lo + CONTACT_CHUNK]
            _, overlap, _ = contact_geometry(model, s, part)
            energy[..., lo:lo + len(part)] = elastic_energy(model, part, np.maximum(overlap, 0.0))
        spring = np.sum(energy, axis=-1)
    else:
        spring = np.zeros(kinetic.shape)
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
    if stored is not None:
        spring = spring + stored
    return Conserved(kinetic, rotational, spring, gravitational, work if model.dissipative else None,
                     momentum, angular, com)


def trajectory_conserved(model: Model, traj: Trajectory) -> Conserved:
    """The conserved quantities at every row of a trajectory (its knot times)."""
    return conserved(model, traj.t, traj.s, traj.v, traj.w, traj.work, _touched_or_all(model, traj))


def _touched_or_all(model: Model, traj: Trajectory) -> np.ndarray:
    touched = traj.contacts_touched()
    return all_contacts(model) if model.n_bodies <= 64 else touched


def state_conserved(model: Model, state: State) -> Conserved:
    return conserved(model, state.t, state.s, state.v, state.w, state.work, stored=state.stored)


def packing_fraction(model: Model, s: np.ndarray, member: int = 0) -> float:
    """Solid fraction of a settled pile (3D): the spheres' volume over the volume they fill, the
    box the walls bound across gravity from the floor up to the pile's surface, taken as the
    mean top (centre + radius) of the highest 5 % of spheres. NaN without gravity, in 1D/2D, or
    without a wall on every side across gravity."""
    if model.gravity is None or model.dim != 3 or not model.n_walls:
        return float("nan")
    g = model.gravity[member]
    up = -g / np.linalg.norm(g)
    normals, points = model.wall_normal, model.wall_point
    floor = [w for w in range(model.n_walls) if np.dot(normals[w], up) > 0.999]
    if not floor:
        return float("nan")
    base = float(np.dot(points[floor[0]], up))
    radius = model.radius[member]
    heights = s @ up + radius - base
    top = float(np.mean(np.sort(heights)[-max(1, len(heights) // 20):]))
    # The cross-section: for each axis across gravity, the two walls facing each other.
    area = 1.0
    for axis in range(3):
        direction = np.zeros(3)
        direction[axis] = 1.0
        if abs(np.dot(direction, up)) > 1e-9:
            continue
        lows = [float(np.dot(points[w], direction)) for w in range(model.n_walls)
                if np.dot(normals[w], direction) > 0.999]
        highs = [float(np.dot(points[w], direction)) for w in range(model.n_walls)
                 if np.dot(normals[w], direction) < -0.999]
        if not lows or not highs:
            return float("nan")
        area *= min(highs) - max(lows)
    solid = float(np.sum(4.0 / 3.0 * np.pi * radius**3))
    return solid / (area * top) if area > 0 and top > 0 else float("nan")


# ---------------------------------------------------------------------------------------------
# Residuals (relative, dimensionless)


@dataclass
class Residuals:
    """Relative residuals (B,) of the final state against the start; NaN where none applies.

    energy: |E + W - E0| / E0 (W = work dissipated by friction, gravity's potential included);
    momentum: |P - P0 - M g t| / sum m|v|; angular_momentum: |L - L0 - gravity's torque| /
    sum |s x m v| + |I w| (largest of start and end). With walls, momentum and angular momentum
    are not conserved and their residuals are NaN (null in JSON); in a periodic box angular
    momentum is not.
    """

    energy: np.ndarray
    momentum: np.ndarray
    angular_momentum: np.ndarray


def angular_scale(model: Model, s: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """What the angular momentum's round-off is relative to: each body's |s x m v| and I |w|, and
    its momentum times its radius, so that a ball moving through the origin (a cue ball along
    the x axis: s x v is round-off) does not make round-off look like a residual of 0.5."""
    terms = np.sqrt(_dot(_cross_z(s, model.mass[..., None] * v), _cross_z(s, model.mass[..., None] * v)))
    scale = terms.sum(axis=-1) + np.sum(model.mass * model.radius * np.sqrt(_dot(v, v)), axis=-1)
    if w.shape[-1]:
        scale = scale + np.sum(model.inertia * np.sqrt(_dot(w, w)), axis=-1)
    return scale


def residuals(result: RunResult) -> Residuals:
    """Relative energy, momentum and angular momentum residuals of a run (B,). Kept on the result
    for its initial and final states: the run, its summary and the viewer all ask (3 ms each for
    the viewer's 3D scenes, at every slider change)."""
    kept = getattr(result, "_residuals", None)
    if kept is not None and kept[0] is result.initial and kept[1] is result.final:
        return kept[2]
    out = _residuals(result)
    try:
        result._residuals = (result.initial, result.final, out)
    except AttributeError:  # a result without room for it (slots): computed each time
        pass
    return out


def _residuals(result: RunResult) -> Residuals:
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
            l_scale = np.maximum(angular_scale(model, a.s, a.v, a.w), angular_scale(model, b.s, b.v, b.w))
            angular = np.where(l_scale > 0, np.sqrt(_dot(dl, dl)) / l_scale, 0.0)
    if model.n_walls:
        momentum = np.full(model.batch, np.nan)
        angular = np.full(model.batch, np.nan)
    if model.periodic:  # a contact across a periodic side pushes images: no torque balance about a point
        angular = np.full(np.shape(energy), np.nan)
    return Residuals(energy, momentum, angular)


# ---------------------------------------------------------------------------------------------
# Contacts along a trajectory


@dataclass
class ContactSeries:
    """The contacts that ever engaged, at T times: C contacts in the order they began.

    names (C); pairs (C, 2) (j = -1 - wall); overlap (T, 1, C) m; compression (T, 1, C, 2) m,
    how much each of the two spheres is compressed (the wall's column is 0); point (T, 1, C, D)
    m; normal_force (T, 1, C, D) N and friction_force (T, 1, C, D) N, both on the contact's
    first body, as the engine recorded them (collide.contact_forces: the normal force straight
    between records, friction held over a step: the force of the step that ends at or after t).
    """

    names: list[str]
    pairs: np.ndarray
    overlap: np.ndarray
    compression: np.ndarray
    point: np.ndarray
    normal_force: np.ndarray
    friction_force: np.ndarray | None


def contact_series(model: Model, traj: Trajectory, times: np.ndarray | None = None,
                   states: State | None = None) -> ContactSeries:
    """Every contact the run had, at `times` (default: the trajectory's rows); `states` may give
    the bodies there already (from `sample`)."""
    if times is None:
        times = traj.t[:, 0]
    times = np.asarray(times, dtype=float)
    st = states if states is not None else sample(model, traj, times)
    contacts = traj.contacts_touched()
    s = st.s[:, 0]
    n_t, c = len(times), len(contacts)
    d = model.dim
    if c == 0:
        empty = np.zeros((n_t, 1, 0))
        return ContactSeries([], contacts, empty, np.zeros((n_t, 1, 0, 2)), np.zeros((n_t, 1, 0, d)),
                             np.zeros((n_t, 1, 0, d)), None if not model.friction else np.zeros((n_t, 1, 0, d)))
    n, overlap, _ = contact_geometry(model, s, contacts)
    pressed = np.maximum(overlap, 0.0)
    pair = contacts[:, 1] >= 0
    # Equal springs in series share the overlap; a sphere on a rigid wall takes all of it.
    first = np.where(pair, 0.5 * pressed, pressed)
    compression = np.stack((first, np.where(pair, 0.5 * pressed, 0.0)), axis=-1)
    radius_i = model.radius[0, contacts[:, 0]]
    point = s[:, contacts[:, 0], :] + (radius_i - first)[..., None] * n
    # The forces the engine recorded (collide.contact_forces), along the drawn normal.
    forces = RecordedForces(traj, contacts, model.n_bodies, model.n_walls, d, bool(model.friction))
    tk, ck = np.repeat(np.arange(n_t), c), np.tile(np.arange(c), n_t)
    normal = -forces.normal(ck, times[tk]).reshape(n_t, c)[..., None] * n
    friction = None
    if model.friction:
        force, found = forces.friction(ck, times[tk])
        valid = found.reshape(n_t, c) & (overlap >= -1e-9 * radius_i)
        friction = np.where(valid[..., None], force.reshape(n_t, c, d), 0.0)[:, None]
    names = [model.contact_name(int(i), int(j)) for i, j in contacts]
    return ContactSeries(names, contacts, overlap[:, None], compression[:, None], point[:, None],
                         normal[:, None], friction)


# sample, settled and body_knots live with the trajectory (collide.trajectory); here for callers.
__all__ = ["Conserved", "ContactSeries", "Residuals", "body_knots", "conserved", "contact_series", "residuals",
           "sample", "settled", "state_conserved", "trajectory_conserved"]
