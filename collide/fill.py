"""`[[fill]]`: bodies declared by a region, a count or packing fraction, a size distribution and
an arrangement, not listed one by one (docs/design.md section 10).

Random arrangements are random sequential insertion: each sphere's centre is drawn uniformly
where the sphere fits in the region, and kept when it overlaps nothing placed before it (earlier
bodies and fills, walls, the fill's own spheres); spheres are inserted largest first, which fits
more of a wide distribution. Candidates are drawn and judged in batches on a cell grid
(`collide.spheregrid`), so a fill costs time linear in its spheres. A count that cannot be
placed is refused with how many fitted. Lattice arrangements put spheres on a square (2D) or
cubic (3D) lattice of pitch twice the largest radius, filled from the region's lower end up.
A random fill's spheres are then numbered along a Z-order curve of cells, so that spheres near
in space are near in the body arrays. The same `seed` gives the same bodies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from collide.scene_values import (
    MAX_MAGNITUDE,
    MIN_POSITIVE,
    NAME_PATTERN,
    SceneError,
    _check_keys,
    _number,
    _shown,
    _vector,
)
from collide.spheregrid import Grid, size_classes

FILL_KEYS = frozenset({"name", "region", "lower", "upper", "centre", "axis", "cylinder_radius", "height",
                       "count", "packing_fraction", "radius", "distribution", "radius_min", "radius_max",
                       "radius_mean", "radius_std", "radius_median", "radius_sigma", "material",
                       "mass_density", "velocity", "arrangement", "seed"})
DISTRIBUTIONS = {"uniform": ("radius_min", "radius_max"),
                 "normal": ("radius_mean", "radius_std", "radius_min", "radius_max"),
                 "lognormal": ("radius_median", "radius_sigma", "radius_min", "radius_max")}
REGION_KEYS = {"box": ("lower", "upper"), "cylinder": ("centre", "axis", "cylinder_radius", "height")}
MAX_FILL = 10_000_000  # spheres in one fill (memory: a few GB as bodies)
# Random insertion gives up after this many candidates per sphere asked for: beyond it a packing
# is near random sequential insertion's jamming limit (about 0.38 in 3D, 0.55 in 2D).
ATTEMPTS_PER_SPHERE = 100
MIN_ATTEMPTS = 1 << 18  # a few spheres may take many draws (several per sphere each round)
STALLED_ROUNDS = 16  # rounds in a row that place nothing end it
ROUNDS = 16  # a round draws for at most this share of the spheres (the largest left)
ROUND_MIN = 1024
ONE_SIZE = 1.25  # radii within this ratio are inserted in any order
BATCH = 1 << 20  # spheres drawn for in one round (memory: about 100 MB)
JAMMING = {1: 0.75, 2: 0.55, 3: 0.38}
CUT_ROUNDS = 100  # draws of a cut distribution before refusing a cut that keeps almost nothing


@dataclass
class FillBodies:
    """The spheres of one fill, as columns in name order (name0, name1, ...)."""

    prefix: str
    radius: np.ndarray
    mass: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    material: str | None


@dataclass
class Region:
    kind: str
    lower: np.ndarray  # box: corners; cylinder: its bounding box
    upper: np.ndarray
    centre: np.ndarray | None = None
    frame: np.ndarray | None = None  # cylinder: rows u, v, axis (unit)
    radius: float = 0.0
    height: float = 0.0

    def volume(self, dim: int) -> float:
        if self.kind == "cylinder":
            return math.pi * self.radius**2 * self.height
        return float(np.prod(self.upper - self.lower))


def _sphere_volume(r: np.ndarray, dim: int) -> np.ndarray:
    """A sphere's share of the region's measure: length 2r (1D), area pi r^2 (2D), volume (3D)."""
    return {1: 2.0 * r, 2: math.pi * r**2, 3: 4.0 / 3.0 * math.pi * r**3}[dim]


def parse_region(table: dict, where: str, dim: int, domain: Any) -> Region:
    region = table.get("region", "box")
    if region not in REGION_KEYS:
        raise SceneError(f"{where}.region: unknown {_shown(region)} (choose from box, cylinder)")
    for other, keys in REGION_KEYS.items():
        for key in keys:
            if other != region and key in table and key not in REGION_KEYS[region]:
                raise SceneError(f"{where}.{key}: belongs to region '{other}' (this fill's region is '{region}')")
    if region == "box":
        if domain is not None and "lower" not in table and "upper" not in table:
            lower, upper = np.array(domain.lower), np.array(domain.upper)
        else:
            for key in ("lower", "upper"):
                if key not in table:
                    raise SceneError(f"{where}.{key}: missing (a box's corner; or leave both out to fill the [domain])")
            lower = np.array(_vector(table["lower"], f"{where}.lower", dim))
            upper = np.array(_vector(table["upper"], f"{where}.upper", dim))
        if not (upper > lower).all():
            raise SceneError(f"{where}.upper: must exceed lower along every axis, got lower {lower.tolist()}, "
                             f"upper {upper.tolist()}")
        return Region("box", lower, upper)
    if dim != 3:
        raise SceneError(f"{where}.region: a cylinder fills 3D scenes only (this scene is {dim}D; use 'box')")
    for key in REGION_KEYS["cylinder"]:
        if key not in table:
            raise SceneError(f"{where}.{key}: missing for region 'cylinder'")
    centre = np.array(_vector(table["centre"], f"{where}.centre", 3))
    axis = np.array(_vector(table["axis"], f"{where}.axis", 3))
    if not np.linalg.norm(axis) > 0:
        raise SceneError(f"{where}.axis: must not be zero")
    radius = _number(table["cylinder_radius"], f"{where}.cylinder_radius", positive=True)
    height = _number(table["height"], f"{where}.height", positive=True)
    frame = _frame(axis / np.linalg.norm(axis))
    reach = np.abs(frame[2]) * height / 2 + radius * np.sqrt(np.maximum(1.0 - frame[2] ** 2, 0.0))
    return Region("cylinder", centre - reach, centre + reach, centre, frame, radius, height)


def _frame(axis: np.ndarray) -> np.ndarray:
    """Rows u, v, axis: an orthonormal frame whose third row is the cylinder's axis."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return np.array([u, np.cross(axis, u), axis])


def _positive(table: dict, key: str, where: str) -> float:
    if key not in table:
        raise SceneError(f"{where}.{key}: missing")
    return _number(table[key], f"{where}.{key}", positive=True)


def _check_distribution_keys(table: dict, where: str) -> str | None:
    distribution = table.get("distribution")
    if distribution is None:
        if "radius" not in table:
            raise SceneError(f"{where}.radius: missing (one radius, or a distribution: "
                             f"{', '.join(DISTRIBUTIONS)})")
        stray = [k for k in table if k.startswith("radius_")]
        if stray:
            raise SceneError(f"{where}.{stray[0]}: belongs to a distribution (this fill has one radius)")
        return None
    if distribution not in DISTRIBUTIONS:
        raise SceneError(f"{where}.distribution: unknown {_shown(distribution)} (choose from "
                         f"{', '.join(DISTRIBUTIONS)})")
    if "radius" in table:
        raise SceneError(f"{where}.radius: give one radius or a distribution, not both")
    stray = [k for k in table if k.startswith("radius_") and k not in DISTRIBUTIONS[distribution]]
    if stray:
        raise SceneError(f"{where}.{stray[0]}: not a key of distribution {_shown(distribution)} "
                         f"(it takes {', '.join(DISTRIBUTIONS[distribution])})")
    return distribution


def draw_radii(table: dict, where: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """n radii from the fill's size: one radius or a distribution (normal and lognormal cut at
    radius_min and radius_max when given, and always above 0)."""
    distribution = _check_distribution_keys(table, where)
    if distribution is None:
        return np.full(n, _number(table["radius"], f"{where}.radius", positive=True))
    lo = _number(table["radius_min"], f"{where}.radius_min", positive=True) if "radius_min" in table else 0.0
    hi = _number(table["radius_max"], f"{where}.radius_max", positive=True) if "radius_max" in table else math.inf
    if distribution == "uniform":
        lo, hi = _positive(table, "radius_min", where), _positive(table, "radius_max", where)
    if hi < lo:
        raise SceneError(f"{where}.radius_max: must be at least radius_min ({lo:g}), got {hi:g}")
    if distribution == "uniform":
        return rng.uniform(lo, hi, n)
    if distribution == "normal":
        mean = _positive(table, "radius_mean", where)
        std = _number(table.get("radius_std"), f"{where}.radius_std", nonneg=True) if "radius_std" in table \
            else _positive(table, "radius_std", where)

        def draw(k: int) -> np.ndarray:
            return rng.normal(mean, std, k)
    else:
        median = _positive(table, "radius_median", where)
        sigma = _number(table.get("radius_sigma"), f"{where}.radius_sigma", nonneg=True) \
            if "radius_sigma" in table else _positive(table, "radius_sigma", where)

        def draw(k: int) -> np.ndarray:
            return median * np.exp(sigma * rng.standard_normal(k))
    return _cut(draw, n, lo, hi, where)


def _cut(draw: Any, n: int, lo: float, hi: float, where: str) -> np.ndarray:
    kept = np.empty(0)
    for _ in range(CUT_ROUNDS):
        r = draw(max(2 * (n - len(kept)), 64))
        kept = np.concatenate([kept, r[(r >= lo) & (r <= hi) & (r > 0)]])
        if len(kept) >= n:
            return kept[:n]
    raise SceneError(f"{where}.radius_min: the cut [{lo:g}, {hi:g}] keeps almost none of the distribution's radii")


def _count(table: dict, where: str) -> int | None:
    """The count asked for, or None when a packing fraction is."""
    has_count, has_fraction = "count" in table, "packing_fraction" in table
    if has_count == has_fraction:
        raise SceneError(f"{where}.count: give a count or a packing_fraction ({'both' if has_count else 'neither'}"
                         " given)")
    if has_fraction:
        phi = _number(table["packing_fraction"], f"{where}.packing_fraction", positive=True)
        if phi >= 1.0:
            raise SceneError(f"{where}.packing_fraction: a part of the region's volume below 1, got {phi:g}")
        return None
    count = table["count"]
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise SceneError(f"{where}.count: expected a whole number of spheres >= 1, got {_shown(count)}")
    if count > MAX_FILL:
        raise SceneError(f"{where}.count: at most {MAX_FILL:.0e} spheres in one fill, got {count}")
    return count


def _radii(table: dict, where: str, dim: int, region: Region, rng: np.random.Generator) -> np.ndarray:
    count = _count(table, where)
    if count is not None:
        return draw_radii(table, where, count, rng)
    target = float(table["packing_fraction"]) * region.volume(dim)
    radii = np.empty(0)
    while True:  # draw until the spheres' volume reaches the fraction of the region's
        guess = draw_radii(table, where, 1, np.random.default_rng(0)) if not len(radii) else radii
        each = float(_sphere_volume(guess, dim).mean())
        more = max(64, int(1.1 * (target - _sphere_volume(radii, dim).sum()) / each) + 1)
        if len(radii) + more > MAX_FILL:
            raise SceneError(f"{where}.packing_fraction: needs more than {MAX_FILL:.0e} spheres of this size")
        radii = np.concatenate([radii, draw_radii(table, where, more, rng)])
        total = np.cumsum(_sphere_volume(radii, dim))
        if total[-1] >= target:
            # the count whose spheres' volume is nearest the target (each counted at its midpoint)
            n = int(np.searchsorted(total - _sphere_volume(radii, dim) / 2, target, "left"))
            if n == 0:
                raise SceneError(f"{where}.packing_fraction: less than one sphere fits that fraction")
            return radii[:n]


def fill_bodies(table: Any, index: int, dim: int, materials: dict, domain: Any,
                obstacles: tuple[np.ndarray, np.ndarray], walls: tuple, progress: Any = None) -> FillBodies:
    """The spheres of one `[[fill]]` table, placed clear of `obstacles` (positions, radii of the
    bodies so far) and the walls."""
    where = f"fill[{index}]"
    _check_keys(table, FILL_KEYS, where)
    name = table.get("name", "fill" if index == 0 else f"fill{index}_")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise SceneError(f"{where}.name: expected a name of letters, digits, _ or -, got {_shown(name)}")
    if "name" in table:  # (a named fill's messages name it; an unnamed one's give its place)
        where = f"fill.{name}"
    region = parse_region(table, where, dim, domain)
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SceneError(f"{where}.seed: expected a whole number >= 0, got {_shown(seed)}")
    density, material = _density(table, where, materials)
    arrangement = table.get("arrangement", "random")
    if arrangement not in ("random", "lattice"):
        raise SceneError(f"{where}.arrangement: unknown {_shown(arrangement)} (choose from random, lattice)")
    velocity = np.array(_vector(table.get("velocity", [0.0] * dim if dim > 1 else 0.0), f"{where}.velocity", dim))
    rng = np.random.default_rng(seed)
    radius = _radii(table, where, dim, region, rng)
    _check_fits(radius, region, where)
    if arrangement == "lattice":
        position = _lattice(radius, region, dim, where)
    else:
        position = _random(radius, region, dim, where, rng, obstacles, walls, progress or (lambda *_: None))
        near = _z_order(position, 2.0 * float(radius.max()))
        radius, position = radius[near], position[near]
    mass = 4.0 / 3.0 * math.pi * radius**3 * density
    for what, values in (("radii", radius), ("masses", mass), ("moments of inertia", 0.4 * mass * radius**2)):
        if not (values.min() >= MIN_POSITIVE and values.max() <= MAX_MAGNITUDE):
            raise SceneError(f"{where}: gives {what} out of range ({values.min():.3g} to {values.max():.3g}; "
                             f"each within {MIN_POSITIVE:.0e}..{MAX_MAGNITUDE:.0e})")
    return FillBodies(name, radius, mass, position, np.broadcast_to(velocity, position.shape).copy(), material)


def _density(table: dict, where: str, materials: dict) -> tuple[float, str | None]:
    material = table.get("material")
    if material is not None and "mass_density" in table:
        raise SceneError(f"{where}.mass_density: give a material or a mass_density, not both")
    if material is None:
        if "mass_density" not in table:
            raise SceneError(f"{where}.mass_density: missing (give a mass_density, or a material with a density)")
        return _number(table["mass_density"], f"{where}.mass_density", positive=True), None
    if not isinstance(material, str) or material not in materials:
        known = ", ".join(sorted(materials)) or "none defined"
        raise SceneError(f"{where}.material: unknown {_shown(material)} (materials: {known})")
    if materials[material].density is None:
        raise SceneError(f"{where}.material: material {_shown(material)} has no density (give one, or a "
                         "mass_density here)")
    return materials[material].density, material


def _check_fits(radius: np.ndarray, region: Region, where: str) -> None:
    r = float(radius.max())
    if region.kind == "box":
        if (region.upper - region.lower < 2 * r).any():
            raise SceneError(f"{where}: a sphere of radius {r:g} m does not fit in the box")
    elif 2 * r > min(2 * region.radius, region.height):
        raise SceneError(f"{where}: a sphere of radius {r:g} m does not fit in the cylinder")


# ---------------------------------------------------------------------------------------------
# Arrangements


def _lattice(radius: np.ndarray, region: Region, dim: int, where: str) -> np.ndarray:
    """Sites of a lattice of pitch 2 r_max, from the region's lower end (its last axis first)."""
    pitch = 2.0 * float(radius.max())
    if region.kind == "box":
        lo, hi = region.lower + pitch / 2, region.upper - pitch / 2
    else:
        half = np.array([region.radius, region.radius, region.height / 2]) - pitch / 2
        lo, hi = -half, half
    counts = np.floor((hi - lo) / pitch + 1e-9).astype(np.int64) + 1
    if float(np.prod(counts.astype(float))) > 4 * MAX_FILL:
        raise SceneError(f"{where}: the lattice has more than {4 * MAX_FILL:.0e} sites")
    grids = np.meshgrid(*[np.arange(c) for c in counts[::-1]], indexing="ij")
    index = np.stack([g.ravel() for g in grids[::-1]], axis=1)  # last axis slowest: bottom layer first
    sites = lo + index * pitch
    if region.kind == "cylinder":
        inside = np.hypot(sites[:, 0], sites[:, 1]) <= region.radius - pitch / 2
        sites = region.centre + sites[inside] @ region.frame
    if len(sites) < len(radius):
        raise SceneError(f"{where}.count: {len(radius)} spheres asked for; the lattice holds {len(sites)}")
    return sites[:len(radius)]


def _draw_centres(r: np.ndarray, region: Region, dim: int, rng: np.random.Generator) -> np.ndarray:
    """Centres drawn uniformly where each sphere lies inside the region."""
    if region.kind == "box":
        return region.lower + r[:, None] + rng.random((len(r), dim)) * (region.upper - region.lower - 2 * r[:, None])
    rho = np.sqrt(rng.random(len(r))) * (region.radius - r)
    phi = rng.random(len(r)) * 2 * math.pi
    h = (rng.random(len(r)) - 0.5) * (region.height - 2 * r)
    local = np.stack([rho * np.cos(phi), rho * np.sin(phi), h], axis=1)
    return region.centre + local @ region.frame


class _Placed:
    """The spheres placed so far that a candidate might touch, on grids of cell 2 r_cap (spheres
    up to r_cap: fill and small obstacles) and per size class for bigger obstacles."""

    def __init__(self, dim: int, r_cap: float, obstacles: tuple[np.ndarray, np.ndarray]) -> None:
        pos, rad = obstacles
        small = rad <= r_cap
        self.cell, self.dim = 2.0 * r_cap, dim
        self.pos, self.rad = pos[small], rad[small]
        self.big = [(pos[~small][c], rad[~small][c]) for c in size_classes(rad[~small])] if (~small).any() else []
        self.origin = pos.min(axis=0) if len(pos) else np.zeros(dim)
        self.big_grids = [Grid(p, 2.0 * float(r.max()), self.origin) for p, r in self.big]
        self.grid = Grid(self.pos, self.cell, self.origin)

    def add(self, pos: np.ndarray, rad: np.ndarray) -> None:
        self.pos, self.rad = np.concatenate([self.pos, pos]), np.concatenate([self.rad, rad])
        self.grid = Grid(self.pos, self.cell, self.origin)

    def clear(self, pos: np.ndarray, rad: np.ndarray) -> np.ndarray:
        """Which candidates overlap nothing placed."""
        ok = np.ones(len(pos), dtype=bool)
        for grid, (gp, gr) in [(self.grid, (self.pos, self.rad))] + list(zip(self.big_grids, self.big)):
            for q, o in grid.candidates(pos):
                hit = ((pos[q] - gp[o]) ** 2).sum(axis=1) < (rad[q] + gr[o]) ** 2
                ok[q[hit]] = False
        return ok


def _clear_of_walls(pos: np.ndarray, rad: np.ndarray, walls: tuple) -> np.ndarray:
    ok = np.ones(len(pos), dtype=bool)
    for wall in walls:
        ok &= (pos - np.array(wall.point)) @ np.array(wall.normal) >= rad
    return ok


def _random(radius: np.ndarray, region: Region, dim: int, where: str, rng: np.random.Generator,
            obstacles: tuple[np.ndarray, np.ndarray], walls: tuple, progress: Any) -> np.ndarray:
    """Random sequential insertion, largest first, a window of the order at a time: each round
    every sphere of the window not yet placed draws centres (several when few are left), its
    first clear draw is kept unless it overlaps a kept draw of a sphere earlier in the order;
    the window moves on once all of it is placed."""
    order = np.argsort(-radius, kind="stable")
    placed = _Placed(dim, float(radius.max()), obstacles)
    position = np.full((len(radius), dim), np.nan)
    # Spheres of about one size need no order: all draw at once (far fewer rounds)
    one_size = radius.max() <= ONE_SIZE * radius.min()
    width = min(BATCH, len(radius) if one_size else max(ROUND_MIN, len(radius) // ROUNDS))
    tried, stalled, start, placed_count, rate = 0, 0, 0, 0, 1.0
    while start < len(order):
        window = order[start:start + width]
        head = window[np.isnan(position[window, 0])]
        if not len(head):
            start += width
            continue
        # draws per sphere: enough that most find a clear place at the last round's success rate
        reps = max(math.ceil(2.0 / max(rate, 1.0 / 64)), 4 * ROUND_MIN // len(head), 1)
        batch = np.repeat(head, min(64, reps, max(1, 4 * BATCH // len(head))))
        r = radius[batch]
        cand = _draw_centres(r, region, dim, rng)
        tried += len(batch)
        clear = np.flatnonzero(placed.clear(cand, r) & _clear_of_walls(cand, r, walls))
        chosen = np.sort(clear[np.unique(batch[clear], return_index=True)[1]])
        chosen = chosen[_clear_of_each_other(cand[chosen], r[chosen])]
        position[batch[chosen]] = cand[chosen]
        placed.add(cand[chosen], r[chosen])
        stalled = 0 if len(chosen) else stalled + 1
        rate = len(chosen) / len(head)
        placed_count += len(chosen)
        progress(f"filling {where[5:]}", placed_count, len(radius))
        if tried > max(ATTEMPTS_PER_SPHERE * len(radius), MIN_ATTEMPTS) or stalled >= STALLED_ROUNDS:
            done = placed_count
            raise SceneError(f"{where}: only {done} of {len(radius)} spheres fit without overlap in a random "
                             f"arrangement (random insertion jams near a packing fraction of "
                             f"{JAMMING[dim]}); ask for fewer, a bigger region, or arrangement = 'lattice'")
    return position


def _z_order(position: np.ndarray, cell: float) -> np.ndarray:
    """The order of the spheres along a Z-order (Morton) curve through cells of this size: spheres
    near in space are then near in the body arrays, so a contact pass over many bodies reads
    memory nearby (in the order drawn, a pair's two bodies lie anywhere in arrays of 100 000,
    and the contact pass waited on memory)."""
    cells = np.minimum(((position - position.min(axis=0)) / cell).astype(np.int64), (1 << 20) - 1)
    code = np.zeros(len(position), np.int64)
    dim = position.shape[1]
    for bit in range(20):
        for axis in range(dim):
            code |= ((cells[:, axis] >> bit) & 1) << (bit * dim + axis)
    return np.argsort(code, kind="stable")


def _clear_of_each_other(pos: np.ndarray, rad: np.ndarray) -> np.ndarray:
    """Which candidates to keep, in order, each unless it overlaps an earlier kept one: the
    greedy choice, made for all at once by rounds (a candidate is kept once every earlier one it
    overlaps is dropped, dropped once one of them is kept)."""
    keep = np.zeros(len(pos), dtype=bool)
    if not len(pos):
        return keep
    grid = Grid(pos, 2.0 * float(rad.max()), pos.min(axis=0))
    first, later = [], []
    for q, o in grid.candidates(pos):
        hit = (o < q) & (((pos[q] - pos[o]) ** 2).sum(axis=1) < (rad[q] + rad[o]) ** 2)
        first.append(o[hit])
        later.append(q[hit])
    a, b = np.concatenate(first), np.concatenate(later)
    undecided = np.ones(len(pos), dtype=bool)
    while undecided.any():
        blocked = np.zeros(len(pos), dtype=bool)
        blocked[b[undecided[a] | keep[a]]] = True
        now = undecided & ~blocked
        keep |= now
        undecided &= ~now
        undecided[b[keep[a]]] = False
    return keep
