"""The values of a scene's tables: the error every refusal raises, one body, and the checks of
numbers, vectors and keys that name what is wrong (docs/design.md section 3). Shared by the
scene's parser and the modules that make bodies in bulk (fills, body tables)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

# Every number of a scene is at most this large in magnitude, and every positive quantity (mass,
# radius, k, dt, ...) at least its inverse: the physics squares and multiplies them (energies,
# angular momenta, k m, the residuals' norms), and products of a few such numbers must stay far
# inside float64's 1.8e308.
MAX_MAGNITUDE = 1e30
MIN_POSITIVE = 1.0 / MAX_MAGNITUDE

# A body's or material's name: what an override (body.NAME.FIELD) can address.
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*")

# Spheres whose overlap at the start is within this share of r_i + r_j (a radius on a wall) touch:
# positions written in decimal place touching spheres a few ulps apart either way.
TOUCHING = 1e-12


class SceneError(ValueError):
    """A scene (file, built-in or override) is invalid. The message names the key."""


@dataclass(frozen=True, slots=True)
class Body:
    """One sphere. Vectors have length `dim`; `spin` has length 0 (1D), 1 (2D, about z) or 3."""

    name: str
    mass: float
    radius: float
    inertia: float
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    spin: tuple[float, ...]
    material: str | None = None



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


def _check_keys(table: Any, allowed: frozenset[str], where: str) -> None:
    if not isinstance(table, dict):
        raise SceneError(f"{where}: expected a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(f"{where}: unknown key {_shown(unknown[0])} (allowed: {', '.join(sorted(allowed))})")

