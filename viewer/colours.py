"""Colours: colour maps for speed, energy and contact count; body colours come from the core
(`collide.colours`) so the viewer and the Rerun recordings agree body by body.

Pure numpy.
"""

from __future__ import annotations

import numpy as np

from collide.colours import PALETTE, body_colour, body_colours

__all__ = ["PALETTE", "body_colour", "body_colours", "colour_map", "darker", "hex_colour", "legend_html",
           "lighter"]

# viridis at nine stops (matplotlib's), interpolated linearly: perceptually ordered, readable
# by most colour-blind viewers, and dark-to-bright so it survives greyscale printing.
_VIRIDIS = np.array([(68, 1, 84), (71, 44, 122), (59, 81, 139), (44, 113, 142), (33, 144, 141),
                     (39, 173, 129), (92, 200, 99), (170, 220, 50), (253, 231, 37)], dtype=float)


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


def mixed(colours: np.ndarray, mix, f: float) -> np.ndarray:
    """Each colour (N, 3) through `mix` (lighter or darker) by f."""
    return np.array([mix(tuple(int(c) for c in rgb), f) for rgb in colours], np.uint8).reshape(-1, 3)


def as_linear(colours: np.ndarray) -> np.ndarray:
    """sRGB colours (..., 3) as the linear values a line's or an instance's own colours are read
    as (three.js converts a node's single colour from sRGB, not those): the same colour on screen."""
    c = np.asarray(colours, float) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.round(255.0 * lin).astype(np.uint8)


def faded(colour: tuple[int, int, int], ground: tuple[int, int, int], strength: np.ndarray) -> np.ndarray:
    """Instance colours (N, 3) that, at one opacity over `ground` (a node's single colour),
    show `colour` at `strength` (N,; 0 to 1) of that opacity: a fade kept in the colours. Mixed
    as the client blends, in linear values (instance colours are read as linear)."""
    floor = as_linear(np.array(ground)) / 255.0
    mix = floor + (np.array(colour) / 255.0 - floor) * np.clip(strength, 0.0, 1.0)[:, None]
    return np.round(255.0 * mix).astype(np.uint8)


def legend_html(title: str, lo: float, hi: float, unit: str, *, integer: bool = False) -> str:
    """A horizontal colour bar with its end values, for the GUI."""
    stops = ", ".join(hex_colour(c) for c in _VIRIDIS.astype(int))
    fmt = (lambda x: f"{x:.0f}") if integer else (lambda x: f"{x:.3g}")
    return (f"<div style='font-size:0.8em;margin:0 0.6em'><div>{title}</div>"
            f"<div style='height:0.7em;border-radius:2px;background:linear-gradient(to right, {stops})'></div>"
            f"<div style='display:flex;justify-content:space-between'><span>{fmt(lo)}</span>"
            f"<span>{fmt(hi)} {unit}</span></div></div>")
