"""Bodies as a table file (`[bodies] file = ...`, `collide run --save-state`): one row per body,
columns name, radius, mass and/or material, inertia, position_x.., velocity_x.., spin (2D) or
spin_x, spin_y, spin_z (3D), as `.csv` or `.npz` (docs/design.md section 10).

A saved state read back gives the same bodies to the last bit: numbers are written with `repr`
(shortest text that reads back exactly) and every column a body has is written.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from collide.body_columns import as_bodies
from collide.scene_values import MAX_MAGNITUDE, MIN_POSITIVE, NAME_PATTERN, SceneError, _shown

AXES = ("x", "y", "z")
SPIN_COLUMNS = {1: (), 2: ("spin",), 3: ("spin_x", "spin_y", "spin_z")}


def columns(dim: int) -> dict[str, bool]:
    """Every column a table of this dimension may have, and whether it is required."""
    out = {"name": True, "radius": True, "mass": False, "material": False, "inertia": False}
    out.update({f"position_{a}": True for a in AXES[:dim]})
    out.update({f"velocity_{a}": False for a in AXES[:dim]})
    out.update({c: False for c in SPIN_COLUMNS[dim]})
    return out


@dataclass
class Table:
    """A body table's columns; None where the file leaves a column out."""

    name: list[str]
    radius: np.ndarray
    mass: np.ndarray | None  # NaN where a row leaves it to its material
    material: list[str | None]
    inertia: np.ndarray | None
    position: np.ndarray
    velocity: np.ndarray
    spin: np.ndarray


def read_table(path: Path, dim: int, where: str = "bodies.file") -> Table:
    """Read and check a body table (values are checked here; materials by the caller)."""
    if path.suffix not in (".csv", ".npz"):
        raise SceneError(f"{where}: '{path}' is not a .csv or .npz file")
    if not path.is_file():
        raise SceneError(f"{where}: '{path}' does not exist")
    raw = _read_npz(path, where) if path.suffix == ".npz" else _read_csv(path, where)
    allowed = columns(dim)
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise SceneError(f"{where}: unknown column {_shown(unknown[0])} in {path.name} for a {dim}D scene "
                         f"(columns: {', '.join(allowed)})")
    missing = [c for c, required in allowed.items() if required and c not in raw]
    if missing:
        raise SceneError(f"{where}: column {_shown(missing[0])} missing in {path.name}")
    n = len(raw["name"])
    if n == 0:
        raise SceneError(f"{where}: {path.name} has no rows")
    names = [str(x) for x in raw["name"]]
    bad = next((i for i, x in enumerate(names) if not NAME_PATTERN.fullmatch(x)), None)
    if bad is not None:
        raise SceneError(f"{where}: {path.name} row {bad + 1}, name: expected letters, digits, _ or -, "
                         f"got {_shown(names[bad])}")

    def number(column: str, positive: bool = False, default: float | None = None) -> np.ndarray:
        if column not in raw:
            return np.full(n, default)
        return _numbers(raw[column], f"{where}: {path.name}", column, positive)

    # One string a material name, not one a body (a body table's bodies share a few materials).
    shared: dict[str, str] = {}
    material = [shared.setdefault(m, m) or None for m in map(str, raw["material"])] if "material" in raw \
        else [None] * n
    vel = [number(f"velocity_{a}", default=0.0) for a in AXES[:dim]]
    spin = [number(c, default=0.0) for c in SPIN_COLUMNS[dim]]
    return Table(names, number("radius", True),
                 number("mass", True, np.nan) if "mass" in raw else None, material,
                 number("inertia", True) if "inertia" in raw else None,
                 np.stack([number(f"position_{a}") for a in AXES[:dim]], axis=1),
                 np.stack(vel, axis=1), np.stack(spin, axis=1) if spin else np.zeros((n, 0)))


def _numbers(values: object, where: str, column: str, positive: bool) -> np.ndarray:
    """A numeric column: finite, within MAX_MAGNITUDE, positive where asked; empty cells (NaN
    from a CSV's empty text) only in `mass`, whose rows then take their material's density."""
    a = np.asarray(values)
    if a.dtype.kind in "US":
        out = np.empty(len(a))
        for i, text in enumerate(a.tolist()):
            try:
                out[i] = float(text) if text.strip() or column != "mass" else np.nan
            except ValueError:
                raise SceneError(f"{where} row {i + 1}, {column}: expected a number, got {_shown(text)}") from None
        a = out
    elif a.dtype.kind not in "fiu":
        raise SceneError(f"{where}, {column}: expected numbers, got {a.dtype}")
    a = a.astype(float)
    blank = np.isnan(a) if column == "mass" else np.zeros(len(a), dtype=bool)
    ok = blank | (np.isfinite(a) & (np.abs(a) <= MAX_MAGNITUDE))
    if positive:
        ok &= blank | (a >= MIN_POSITIVE)
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        need = "a positive number within 1e-30..1e30" if positive else "a finite number within 1e30 in magnitude"
        raise SceneError(f"{where} row {i + 1}, {column}: expected {need}, got {a[i]!r}")
    return a


def _read_csv(path: Path, where: str) -> dict[str, list[str]]:
    try:
        with path.open(newline="") as handle:
            rows = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SceneError(f"{where}: cannot read '{path}': {exc}") from None
    if not rows:
        raise SceneError(f"{where}: {path.name} is empty (it needs a header row)")
    header = [h.strip() for h in rows[0]]
    if len(set(header)) != len(header):
        raise SceneError(f"{where}: {path.name} names a column twice")
    body = rows[1:]
    bad = next((i for i, row in enumerate(body) if len(row) != len(header)), None)
    if bad is not None:
        raise SceneError(f"{where}: {path.name} row {bad + 1} has {len(body[bad])} cells, the header "
                         f"{len(header)}")
    cols = list(zip(*body)) if body else [()] * len(header)
    return {h: np.array(c, dtype=str) if h not in ("name", "material") else [x.strip() for x in c]
            for h, c in zip(header, cols)}


def _read_npz(path: Path, where: str) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            raw = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError) as exc:
        raise SceneError(f"{where}: cannot read '{path}': {exc}") from None
    lengths = {k: v.shape for k, v in raw.items()}
    if any(len(s) != 1 for s in lengths.values()) or len({s[0] for s in lengths.values()}) > 1:
        raise SceneError(f"{where}: {path.name}: every array must be one column of the same length "
                         f"({', '.join(f'{k} {s}' for k, s in lengths.items())})")
    for key in ("name", "material"):
        if key in raw and raw[key].dtype.kind != "U":
            raise SceneError(f"{where}: {path.name}, {key}: expected strings, got {raw[key].dtype}")
    return raw


def state_text(names: list[str], radius: np.ndarray, mass: np.ndarray, inertia: np.ndarray,
               material: list[str | None], pos: np.ndarray, vel: np.ndarray, spin: np.ndarray) -> str:
    """A body table as CSV text: every number written so that it reads back exactly."""
    dim = pos.shape[1]
    header = ["name", "radius", "mass", "inertia"] + (["material"] if any(material) else []) + \
        [f"position_{a}" for a in AXES[:dim]] + [f"velocity_{a}" for a in AXES[:dim]] + list(SPIN_COLUMNS[dim])
    numbers = np.column_stack([radius, mass, inertia]).tolist()
    rest = np.column_stack([pos, vel, spin.reshape(len(names), -1)]).tolist()
    lines = [",".join(header)]
    has_material = any(material)
    for name, front, mat, back in zip(names, numbers, material, rest):
        cells = [name, *map(repr, front)] + ([mat or ""] if has_material else []) + list(map(repr, back))
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


def state_arrays(names: list[str], radius: np.ndarray, mass: np.ndarray, inertia: np.ndarray,
                 material: list[str | None], pos: np.ndarray, vel: np.ndarray, spin: np.ndarray) -> dict:
    """The same table as named arrays for a `.npz` file."""
    dim = pos.shape[1]
    out = {"name": np.array(names, dtype=str), "radius": radius, "mass": mass, "inertia": inertia}
    if any(material):
        out["material"] = np.array([m or "" for m in material], dtype=str)
    for k, a in enumerate(AXES[:dim]):
        out[f"position_{a}"], out[f"velocity_{a}"] = pos[:, k], vel[:, k]
    for k, c in enumerate(SPIN_COLUMNS[dim]):
        out[c] = spin.reshape(len(names), -1)[:, k]
    return out


def write_state(path: Path, scene: object, pos: np.ndarray, vel: np.ndarray, spin: np.ndarray) -> Path:
    """Write a scene's bodies at a state (positions, velocities, spins: (n, dim), (n, dim),
    (n, spin components)) as a body table, `.csv` or `.npz`, whole or not at all."""
    from collide.output import write_atomic, write_text_atomic

    bodies = as_bodies(scene.bodies, scene.dim)  # type: ignore[attr-defined]
    n = len(bodies)
    columns_ = (bodies.names, bodies.radius, bodies.mass, bodies.inertia, bodies.material,
                np.asarray(pos, dtype=float).reshape(n, -1), np.asarray(vel, dtype=float).reshape(n, -1),
                np.asarray(spin, dtype=float).reshape(n, -1))
    if path.suffix == ".npz":
        arrays = state_arrays(*columns_)

        def produce(tmp: Path) -> None:
            with tmp.open("wb") as handle:
                np.savez(handle, **arrays)

        return write_atomic(path, produce)
    return write_text_atomic(path, state_text(*columns_))
