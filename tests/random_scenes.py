"""Random frictional scenes of issue 10 (2-6 balls, 2D and 3D, with and without a floor under
gravity), shared by tests/test_error_estimate.py and scripts/check_estimates.py."""

from __future__ import annotations

import numpy as np

from collide.scene import Scene, parse_scene

RADIUS, MASS = 0.03, 0.0254


def random_scene(rng: np.random.Generator, index: int, k: float = 1e4, mu: float | None = None) -> Scene:
    """Scene `index` of the sequence `rng` draws; `mu` (else drawn, 0.1-0.6) and `k` replace the
    contact's constants without changing what is drawn."""
    dim = int(rng.choice([2, 3]))
    count = int(rng.integers(2, 7))
    floor = bool(rng.random() < 0.5)
    bodies: list[dict] = []
    for _ in range(1000):
        if len(bodies) == count:
            break
        p = rng.uniform(-0.15, 0.15, size=dim)
        if floor:
            p[-1] = abs(p[-1]) + RADIUS + 0.001
        if all(np.linalg.norm(p - np.array(b["position"])) > 2 * RADIUS + 1e-3 for b in bodies):
            spin = rng.normal(size=3) * 20 if dim == 3 else float(rng.normal() * 20)
            bodies.append({"name": f"b{len(bodies)}", "mass": MASS, "radius": RADIUS, "position": p.tolist(),
                           "velocity": (rng.normal(size=dim) * 0.5).tolist(),
                           "spin": spin if dim == 2 else spin.tolist()})
    raw: dict = {"name": f"random-{index}", "dim": dim, "duration": 0.5,
                 "contact": {"k": k, "mu": float(rng.uniform(0.1, 0.6))}, "body": bodies}
    if mu is not None:
        raw["contact"]["mu"] = mu
    if floor:
        up = [0.0] * dim
        up[-1] = 1.0
        raw["gravity"] = [-9.81 * x for x in up]
        raw["wall"] = [{"point": [0.0] * dim, "normal": up}]
    return parse_scene(raw)
