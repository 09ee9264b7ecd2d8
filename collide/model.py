"""Compile scenes into a frozen, batched `Model` and its initial `State`.

Shapes (B = batch, N = bodies, D = dim, K = spin components, P = sphere pairs, W = walls):

=================  ===========  =====================================================
array              shape        meaning (SI units)
=================  ===========  =====================================================
mass, inv_mass     (B, N)       kg, 1/kg
radius             (B, N)       m
inertia            (B, N)       kg m^2 (isotropic: spheres)
k_pair             (B, P)       N/m, springs in series k_i k_j / (k_i + k_j)
k_wall             (B, N)       N/m, the sphere's own spring (the wall is rigid)
mu, eps            (B,)         Coulomb coefficient, dead band in m/s
gravity            (B, D)       m/s^2, or None
wall_point         (W, D)       m
wall_normal        (W, D)       outward unit normals
State.s, State.v   (B, N, D)    m, m/s
State.w            (B, N, K)    rad/s; K = 0 when nothing can spin, 1 in 2D (about z), 3 in 3D
State.q            (B, N, Q)    orientation: Q = 0 (no spin), 1 (angle, 2D), 4 (quaternion wxyz)
State.t, work      (B,)         s; J dissipated by friction
=================  ===========  =====================================================

A sweep widens only the first axis: `compile_scenes` takes B scenes of the same shape.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from collide.scene import Scene, SceneError


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
    pair_i: np.ndarray
    pair_j: np.ndarray
    k_pair: np.ndarray
    k_wall: np.ndarray
    mu: np.ndarray
    eps: np.ndarray
    gravity: np.ndarray | None
    wall_point: np.ndarray
    wall_normal: np.ndarray
    friction: bool
    seed_lever: bool
    pair_to_body_i: np.ndarray
    pair_to_body_j: np.ndarray
    # Derived per-pair arrays, precomputed because gathers are slow on small arrays.
    select_i: np.ndarray  # (P, N): row p picks body i of pair p
    select_j: np.ndarray
    pair_diff: np.ndarray  # (P, N): select_j - select_i
    pair_ri: np.ndarray  # (B, P)
    pair_rj: np.ndarray
    pair_reach: np.ndarray  # r_i + r_j
    pair_inv_mass: np.ndarray  # 1/m_i + 1/m_j
    pair_inv_inertia_i: np.ndarray  # (B, P)
    pair_inv_inertia_j: np.ndarray
    inv_mass_gen: np.ndarray  # (B, N D + N K): 1/m per velocity component, then 1/I per spin one

    @property
    def batch(self) -> int:
        return self.mass.shape[0]

    @property
    def n_bodies(self) -> int:
        return self.mass.shape[1]

    @property
    def n_pairs(self) -> int:
        return self.pair_i.shape[0]

    @property
    def n_walls(self) -> int:
        return self.wall_point.shape[0]

    @property
    def orient_dim(self) -> int:
        return {0: 0, 1: 1, 3: 4}[self.spin_dim]

    def contact_names(self) -> list[str]:
        """Names of every possible contact: pairs first, then sphere-wall contacts."""
        names = [f"{self.body_names[i]}-{self.body_names[j]}" for i, j in zip(self.pair_i, self.pair_j)]
        names += [f"{self.body_names[n]}-wall{w}" for w in range(self.n_walls) for n in range(self.n_bodies)]
        return names


@dataclass
class State:
    """Dynamic state of B runs (see module docstring for shapes and units)."""

    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    w: np.ndarray
    q: np.ndarray
    work: np.ndarray

    def copy(self) -> State:
        return State(self.t.copy(), self.s.copy(), self.v.copy(), self.w.copy(), self.q.copy(),
                     self.work.copy())


def shape_key(scene: Scene) -> tuple:
    return (scene.dim, tuple(b.name for b in scene.bodies), len(scene.walls),
            scene.gravity is not None, scene.has_spin, scene.contact.lever)


def compile_scenes(scenes: list[Scene]) -> tuple[Model, State]:
    """Pack B scenes of the same shape (dim, bodies, walls) into one model and state."""
    if not scenes:
        raise SceneError("no scenes to run")
    first = scenes[0]
    key = shape_key(first)
    for scene in scenes[1:]:
        if shape_key(scene) != key:
            raise SceneError(f"scene '{scene.name}' differs in shape from '{first.name}' "
                             "(dim, bodies, walls, gravity or spin); batch only same-shaped scenes")
    dim = first.dim
    n = len(first.bodies)
    friction = any(s.has_friction for s in scenes)
    spin_dim = first.spin_dim if any(s.has_spin for s in scenes) else 0

    def per_body(attr: str) -> np.ndarray:
        return np.array([[getattr(b, attr) for b in s.bodies] for s in scenes], dtype=float)

    mass = per_body("mass")
    radius = per_body("radius")
    inertia = per_body("inertia")
    pair_i, pair_j = np.triu_indices(n, k=1)
    k = np.array([s.contact.k for s in scenes], dtype=float)
    # Each sphere is a spring of constant k; two in series (DESIGN section 2).
    k_pair = np.repeat((k * k / (k + k))[:, None], len(pair_i), axis=1)
    k_wall = np.repeat(k[:, None], n, axis=1)
    gravity = None
    if first.gravity is not None:
        gravity = np.array([s.gravity for s in scenes], dtype=float)
    walls = first.walls
    wall_point = np.array([w.point for w in walls], dtype=float).reshape(len(walls), dim)
    wall_normal = np.array([w.normal for w in walls], dtype=float).reshape(len(walls), dim)
    incidence_i = np.zeros((n, len(pair_i)))
    incidence_j = np.zeros((n, len(pair_i)))
    incidence_i[pair_i, np.arange(len(pair_i))] = 1.0
    incidence_j[pair_j, np.arange(len(pair_i))] = 1.0
    model = Model(
        dim=dim, spin_dim=spin_dim, body_names=tuple(b.name for b in first.bodies),
        mass=mass, inv_mass=1.0 / mass, radius=radius, inertia=inertia, inv_inertia=1.0 / inertia,
        pair_i=pair_i, pair_j=pair_j, k_pair=k_pair, k_wall=k_wall,
        mu=np.array([s.contact.mu for s in scenes], dtype=float),
        eps=np.array([s.contact.eps for s in scenes], dtype=float),
        gravity=gravity, wall_point=wall_point, wall_normal=wall_normal,
        friction=friction, seed_lever=first.contact.lever == "seed",
        pair_to_body_i=incidence_i, pair_to_body_j=incidence_j,
        **_pair_arrays(pair_i, pair_j, radius, 1.0 / mass, 1.0 / inertia),
        inv_mass_gen=np.concatenate((np.repeat(1.0 / mass, dim, axis=1), np.repeat(1.0 / inertia, spin_dim, axis=1)),
                                    axis=1),
    )
    b = len(scenes)
    s = np.array([[b_.position for b_ in sc.bodies] for sc in scenes], dtype=float).reshape(b, n, dim)
    v = np.array([[b_.velocity for b_ in sc.bodies] for sc in scenes], dtype=float).reshape(b, n, dim)
    if spin_dim:
        w = np.array([[b_.spin for b_ in sc.bodies] for sc in scenes], dtype=float).reshape(b, n, spin_dim)
    else:
        w = np.zeros((b, n, 0))
    q = np.zeros((b, n, model.orient_dim))
    if model.orient_dim == 4:
        q[..., 0] = 1.0
    state = State(t=np.zeros(b), s=s, v=v, w=w, q=q, work=np.zeros(b))
    return model, state


def _pair_arrays(pair_i: np.ndarray, pair_j: np.ndarray, radius: np.ndarray,
                 inv_mass: np.ndarray, inv_inertia: np.ndarray) -> dict[str, np.ndarray]:
    n = radius.shape[1]
    select_i = np.zeros((len(pair_i), n))
    select_j = np.zeros((len(pair_i), n))
    select_i[np.arange(len(pair_i)), pair_i] = 1.0
    select_j[np.arange(len(pair_i)), pair_j] = 1.0
    return dict(select_i=select_i, select_j=select_j, pair_diff=select_j - select_i,
                pair_ri=radius[:, pair_i], pair_rj=radius[:, pair_j],
                pair_reach=radius[:, pair_i] + radius[:, pair_j],
                pair_inv_mass=inv_mass[:, pair_i] + inv_mass[:, pair_j],
                pair_inv_inertia_i=inv_inertia[:, pair_i], pair_inv_inertia_j=inv_inertia[:, pair_j])


def select_model(model: Model, index: int) -> Model:
    """Batch member `index` as a model of batch 1."""
    sl = slice(index, index + 1)
    changes = {name: getattr(model, name)[sl] for name in
               ("mass", "inv_mass", "radius", "inertia", "inv_inertia", "k_pair", "k_wall", "mu", "eps",
                "pair_ri", "pair_rj", "pair_reach", "pair_inv_mass", "pair_inv_inertia_i",
                "pair_inv_inertia_j", "inv_mass_gen")}
    if model.gravity is not None:
        changes["gravity"] = model.gravity[sl]
    return replace(model, **changes)


def select_state(state: State, index: int) -> State:
    sl = slice(index, index + 1)
    return State(state.t[sl], state.s[sl], state.v[sl], state.w[sl], state.q[sl], state.work[sl])
