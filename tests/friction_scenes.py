"""Scenes the friction tests share (tests/test_friction.py, tests/engine/event/): the bonus demo
tilted out of its plane, a built-in turned as a whole into a tilted plane, a sphere thrown at a
wall of any orientation."""

from __future__ import annotations

import numpy as np

from collide.scene import generic_turn, load_scene, turned_source


def tilted_bonus(**changes) -> dict:
    """The bonus demo in 3D with the first ball thrown and both spinning out of the plane: the
    slip turns as the contact goes on."""
    raw = {"name": "tilted", "dim": 3, "contact": {"k": 1500.0, "mu": 0.5, "lever": "seed"},
           "body": [{"name": "ball1", "mass": 0.0254, "radius": 0.03021, "position": [0.0, 0.01, 0.0],
                     "velocity": [1.0, 0.0, 0.3], "spin": [2.0, -1.0, 3.0]},
                    {"name": "ball2", "mass": 0.0254, "radius": 0.03021, "position": [0.5, 0.0, 0.0],
                     "velocity": [-2.0, 0.0, 0.0], "spin": [-1.0, 4.0, -5.0]}]}
    raw.update(changes)
    return raw


def turned_scene(name: str = "demo-bonus", overrides: tuple[str, ...] = ()) -> tuple[dict, dict, np.ndarray]:
    """A built-in 2D scene and the same turned as a whole into a tilted plane (3D), with the turn."""
    raw2 = load_scene(name, list(overrides)).source
    return raw2, turned_source(raw2), generic_turn()


def _wall_impact(normal, velocity, spin, k: float, lever: str, dim: int, mu: float = 0.3) -> dict:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    point = np.full(dim, 1.0)
    body = {"name": "b", "mass": 0.1, "radius": 0.05, "position": (point + n * 0.06).tolist(),
            "velocity": list(velocity), "spin": spin if dim == 2 else list(spin)}
    return {"name": "wall-impact", "dim": dim, "tol": 1e-8, "contact": {"k": k, "mu": mu, "lever": lever},
            "body": [body], "wall": [{"point": point.tolist(), "normal": n.tolist()}]}


def random_wall_frame(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A wall's unit normal of random orientation and a random unit direction along it."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    along = np.cross(n, rng.normal(size=3))
    return n, along / np.linalg.norm(along)
