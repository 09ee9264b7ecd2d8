"""Body colours shared by the Rerun recordings and the viewer, so a body keeps its colour
from one to the other.

The first ten are a hand-picked categorical palette tuned to read on white; from the eleventh
on, hues step by the golden angle around the hue circle (each new hue lands in the widest gap
left by the previous ones) at alternating lightness and saturation, so no two of the first few
thousand bodies share a colour and neighbours in index never look alike.
"""

from __future__ import annotations

import colorsys

import numpy as np

PALETTE = [(66, 133, 244), (244, 132, 36), (52, 168, 83), (171, 71, 188), (219, 68, 55),
           (0, 172, 193), (124, 179, 66), (233, 30, 99), (121, 85, 72), (96, 125, 139)]
_GOLDEN = 0.381966011250105  # 1 - 1/phi: successive hues as far apart as possible


def body_colour(i: int) -> tuple[int, int, int]:
    """The (r, g, b) colour of body i (0-based): distinct for every body of a scene."""
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


# Energy series, as the viewer's plots draw them (viewer/plots.py), so a line keeps its colour
# from one to the other; on Rerun's dark background the total is light instead of near-black.
ENERGY_COLOURS = {"kinetic": (66, 133, 244), "rotational": (171, 71, 188), "spring": (244, 132, 42),
                  "gravitational": (141, 110, 99), "total": (232, 234, 237), "dissipated": (154, 160, 166),
                  "total_plus_dissipated": (52, 168, 83), "dissipated_damping": (219, 68, 55),
                  "dissipated_friction": (0, 172, 193), "dissipated_rolling": (233, 30, 99),
                  "tangential_spring": (251, 192, 45)}
