"""Where a recording has frames (`frame_times`), the states there, and the geometry that turns
a run's vectors into Rerun's 3D ones."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import rerun as rr

from collide import diagnostics as dg
from collide.contact_index import Engaged
from collide.engine import layout
from collide.model import Model, State
from collide.results import Trajectory


def _pad3(x: np.ndarray) -> np.ndarray:
    """Vectors of length D (1, 2 or 3) as 3D points; 1D and 2D scenes live in the z = 0 plane."""
    if x.shape[-1] == 3:
        return x
    return np.concatenate((x, np.zeros((*x.shape[:-1], 3 - x.shape[-1]))), axis=-1)


def _quaternion_xyzw(q: np.ndarray) -> np.ndarray:
    """Orientation q (..., Q) as Rerun's xyzw quaternion: Q = 1 is an angle about z, Q = 4 wxyz."""
    if q.shape[-1] == 1:
        half = 0.5 * q[..., 0]
        zero = np.zeros_like(half)
        return np.stack((zero, zero, np.sin(half), np.cos(half)), axis=-1)
    return q[..., [1, 2, 3, 0]]


def _rotate(q: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """Rotate a 3-vector by orientations q (..., Q)."""
    if q.shape[-1] == 1:
        c, s = np.cos(q[..., 0]), np.sin(q[..., 0])
        return np.stack((c * vec[0] - s * vec[1], s * vec[0] + c * vec[1], np.full_like(c, vec[2])), -1)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, vec)
    return vec + w * t + np.cross(u, t)


def _frame_residuals(model: Model, initial: State, frames: State) -> dg.Residuals:
    """Residuals of every frame against the start, with the summary's formulas.

    Frames stand in for batch members: the formulas broadcast a batch-of-one model over them.
    """
    return dg.residuals(SimpleNamespace(model=model, initial=initial, final=frames))


def _one_run(sampled: State) -> State:
    """`diagnostics.sample`'s states (T, 1, N, D) as frames (T, N, D)."""
    return State(sampled.t, sampled.s[:, 0], sampled.v[:, 0], sampled.w[:, 0], sampled.q[:, 0], sampled.work[:, 0])


@dataclass
class _Frames:
    """States at a set of times (T,) for one run: s, v (T, N, D), w (T, N, K), q (T, N, Q)."""

    times: np.ndarray
    state: State
    contacts: dg.ContactSeries | None  # None for many contacts: `engaged` holds them
    index: rr.TimeColumn
    engaged: Engaged | None = None  # many contacts: only those engaged at each time


def _contact_segments(traj: Trajectory) -> np.ndarray:
    """(S - 1,) True where the step from row k to row k + 1 was a contact step (not free flight).

    `free[k + 1]` flags the segment that ends at row k + 1 (as `diagnostics.sample` reads it).
    """
    return ~traj.free[1:, 0]


def frame_times(traj: Trajectory, fps: float, stride: int, contact_frames: int,
                many: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Times of exact frames and of view frames for run 0 of a trajectory.

    Exact frames: every `stride`-th contact step (each contact's first and last step always),
    a steady `fps` inside free flight, where the closed form is exact, and any contact record
    between the knots (the DEM kernel's peaks). View frames add at
    least `contact_frames` evenly spaced frames across each contact, interpolated between steps,
    so that a contact taken in a few long steps still animates smoothly. With `many` bodies the
    frames are a steady `fps` throughout (plus the start and end): every body's every step
    would be too many frames to send or draw.
    """
    if many:
        knots = traj.knots[:, layout.K_T]
        start, end = float(knots.min()), float(knots.max())
        grid = np.arange(start, end, 1.0 / fps)
        frames = np.union1d(grid, [start, end])
        return frames, frames
    t = traj.t[:, 0]
    contact = _contact_segments(traj)
    touches = np.zeros(len(t), bool)
    touches[1:] |= contact
    touches[:-1] |= contact
    idx = np.flatnonzero(touches)
    edges = np.flatnonzero(touches & ~np.roll(touches, 1) | touches & ~np.roll(touches, -1))
    if stride > 1 and len(idx):
        idx = np.union1d(idx[::stride], edges)
    grid = np.arange(t[0], t[-1], 1.0 / fps)
    segment = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, max(len(t) - 2, 0))
    in_free = ~contact[segment] if len(contact) else np.ones(len(grid), bool)
    exact = np.union1d(np.union1d(t[idx], grid[in_free]), [t[0], t[-1]])
    # The DEM kernel's records between its frames: each contact phase's peak (a collision can
    # be shorter than a frame). Its plots and arrows show the peak there.
    records = np.unique(traj.records[:, layout.R_T]) if len(traj.records) else np.zeros(0)
    exact = np.union1d(exact, np.setdiff1d(records, t))
    dense = [np.linspace(t[a], t[b], contact_frames + 1) for a, b in zip(edges[::2], edges[1::2])]
    view = np.union1d(exact, np.concatenate(dense)) if dense else exact
    return exact, view
