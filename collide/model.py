"""Compile scenes into a frozen, batched `Model` and its initial `State`.

Shapes (B = batch, N = bodies, D = dim, K = spin components, M = materials, W = walls):

==================  ============  =========================================================
array               shape         meaning (SI units)
==================  ============  =========================================================
mass, inv_mass      (B, N)        kg, 1/kg
radius              (B, N)        m
inertia             (B, N)        kg m^2 (isotropic: spheres)
material            (B, N)        index into the contact tables
pair_table          (B, M, M, 7)  per pair of materials: k (N/m, springs in series), mu, eps,
                                  E* (Pa, Hertz), restitution, rolling friction, k_t / k_n
wall_table          (B, M, 7)     per material on a wall (rigid): the same columns
k, mu, eps          (B,)          the scene's [contact] values
gravity             (B, D)        m/s^2, or None
wall_point          (W, D)        m
wall_normal         (W, D)        outward unit normals
State.s, State.v    (B, N, D)     m, m/s
State.w             (B, N, K)     rad/s; K = 0 when nothing can spin, 1 in 2D (about z), 3 in 3D
State.q             (B, N, Q)     orientation: Q = 0 (no spin), 1 (angle, 2D), 4 (quaternion wxyz)
State.t, work       (B,)          s; J dissipated by friction
==================  ============  =========================================================

Nothing here grows with the number of pairs: contacts are found as the bodies move. A sweep
widens only the first axis: `compile_scenes` takes B scenes of the same shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from collide.body_columns import Bodies, as_bodies
from collide.scene import Scene, SceneError

TABLE_K, TABLE_MU, TABLE_EPS, TABLE_ESTAR, TABLE_REST, TABLE_ROLL, TABLE_KTR = range(7)
N_TABLE = 7
EVENT_COLUMNS = 3  # the event engine reads k, mu, eps only
KISSING = {1: 2, 2: 6, 3: 12}  # most equal spheres that can touch one sphere at once


def damping_ratio(restitution: np.ndarray, hertz: bool) -> np.ndarray:
    """The dashpot's zeta (gamma = 2 zeta sqrt(m* dF/d delta)) that gives this restitution:
    -ln e / sqrt(ln^2 e + pi^2) for the linear spring; for Hertz LIGGGHTS' and LAMMPS'
    coefficient 2 sqrt(5/6) beta sqrt(S_n m*), the same times sqrt(5/6), which gives e exactly
    too when the force may pull at the end (tests/engine/dem/test_damping.py)."""
    e = np.asarray(restitution, dtype=float)
    le = np.log(np.where(e > 0, e, 1.0))
    zeta = np.where(e > 0, -le / np.sqrt(le**2 + math.pi**2), 1.0)  # e -> 0: critically damped
    return zeta * (math.sqrt(5.0 / 6.0) if hertz else 1.0)


@dataclass(frozen=True)
class Model:
    """Static description of B scenes of the same shape (see module docstring for shapes)."""

    dim: int
    spin_dim: int
    body_names: tuple[str, ...]
    mass: np.ndarray
    inv_mass: np.ndarray
    radius: np.ndarray
    inertia: np.ndarray
    inv_inertia: np.ndarray
    material: np.ndarray
    pair_table: np.ndarray
    wall_table: np.ndarray
    k: np.ndarray
    mu: np.ndarray
    eps: np.ndarray
    gravity: np.ndarray | None
    wall_point: np.ndarray
    wall_normal: np.ndarray
    friction: bool
    seed_lever: bool
    hertz: bool = False
    tangential_spring: bool = False
    dissipative: bool = False  # damping, friction or rolling resistance can take energy out
    # The periodic box (docs/design.md section 10), shared by the batch: each axis's period (x, y,
    # z; 0 where it does not wrap) and the box's lower corner.
    period: tuple[float, float, float] = (0.0, 0.0, 0.0)
    box_lower: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def periodic(self) -> bool:
        return any(p > 0.0 for p in self.period)

    @property
    def batch(self) -> int:
        return self.mass.shape[0]

    @property
    def n_bodies(self) -> int:
        return self.mass.shape[1]

    @property
    def n_walls(self) -> int:
        return self.wall_point.shape[0]

    @property
    def orient_dim(self) -> int:
        return {0: 0, 1: 1, 3: 4}[self.spin_dim]

    def pair_stiffness(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Spring constant (B, P) of the contacts between bodies i and j (arrays of P)."""
        b = np.arange(self.batch)[:, None]
        return self.pair_table[b, self.material[:, i], self.material[:, j], TABLE_K]

    def pair_column(self, i: np.ndarray, j: np.ndarray, column: int) -> np.ndarray:
        """Column `column` (B, P) of the pair table for the contacts between bodies i and j."""
        b = np.arange(self.batch)[:, None]
        return self.pair_table[b, self.material[:, i], self.material[:, j], column]

    def wall_column(self, column: int) -> np.ndarray:
        """Column `column` (B, N) of the wall table for each sphere."""
        b = np.arange(self.batch)[:, None]
        return self.wall_table[b, self.material, column]

    def wall_stiffness(self) -> np.ndarray:
        """Spring constant (B, N) of each sphere on a wall (its own: the wall is rigid)."""
        b = np.arange(self.batch)[:, None]
        return self.wall_table[b, self.material, TABLE_K]

    def contact_name(self, i: int, j: int) -> str:
        """`ball1-ball2` for a pair, `ball1-wall0` for a sphere on wall 0 (j = -1 - wall)."""
        return f"{self.body_names[i]}-{self.body_names[j]}" if j >= 0 else f"{self.body_names[i]}-wall{-1 - j}"


@dataclass
class State:
    """Dynamic state of B runs (see module docstring for shapes and units)."""

    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    w: np.ndarray
    q: np.ndarray
    work: np.ndarray
    stored: np.ndarray | None = None  # (B,) J held by tangential springs (DEM); None: nothing held

    def copy(self) -> State:
        return State(self.t.copy(), self.s.copy(), self.v.copy(), self.w.copy(), self.q.copy(),
                     self.work.copy(), None if self.stored is None else self.stored.copy())


def _material_numbers(scene: Scene, bodies: Bodies) -> list[int]:
    """Each body's material as the model numbers it: 0 for none, 1 + its place in the scene's."""
    number: dict[str, int] = {}
    for i, m in enumerate(scene.materials):
        number.setdefault(m.name, 1 + i)
    return [0 if m is None else number[m] for m in bodies.material]


def shape_key(scene: Scene) -> tuple:
    """What scenes run together in one batch must share. Walls are the model's, not a member's:
    two scenes with walls elsewhere ran the first one's (a ball on a floor turned another way
    came out 7.7 m/s off)."""
    return (scene.dim, tuple(as_bodies(scene.bodies, scene.dim).names), tuple((w.point, w.normal) for w in scene.walls),
            scene.gravity is not None, scene.has_spin, scene.contact.lever, len(scene.materials),
            scene.contact.model, scene.contact.tangential, _box(scene))


def _box(scene: Scene) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A scene's periodic box: (periods, lower corner), zeros where nothing wraps."""
    domain = scene.domain
    if domain is None or not domain.periodic:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return domain.period, tuple(float(x) for x in (tuple(domain.lower) + (0.0, 0.0, 0.0))[:3])


def _mixed(a: float | None, b: float | None, default: float, mean: str) -> float:
    """A pair's value from its two materials': the [contact] default unless a material gives
    one; two given values mix arithmetically (mu, rolling friction) or geometrically (restitution:
    the product of two dampings' losses)."""
    if a is None and b is None:
        return default
    a = default if a is None else a
    b = default if b is None else b
    return math.sqrt(a * b) if mean == "geometric" else 0.5 * (a + b)


def contact_tables(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Pair table (M, M, N_TABLE) and wall table (M, N_TABLE) of one scene; material 0 is the
    [contact] table itself (bodies naming no material), 1.. the scene's [[material]]s."""
    c = scene.contact
    mats = [None, *scene.materials]
    count = len(mats)
    young = [c.youngs_modulus if m is None or m.youngs_modulus is None else m.youngs_modulus for m in mats]
    poisson = [c.poisson_ratio if m is None or m.poisson_ratio is None else m.poisson_ratio for m in mats]
    pair = np.zeros((count, count, N_TABLE))
    wall = np.zeros((count, N_TABLE))
    overrides = {frozenset(p.materials): p for p in scene.pairs}
    for a in range(count):
        ma = mats[a]
        for b in range(count):
            mb = mats[b]
            row = pair[a, b]
            row[TABLE_K] = c.k * c.k / (c.k + c.k)
            row[TABLE_EPS] = c.eps
            row[TABLE_MU] = _mixed(ma and ma.mu, mb and mb.mu, c.mu, "arithmetic")
            row[TABLE_REST] = _mixed(ma and ma.restitution, mb and mb.restitution, c.restitution, "geometric")
            row[TABLE_ROLL] = _mixed(ma and ma.rolling_friction, mb and mb.rolling_friction, c.rolling_friction,
                                     "arithmetic")
            over = overrides.get(frozenset((ma.name, mb.name))) if ma is not None and mb is not None else None
            if over is not None:
                for column, value in ((TABLE_MU, over.mu), (TABLE_REST, over.restitution),
                                      (TABLE_ROLL, over.rolling_friction)):
                    if value is not None:
                        row[column] = value
            if young[a] is not None and young[b] is not None:
                row[TABLE_ESTAR] = 1.0 / ((1 - poisson[a] ** 2) / young[a] + (1 - poisson[b] ** 2) / young[b])
                # Mindlin: k_t / k_n = 4 G* / E*, G* = 1 / ((2 - nu_a)/G_a + (2 - nu_b)/G_b).
                shear = [young[x] / (2 * (1 + poisson[x])) for x in (a, b)]
                g_star = 1.0 / ((2 - poisson[a]) / shear[0] + (2 - poisson[b]) / shear[1])
                mindlin = 4.0 * g_star / row[TABLE_ESTAR]
            else:
                mindlin = 2.0 / 7.0
            row[TABLE_KTR] = c.tangential_stiffness_ratio if c.tangential_stiffness_ratio is not None else \
                (mindlin if c.model == "hertz" else 2.0 / 7.0)
        wrow = wall[a]
        wrow[TABLE_K] = c.k
        wrow[TABLE_EPS] = c.eps
        wrow[TABLE_MU] = c.mu if ma is None or ma.mu is None else ma.mu
        wrow[TABLE_REST] = c.restitution if ma is None or ma.restitution is None else ma.restitution
        wrow[TABLE_ROLL] = c.rolling_friction if ma is None or ma.rolling_friction is None else ma.rolling_friction
        if young[a] is not None:
            wrow[TABLE_ESTAR] = young[a] / (1 - poisson[a] ** 2)  # a rigid wall
        # Mindlin on a rigid wall: 4 G*/E* with G* = G / (2 - nu): 2 (1 - nu) / (2 - nu).
        wrow[TABLE_KTR] = c.tangential_stiffness_ratio if c.tangential_stiffness_ratio is not None else \
            (2 * (1 - poisson[a]) / (2 - poisson[a]) if c.model == "hertz" else 2.0 / 7.0)
    return pair, wall


PLANE_TOL = 1e-12  # relative: what round-off leaves of a scene turned into another plane


def plane_of_motion(model: Model, state: State, b: int) -> np.ndarray | None:
    """The unit normal of the plane run b stays in, of any orientation (centres, velocities,
    gravity and wall normals all lie in it, and every spin is along its normal), or None. Only
    outside such a plane can a sliding contact's slip turn."""
    if model.dim < 3:
        return np.array([0.0, 0.0, 1.0])
    rows = [state.s[b] - state.s[b, :1], state.v[b], model.wall_normal]
    if model.gravity is not None:
        rows.append(model.gravity[b][None])
    in_plane = np.concatenate(rows)
    size = max(float(np.abs(in_plane).max(initial=0.0)), 1e-300)
    spins = state.w[b] if model.spin_dim == 3 else np.zeros((0, 3))
    spin_size = np.linalg.norm(spins, axis=1)
    if not spin_size.any():
        _, sizes, axes = np.linalg.svd(in_plane)
        spread = np.zeros(3)
        spread[:len(sizes)] = sizes
        return axes[-1] if spread[-1] <= PLANE_TOL * size else None
    # Spinning: the plane's normal can only be the spins' common axis.
    normal = spins[int(spin_size.argmax())] / spin_size.max()
    if (np.abs(in_plane @ normal).max() <= PLANE_TOL * size
            and np.linalg.norm(np.cross(spins, normal), axis=1).max() <= PLANE_TOL * spin_size.max()):
        return normal
    return None


def turned_quaternions(q: np.ndarray, w: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Orientations q (T, 4), scalar first, after turning at w (T, 3) rad/s for tau (T,) seconds."""
    rate = np.sqrt((w * w).sum(-1))
    half = 0.5 * rate * tau
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = np.where(rate[:, None] > 0, w / np.where(rate > 0, rate, 1.0)[:, None], 0.0)
    dq = np.concatenate((np.cos(half)[:, None], np.sin(half)[:, None] * axis), axis=1)
    a, b = dq, q
    return np.stack((a[:, 0] * b[:, 0] - a[:, 1] * b[:, 1] - a[:, 2] * b[:, 2] - a[:, 3] * b[:, 3],
                     a[:, 0] * b[:, 1] + a[:, 1] * b[:, 0] + a[:, 2] * b[:, 3] - a[:, 3] * b[:, 2],
                     a[:, 0] * b[:, 2] - a[:, 1] * b[:, 3] + a[:, 2] * b[:, 0] + a[:, 3] * b[:, 1],
                     a[:, 0] * b[:, 3] + a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1] + a[:, 3] * b[:, 0]), axis=1)


def compile_scenes(scenes: list[Scene]) -> tuple[Model, State]:
    """Pack B scenes of the same shape (dim, bodies, walls) into one model and state."""
    if not scenes:
        raise SceneError("no scenes to run")
    first = scenes[0]
    key = shape_key(first)
    for scene in scenes[1:]:
        if shape_key(scene) != key:
            raise SceneError(f"scene '{scene.name}' differs in shape from '{first.name}' "
                             "(dim, bodies, walls or where they are, gravity or spin); batch only same-shaped scenes")
    dim = first.dim
    n = len(first.bodies)
    b = len(scenes)
    spin_dim = first.spin_dim if any(s.has_spin for s in scenes) else 0

    columns = [as_bodies(s.bodies, dim) for s in scenes]
    mass = np.stack([c.mass for c in columns]).reshape(b, n)
    radius = np.stack([c.radius for c in columns]).reshape(b, n)
    inertia = np.stack([c.inertia for c in columns]).reshape(b, n)
    k = np.array([s.contact.k for s in scenes], dtype=float)
    mu = np.array([s.contact.mu for s in scenes], dtype=float)
    eps = np.array([s.contact.eps for s in scenes], dtype=float)
    # Every sphere is a spring of constant k, two in series (docs/design.md section 2); materials add
    # Hertz constants and their own contact values (docs/design.md section 9).
    tables = [contact_tables(s) for s in scenes]
    pair_table = np.stack([t[0] for t in tables])
    wall_table = np.stack([t[1] for t in tables])
    material = np.array([_material_numbers(s, c) for s, c in zip(scenes, columns)], dtype=np.int64).reshape(b, n)
    gravity = None if first.gravity is None else np.array([s.gravity for s in scenes], dtype=float)
    walls = first.walls
    model = Model(
        dim=dim, spin_dim=spin_dim, body_names=tuple(columns[0].names),
        mass=mass, inv_mass=1.0 / mass, radius=radius, inertia=inertia, inv_inertia=1.0 / inertia,
        material=material, pair_table=pair_table, wall_table=wall_table,
        k=k, mu=mu, eps=eps, gravity=gravity,
        wall_point=np.array([w.point for w in walls], dtype=float).reshape(len(walls), dim),
        wall_normal=np.array([w.normal for w in walls], dtype=float).reshape(len(walls), dim),
        friction=any(s.has_friction for s in scenes), seed_lever=first.contact.lever == "seed",
        hertz=first.contact.model == "hertz", tangential_spring=first.contact.tangential == "spring",
        dissipative=any(s.has_friction or s.needs_dem for s in scenes),
        period=_box(first)[0], box_lower=_box(first)[1],
    )
    s = np.stack([c.position for c in columns]).reshape(b, n, dim)
    v = np.stack([c.velocity for c in columns]).reshape(b, n, dim)
    if spin_dim:
        w = np.stack([c.spin for c in columns]).reshape(b, n, spin_dim)
    else:
        w = np.zeros((b, n, 0))
    q = np.zeros((b, n, model.orient_dim))
    if model.orient_dim == 4:
        q[..., 0] = 1.0
    return model, State(t=np.zeros(b), s=s, v=v, w=w, q=q, work=np.zeros(b))


def select_model(model: Model, index: int) -> Model:
    """Batch member `index` as a model of batch 1."""
    sl = slice(index, index + 1)
    changes = {name: getattr(model, name)[sl] for name in
               ("mass", "inv_mass", "radius", "inertia", "inv_inertia", "material", "pair_table", "wall_table",
                "k", "mu", "eps")}
    if model.gravity is not None:
        changes["gravity"] = model.gravity[sl]
    return replace(model, **changes)


def select_state(state: State, index: int) -> State:
    sl = slice(index, index + 1)
    return State(state.t[sl], state.s[sl], state.v[sl], state.w[sl], state.q[sl], state.work[sl],
                 None if state.stored is None else state.stored[sl])


def hertz_bound(model: Model, speed: np.ndarray) -> Model:
    """The model with its tables' k (TABLE_K) a bound on the stiffness dF/d delta = 2 E* sqrt(R*
    delta) of its Hertz contacts, for the event engine's islands (their step, frequencies and
    dashpot's contraction bound): at the overlap where an approach at `speed` (B,) stops,
    8/15 E* sqrt(R*) delta^2.5 = m* v^2 / 2, plus where the weight of every body rests on one
    contact, 4/3 E* sqrt(R*) delta^1.5 = sum m g (at least 1e-9 R*); with each material's largest
    radius and mass (dF/d delta grows with both)."""
    n_mat = model.pair_table.shape[1]
    big_r = np.stack([np.where(model.material == a, model.radius, 0.0).max(axis=1) for a in range(n_mat)], axis=1)
    big_m = np.stack([np.where(model.material == a, model.mass, 0.0).max(axis=1) for a in range(n_mat)], axis=1)
    g = 0.0 if model.gravity is None else np.sqrt((model.gravity ** 2).sum(-1))
    weight = model.mass.sum(axis=1) * g
    v2 = np.asarray(speed, dtype=float) ** 2

    def stiffness(estar: np.ndarray, rstar: np.ndarray, mstar: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(rstar)
            delta = (15.0 * mstar * v2 / (16.0 * estar * root)) ** 0.4 + (0.75 * weight / (estar * root)) ** (2.0 / 3.0)
            # (Nothing approaching nor weighing: a billionth of R*, whatever stiffness a contact at
            # rest has.)
            delta = np.maximum(delta, 1e-9 * rstar)
            return np.nan_to_num(2.0 * estar * np.sqrt(rstar * delta))

    pair, wall = model.pair_table.copy(), model.wall_table.copy()
    for a in range(n_mat):
        for c in range(n_mat):
            rstar = big_r[:, a] * big_r[:, c] / np.maximum(big_r[:, a] + big_r[:, c], 1e-300)
            mstar = big_m[:, a] * big_m[:, c] / np.maximum(big_m[:, a] + big_m[:, c], 1e-300)
            pair[:, a, c, TABLE_K] = stiffness(pair[:, a, c, TABLE_ESTAR], rstar, mstar)
        wall[:, a, TABLE_K] = stiffness(wall[:, a, TABLE_ESTAR], big_r[:, a], big_m[:, a])
    # A material no body has makes no contact: its rows take the stiffest's (bounds take the
    # tables' least and largest k).
    for table in (pair, wall):
        k = table[..., TABLE_K]
        top = k.reshape(model.batch, -1).max(axis=1).reshape((-1,) + (1,) * (k.ndim - 1))
        table[..., TABLE_K] = np.where(k > 0.0, k, top)
    return replace(model, pair_table=pair, wall_table=wall)


def reference_frequency(model: Model) -> np.ndarray:
    """The stiffest single contact's angular frequency (B,): sqrt(k (1/m_i + 1/m_j)) for the
    pair of materials and bodies that maximise it, sqrt(k / m) on a wall. The auto step is
    omega h over it; an island of several contacts steps by its own (stiffer) frequency.
    Vectorised over the batch (a loop per member was 44 us each, three times a run)."""
    n_mat = model.pair_table.shape[1]
    # Each material's two largest inverse masses (B, M, 2); NaN where it has fewer bodies, which
    # np.fmax passes over (a pair that does not exist sets no frequency).
    top = np.full((model.batch, n_mat, 2), np.nan)
    pick = min(2, model.n_bodies)
    for m in range(n_mat):
        mine = np.where(model.material == m, model.inv_mass, np.nan)
        top[:, m, :pick] = -np.partition(-mine, pick - 1, axis=1)[:, :pick]  # NaN sorts last
    best = np.zeros(model.batch)
    for a in range(n_mat):
        for c in range(a, n_mat):
            best = np.fmax(best, model.pair_table[:, a, c, TABLE_K] * (top[:, a, 0] + top[:, c, 1 if a == c else 0]))
        if model.n_walls:
            best = np.fmax(best, model.wall_table[:, a, TABLE_K] * top[:, a, 0])
    return np.sqrt(best)


def max_frequency(model: Model) -> np.ndarray:
    """A bound (B,) on the stiffest frequency contacts can produce together: one pair alone,
    exactly; otherwise Gershgorin on the mass-symmetrised stiffness matrix, with as many
    neighbours as can touch a sphere at once (rows k/m_i + k/sqrt(m_i m_j) each, plus walls)."""
    if model.n_bodies == 2 and not model.n_walls:
        return reference_frequency(model)
    z = min(model.n_bodies - 1, KISSING[model.dim])
    k_pair = model.pair_table[..., TABLE_K].reshape(model.batch, -1).max(axis=1)
    k_wall = model.wall_table[..., TABLE_K].reshape(model.batch, -1).max(axis=1)
    lightest = model.mass.min(axis=1)
    rows = z * k_pair[:, None] * (model.inv_mass + 1.0 / np.sqrt(model.mass * lightest[:, None]))
    if model.n_walls:
        rows = rows + model.n_walls * k_wall[:, None] * model.inv_mass
    return np.sqrt(rows.max(axis=1))
