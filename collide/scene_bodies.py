"""A scene's bodies: the `[[body]]` tables read in bulk, and the start-overlap check, both in time
linear in the bodies (docs/design.md sections 3 and 10).

The bulk reader checks every body's values at once with numpy; when anything is not plainly
right it reads the bodies one by one (`parse_body`), which raises the error naming the first bad
key, so a message is the same whichever way the bodies were read.
"""

from __future__ import annotations

import math
from collections import Counter
from itertools import chain
from typing import Any

import numpy as np

from collide.body_columns import Bodies
from collide.scene_values import (
    MAX_MAGNITUDE,
    MIN_POSITIVE,
    NAME_PATTERN,
    TOUCHING,
    Body,
    SceneError,
    _check_keys,
    _number,
    _shown,
    _vector,
)
from collide.spheregrid import Grid, size_classes

BODY_KEYS = frozenset({"name", "mass", "radius", "inertia", "position", "velocity", "spin", "material"})
_NUMBER_TYPES = (int, float)


def _mass_from_density(radius: float, density: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * density


def parse_body(b: Any, index: int, dim: int, materials: dict) -> Body:
    """One `[[body]]` table, checked key by key (the message names the first bad one)."""
    where = f"body[{index}]"
    _check_keys(b, BODY_KEYS, where)
    bname = b.get("name", f"ball{index + 1}")
    if not isinstance(bname, str) or not NAME_PATTERN.fullmatch(bname):
        raise SceneError(f"{where}.name: expected a name of letters, digits, _ or -, got {_shown(bname)}")
    where = f"body.{bname}"
    for required in ("radius", "position"):
        if required not in b:
            raise SceneError(f"{where}.{required}: missing")
    radius = _number(b["radius"], f"{where}.radius", positive=True)
    material = b.get("material")
    if material is not None and not isinstance(material, str):
        raise SceneError(f"{where}.material: expected a material's name, got {_shown(material)}")
    if material is not None and material not in materials:
        known = ", ".join(sorted(materials)) or "none defined"
        raise SceneError(f"{where}.material: unknown {_shown(material)} (materials: {known})")
    if "mass" in b:
        mass = _number(b["mass"], f"{where}.mass", positive=True)
    elif material is not None and materials[material].density is not None:
        mass = _number(_mass_from_density(radius, materials[material].density), f"{where}.mass", positive=True)
    else:
        raise SceneError(f"{where}.mass: missing (give a mass, or a material with a density)")
    inertia = _inertia(b.get("inertia", "solid"), mass, radius, where)
    position = _vector(b["position"], f"{where}.position", dim)
    velocity = _vector(b.get("velocity", [0.0] * dim if dim > 1 else 0.0), f"{where}.velocity", dim)
    spin_len = {1: 0, 2: 1, 3: 3}[dim]
    spin_raw = b.get("spin")
    if spin_len == 0:
        if spin_raw not in (None, 0, 0.0):
            raise SceneError(f"{where}.spin: 1D scenes have no rotation")
        spin: tuple[float, ...] = ()
    elif spin_raw is None:
        spin = (0.0,) * spin_len
    else:
        spin = _vector(spin_raw, f"{where}.spin", spin_len)
    return Body(bname, mass, radius, inertia, position, velocity, spin, material)


def _inertia(value: Any, mass: float, radius: float, where: str) -> float:
    if value == "solid":
        return 0.4 * mass * radius**2
    if value == "shell":
        return 2.0 / 3.0 * mass * radius**2
    if isinstance(value, str):
        raise SceneError(f"{where}.inertia: 'solid', 'shell' or a number, got {_shown(value)}")
    return _number(value, f"{where}.inertia", positive=True)


def parse_bodies(tables: list, dim: int, materials: dict) -> Bodies:
    """Every `[[body]]` table (in bulk when each is plainly right, else one by one)."""
    bodies = _bulk(tables, dim, materials)
    if bodies is None:
        bodies = Bodies.of([parse_body(b, index, dim, materials) for index, b in enumerate(tables)], dim)
    check_names(bodies.names)
    return bodies


def check_names(names: list[str]) -> None:
    """No name twice (the first name, in order, that is used again is named)."""
    if len(set(names)) != len(names):
        counts = Counter(names)
        duplicate = next(n for n in names if counts[n] > 1)
        raise SceneError(f"body.{duplicate}: the name is used twice")


def _plain(values: list) -> bool:
    return all(type(v) in _NUMBER_TYPES for v in values)


def _in_range(a: np.ndarray, positive: bool) -> bool:
    """What `_number` accepts, for a whole column."""
    ok = np.isfinite(a) & (np.abs(a) <= MAX_MAGNITUDE)
    if positive:
        ok &= a >= MIN_POSITIVE
    return bool(ok.all())


def _vectors(tables: list, key: str, dim: int, default: Any) -> np.ndarray | None:
    """A vector column (n, dim) when every value is plain numbers of the right length."""
    raw = [t.get(key, default) for t in tables]
    if dim == 1:
        raw = [v[0] if type(v) is list and len(v) == 1 else v for v in raw]
        flat = raw
    else:
        if not all(type(v) is list and len(v) == dim for v in raw):
            return None
        flat = list(chain.from_iterable(raw))
    if not _plain(flat):
        return None
    try:
        out = np.array(flat, dtype=float).reshape(len(tables), dim)
    except OverflowError:
        return None
    return out if _in_range(out, positive=False) else None


def _column(tables: list, key: str) -> np.ndarray | None:
    raw = [t[key] for t in tables]
    if not _plain(raw):
        return None
    try:
        return np.array(raw, dtype=float)
    except OverflowError:
        return None


def _bulk(tables: list, dim: int, materials: dict) -> Bodies | None:
    """The bodies, or None when any is not plainly right (the one-by-one reader then names it).
    Solid spheres only: a body that gives its inertia is read one by one."""
    if not all(type(t) is dict and t.keys() <= BODY_KEYS and "radius" in t and "position" in t
               and t.get("inertia", "solid") == "solid" for t in tables):
        return None
    names = [t["name"] if "name" in t else f"ball{i + 1}" for i, t in enumerate(tables)]
    if not all(type(n) is str and NAME_PATTERN.fullmatch(n) for n in names):
        return None
    material = [t.get("material") for t in tables]
    if not all(m is None or (type(m) is str and m in materials) for m in material):
        return None
    radius = _column(tables, "radius")
    if radius is None or not _in_range(radius, True):
        return None
    r = radius.tolist()
    mass = []
    for t, ri, m in zip(tables, r, material):
        if "mass" in t:
            mass.append(t["mass"])
        elif m is not None and materials[m].density is not None:
            mass.append(_mass_from_density(ri, materials[m].density))
        else:
            return None
    if not _plain(mass):
        return None
    try:
        masses = np.array(mass, dtype=float)
    except OverflowError:
        return None
    if not _in_range(masses, True):
        return None
    return _assemble(tables, dim, names, r, masses.tolist(), material)


def _assemble(tables: list, dim: int, names: list, radius: list, mass: list, material: list) -> Bodies | None:
    """The bodies from checked columns (solid spheres), or None when a vector is not plain."""
    zero = [0.0] * dim if dim > 1 else 0.0
    position = _vectors(tables, "position", dim, None)
    velocity = _vectors(tables, "velocity", dim, zero)
    if position is None or velocity is None:
        return None
    spin_len = {1: 0, 2: 1, 3: 3}[dim]
    if spin_len == 0:
        if any("spin" in t for t in tables):
            return None
        spin = np.zeros((len(tables), 0))
    else:
        spin = _vectors(tables, "spin", spin_len, [0.0] * spin_len if spin_len > 1 else 0.0)
        if spin is None:
            return None
    inertia = [0.4 * m * r**2 for m, r in zip(mass, radius)]
    if not _in_range(np.array(inertia), True):
        return None
    return Bodies(names, np.array(mass), np.array(radius), np.array(inertia), position, velocity, spin, material)


# ---------------------------------------------------------------------------------------------
# Start overlaps

# Candidate pairs examined before a scene known to overlap is refused on the first overlap found
# (rather than the first in body order): spheres that do not overlap have a bounded number of
# neighbours, so only a scene piled on itself gets there.
PAIRS_PER_BODY = 100
# A saved state's bodies in a DEM scene may start pressed into each other and walls by up to this
# share of the smaller radius: a settled pile rests in its contacts (DEM overlaps are well below it).
CONTACT_SHARE = 0.1
PAIR_FLOOR = 1 << 20


def check_start_overlap(names: list[str], pos: np.ndarray, radius: np.ndarray, walls: tuple,
                        in_contact: np.ndarray | None = None) -> None:
    """Spheres may touch at the start, never overlap (docs/design.md section 3): a pair overlaps
    when its gap is below -TOUCHING (r_i + r_j), a sphere and a wall when the sphere's height
    above the wall is below r (1 - TOUCHING). The first overlap in body order is named (for each
    body, its pairs with later bodies, then the walls).

    Bodies marked `in_contact` (a saved state's, in a DEM scene: a settled pile rests in its
    contacts) may press into each other and into walls by up to CONTACT_SHARE of the smaller
    radius."""
    if not len(names):
        return
    mask = np.zeros(len(names), dtype=bool) if in_contact is None else in_contact
    pair = _first_pair_overlap(pos, radius, mask)
    wall = _first_wall_overlap(pos, radius, walls, mask)
    deeper = " (deeper than a saved state's contacts may start)" if mask.any() else ""
    if pair is not None and (wall is None or pair[0] <= wall[0]):
        i, j, gap = pair
        raise SceneError(f"body.{names[i]}.position: overlaps body.{names[j]} at the start by {-gap:.3g} m"
                         + (deeper if mask[i] and mask[j] else ""))
    if wall is not None:
        i, index, height = wall
        raise SceneError(f"body.{names[i]}.position: overlaps wall[{index}] at the start "
                         f"(distance {height:.3g} m < radius {radius[i]:.3g} m)" + (deeper if mask[i] else ""))


def _first_wall_overlap(pos: np.ndarray, radius: np.ndarray, walls: tuple,
                        mask: np.ndarray) -> tuple[int, int, float] | None:
    """(body, wall, height) of the first body in order below a wall; the height is summed in the
    order the one-body check sums it, so the verdict is the same to the last bit."""
    first = None
    for index, wall in enumerate(walls):
        terms = (pos - np.array(wall.point)) * np.array(wall.normal)
        height = terms[:, 0].copy()
        for axis in range(1, terms.shape[1]):
            height = height + terms[:, axis]
        below = np.flatnonzero(height < np.where(mask, radius * (1 - CONTACT_SHARE), radius * (1 - TOUCHING)))
        if len(below) and (first is None or below[0] < first[0]):
            first = (int(below[0]), index, float(height[below[0]]))
    return first


def _first_pair_overlap(pos: np.ndarray, radius: np.ndarray, mask: np.ndarray) -> tuple[int, int, float] | None:
    """(i, j, gap) of the overlapping pair first in body order (i < j), or None."""
    best = None
    examined = 0
    origin = pos.min(axis=0)
    classes = size_classes(radius)
    for at, big in enumerate(classes):
        grid = Grid(pos[big], 2.0 * float(radius[big].max()), origin)
        for small in classes[at:]:
            for q, o in grid.candidates(pos[small]):
                i, j = small[q], big[o]
                keep = i < j if small is big else i != j
                i, j = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
                examined += len(i)
                found = _overlapping(pos, radius, i, j, mask)
                if found is not None and (best is None or found[:2] < best[:2]):
                    best = found
                if best is not None and examined > PAIRS_PER_BODY * len(pos) + PAIR_FLOOR:
                    return best
    return best



def _overlapping(pos: np.ndarray, radius: np.ndarray, i: np.ndarray, j: np.ndarray,
                 mask: np.ndarray) -> tuple[int, int, float] | None:
    """The first overlapping pair (by i, then j) among candidates, judged as `math.dist` judges:
    numpy's distance decides where it is clear by far more than its rounding, the rest is
    recomputed one pair at a time."""
    if not len(i):
        return None
    d = np.sqrt(((pos[i] - pos[j]) ** 2).sum(axis=1))
    rsum = radius[i] + radius[j]
    gap = d - radius[i] - radius[j]
    contact = mask[i] & mask[j]
    limit = np.where(contact, -CONTACT_SHARE * np.minimum(radius[i], radius[j]), -TOUCHING * rsum)
    band = 16 * np.finfo(float).eps * (d + rsum)
    sure = gap < limit - band
    unsure = np.flatnonzero(np.abs(gap - limit) <= band)
    hits = []
    if sure.any():
        first = np.lexsort((j[sure], i[sure]))[0]
        hits.append((int(i[sure][first]), int(j[sure][first])))
    for k in unsure.tolist():
        a, b = int(i[k]), int(j[k])
        exact = math.dist(pos[a].tolist(), pos[b].tolist()) - float(radius[a]) - float(radius[b])
        if exact < float(limit[k]):
            hits.append((a, b))
    if not hits:
        return None
    a, b = min(hits)
    return a, b, math.dist(pos[a].tolist(), pos[b].tolist()) - float(radius[a]) - float(radius[b])


# ---------------------------------------------------------------------------------------------
# Bodies made in bulk: from a table file, from a fill


def bodies_from_columns(names: list[str], radius: np.ndarray, mass: np.ndarray, inertia: np.ndarray | None,
                        pos: np.ndarray, vel: np.ndarray, spin: np.ndarray, material: list) -> Bodies:
    """Bodies from checked columns; a missing inertia is a solid sphere's."""
    if inertia is None:
        inertia = 0.4 * mass * radius**2
    return Bodies(names, mass, radius, inertia, pos, vel, spin, material)


def bodies_from_table(table: Any, dim: int, materials: dict, where: str) -> Bodies:
    """The bodies of a table file (`collide.bodies_file.Table`): materials known, a mass for each
    row (its own, or its material's density)."""
    bad = next((i for i, m in enumerate(table.material) if m is not None and m not in materials), None)
    if bad is not None:
        known = ", ".join(sorted(materials)) or "none defined"
        raise SceneError(f"{where} row {bad + 1}, material: unknown {_shown(table.material[bad])} (materials: {known})")
    mass = table.mass if table.mass is not None else np.full(len(table.name), np.nan)
    need = np.flatnonzero(np.isnan(mass))
    if len(need):
        mass = mass.copy()
        material = np.array([m if m is not None else "" for m in table.material], dtype=object)
        for m in dict.fromkeys(material[need].tolist()):
            rows = need[material[need] == m]
            if m == "" or materials[m].density is None:
                raise SceneError(f"{where} row {int(rows[0]) + 1}, mass: missing (give a mass, or a material "
                                 "with a density)")
            # numpy's power and Python's ** both call the C library's pow: the same bits as
            # _mass_from_density row by row.
            mass[rows] = 4.0 / 3.0 * math.pi * table.radius[rows] ** 3 * materials[m].density
        if not _in_range(mass, True):
            i = int(np.flatnonzero(~(np.isfinite(mass) & (mass >= MIN_POSITIVE) & (mass <= MAX_MAGNITUDE)))[0])
            raise SceneError(f"{where} row {i + 1}, mass: out of range from its material's density ({mass[i]:.3g})")
    inertia = table.inertia
    if inertia is None and not _in_range(0.4 * mass * table.radius**2, True):
        raise SceneError(f"{where}: a solid sphere's inertia 0.4 m r^2 is out of range (give an inertia column)")
    return bodies_from_columns(table.name, table.radius, mass, inertia, table.position, table.velocity,
                               table.spin, table.material)


def bodies_from_fill(fill: Any, dim: int) -> Bodies:
    """The bodies of one fill (`collide.fill.FillBodies`), named prefix0, prefix1, ..."""
    n = len(fill.radius)
    names = [f"{fill.prefix}{i}" for i in range(n)]
    spin = np.zeros((n, {1: 0, 2: 1, 3: 3}[dim]))
    return bodies_from_columns(names, fill.radius, fill.mass, None, fill.position, fill.velocity, spin,
                               [fill.material] * n)
