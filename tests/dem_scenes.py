"""Scenes and closed forms the DEM tests share (tests/test_contact_laws.py, tests/engine/dem/):
a sphere dropped on a wall, the Hertz impact's closed form, a small settling pile."""

from __future__ import annotations

import math

import numpy as np

GLASS = {"youngs_modulus": 4.8e10, "poisson_ratio": 0.2}


def _wall_scene(**contact) -> dict:
    law = {"model": "hertz", "youngs_modulus": 7e10, "poisson_ratio": 0.3}
    law.update(contact)
    return {"dim": 3, "integrator": "dem", "dt": 2e-7,
            "contact": law,
            "body": [{"name": "a", "radius": 0.1, "mass": 10.0, "position": [0.0, 0.0, 0.1],
                      "velocity": [0.0, 0.0, -0.2]}],
            "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]}


def hertz_closed_form(m_star: float, r_star: float, e_star: float, speed: float) -> tuple[float, float, float]:
    """delta_max, F_max and contact time of an elastic Hertz impact at this approach speed."""
    delta = (15.0 * m_star * speed**2 / (16.0 * e_star * math.sqrt(r_star))) ** 0.4
    force = 4.0 / 3.0 * e_star * math.sqrt(r_star) * delta**1.5
    # The integral of the Hertz impact: t_c = 2.9432 delta_max / v (2.868 (m*^2/(R* E*^2 v))^(1/5)).
    time = 2.9432 * delta / speed
    return delta, force, time


def open_box_walls(side: float) -> list[dict]:
    """A floor at z = 0 and four side walls at x, y = 0 and side: a box open at the top."""
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    for axis in range(2):
        for value, sign in ((0.0, 1.0), (side, -1.0)):
            point, normal = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            point[axis], normal[axis] = value, sign
            walls.append({"point": point, "normal": normal})
    return walls


def _pile(per_side: int, layers: int) -> dict:
    """Spheres on a loose lattice above the floor of a box open at the top, like `pile`."""
    r, spacing = 0.005, 0.012
    side = per_side * spacing
    rng = np.random.default_rng(5)
    bodies = []
    for k in range(layers):
        for i in range(per_side):
            for j in range(per_side):
                x, y = (i + 0.5) * spacing + rng.uniform(-1e-4, 1e-4), (j + 0.5) * spacing + rng.uniform(-1e-4, 1e-4)
                bodies.append({"name": f"g{len(bodies)}", "material": "glass", "radius": r,
                               "position": [x, y, r + 0.002 + k * spacing], "velocity": [0.0, 0.0, 0.0]})
    walls = open_box_walls(side)
    return {"dim": 3, "integrator": "dem", "dt": "auto", "tol": 2e-2, "duration": 5.0, "rest": 1e-6,
            "gravity": [0.0, 0.0, -9.81],
            "contact": {"model": "hertz", "restitution": 0.5, "tangential": "spring", "mu": 0.5,
                        "rolling_friction": 0.02},
            "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6, "poisson_ratio": 0.25}],
            "body": bodies, "wall": walls}
