"""Long-form CSV: one row per body per frame, and a contacts table, one row per pressed contact
per frame. Only the columns the scene's dimension has (x, y in 2D; spin wz in 2D, none in 1D).

`collide run --csv` keeps its wide table (a column per body and quantity); this is the layout
for pandas, R or a spreadsheet's pivot.
"""

from __future__ import annotations

import io

import numpy as np

from collide.export.frames import Frames

_AXES = "xyz"


def _spin_axes(spin_dim: int) -> list[int]:
    return {0: [], 1: [2], 3: [0, 1, 2]}[spin_dim]


def _write(header: list[str], label_columns: list[np.ndarray], numbers: np.ndarray, at: int) -> str:
    """CSV text: numeric columns (float64, shortest round-trip text) with string columns
    inserted at position `at`."""
    out = io.StringIO()
    out.write(",".join(header) + "\n")
    text = list(map(repr, numbers.T.ravel().tolist()))  # shortest text that reads back exactly
    rows = len(numbers)
    cols = [text[c * rows:(c + 1) * rows] for c in range(numbers.shape[1])]
    cols[at:at] = label_columns
    for row in zip(*cols):
        out.write(",".join(row) + "\n")
    return out.getvalue()


def bodies_csv(frames: Frames) -> str:
    """t, body, position, velocity and spin of every body at every frame."""
    d = frames.dim
    spin = _spin_axes(frames.spin_dim)
    header = ["t", "body", *_AXES[:d], *(f"v{a}" for a in _AXES[:d]), *(f"w{_AXES[a]}" for a in spin)]
    t_count, n = frames.s.shape[:2]
    rows = t_count * n
    numbers = np.concatenate((np.repeat(frames.times, n)[:, None], frames.s[:, :, :d].reshape(rows, d),
                              frames.v[:, :, :d].reshape(rows, d), frames.w[:, :, spin].reshape(rows, len(spin))),
                             axis=1)
    names = np.tile(np.asarray(frames.names, dtype=object), t_count).astype(str)
    return _write(header, [names], numbers, 1)


def contact_label(names: tuple[str, ...], j: int) -> str:
    return names[j] if j >= 0 else f"wall{-1 - j}"


def contacts_csv(frames: Frames) -> str:
    """t, i, j (body names; a wall as wall<k>), overlap, normal force magnitude and the friction
    force on body i by component (with friction) of every pressed contact at every frame."""
    d = frames.dim
    header = ["t", "i", "j", "overlap", "normal_force"]
    parts = [frames.times[frames.contact_frame][:, None], frames.overlap[:, None],
             np.linalg.norm(frames.normal_force, axis=1)[:, None]]
    if frames.friction is not None:
        header += [f"friction_{a}" for a in _AXES[:d]]
        parts.append(frames.friction[:, :d])
    numbers = np.concatenate(parts, axis=1)
    i = np.array([frames.names[k] for k in frames.pairs[:, 0]], dtype=str)
    j = np.array([contact_label(frames.names, int(k)) for k in frames.pairs[:, 1]], dtype=str)
    return _write(header, [i, j], numbers, 1)
