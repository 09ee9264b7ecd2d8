"""Rigid-body reference: the outcome of one impact of infinitely stiff spheres, in closed form.

This module is written apart from the stepper (it imports nothing from `collide.physics`,
`collide.stepper` or `collide.integrators`) so that it can check them.

Why this is the k -> infinity limit of the soft model (docs/design.md section 2)
-------------------------------------------------------------------------
In the soft model two spheres touch through springs of stiffness k_eff = k/2 (a sphere on a
rigid wall: k). A contact lasts T = pi sqrt(m_red / k_eff) and compresses by at most
delta = u_n sqrt(m_red / k_eff), both -> 0 as k -> infinity while the impulses stay finite.
So in the limit:

* the positions, hence the normal n, do not change during the contact;
* the normal force is a linear spring in the overlap, which has no loss: the normal relative
  velocity reverses exactly (restitution 1) and the normal impulse is J_n = 2 m_red u_n;
* every other force (gravity) gives an impulse of order T -> 0 and drops out;
* Coulomb friction mu F_n opposes the slip u_t of the surfaces at the contact point. For
  spheres the normal force passes through the centres, so it does not change the slip; only
  the friction does, by du_t = -K_t dJ_t along the slip direction, with the tangential
  compliance K_t = 1/m1 + 1/m2 + r1^2/I1 + r2^2/I2 (wall: 1/m + r^2/I). While sliding,
  dJ_t = mu dJ_n, so the slip falls *linearly in the accumulated normal impulse* and keeps its
  direction. If it reaches the dead band edge eps before the contact ends, the soft model
  holds it there (a sliding mode, zero friction work beyond that point in the limit), so
  J_t = min(mu J_n, (|u_t| - eps) / K_t): "sliding then rolling" (rolling exactly for eps = 0).

The soft model's distance from this limit shrinks as k^(-1/2) (the normal turns by about
|v_t| T / (r1 + r2) during contact, and the centres come closer by delta); `softness_estimate`
gives that a-priori size. Head-on, the soft model is exact for every k.

Vectors are embedded in 3D internally (2D: z = 0, spin about z); 1D uses the x axis only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from collide.scene import Scene

FRICTIONLESS = "frictionless"
SLIDING = "sliding throughout"
STICKING = "sliding then rolling"
NO_CONTACT = "no contact"

Vec = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class Impact:
    """Outcome of one rigid impact. Velocities (D,), spins (K,) in the input's dimension.

    `normal` points from body 1 to body 2 (to the wall for a wall impact); `tangent` is the
    initial slip direction of body 1's surface relative to body 2's (zero if no slip).
    """

    v1: np.ndarray
    w1: np.ndarray
    v2: np.ndarray | None
    w2: np.ndarray | None
    normal_impulse: float
    tangential_impulse: float
    regime: str
    normal: np.ndarray
    tangent: np.ndarray
    slip_before: float
    slip_after: float
    approach_speed: float


# ---------------------------------------------------------------------------------------------
# Embedding: everything is done in 3D


def _vec3(x: Vec | float, what: str) -> tuple[np.ndarray, int]:
    """A position or velocity as a 3-vector, and its original dimension."""
    arr = np.atleast_1d(np.asarray(x, dtype=float))
    if arr.ndim != 1 or arr.size not in (1, 2, 3):
        raise ValueError(f"{what}: expected 1, 2 or 3 components, got shape {arr.shape}")
    out = np.zeros(3)
    out[: arr.size] = arr
    return out, arr.size


def _spin3(w: Vec | float | None, dim: int, what: str) -> np.ndarray:
    """A spin as a 3-vector: 2D spin is a scalar about z; 1D has none."""
    if w is None:
        return np.zeros(3)
    arr = np.atleast_1d(np.asarray(w, dtype=float))
    if dim == 1:
        if arr.size and np.any(arr != 0.0):
            raise ValueError(f"{what}: 1D bodies do not spin")
        return np.zeros(3)
    if dim == 2:
        if arr.size != 1:
            raise ValueError(f"{what}: a 2D spin is one number (about z), got {arr.size}")
        return np.array([0.0, 0.0, float(arr[0])])
    if arr.size != 3:
        raise ValueError(f"{what}: a 3D spin has 3 components, got {arr.size}")
    return arr.copy()


def _out_vec(x: np.ndarray, dim: int) -> np.ndarray:
    return x[:dim].copy()


def _out_spin(w: np.ndarray, dim: int) -> np.ndarray:
    return {1: np.zeros(0), 2: w[2:3].copy(), 3: w.copy()}[dim]


# ---------------------------------------------------------------------------------------------
# Free flight to first touch (closed form; no gravity)


def touch_time_pair(s1: Vec, v1: Vec, r1: float, s2: Vec, v2: Vec, r2: float) -> float | None:
    """Time until two spheres in free flight first touch (|d + u t| = r1 + r2), or None.

    Solves the quadratic |d|^2 + 2 (d.u) t + |u|^2 t^2 = R^2 for its smaller root t >= 0.
    Spheres already touching and approaching give 0.
    """
    p1, _ = _vec3(s1, "s1")
    p2, _ = _vec3(s2, "s2")
    u1, _ = _vec3(v1, "v1")
    u2, _ = _vec3(v2, "v2")
    d, u, reach = p2 - p1, u2 - u1, r1 + r2
    b = float(d @ u)
    if b >= 0.0:  # not approaching: they never touch
        return None
    a = float(u @ u)
    c = float(d @ d) - reach * reach
    if c <= 0.0:
        return 0.0
    disc = b * b - a * c
    if disc < 0.0:  # they pass each other
        return None
    # Stable form of the smaller root (b < 0): t = c / (-b + sqrt(disc)).
    return c / (-b + math.sqrt(disc))


def touch_time_wall(s: Vec, v: Vec, r: float, point: Vec, normal: Vec) -> float | None:
    """Time until a sphere in free flight touches a plane (point, unit normal), or None."""
    p, _ = _vec3(s, "s")
    u, _ = _vec3(v, "v")
    q, _ = _vec3(point, "point")
    n = _unit(normal, "normal")
    gap = float((p - q) @ n) - r
    rate = float(u @ n)
    if rate >= 0.0:
        return None
    return max(gap, 0.0) / -rate


def _unit(x: Vec, what: str) -> np.ndarray:
    n, _ = _vec3(x, what)
    norm = float(np.linalg.norm(n))
    if norm == 0.0:
        raise ValueError(f"{what}: must not be zero")
    return n / norm


# ---------------------------------------------------------------------------------------------
# The impulse law shared by pairs and walls


def _impulses(u: np.ndarray, n: np.ndarray, inv_m: float, k_t: float, mu: float,
              eps: float) -> tuple[float, float, np.ndarray, str, float, float, float]:
    """Normal and tangential impulse magnitudes for slip u (body 1 relative to body 2).

    inv_m = 1/m1 + 1/m2 is the normal compliance; k_t the tangential one (see module docstring).
    """
    u_n = float(u @ n)  # > 0: approaching along n
    if u_n <= 0.0:
        raise ValueError("the bodies are not approaching at the contact: no impact")
    # Elastic normal impulse (restitution 1: the linear spring returns all its energy).
    j_n = 2.0 * u_n / inv_m
    u_t = u - u_n * n
    slip = float(np.linalg.norm(u_t))
    if mu == 0.0 or slip <= eps or k_t == 0.0:
        return j_n, 0.0, np.zeros(3), FRICTIONLESS, slip, slip, u_n
    t_hat = u_t / slip
    # Coulomb: the slip falls by K_t mu dJ_n until it reaches the dead band edge eps.
    j_stop = (slip - eps) / k_t
    if mu * j_n < j_stop:
        j_t, regime = mu * j_n, SLIDING
    else:
        j_t, regime = j_stop, STICKING
    return j_n, j_t, t_hat, regime, slip, slip - k_t * j_t, u_n


def impact_pair(m1: float, r1: float, i1: float, s1: Vec, v1: Vec, w1: Vec | float | None,
                m2: float, r2: float, i2: float, s2: Vec, v2: Vec, w2: Vec | float | None,
                mu: float = 0.0, eps: float = 0.0) -> Impact:
    """Post-impact state of two rigid spheres touching now (|s2 - s1| = r1 + r2, approaching).

    Normal impulse elastic; tangential Coulomb impulse along the initial slip direction,
    J_t = min(mu J_n, (|u_t| - eps) / K_t). Spin w in rad/s (2D: a number about z).
    """
    p1, dim = _vec3(s1, "s1")
    p2, _ = _vec3(s2, "s2")
    u1, _ = _vec3(v1, "v1")
    u2, _ = _vec3(v2, "v2")
    o1, o2 = _spin3(w1, dim, "w1"), _spin3(w2, dim, "w2")
    n = p2 - p1
    n /= np.linalg.norm(n)
    # Lever arms from each centre to the contact point.
    a1, a2 = r1 * n, -r2 * n
    # Slip: velocity of body 1's surface relative to body 2's at the contact point (v + w x a).
    u = (u1 + np.cross(o1, a1)) - (u2 + np.cross(o2, a2))
    inv_m = 1.0 / m1 + 1.0 / m2
    k_t = inv_m + r1 * r1 / i1 + r2 * r2 / i2
    j_n, j_t, t_hat, regime, slip0, slip1, u_n = _impulses(u, n, inv_m, k_t, mu, eps)
    # Impulse on body 2 (on body 1: minus it): normal push along n, friction along the slip.
    jvec = j_n * n + j_t * t_hat
    u1n = u1 - jvec / m1
    u2n = u2 + jvec / m2
    # Angular impulse a x J about each centre: only friction has a lever (a is along n).
    o1n = o1 + np.cross(a1, -j_t * t_hat) / i1
    o2n = o2 + np.cross(a2, j_t * t_hat) / i2
    return Impact(_out_vec(u1n, dim), _out_spin(o1n, dim), _out_vec(u2n, dim), _out_spin(o2n, dim),
                  j_n, j_t, regime, _out_vec(n, dim), _out_vec(t_hat, dim), slip0, slip1, u_n)


def impact_wall(m: float, r: float, inertia: float, s: Vec, v: Vec, w: Vec | float | None,
                point: Vec, normal: Vec, mu: float = 0.0, eps: float = 0.0) -> Impact:
    """Post-impact state of a rigid sphere touching a static plane now (outward unit normal).

    The wall is body 2 with infinite mass: J_n = 2 m u_n, K_t = 1/m + r^2/I.
    """
    _, dim = _vec3(s, "s")  # at touch, position and wall point matter only through the normal
    u1, _ = _vec3(v, "v")
    o1 = _spin3(w, dim, "w")
    n = -_unit(normal, "normal")  # from the sphere into the wall
    a1 = r * n
    u = u1 + np.cross(o1, a1)
    inv_m = 1.0 / m
    k_t = inv_m + r * r / inertia
    j_n, j_t, t_hat, regime, slip0, slip1, u_n = _impulses(u, n, inv_m, k_t, mu, eps)
    jvec = j_n * n + j_t * t_hat  # impulse on the wall; the sphere gets -jvec
    u1n = u1 - jvec / m
    o1n = o1 + np.cross(a1, -j_t * t_hat) / inertia
    return Impact(_out_vec(u1n, dim), _out_spin(o1n, dim), None, None, j_n, j_t, regime,
                  _out_vec(n, dim), _out_vec(t_hat, dim), slip0, slip1, u_n)


# ---------------------------------------------------------------------------------------------
# From pre-contact states: free flight, then the impact


def collide_pair(m1: float, r1: float, i1: float, s1: Vec, v1: Vec, w1: Vec | float | None,
                 m2: float, r2: float, i2: float, s2: Vec, v2: Vec, w2: Vec | float | None,
                 mu: float = 0.0, eps: float = 0.0) -> tuple[Impact | None, float | None]:
    """Advance two spheres in free flight to first touch, then apply `impact_pair`.

    Returns (impact, touch time); (None, None) if they never touch.
    """
    t = touch_time_pair(s1, v1, r1, s2, v2, r2)
    if t is None:
        return None, None
    q1 = np.asarray(s1, float) + t * np.asarray(v1, float)
    q2 = np.asarray(s2, float) + t * np.asarray(v2, float)
    return impact_pair(m1, r1, i1, q1, v1, w1, m2, r2, i2, q2, v2, w2, mu, eps), t


def collide_wall(m: float, r: float, inertia: float, s: Vec, v: Vec, w: Vec | float | None,
                 point: Vec, normal: Vec, mu: float = 0.0,
                 eps: float = 0.0) -> tuple[Impact | None, float | None]:
    """Advance a sphere in free flight to a plane, then apply `impact_wall` ((None, None): miss)."""
    t = touch_time_wall(s, v, r, point, normal)
    if t is None:
        return None, None
    q = np.asarray(s, float) + t * np.asarray(v, float)
    return impact_wall(m, r, inertia, q, v, w, point, normal, mu, eps), t


@dataclass(frozen=True)
class RigidOutcome:
    """Final velocities (N, D) and spins (N, K) of a scene in the rigid limit."""

    v: np.ndarray
    w: np.ndarray
    regime: str
    touch_time: float | None
    impact: Impact | None


def rigid_outcome(scene: Scene) -> RigidOutcome:
    """Rigid-limit outcome of a 2-sphere scene or a 1-sphere + 1-wall scene without gravity.

    One impact at most happens there (after an elastic impact the bodies separate for good),
    so the answer is closed form. Other scenes raise ValueError.
    """
    if scene.gravity is not None and any(g != 0.0 for g in scene.gravity):
        raise ValueError(f"scene '{scene.name}': the rigid reference does not handle gravity")
    bodies, walls, dim = scene.bodies, scene.walls, scene.dim
    v = np.array([b.velocity for b in bodies], dtype=float).reshape(len(bodies), dim)
    w = np.array([b.spin for b in bodies], dtype=float).reshape(len(bodies), scene.spin_dim)
    mu = scene.contact.mu if dim > 1 else 0.0
    eps = scene.contact.eps
    if len(bodies) == 2 and not walls:
        b1, b2 = bodies
        impact, t = collide_pair(b1.mass, b1.radius, b1.inertia, b1.position, b1.velocity, b1.spin or None,
                                 b2.mass, b2.radius, b2.inertia, b2.position, b2.velocity, b2.spin or None,
                                 mu, eps)
        if impact is None:
            return RigidOutcome(v, w, NO_CONTACT, None, None)
        v = np.stack([impact.v1, impact.v2])
        w = np.stack([impact.w1, impact.w2]).reshape(2, scene.spin_dim)
        return RigidOutcome(v, w, impact.regime, t, impact)
    if len(bodies) == 1 and len(walls) == 1:
        b, wall = bodies[0], walls[0]
        impact, t = collide_wall(b.mass, b.radius, b.inertia, b.position, b.velocity, b.spin or None,
                                 wall.point, wall.normal, mu, eps)
        if impact is None:
            return RigidOutcome(v, w, NO_CONTACT, None, None)
        return RigidOutcome(impact.v1[None, :], impact.w1.reshape(1, scene.spin_dim), impact.regime,
                            t, impact)
    raise ValueError(f"scene '{scene.name}': the rigid reference handles 2 spheres, or 1 sphere and "
                     f"1 wall (got {len(bodies)} bodies, {len(walls)} walls)")


def softness_estimate(scene: Scene) -> float:
    """A-priori size of the soft model's distance from the rigid limit, relative to the
    fastest initial speed (0 when the bodies never touch or meet head-on).

    The soft impulse acts along a normal that turns during the contact, which lasts
    T = pi sqrt(m_red/k_eff): the centres slide past each other by about |v_t| T over the
    distance R = r1 + r2 (pi |v_t| sqrt(m_red/k_eff) / R), and they come closer by
    delta = u_n sqrt(m_red/k_eff), which tilts the line of centres by about (v_t/u_n) delta/R =
    |v_t| sqrt(m_red/k_eff) / R. Here v_t is the larger of the centres' relative tangential
    speeds before and after the rigid impact (friction adds tangential motion). The velocity
    changes |dv| are off by about that angle. Both effects scale as k^(-1/2). Head-on (v_t = 0,
    also every 1D scene) the linear spring gives the rigid answer exactly, for every k.
    """
    out = rigid_outcome(scene)
    if out.impact is None or scene.dim == 1:
        return 0.0
    bodies = scene.bodies
    v0 = np.array([b.velocity for b in bodies], dtype=float).reshape(len(bodies), scene.dim)
    w0 = np.array([b.spin for b in bodies], dtype=float).reshape(len(bodies), scene.spin_dim)
    if len(bodies) == 2:
        m_red = 1.0 / (1.0 / bodies[0].mass + 1.0 / bodies[1].mass)
        k_eff, reach = scene.contact.k / 2.0, bodies[0].radius + bodies[1].radius
        rel_before, rel_after = v0[0] - v0[1], out.v[0] - out.v[1]
    else:
        m_red, k_eff, reach = bodies[0].mass, scene.contact.k, bodies[0].radius
        rel_before, rel_after = v0[0], out.v[0]
    n = out.impact.normal

    def tangential(u: np.ndarray) -> float:
        return float(np.linalg.norm(u - (u @ n) * n))

    v_t = max(tangential(rel_before), tangential(rel_after))
    angle = (math.pi + 1.0) * v_t * math.sqrt(m_red / k_eff) / reach
    dv = float(np.max(np.linalg.norm(out.v - v0, axis=1)))
    radii = np.array([b.radius for b in bodies])
    dspin = float(np.max(np.linalg.norm(out.w - w0, axis=1) * radii)) if w0.size else 0.0
    return angle * max(dv, dspin) / reference_speed(scene)


def reference_speed(scene: Scene) -> float:
    """Fastest initial speed including surface speed from spin: max |v| + r |w| (m/s)."""
    speeds = []
    for b in scene.bodies:
        speeds.append(math.hypot(*b.velocity) + b.radius * math.hypot(*b.spin) if b.spin else
                      math.hypot(*b.velocity))
    return max(max(speeds), 1e-300)
