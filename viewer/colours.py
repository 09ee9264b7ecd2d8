"""Colours: one distinct colour per body, colour maps for speed, energy and contact count.

Pure numpy. Body colours come from a hand-picked palette for the first ten (the usual
categorical ones, tuned to read on white), then from the golden angle around the hue circle at
alternating lightness, so no two of the first few hundred bodies share a colour.
"""

from __future__ import annotations

import colorsys

import numpy as np

PALETTE = [(66, 133, 244), (244, 132, 36), (52, 168, 83), (171, 71, 188), (219, 68, 55),
           (0, 172, 193), (124, 179, 66), (233, 30, 99), (121, 85, 72), (96, 125, 139)]
_GOLDEN = 0.381966011250105  # 1 - 1/phi: successive hues as far apart as possible

# viridis at nine stops (matplotlib's), interpolated linearly: perceptually ordered, readable
# by most colour-blind viewers, and dark-to-bright so it survives greyscale printing.
_VIRIDIS = np.array([(68, 1, 84), (71, 44, 122), (59, 81, 139), (44, 113, 142), (33, 144, 141),
                     (39, 173, 129), (92, 200, 99), (170, 220, 50), (253, 231, 37)], dtype=float)


def body_colour(i: int) -> tuple[int, int, int]:
    """The colour of body i (0-based): distinct for every body of a scene."""
    if i < len(PALETTE):
        return PALETTE[i]
    k = i - len(PALETTE)
    hue = (0.13 + k * _GOLDEN) % 1.0
    light = (0.45, 0.60, 0.35)[k % 3]
    sat = (0.75, 0.65, 0.85)[(k // 3) % 3]
    r, g, b = colorsys.hls_to_rgb(hue, light, sat)
    return int(round(255 * r)), int(round(255 * g)), int(round(255 * b))


def body_colours(n: int) -> np.ndarray:
    """(n, 3) uint8: `body_colour` for bodies 0..n-1."""
    return np.array([body_colour(i) for i in range(n)], dtype=np.uint8).reshape(n, 3)


def colour_map(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Values mapped through viridis on [lo, hi] (clipped): (..., 3) uint8."""
    x = np.asarray(values, dtype=float)
    span = hi - lo
    u = np.clip((x - lo) / span, 0.0, 1.0) if span > 0 else np.zeros_like(x)
    u = np.where(np.isfinite(u), u, 0.0)
    pos = u * (len(_VIRIDIS) - 1)
    k = np.minimum(pos.astype(int), len(_VIRIDIS) - 2)
    f = (pos - k)[..., None]
    rgb = _VIRIDIS[k] * (1 - f) + _VIRIDIS[k + 1] * f
    return np.round(rgb).astype(np.uint8)


def hex_colour(rgb: tuple[int, int, int] | np.ndarray) -> str:
    r, g, b = (int(c) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


def lighter(c: tuple[int, int, int], f: float) -> tuple[int, int, int]:
    """Mixed towards white by f (0: unchanged, 1: white)."""
    return tuple(int(x + (255 - x) * f) for x in c)  # type: ignore[return-value]


def darker(c: tuple[int, int, int], f: float = 0.45) -> tuple[int, int, int]:
    """Scaled towards black: f = 1 unchanged, 0 black."""
    return tuple(int(x * f) for x in c)  # type: ignore[return-value]


def legend_html(title: str, lo: float, hi: float, unit: str, *, integer: bool = False) -> str:
    """A horizontal colour bar with its end values, for the GUI."""
    stops = ", ".join(hex_colour(c) for c in _VIRIDIS.astype(int))
    fmt = (lambda x: f"{x:.0f}") if integer else (lambda x: f"{x:.3g}")
    return (f"<div style='font-size:0.8em;margin:0 0.6em'><div>{title}</div>"
            f"<div style='height:0.7em;border-radius:2px;background:linear-gradient(to right, {stops})'></div>"
            f"<div style='display:flex;justify-content:space-between'><span>{fmt(lo)}</span>"
            f"<span>{fmt(hi)} {unit}</span></div></div>")
