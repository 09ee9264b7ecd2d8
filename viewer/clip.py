"""Looking inside a pile: a clip plane that hides the spheres on one side, and a picked sphere
highlighted with its neighbours in contact (issue 54, item 5).

Pure numpy (no viser). `BodyLook` is what the 3D drawing asks, once a frame, whatever way it
draws the bodies (one node each or one instanced mesh): which bodies are hidden (`hidden`),
which contacts are still drawn (`links_shown`, `contact_shown`), and the colours with the
highlight laid over them (`colours`). The panel's controls set it (`viewer.inspect`).

As OVITO's slice modifier does, a sphere belongs to the side its centre is on; a contact is
drawn only when every sphere it touches is shown (a wall counts as shown).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

AXES = ("x", "y", "z")
KEEP = ("below", "above")  # which side of the plane stays: coordinate <= offset, or >= offset
PICKED_COLOUR = (230, 0, 180)  # magenta: in no colour map the spheres use (viridis, the palette)
NEIGHBOUR_COLOUR = (255, 140, 0)  # orange
FADE_TO = (215, 215, 220)  # the other spheres, while one is picked: towards a light grey
FADE = 0.75


@dataclass
class ClipPlane:
    """A plane across one axis at `offset` (m); the spheres whose centre lies on the other side
    than `keep` are hidden."""

    on: bool = False
    axis: int = 0
    offset: float = 0.0
    keep: str = "below"

    def hidden(self, positions: np.ndarray) -> np.ndarray:
        """Which bodies (N,) the plane hides, their centres at positions (N, 3)."""
        n = len(positions)
        if not self.on or n == 0:
            return np.zeros(n, bool)
        x = np.asarray(positions, float)[:, self.axis]
        return x > self.offset if self.keep == "below" else x < self.offset


def links_shown(i: np.ndarray, j: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """Which contacts (K,) between bodies i (K,) and j (K,; negative: a wall) touch no hidden
    body."""
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    if not hidden.any():
        return np.ones(len(i), bool)
    return ~hidden[i] & ~np.where(j >= 0, hidden[np.maximum(j, 0)], False)


def highlight(colours: np.ndarray, picked: int, neighbours: np.ndarray) -> np.ndarray:
    """`colours` (N, 3) uint8 with the picked body magenta, its neighbours orange and every other
    body faded towards grey (the picked one's surroundings read at a glance in a pile)."""
    out = np.asarray(colours, float) * (1 - FADE) + np.array(FADE_TO, float) * FADE
    out[np.asarray(neighbours, np.int64)] = NEIGHBOUR_COLOUR
    out[picked] = PICKED_COLOUR
    return np.round(out).astype(np.uint8)


def neighbours_of(i: np.ndarray, j: np.ndarray, k: int) -> np.ndarray:
    """The bodies (sorted, no walls) in contact with body k, from the contacts' bodies i, j."""
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    other = np.concatenate((j[i == k], i[j == k]))
    return np.unique(other[other >= 0])


class BodyLook:
    """The clip plane and the picked body, as the drawing applies them each frame."""

    def __init__(self) -> None:
        self.clip = ClipPlane()
        self.picked: int | None = None
        self.listener: Callable[[object], None] | None = None  # told of every frame drawn

    def frame_shown(self, frame: object) -> None:
        if self.listener is not None:
            self.listener(frame)

    def hidden(self, positions: np.ndarray) -> np.ndarray:
        """The bodies hidden now (N,): on the far side of the clip plane."""
        return self.clip.hidden(positions)

    def active(self) -> bool:
        return self.clip.on or self.picked is not None

    def colours(self, colours: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The colours to draw (N, 3): `colours` with the pick's highlight, if any; i, j are the
        frame's contacts' bodies."""
        k = self.picked
        if k is None or k >= len(colours):
            return colours
        return highlight(colours, k, neighbours_of(i, j, k))

    def contact_shown(self, hidden: np.ndarray, i: int, j: int | None) -> bool:
        """Whether one contact (j None: a wall) is drawn."""
        return not hidden[i] and (j is None or not hidden[j])
