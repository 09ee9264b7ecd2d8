"""Scene files: load, validate and override TOML scenes (DESIGN section 3).

A scene is plain data. `load_scene` turns a built-in name or a `.toml` path into a `Scene`;
`apply_overrides` edits the raw TOML table with `key=value` strings before validation, so an
error always names the key the user typed.
"""

from __future__ import annotations

import copy
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

INTEGRATORS = ("seed", "verlet", "yoshida4", "kahan6")
DEFAULT_INTEGRATOR = "kahan6"
DEFAULT_TOL = 1e-6
# Every number of a scene is at most this large in magnitude, and every positive quantity (mass,
# radius, k, dt, ...) at least its inverse: the physics squares and multiplies them (energies,
# angular momenta, k m, the residuals' norms), and products of a few such numbers must stay far
# inside float64's 1.8e308.
MAX_MAGNITUDE = 1e30
MIN_POSITIVE = 1.0 / MAX_MAGNITUDE
MAX_DEPTH = 8  # tables and arrays nested deeper than this are no scene (a scene needs 4)


class SceneError(ValueError):
    """A scene (file, built-in or override) is invalid. The message names the key."""


@dataclass(frozen=True)
class Body:
    """One sphere. Vectors have length `dim`; `spin` has length 0 (1D), 1 (2D, about z) or 3."""

    name: str
    mass: float
    radius: float
    inertia: float
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    spin: tuple[float, ...]


@dataclass(frozen=True)
class Wall:
    """A static plane: a point on it and its outward unit normal."""

    point: tuple[float, ...]
    normal: tuple[float, ...]


@dataclass(frozen=True)
class Contact:
    """Contact law for every pair and wall: linear springs in series plus Coulomb friction.

    `lever = "seed"` reproduces the report: slip measured with the undeformed radius while the
    torque acts at the deformed contact point (DESIGN section 2).
    """

    model: str = "linear"
    k: float = 1500.0
    mu: float = 0.0
    eps: float = 1e-6
    lever: str = "contact"


@dataclass(frozen=True)
class Scene:
    """A validated scene. `dt` is a float or the string "auto"."""

    name: str
    dim: int
    dt: float | str
    integrator: str
    contact: Contact
    bodies: tuple[Body, ...]
    walls: tuple[Wall, ...] = ()
    gravity: tuple[float, ...] | None = None
    duration: float | None = None
    tail: float | None = None
    tol: float = DEFAULT_TOL
    description: str = ""
    source: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def spin_dim(self) -> int:
        """Components of angular velocity: 0 in 1D, 1 in 2D (about z), 3 in 3D."""
        return {1: 0, 2: 1, 3: 3}[self.dim]

    @property
    def has_friction(self) -> bool:
        return self.dim > 1 and self.contact.mu > 0.0

    @property
    def has_spin(self) -> bool:
        """Angular state is carried only when something can spin."""
        if self.dim == 1:
            return False
        return self.has_friction or any(any(c != 0.0 for c in b.spin) for b in self.bodies)

    @property
    def stays_in_plane(self) -> bool:
        """Whether the motion stays in a plane z = const: 1D, 2D, or 3D with every centre at the
        same z, no z velocity, spins about z only, and gravity and wall normals in the plane."""
        if self.dim < 3:
            return True
        z = {b.position[2] for b in self.bodies}
        return (len(z) == 1 and all(b.velocity[2] == 0.0 and b.spin[0] == 0.0 and b.spin[1] == 0.0
                                    for b in self.bodies)
                and (self.gravity is None or self.gravity[2] == 0.0)
                and all(w.normal[2] == 0.0 for w in self.walls))

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


def builtin_names() -> list[str]:
    """Names of the built-in scenes: the report's demos first, then its textbook checks, then
    the scenes beyond the report (what a new user meets first in a list)."""
    files = resources.files(_BUILTIN_PACKAGE).iterdir()
    names = [p.name[:-5] for p in files if p.name.endswith(".toml")]
    return sorted(names, key=lambda n: (0 if n.startswith("demo") else 1 if n.startswith("textbook") else 2, n))


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
        raw = tomllib.loads(text)
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
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else ()
        stack.extend((child, depth + 1) for child in children if isinstance(child, (dict, list)))


def load_scene(source: str | Path, overrides: list[str] | None = None) -> Scene:
    """Load a built-in name or a `.toml` path, apply `key=value` overrides, validate."""
    raw, default_name = read_raw(source)
    raw = apply_overrides(raw, overrides or [])
    return parse_scene(raw, default_name)


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
    raw = copy.deepcopy(raw)
    for item in overrides:
        key, text = split_override(item)
        set_path(raw, key, parse_value(text))
    return raw


def set_path(raw: dict, key: str, value: Any) -> None:
    """Set a dotted key in the raw scene table (bodies addressed by name, vectors by x/y/z)."""
    parts = key.split(".")
    if parts[0] == "body":
        if len(parts) < 3:
            raise SceneError(f"override key '{key}': use body.NAME.FIELD")
        bodies = raw.get("body", [])
        matches = [b for b in bodies if b.get("name") == parts[1]]
        if not matches:
            names = ", ".join(str(b.get("name")) for b in bodies)
            raise SceneError(f"override key '{key}': no body named '{parts[1]}' (bodies: {names})")
        table, rest = matches[0], parts[2:]
    elif parts[0] == "wall":
        if len(parts) < 3 or not parts[1].isdigit():
            raise SceneError(f"override key '{key}': use wall.INDEX.FIELD (INDEX from 0)")
        walls = raw.get("wall", [])
        index = int(parts[1])
        if index >= len(walls):
            raise SceneError(f"override key '{key}': the scene has {len(walls)} wall(s)")
        table, rest = walls[index], parts[2:]
    else:
        table, rest = raw, parts
    if len(rest) == 2 and rest[1] in _COMPONENTS and isinstance(table.get(rest[0]), list):
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
        table = nxt
    table[rest[-1]] = value


def _set_component(vector: list, component: str, value: Any, key: str) -> None:
    index = _COMPONENTS[component]
    if index >= len(vector):
        raise SceneError(f"override key '{key}': the vector has {len(vector)} component(s)")
    vector[index] = value


# ---------------------------------------------------------------------------------------------
# Validation

_TOP_KEYS = {"name", "description", "dim", "dt", "integrator", "duration", "tail", "tol",
             "gravity", "contact", "body", "wall"}
_CONTACT_KEYS = {"model", "k", "mu", "eps", "lever"}
_BODY_KEYS = {"name", "mass", "radius", "inertia", "position", "velocity", "spin"}
_WALL_KEYS = {"point", "normal"}


def _shown(value: Any) -> str:
    """A value as an error message shows it (a 400-digit integer is not printed whole)."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:12]}...{text[-6:]} ({len(text)} characters)"


def _number(value: Any, key: str, *, positive: bool = False, nonneg: bool = False) -> float:
    """A finite float within MAX_MAGNITUDE (and at least MIN_POSITIVE if positive)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{key}: expected a number, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond float64
        number = math.inf
    if math.isnan(number):
        raise SceneError(f"{key}: must be finite, got {_shown(value)}")
    if positive and number <= 0:
        raise SceneError(f"{key}: must be positive, got {_shown(value)}")
    if nonneg and number < 0:
        raise SceneError(f"{key}: must not be negative, got {_shown(value)}")
    if not abs(number) <= MAX_MAGNITUDE:
        what = "must be finite" if isinstance(value, float) and math.isinf(value) else \
            f"out of range (at most {MAX_MAGNITUDE:.0e} in magnitude, so that the physics can square and " \
            "multiply it in float64)"
        raise SceneError(f"{key}: {what}, got {_shown(value)}")
    if positive and number < MIN_POSITIVE:
        raise SceneError(f"{key}: too small (at least {MIN_POSITIVE:.0e}, so that the physics can divide by "
                         f"it in float64), got {_shown(value)}")
    return number


def _vector(value: Any, key: str, length: int) -> tuple[float, ...]:
    if length == 1 and not isinstance(value, list):
        return (_number(value, key),)
    if not isinstance(value, list):
        raise SceneError(f"{key}: expected a list of {length} numbers, got {_shown(value)}")
    if len(value) != length:
        raise SceneError(f"{key}: expected {length} component(s), got {len(value)}")
    return tuple(_number(v, f"{key}[{i}]") for i, v in enumerate(value))


def _check_keys(table: Any, allowed: set[str], where: str) -> None:
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(f"{where}: unknown key {_shown(unknown[0])} (allowed: {', '.join(sorted(allowed))})")


def parse_scene(raw: dict, default_name: str = "scene") -> Scene:
    """Validate a raw TOML table into a `Scene`; raise `SceneError` naming the bad key."""
    _check_keys(raw, _TOP_KEYS, "scene")
    _check_depth(raw, "scene")
    dim = raw.get("dim", 2)
    if isinstance(dim, bool) or not isinstance(dim, int) or dim not in (1, 2, 3):
        raise SceneError(f"dim: must be the whole number 1, 2 or 3, got {_shown(dim)}")
    name = raw.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SceneError(f"name: expected a non-empty string, got {_shown(name)}")

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

    contact_raw = raw.get("contact", {})
    _check_keys(contact_raw, _CONTACT_KEYS, "contact")
    model = contact_raw.get("model", "linear")
    if model != "linear":
        raise SceneError(f"contact.model: unknown {_shown(model)} (only 'linear')")
    lever = contact_raw.get("lever", "contact")
    if lever not in ("contact", "seed"):
        raise SceneError(f"contact.lever: must be 'contact' or 'seed', got {_shown(lever)}")
    contact = Contact(
        model=model,
        k=_number(contact_raw.get("k", 1500.0), "contact.k", positive=True),
        mu=_number(contact_raw.get("mu", 0.0), "contact.mu", nonneg=True),
        eps=_number(contact_raw.get("eps", 1e-6), "contact.eps", nonneg=True),
        lever=lever,
    )

    bodies_raw = raw.get("body")
    if not isinstance(bodies_raw, list) or not bodies_raw:
        raise SceneError("body: a scene needs at least one [[body]]")
    spin_len = {1: 0, 2: 1, 3: 3}[dim]
    bodies = []
    for index, b in enumerate(bodies_raw):
        where = f"body[{index}]"
        _check_keys(b, _BODY_KEYS, where)
        bname = b.get("name", f"ball{index + 1}")
        if not isinstance(bname, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", bname):
            raise SceneError(f"{where}.name: expected a name of letters, digits, _ or -, got {_shown(bname)}")
        where = f"body.{bname}"
        for required in ("mass", "radius", "position"):
            if required not in b:
                raise SceneError(f"{where}.{required}: missing")
        mass = _number(b["mass"], f"{where}.mass", positive=True)
        radius = _number(b["radius"], f"{where}.radius", positive=True)
        inertia_raw = b.get("inertia", "solid")
        if inertia_raw == "solid":
            inertia = 0.4 * mass * radius**2
        elif inertia_raw == "shell":
            inertia = 2.0 / 3.0 * mass * radius**2
        else:
            if isinstance(inertia_raw, str):
                raise SceneError(f"{where}.inertia: 'solid', 'shell' or a number, got {_shown(inertia_raw)}")
            inertia = _number(inertia_raw, f"{where}.inertia", positive=True)
        position = _vector(b["position"], f"{where}.position", dim)
        velocity = _vector(b.get("velocity", [0.0] * dim if dim > 1 else 0.0), f"{where}.velocity", dim)
        spin_raw = b.get("spin")
        if spin_len == 0:
            if spin_raw not in (None, 0, 0.0):
                raise SceneError(f"{where}.spin: 1D scenes have no rotation")
            spin: tuple[float, ...] = ()
        elif spin_raw is None:
            spin = (0.0,) * spin_len
        else:
            spin = _vector(spin_raw, f"{where}.spin", spin_len)
        bodies.append(Body(bname, mass, radius, inertia, position, velocity, spin))
    names = [b.name for b in bodies]
    duplicate = next((n for n in names if names.count(n) > 1), None)
    if duplicate:
        raise SceneError(f"body.{duplicate}: the name is used twice")

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

    scene = Scene(name=name, dim=dim, dt=dt, integrator=integrator, contact=contact,
                  bodies=tuple(bodies), walls=tuple(walls), gravity=gravity, duration=duration,
                  tail=tail, tol=tol, description=str(raw.get("description", "")), source=raw)
    _check_start_overlap(scene)
    return scene


def _check_start_overlap(scene: Scene) -> None:
    """Spheres may touch at the start, never overlap (DESIGN section 3)."""
    bodies = scene.bodies
    for i, a in enumerate(bodies):
        for b in bodies[i + 1:]:
            gap = math.dist(a.position, b.position) - a.radius - b.radius
            if gap < -1e-12 * (a.radius + b.radius):
                raise SceneError(f"body.{a.name}.position: overlaps body.{b.name} at the start "
                                 f"by {-gap:.3g} m")
        for index, wall in enumerate(scene.walls):
            height = sum((p - q) * n for p, q, n in zip(a.position, wall.point, wall.normal))
            if height < a.radius * (1 - 1e-12):
                raise SceneError(f"body.{a.name}.position: overlaps wall[{index}] at the start "
                                 f"(distance {height:.3g} m < radius {a.radius:.3g} m)")


def with_settings(scene: Scene, **changes: Any) -> Scene:
    """A copy of the scene with top-level settings changed (keeps `source` in step)."""
    source = dict(scene.source)
    for key, value in changes.items():
        if value is not None:
            source[key] = value
    return replace(scene, source=source, **{k: v for k, v in changes.items() if v is not None})
