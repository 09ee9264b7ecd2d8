"""Scene files: load, validate and override TOML scenes (docs/design.md section 3).

A scene is plain data. `load_scene` turns a built-in name or a `.toml` path into a `Scene`;
`apply_overrides` edits the raw TOML table with `key=value` strings before validation, so an
error always names the key the user typed.
"""

from __future__ import annotations

import copy
import gc
import math
import re
import tomllib
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from collide.body_columns import Bodies, as_bodies
from collide.fill import FILL_KEYS
from collide.periodic import check_image_overlap, check_periodic
from collide.scene_bodies import BODY_KEYS, check_names, check_start_overlap, parse_bodies
from collide.scene_toml import FlatTables, loads_scene
from collide.scene_values import (  # noqa: F401 (re-exported: the scene's API)
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

INTEGRATORS = ("seed", "verlet", "yoshida4", "kahan6", "dem")
DEFAULT_INTEGRATOR = "kahan6"
DEFAULT_TOL = 1e-6
MAX_DEPTH = 8  # tables and arrays nested deeper than this are no scene (a scene needs 4)


@dataclass(frozen=True)
class Wall:
    """A static plane: a point on it and its outward unit normal."""

    point: tuple[float, ...]
    normal: tuple[float, ...]


@dataclass(frozen=True)
class Contact:
    """Contact law for every pair and wall (docs/design.md sections 2 and 9): a normal model (the
    report's linear springs in series, or Hertz), optional normal damping for a restitution,
    a tangential model (the report's Coulomb slip with a dead band, or a history spring capped
    by Coulomb) and optional rolling resistance.

    `lever = "seed"` reproduces the report: slip measured with the undeformed radius while the
    torque acts at the deformed contact point (docs/design.md section 2).
    """

    model: str = "linear"
    k: float = 1500.0
    mu: float = 0.0
    eps: float = 1e-6
    lever: str = "contact"
    youngs_modulus: float | None = None
    poisson_ratio: float = 0.3
    restitution: float = 1.0
    tangential: str = "coulomb"
    tangential_stiffness_ratio: float | None = None
    rolling_friction: float = 0.0

    @property
    def stiffness_ratio(self) -> float:
        """k_t over the normal stiffness dF_n/d delta: as given, else 2/7 (linear) or Mindlin's
        2(1 - nu)/(2 - nu) (Hertz, both spheres of this Poisson ratio)."""
        if self.tangential_stiffness_ratio is not None:
            return self.tangential_stiffness_ratio
        if self.model == "hertz":
            return 2.0 * (1.0 - self.poisson_ratio) / (2.0 - self.poisson_ratio)
        return 2.0 / 7.0


@dataclass(frozen=True)
class Material:
    """A named material: density (for bodies without a mass), elastic constants, and contact
    values that replace [contact]'s for its pairs (None: not given)."""

    name: str
    density: float | None = None
    youngs_modulus: float | None = None
    poisson_ratio: float | None = None
    mu: float | None = None
    restitution: float | None = None
    rolling_friction: float | None = None


@dataclass(frozen=True)
class PairLaw:
    """Contact values for one pair of materials, overriding the mixing rules."""

    materials: tuple[str, str]
    mu: float | None = None
    restitution: float | None = None
    rolling_friction: float | None = None


@dataclass(frozen=True)
class Domain:
    """The box a scene lives in (docs/design.md section 10): every body starts inside it, and a
    box fill without corners fills it. Along the `periodic` axes it wraps: a body leaving one
    side enters the other and contacts see the images across it; along the others nothing holds
    bodies in it once they move (walls do)."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    periodic: tuple[str, ...] = ()

    @property
    def period(self) -> tuple[float, float, float]:
        """Each axis's period (x, y, z; 0 where it does not wrap)."""
        return tuple(u - lo if axis in self.periodic else 0.0
                     for axis, lo, u in zip("xyz", self.lower + (0.0,) * 3, self.upper + (0.0,) * 3))


@dataclass(frozen=True)
class Scene:
    """A validated scene. `dt` is a float or the string "auto"."""

    name: str
    dim: int
    dt: float | str
    integrator: str
    contact: Contact
    bodies: Sequence[Body]  # a tuple of Body, or Bodies (the same, held as columns)
    walls: tuple[Wall, ...] = ()
    materials: tuple[Material, ...] = ()
    pairs: tuple[PairLaw, ...] = ()
    gravity: tuple[float, ...] | None = None
    duration: float | None = None
    tail: float | None = None
    tol: float = DEFAULT_TOL
    rest: float | None = None  # DEM: end when the kinetic energy falls below this part of its peak
    description: str = ""
    domain: Domain | None = None
    source: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def spin_dim(self) -> int:
        """Components of angular velocity: 0 in 1D, 1 in 2D (about z), 3 in 3D."""
        return {1: 0, 2: 1, 3: 3}[self.dim]

    @property
    def has_friction(self) -> bool:
        mus = [self.contact.mu] + [m.mu for m in self.materials if m.mu is not None] + \
            [p.mu for p in self.pairs if p.mu is not None]
        return self.dim > 1 and max(mus) > 0.0

    @property
    def needs_dem(self) -> bool:
        """Whether the contact law goes beyond the report's (linear, undamped, Coulomb with a
        dead band, no rolling resistance): such laws run in the fixed-step DEM kernel."""
        c = self.contact
        return c.model != "linear" or c.tangential != "coulomb" or self.damped or self.has_rolling

    @property
    def damped(self) -> bool:
        """Whether any contact has a restitution below 1 (the contact's, a material's or a pair's)."""
        rest = [self.contact.restitution] + [m.restitution for m in self.materials if m.restitution is not None] + \
            [p.restitution for p in self.pairs if p.restitution is not None]
        return min(rest) < 1.0

    @property
    def has_rolling(self) -> bool:
        """Whether any contact has rolling resistance (the contact's, a material's or a pair's)."""
        rolling = [self.contact.rolling_friction] + [m.rolling_friction for m in self.materials
                                                     if m.rolling_friction is not None] + \
            [p.rolling_friction for p in self.pairs if p.rolling_friction is not None]
        return max(rolling) > 0.0

    @property
    def has_spin(self) -> bool:
        """Angular state is carried only when something can spin."""
        if self.dim == 1:
            return False
        return self.has_friction or bool(as_bodies(self.bodies, self.dim).spin.any())

    def body_index(self, name: str) -> int:
        for i, body in enumerate(self.bodies):
            if body.name == name:
                return i
        raise SceneError(f"body '{name}' not found (bodies: {', '.join(b.name for b in self.bodies)})")

    def to_toml(self) -> str:
        """The scene as TOML text that `load_scene` reads back to an equal scene."""
        return dump_toml(self.source)


# ---------------------------------------------------------------------------------------------
# TOML writing (a tiny emitter for the scene subset: scalars, arrays, tables, arrays of tables)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def dump_toml(data: dict) -> str:
    """Write a scene table as TOML (top-level scalars, then tables, then arrays of tables)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list)) or
             (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{key}]"] + [f"{k} = {_toml_value(v)}" for k, v in value.items()]
    for key, value in data.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            for item in value:
                lines += ["", f"[[{key}]]"] + [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Built-in scenes

_BUILTIN_PACKAGE = "collide.scenes"
# A built-in declaring more bodies than this is heavy: its run takes minutes, so what runs every
# built-in (the tests, `collide validate`, the outcomes, the viewer's picker) leaves it out.
HEAVY_BODIES = 10_000


def builtin_names(heavy: bool = True) -> list[str]:
    """Names of the built-in scenes: the report's demos first, then its textbook checks, then
    the scenes beyond the report (what a new user meets first in a list). `heavy=False` leaves
    out the heavy ones (`is_heavy`)."""
    files = resources.files(_BUILTIN_PACKAGE).iterdir()
    names = [p.name[:-5] for p in files if p.name.endswith(".toml")]
    names = [n for n in names if heavy or not is_heavy(n)]
    return sorted(names, key=lambda n: (0 if n.startswith("demo") else 1 if n.startswith("textbook") else 2, n))


def declared_bodies(raw: dict) -> int:
    """The bodies a raw scene table declares by count, without placing them: its `[[body]]`
    tables and its fills' `count`s (a fill to a packing fraction counts by its spheres only once
    drawn, and a `[bodies]` file by its rows once read: neither is counted here)."""
    bodies, fills = raw.get("body", []), raw.get("fill", [])
    count = len(bodies) if isinstance(bodies, list) else 0
    for fill in fills if isinstance(fills, list) else []:
        value = fill.get("count") if isinstance(fill, dict) else None
        count += value if isinstance(value, int) and not isinstance(value, bool) else 0
    return count


def is_heavy(name: str) -> bool:
    """Whether a built-in declares more than HEAVY_BODIES bodies (read from its file, not loaded)."""
    text = resources.files(_BUILTIN_PACKAGE).joinpath(f"{name}.toml").read_text()
    return declared_bodies(_parse_toml(text, name)) > HEAVY_BODIES


def builtin_text(name: str) -> str:
    """The TOML text of a built-in scene (what `collide scenes --show NAME` prints)."""
    if name not in builtin_names():
        raise SceneError(f"unknown scene '{name}' (built-ins: {', '.join(builtin_names())})")
    return resources.files(_BUILTIN_PACKAGE).joinpath(f"{name}.toml").read_text()


def read_raw(source: str | Path) -> tuple[dict, str]:
    """Raw TOML table and default name for a built-in name or a `.toml` path."""
    text_source = str(source)
    if text_source in builtin_names():
        return _parse_toml(builtin_text(text_source), text_source), text_source
    path = Path(text_source)
    if path.suffix != ".toml" and not path.exists():
        raise SceneError(f"unknown scene '{text_source}': not a built-in "
                         f"({', '.join(builtin_names())}) and not a .toml file")
    if not path.is_file():
        raise SceneError(f"scene file '{path}' does not exist")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene file '{path}': {exc}") from None
    return _parse_toml(text, str(path)), path.stem


def _parse_toml(text: str, where: str) -> dict:
    try:
        raw = loads_scene(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{where}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses once per nested array or inline table
        raise SceneError(f"{where}: arrays or tables nested too deeply (a scene needs at most "
                         f"{MAX_DEPTH} levels)") from None
    _check_depth(raw, where)
    return raw


def _check_depth(value: Any, where: str) -> None:
    """Refuse values nested deeper than MAX_DEPTH (checked without recursion: the copies and
    checks that follow recurse)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise SceneError(f"{where}: arrays or tables nested more than {MAX_DEPTH} levels deep; "
                             "no scene key takes that")
        if isinstance(item, FlatTables):
            continue  # tables of numbers and flat arrays (collide.scene_toml): two levels below
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else ()
        stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))


@contextmanager
def _no_gc() -> Iterator[None]:
    """Without the cyclic garbage collector: a large scene makes millions of objects, none in a
    cycle, and each collection would walk them all (it would double the time of a large load)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


Progress = Callable[[str, int, int], None]  # what the set-up is doing, how far of how much (0 of 0: unknown)


def load_scene(source: str | Path, overrides: list[str] | None = None, progress: Progress | None = None) -> Scene:
    """Load a built-in name or a `.toml` path, apply `key=value` overrides, validate. `progress`
    hears how a long load goes (reading, each fill, the checks)."""
    with _no_gc():
        if progress is not None:
            progress("reading", 0, 0)
        raw, default_name = read_raw(source)
        raw = apply_overrides(raw, overrides or [])
        if str(source) in builtin_names():
            _follow_the_law(raw, overrides or [])
        _resolve_bodies_file(raw, source)
        return parse_scene(raw, default_name, progress)


# The tables whose keys make a scene's contact law.
_LAW_TABLES = ("contact", "material", "pair")


def _follow_the_law(raw: dict, overrides: list[str]) -> None:
    """A built-in's `integrator` is the one recommended for its own contact law (docs/design.md,
    built-in scenes): an override that changes the law, and names no integrator, drops it, so the
    engine is chosen by the new law as for a scene that names none."""
    keys = [split_override(item)[0] for item in overrides]
    if "integrator" not in keys and any(key.split(".")[0] in _LAW_TABLES for key in keys):
        raw.pop("integrator", None)


def _resolve_bodies_file(raw: dict, source: str | Path) -> None:
    """A `[bodies] file` is relative to the scene file (a built-in's: the built-ins' folder); the
    scene keeps it as an absolute path, so its source (and a recording's copy) reads the same file
    from anywhere."""
    table = raw.get("bodies")
    if not isinstance(table, dict) or not isinstance(table.get("file"), str) or not table["file"]:
        return
    path = Path(table["file"]).expanduser()
    if not path.is_absolute():
        base = Path(str(resources.files(_BUILTIN_PACKAGE))) if str(source) in builtin_names() \
            else Path(source).resolve().parent
        table["file"] = str(base / path)


# ---------------------------------------------------------------------------------------------
# Overrides: `contact.mu=0.3`, `body.ball1.velocity=[1,0]`, `body.ball1.velocity.y=0.2`

_COMPONENTS = {"x": 0, "y": 1, "z": 2}


def parse_value(text: str) -> Any:
    """A value as TOML would read it; bare words (`auto`, `seed`) stay strings."""
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except RecursionError:
        raise SceneError(f"value '{text[:40]}...': arrays nested too deeply (a scene needs at most "
                         f"{MAX_DEPTH} levels)") from None
    except tomllib.TOMLDecodeError:
        if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", text.strip()):
            return text.strip()
        shown = text if len(text) <= 60 else text[:57] + "..."
        raise SceneError(f"cannot read value '{shown}' (use TOML syntax, e.g. 0.3 or [1, 0])") from None
    _check_depth(value, f"value '{text if len(text) <= 60 else text[:57] + '...'}'")
    return value


def split_override(item: str) -> tuple[str, str]:
    if "=" not in item:
        raise SceneError(f"override '{item}' is not key=value")
    key, value = item.split("=", 1)
    key = key.strip()
    if not key:
        raise SceneError(f"override '{item}' has no key")
    return key, value.strip()


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Return a copy of `raw` with each `key=value` applied."""
    raw = _copy_raw(raw)
    for item in overrides:
        key, text = split_override(item)
        if key.startswith("body") and isinstance(raw.get("body"), FlatTables):
            raw["body"] = list(raw["body"])  # no longer known flat: its depth is checked again
        set_path(raw, key, parse_value(text))
    return raw


def _copy_raw(raw: dict) -> dict:
    """A copy that `set_path` may change without touching `raw`: every table copied whole but the
    bodies, each of which is copied one level deep (`set_path` replaces what it changes below)."""
    out = {k: copy.deepcopy(v) for k, v in raw.items() if k != "body"}
    if "body" in raw:
        bodies = raw["body"]
        out["body"] = type(bodies)(dict(b) if type(b) is dict else copy.deepcopy(b) for b in bodies) \
            if isinstance(bodies, list) else copy.deepcopy(bodies)
    return out


def set_path(raw: dict, key: str, value: Any) -> None:
    """Set a dotted key in the raw scene table (bodies and materials addressed by name, vectors
    by x/y/z)."""
    parts = key.split(".")
    if parts[0] in ("body", "material"):
        kind = parts[0]
        if len(parts) < 3:
            raise SceneError(f"override key '{key}': use {kind}.NAME.FIELD")
        tables = raw.get(kind, [])
        matches = [b for b in tables if isinstance(b, dict) and b.get("name") == parts[1]] \
            if isinstance(tables, list) else []
        if not matches:
            names = ", ".join(str(b.get("name")) for b in tables if isinstance(b, dict)) \
                if isinstance(tables, list) else ""
            plural = "bodies" if kind == "body" else "materials"
            raise SceneError(f"override key '{key}': no {kind} named '{parts[1]}' ({plural}: {names or 'none'})")
        table, rest = matches[0], parts[2:]
    elif parts[0] in ("wall", "fill"):
        kind = parts[0]
        if len(parts) < 3 or not parts[1].isdigit():
            raise SceneError(f"override key '{key}': use {kind}.INDEX.FIELD (INDEX from 0)")
        tables = raw.get(kind, [])
        index = int(parts[1])
        if not isinstance(tables, list) or index >= len(tables) or not isinstance(tables[index], dict):
            count = len(tables) if isinstance(tables, list) else 0
            raise SceneError(f"override key '{key}': the scene has {count} {kind}(s)")
        table, rest = tables[index], parts[2:]
    else:
        table, rest = raw, parts
    if len(rest) == 2 and rest[1] in _COMPONENTS and isinstance(table.get(rest[0]), list):
        table[rest[0]] = list(table[rest[0]])
        _set_component(table[rest[0]], rest[1], value, key)
        return
    if len(rest) == 2 and rest[1] == "x" and isinstance(table.get(rest[0]), (int, float)) \
            and not isinstance(table.get(rest[0]), bool):
        table[rest[0]] = value  # a 1D scene's vector is a plain number: its only component is x
        return
    for part in rest[:-1]:
        nxt = table.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise SceneError(f"override key '{key}': '{part}' is not a table")
        table[part] = table = dict(nxt)
    table[rest[-1]] = value


def _set_component(vector: list, component: str, value: Any, key: str) -> None:
    index = _COMPONENTS[component]
    if index >= len(vector):
        raise SceneError(f"override key '{key}': the vector has {len(vector)} component(s)")
    vector[index] = value


# ---------------------------------------------------------------------------------------------
# Validation

# The keys each table of a scene file accepts: the single source of truth. The parser refuses
# any other key, and tests/test_docs.py holds docs/design.md's scene-key reference to exactly
# these ("scene" is the top level; "body", "wall", "material" and "pair" are arrays of tables).
SCENE_KEYS: dict[str, frozenset[str]] = {
    "scene": frozenset({"name", "description", "dim", "dt", "integrator", "duration", "tail", "tol",
                        "gravity", "contact", "body", "wall", "material", "pair", "rest", "domain", "fill",
                        "bodies"}),
    "contact": frozenset({"model", "k", "mu", "eps", "lever", "youngs_modulus", "poisson_ratio", "restitution",
                          "tangential", "tangential_stiffness_ratio", "rolling_friction"}),
    "body": BODY_KEYS,
    "wall": frozenset({"point", "normal"}),
    "material": frozenset({"name", "density", "youngs_modulus", "poisson_ratio", "mu", "restitution",
                           "rolling_friction"}),
    "pair": frozenset({"materials", "mu", "restitution", "rolling_friction"}),
    "domain": frozenset({"lower", "upper", "periodic"}),
    "fill": FILL_KEYS,
    "bodies": frozenset({"file"}),
}
_TOP_KEYS = SCENE_KEYS["scene"]
_CONTACT_KEYS = SCENE_KEYS["contact"]
_MATERIAL_KEYS = SCENE_KEYS["material"]
_PAIR_KEYS = SCENE_KEYS["pair"]
_BODY_KEYS = SCENE_KEYS["body"]
_WALL_KEYS = SCENE_KEYS["wall"]


def parse_scene(raw: dict, default_name: str = "scene", progress: Progress | None = None) -> Scene:
    """Validate a raw TOML table into a `Scene`; raise `SceneError` naming the bad key."""
    with _no_gc():
        return _parse_scene(raw, default_name, progress or _silent)


def _silent(what: str, done: int, total: int) -> None:
    pass


def _parse_scene(raw: dict, default_name: str, progress: Progress) -> Scene:
    _check_keys(raw, _TOP_KEYS, "scene")
    _check_depth(raw, "scene")
    dim = raw.get("dim", 2)
    if isinstance(dim, bool) or not isinstance(dim, int) or dim not in (1, 2, 3):
        raise SceneError(f"dim: must be the whole number 1, 2 or 3, got {_shown(dim)}")
    name = raw.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SceneError(f"name: expected a non-empty string, got {_shown(name)}")
    if not isinstance(raw.get("description", ""), str):
        raise SceneError(f"description: expected a string, got {_shown(raw['description'])}")

    dt_raw = raw.get("dt", "auto")
    dt: float | str = "auto" if dt_raw == "auto" else _number(dt_raw, "dt", positive=True)
    integrator = raw.get("integrator", DEFAULT_INTEGRATOR)
    if integrator not in INTEGRATORS:
        raise SceneError(f"integrator: unknown {_shown(integrator)} (choose from {', '.join(INTEGRATORS)})")
    duration = raw.get("duration")
    duration = None if duration is None else _number(duration, "duration", positive=True)
    tail = raw.get("tail")
    tail = None if tail is None else _number(tail, "tail", nonneg=True)
    tol = _number(raw.get("tol", DEFAULT_TOL), "tol", positive=True)
    gravity = raw.get("gravity")
    gravity = None if gravity is None else _vector(gravity, "gravity", dim)

    contact = _parse_contact(raw.get("contact", {}))
    materials = _parse_materials(raw.get("material", []))
    by_name = {m.name: m for m in materials}
    pairs = _parse_pairs(raw.get("pair", []), by_name)
    rest = raw.get("rest")
    rest = None if rest is None else _number(rest, "rest", positive=True)
    if rest is not None and rest >= 1.0:
        raise SceneError(f"rest: a fraction of the peak kinetic energy below 1, got {_shown(raw.get('rest'))}")

    domain = _parse_domain(raw.get("domain"), dim)
    bodies_raw = raw.get("body", [])
    if not isinstance(bodies_raw, list):
        raise SceneError("body: expected [[body]] tables")
    progress(f"checking {len(bodies_raw):,} bodies", 0, 0)
    bodies = parse_bodies(bodies_raw, dim, by_name)

    walls = []
    walls_raw = raw.get("wall", [])
    if not isinstance(walls_raw, list):
        raise SceneError("wall: expected [[wall]] tables")
    for index, w in enumerate(walls_raw):
        where = f"wall[{index}]"
        _check_keys(w, _WALL_KEYS, where)
        for required in ("point", "normal"):
            if required not in w:
                raise SceneError(f"{where}.{required}: missing")
        point = _vector(w["point"], f"{where}.point", dim)
        normal = _vector(w["normal"], f"{where}.normal", dim)
        norm = math.sqrt(sum(c * c for c in normal))
        if norm == 0.0:
            raise SceneError(f"{where}.normal: must not be zero")
        walls.append(Wall(point, tuple(c / norm for c in normal)))

    bodies, from_file = _more_bodies(raw, dim, by_name, domain, bodies, tuple(walls), progress)
    scene = Scene(name=name, dim=dim, dt=dt, integrator=integrator, contact=contact,
                  bodies=bodies, walls=tuple(walls), materials=materials, pairs=pairs,
                  gravity=gravity, duration=duration, tail=tail, tol=tol, rest=rest,
                  description=raw.get("description", ""), domain=domain, source=raw)
    if scene.needs_dem:
        # The event engine where it runs these laws at full order (a sphere alone among walls, or
        # in islands: `island_blocker`), else the DEM kernel (collide.alone.engine_choice says
        # which and why).
        blocker = alone_blocker(scene)
        if blocker and integrator != "seed" and island_blocker(scene) is None:
            blocker = None
        if "integrator" not in raw:
            scene = replace(scene, integrator="dem" if blocker else DEFAULT_INTEGRATOR)
        elif integrator == "seed" or (integrator != "dem" and blocker):
            why = "the report's update runs its contact law only" if integrator == "seed" else blocker
            raise SceneError(f"integrator: {_shown(integrator)} cannot run this scene's contact law "
                             f"({dem_reason(scene)}): {why}; it runs with integrator = 'dem', or with no "
                             "integrator key (the law then chooses)")
    _check_sticky(scene)
    check_periodic(scene)
    if scene.contact.model == "hertz" and contact.youngs_modulus is None:
        _check_hertz_moduli(bodies, by_name)
    if rest is not None and scene.integrator != "dem":
        raise SceneError("rest: ends a DEM run (integrator = 'dem') when it comes to rest; this scene's "
                         f"integrator is {_shown(scene.integrator)}")
    progress(f"checking {len(scene.bodies):,} bodies for overlaps", 0, 0)
    _check_start(scene, from_file)
    return scene


def _check_hertz_moduli(bodies: Bodies, materials: dict) -> None:
    """Without [contact] youngs_modulus, every body's material must give one (the first body
    in order without one is named)."""
    lacking = {None} | {name for name, m in materials.items() if m.youngs_modulus is None}
    if lacking.isdisjoint(bodies.material):
        return
    i = next(i for i, m in enumerate(bodies.material) if m in lacking)
    if bodies.material[i] is None:
        raise SceneError(f"contact.youngs_modulus: missing for model = 'hertz' (body.{bodies.names[i]} has no "
                         "material giving one)")
    raise SceneError(f"material.{bodies.material[i]}.youngs_modulus: missing for model = 'hertz'")


def _parse_domain(table: Any, dim: int) -> Domain | None:
    if table is None:
        return None
    _check_keys(table, SCENE_KEYS["domain"], "domain")
    periodic = table.get("periodic", [])
    if not isinstance(periodic, list) or not all(a in ("x", "y", "z")[:dim] for a in periodic):
        raise SceneError(f"domain.periodic: expected a list of axes among {', '.join(('x', 'y', 'z')[:dim])}, "
                         f"got {_shown(periodic)}")
    if len(set(periodic)) != len(periodic):
        raise SceneError(f"domain.periodic: an axis named twice in {_shown(periodic)}")
    for key in ("lower", "upper"):
        if key not in table:
            raise SceneError(f"domain.{key}: missing" + (" (a periodic axis wraps from lower to upper)"
                                                         if periodic else ""))
    lower = _vector(table["lower"], "domain.lower", dim)
    upper = _vector(table["upper"], "domain.upper", dim)
    if not all(u > lo for lo, u in zip(lower, upper)):
        raise SceneError(f"domain.upper: must exceed lower along every axis, got lower {list(lower)}, "
                         f"upper {list(upper)}")
    return Domain(lower, upper, tuple(a for a in "xyz" if a in periodic))


def _more_bodies(raw: dict, dim: int, materials: dict, domain: Domain | None, bodies: Bodies,
                 walls: tuple[Wall, ...], progress: Progress) -> tuple[Bodies, range]:
    """The [[body]] tables' bodies, then a [bodies] file's, then each [[fill]]'s (docs/design.md
    section 10); and where the file's are."""
    from collide.bodies_file import read_table
    from collide.fill import fill_bodies
    from collide.scene_bodies import bodies_from_fill, bodies_from_table

    table = raw.get("bodies")
    if table is not None:
        _check_keys(table, SCENE_KEYS["bodies"], "bodies")
        path = table.get("file")
        if not isinstance(path, str) or not path:
            raise SceneError(f"bodies.file: expected a file name, got {_shown(path)}")
        progress(f"reading {Path(path).name}", 0, 0)
        bodies = bodies + bodies_from_table(read_table(Path(path), dim), dim, materials, f"bodies.file ({path})")
    from_file = range(len(raw.get("body", [])), len(bodies))
    fills = raw.get("fill", [])
    if not isinstance(fills, list):
        raise SceneError("fill: expected [[fill]] tables")
    for index, fill in enumerate(fills):
        placed = (bodies.position, bodies.radius)
        made = fill_bodies(fill, index, dim, materials, domain, placed, walls, progress)
        bodies = bodies + bodies_from_fill(made, dim)
    if not bodies:
        raise SceneError("body: a scene needs at least one body ([[body]], [[fill]] or [bodies] file)")
    if len(bodies) > len(raw.get("body", [])):
        check_names(bodies.names)
    return bodies, from_file


def _check_sticky(scene: Scene) -> None:
    """Restitution 0 (perfectly inelastic) is the linear law's critically damped contact: the
    bodies end moving together while their overlap only decays, so the contact never ends by
    itself and the run needs a duration (or rest). The Hertz dashpot is matched to e > 0 only."""
    rest = [scene.contact.restitution] + [m.restitution for m in scene.materials] + \
        [q.restitution for q in scene.pairs]
    if not any(e == 0.0 for e in rest):
        return
    if scene.contact.model != "linear":
        raise SceneError("restitution = 0 (perfectly inelastic) is answered with the linear spring only: "
                         "use model = 'linear' or a restitution above 0")
    if scene.duration is None and scene.rest is None:
        raise SceneError("restitution = 0 (perfectly inelastic): the bodies stay in contact (critically damped, "
                         "the overlap only decays), so the run would not end by itself; give it a duration")


def _check_start(scene: Scene, from_file: range) -> None:
    """No overlaps at the start (docs/design.md section 3; a saved state's contacts in a DEM
    scene excepted) and every body inside the domain."""
    bodies = as_bodies(scene.bodies, scene.dim)
    n, pos, radius = len(bodies), bodies.position, bodies.radius
    in_contact = None
    if scene.integrator == "dem" and len(from_file):
        in_contact = np.zeros(n, dtype=bool)
        in_contact[from_file.start:from_file.stop] = True
    check_start_overlap(bodies.names, pos, radius, scene.walls, in_contact)
    if scene.domain is not None and scene.domain.periodic:
        check_image_overlap(scene, pos, radius, in_contact)
    if scene.domain is not None:
        outside = ((pos < np.array(scene.domain.lower)) | (pos > np.array(scene.domain.upper))).any(axis=1)
        if outside.any():
            body = scene.bodies[int(np.flatnonzero(outside)[0])]
            raise SceneError(f"body.{body.name}.position: outside the domain at the start "
                             f"({list(body.position)} not within {list(scene.domain.lower)} .. "
                             f"{list(scene.domain.upper)})")


def dem_reason(scene: Scene) -> str:
    """Which part of a scene's contact law needs the DEM kernel, for messages."""
    c = scene.contact
    if c.model != "linear":
        return f"model = '{c.model}'"
    if c.tangential != "coulomb":
        return f"tangential = '{c.tangential}'"
    if scene.needs_dem and not scene.has_rolling:
        return "restitution below 1"
    return "rolling_friction"


# A damped scene of more bodies than this under gravity among walls settles into lasting contacts
# (a pile): DEM's, whose cost does not grow with the contacts' events.
ISLAND_PILE = 50
# Bodies at most for the islands' tangential springs, as collide.measure.MEASURED_MAX_BODIES: each
# such run is confirmed by one at a tenth of --tol, and beyond this many final states decorrelate.
SPRING_BODIES = 64


def island_blocker(scene: Scene) -> str | None:
    """Why the event engine's islands cannot run a scene whose law goes beyond the report's (None:
    they can: the linear spring or Hertz, with the restitution's dashpot and Coulomb friction)."""
    c = scene.contact
    if scene.has_rolling:
        return ("the islands do not take rolling resistance (a sphere alone among walls, or two spheres and no "
                "walls, take it at full order)")
    if c.tangential != "coulomb" and scene.dim == 3:
        return ("a tangential spring between spheres inside an island (three or more, or two with walls) in 3D is "
                "DEM's so far: in 2D the islands take it, and in 3D two spheres and no walls")
    if c.tangential != "coulomb" and len(scene.bodies) > SPRING_BODIES:
        return (f"{len(scene.bodies)} spheres with a tangential spring: the islands take at most {SPRING_BODIES} "
                "(each run confirmed by one at a tenth of --tol, and beyond that many final states decorrelate)")
    if len(scene.bodies) > ISLAND_PILE and scene.gravity is not None and scene.walls:
        what = "damped" if c.model == "linear" else "Hertz"
        return (f"{len(scene.bodies)} {what} spheres under gravity among walls settle into lasting contacts "
                "(a pile), which DEM steps at a cost that does not grow with their events")
    return None


def alone_blocker(scene: Scene) -> str | None:
    """Why the event engine cannot run a scene whose law goes beyond the report's (None: it can,
    as a sphere alone among walls or two spheres and no walls)."""
    c = scene.contact
    if scene.has_rolling and (len(scene.bodies) > 2 or len(scene.bodies) == 2 and scene.walls):
        return ("rolling resistance among more than two spheres, or between two with walls, is DEM's so far: the "
                "event engine takes it for a sphere alone among walls and for two spheres and no walls")
    if scene.has_rolling and scene.has_friction and c.tangential != "spring":
        return ("rolling resistance with Coulomb friction's dead band is DEM's so far: with tangential = 'spring' "
                "(Coulomb's cap on a history spring) the event engine takes a sphere alone among walls, or two "
                "spheres and no walls, at full order")
    if len(scene.bodies) == 2 and scene.walls:
        return ("two spheres with walls: the event engine takes a sphere alone among walls, or two spheres and no "
                "walls, whole; more run in its islands where they can")
    if len(scene.bodies) > 2:
        return (f"{len(scene.bodies)} spheres: the event engine takes a sphere alone among walls, or two spheres "
                "and no walls, whole; more run in its islands where they can")
    if scene.has_friction and len(scene.bodies) == 2 and c.tangential != "spring":
        return "friction between two spheres under these laws is DEM's so far"
    if scene.has_friction and c.tangential != "spring":
        return "Coulomb friction with a dead band during a Hertz or damped contact is DEM's so far"
    if scene.domain is not None and scene.domain.periodic:
        return "a periodic box is DEM's for these laws"
    if scene.rest is not None:
        return "rest (an end when the motion dies down) is DEM's"
    return None


def _choice(table: dict, key: str, where: str, options: tuple[str, ...]) -> str:
    value = table.get(key, options[0])
    if value not in options:
        raise SceneError(f"{where}.{key}: unknown {_shown(value)} (choose from {', '.join(options)})")
    return value


def _restitution(value: Any, key: str) -> float:
    # 0 is perfectly inelastic ("sticky"): a critically damped dashpot (collide.dem.damping_ratio);
    # what such a scene needs is checked with the rest of the scene (`_check_sticky`).
    e = _number(value, key, nonneg=True)
    if e > 1.0:
        raise SceneError(f"{key}: a restitution is at most 1 (1 = no damping), got {_shown(value)}")
    return e


def _poisson(value: Any, key: str) -> float:
    nu = _number(value, key, nonneg=True)
    if nu >= 0.5:
        raise SceneError(f"{key}: a Poisson ratio is below 0.5, got {_shown(value)}")
    return nu


def _parse_contact(table: Any) -> Contact:
    _check_keys(table, _CONTACT_KEYS, "contact")
    lever = table.get("lever", "contact")
    if lever not in ("contact", "seed"):
        raise SceneError(f"contact.lever: must be 'contact' or 'seed', got {_shown(lever)}")
    young = table.get("youngs_modulus")
    ratio = table.get("tangential_stiffness_ratio")
    return Contact(
        model=_choice(table, "model", "contact", ("linear", "hertz")),
        k=_number(table.get("k", 1500.0), "contact.k", positive=True),
        mu=_number(table.get("mu", 0.0), "contact.mu", nonneg=True),
        eps=_number(table.get("eps", 1e-6), "contact.eps", nonneg=True),
        lever=lever,
        youngs_modulus=None if young is None else _number(young, "contact.youngs_modulus", positive=True),
        poisson_ratio=_poisson(table.get("poisson_ratio", 0.3), "contact.poisson_ratio"),
        restitution=_restitution(table.get("restitution", 1.0), "contact.restitution"),
        tangential=_choice(table, "tangential", "contact", ("coulomb", "spring")),
        tangential_stiffness_ratio=None if ratio is None else _number(ratio, "contact.tangential_stiffness_ratio",
                                                                      positive=True),
        rolling_friction=_number(table.get("rolling_friction", 0.0), "contact.rolling_friction", nonneg=True),
    )


def _optional(table: dict, key: str, where: str, read: Any) -> Any:
    return None if table.get(key) is None else read(table[key], f"{where}.{key}")


def _parse_materials(tables: Any) -> tuple[Material, ...]:
    if not isinstance(tables, list):
        raise SceneError("material: expected [[material]] tables")
    out = []
    for index, table in enumerate(tables):
        _check_keys(table, _MATERIAL_KEYS, f"material[{index}]")
        name = table.get("name")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", name):
            raise SceneError(f"material[{index}].name: expected a name of letters, digits, _ or -, got {_shown(name)}")
        where = f"material.{name}"
        if any(m.name == name for m in out):
            raise SceneError(f"{where}: the name is used twice")

        def positive(v: Any, k: str) -> float:
            return _number(v, k, positive=True)

        def nonneg(v: Any, k: str) -> float:
            return _number(v, k, nonneg=True)

        out.append(Material(name, _optional(table, "density", where, positive),
                            _optional(table, "youngs_modulus", where, positive),
                            _optional(table, "poisson_ratio", where, _poisson),
                            _optional(table, "mu", where, nonneg),
                            _optional(table, "restitution", where, _restitution),
                            _optional(table, "rolling_friction", where, nonneg)))
    return tuple(out)


def _parse_pairs(tables: Any, materials: dict[str, Material]) -> tuple[PairLaw, ...]:
    if not isinstance(tables, list):
        raise SceneError("pair: expected [[pair]] tables")
    out = []
    for index, table in enumerate(tables):
        where = f"pair[{index}]"
        _check_keys(table, _PAIR_KEYS, where)
        names = table.get("materials")
        if not isinstance(names, list) or len(names) != 2 or not all(isinstance(n, str) for n in names):
            raise SceneError(f"{where}.materials: expected two material names, got {_shown(names)}")
        for n in names:
            if n not in materials:
                raise SceneError(f"{where}.materials: unknown material {_shown(n)}")

        def nonneg(v: Any, k: str) -> float:
            return _number(v, k, nonneg=True)

        out.append(PairLaw((names[0], names[1]), _optional(table, "mu", where, nonneg),
                           _optional(table, "restitution", where, _restitution),
                           _optional(table, "rolling_friction", where, nonneg)))
    return tuple(out)



def generic_turn() -> Any:
    """A rotation (3 x 3) with no axis special: 0.7 rad about (1, 2, 0.5)."""
    import numpy as np

    axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(0.7) * cross + (1 - np.cos(0.7)) * cross @ cross


def turned_source(raw: dict, turn: Any = None) -> dict:
    """A scene's source (1D, 2D or 3D) turned as a whole about the origin by the rotation `turn`
    (3 x 3; default `generic_turn()`), as a 3D scene: bodies' positions, velocities and spins (a
    2D spin is about z), walls' points and normals, gravity. The same physics in another
    orientation: a check that no axis is preferred."""
    import numpy as np

    turn = generic_turn() if turn is None else np.asarray(turn, dtype=float)

    def turned(vector: Any) -> list[float]:
        return (turn @ np.pad(np.asarray(vector, dtype=float), (0, 3 - len(vector)))).tolist()

    def spin(value: Any) -> list[float]:
        return turned([0.0, 0.0, float(value)] if np.ndim(value) == 0 else value)

    out = dict(raw, dim=3)
    out["body"] = [dict(b, position=turned(b["position"]), velocity=turned(b["velocity"]),
                        **({"spin": spin(b["spin"])} if "spin" in b else {})) for b in raw.get("body", [])]
    if "wall" in raw:
        out["wall"] = [dict(w, point=turned(w["point"]), normal=turned(w["normal"])) for w in raw["wall"]]
    if "gravity" in raw:
        out["gravity"] = turned(raw["gravity"])
    return out


def with_settings(scene: Scene, **changes: Any) -> Scene:
    """A copy of the scene with top-level settings changed (keeps `source` in step)."""
    source = dict(scene.source)
    for key, value in changes.items():
        if value is not None:
            source[key] = value
    return replace(scene, source=source, **{k: v for k, v in changes.items() if v is not None})
