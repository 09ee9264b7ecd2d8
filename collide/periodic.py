"""Periodic boundaries (docs/design.md section 10): what a scene with periodic axes must satisfy,
overlaps across its sides at the start, and positions wrapped into the box for output. (A
`scene` here is a `collide.scene.Scene`, which imports this module.)

The engines keep every body's position unwrapped (continuous: its free flight and its recorded
trajectory never jump) and meet two bodies at their nearest images; what is reported is wrapped
into the box, with the number of periods each body has crossed (`wrap`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from collide.scene_values import SceneError

NEIGHBOUR_SKIN = 0.25  # the DEM's neighbour-list skin, in smallest radii (collide.dem.SKIN)
AXES = ("x", "y", "z")


def check_periodic(scene: Any) -> None:
    """Refuse, in one line, a periodic scene the engines cannot answer right: a period too short
    for the nearest image (at least twice the largest diameter plus the neighbour skin: two
    spheres then meet at one image only), a wall across a periodic axis, the seed's
    integrator, or no end (bodies wrapping round may meet again forever)."""
    domain = scene.domain
    if domain is None or not domain.periodic:
        return
    if scene.integrator == "seed":
        raise SceneError("domain.periodic: integrator 'seed' (the report's update) has no periodic boundaries; "
                         "use the default integrator or 'dem'")
    if scene.duration is None and not (scene.integrator == "dem" and scene.rest is not None):
        raise SceneError("domain.periodic: a periodic scene needs a duration (bodies wrapping round may meet "
                         "again forever, so the run would not end by itself)")
    for index, wall in enumerate(scene.walls):
        for axis in domain.periodic:
            if wall.normal[AXES.index(axis)] != 0.0:
                raise SceneError(f"wall[{index}].normal: has a part along the periodic axis {axis}; a wall "
                                 f"must be parallel to every periodic axis (a floor under a chute periodic in x)")
    radius = np.array([b.radius for b in scene.bodies], dtype=float)
    need = 4.0 * radius.max() + NEIGHBOUR_SKIN * radius.min()
    for axis, period in zip(AXES, domain.period):
        if period > 0.0 and period < need:
            raise SceneError(f"domain.periodic: the period along {axis} ({period:.6g} m) is too short for the "
                             f"nearest image: at least twice the largest diameter plus the neighbour skin "
                             f"({need:.6g} m)")


def check_image_overlap(scene: Any, pos: np.ndarray, radius: np.ndarray, in_contact: np.ndarray | None) -> None:
    """No two spheres overlap across a periodic side at the start: the bodies within a diameter
    of a side, copied to the other (corners too), checked against the rest."""
    from collide.scene_bodies import _first_pair_overlap

    domain = scene.domain
    lower, upper, dim = np.array(domain.lower), np.array(domain.upper), scene.dim
    reach = 2.0 * radius.max()
    rows = np.arange(len(pos))
    points = pos.copy()
    for d in range(dim):
        if AXES[d] not in domain.periodic:
            continue
        period = upper[d] - lower[d]
        near_low = np.flatnonzero(points[:, d] - lower[d] < reach)
        near_high = np.flatnonzero(upper[d] - points[:, d] < reach)
        up, down = points[near_low].copy(), points[near_high].copy()
        up[:, d] += period
        down[:, d] -= period
        points = np.concatenate([points, up, down])
        rows = np.concatenate([rows, rows[near_low], rows[near_high]])
    if len(points) == len(pos):
        return
    mask = np.zeros(len(points), bool) if in_contact is None else in_contact[rows]
    found = _first_pair_overlap(points, radius[rows], mask)
    if found is None:
        return
    i, j, gap = found
    a, b = sorted((int(rows[i]), int(rows[j])))
    if a != b:  # (a body never meets its own image: the period is over twice its diameter)
        raise SceneError(f"body.{scene.bodies[a].name}.position: overlaps body.{scene.bodies[b].name} across a "
                         f"periodic side at the start by {-gap:.3g} m")


def kernel_box(period: tuple[float, float, float]) -> np.ndarray:
    """collide.engine.broad's `box` for these periods: the periods, then 1.0 if any wraps."""
    return np.array([*period, 1.0 if any(p > 0.0 for p in period) else 0.0])


def nearest_image(d: np.ndarray, period: tuple[float, float, float]) -> np.ndarray:
    """Separations d (..., dim) taken to the nearest image along the periodic axes (period > 0)."""
    per = np.asarray(period, float)[:d.shape[-1]]
    if not (per > 0.0).any():
        return d
    safe = np.where(per > 0.0, per, 1.0)
    return d - np.where(per > 0.0, per * np.floor(d / safe + 0.5), 0.0)


def wrap(s: np.ndarray, lower: np.ndarray, period: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (..., dim) wrapped into the box along the periodic axes (period > 0), and the
    whole periods each body has crossed there (int; 0 elsewhere): s = wrapped + images period."""
    dim = s.shape[-1]
    lo, per = np.asarray(lower, float)[:dim], np.asarray(period, float)[:dim]
    images = np.where(per > 0.0, np.floor((s - lo) / np.where(per > 0.0, per, 1.0)), 0.0)
    return s - images * per, images.astype(np.int64)
