"""The frames an export writes: every sphere and every pressed contact at the recording's times.

The times are the recording's 3D-view frames (`collide.recording.frame_times`): a steady rate in
free flight and extra frames across each contact, so a contact of a few milliseconds in a run of
seconds still has frames (and rows in the contacts table). Vectors are padded to 3 components
(1D and 2D scenes live in the z = 0 plane), as the recording draws them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from collide import diagnostics as dg
from collide.engine import layout
from collide.recording import CONTACT_FRAMES, DEFAULT_FPS, MANY_BODIES, MAX_FREE_FRAMES, frame_times
from collide.run import SceneRun

MAX_FRAMES = 2_000  # frames in one export at most (evenly thinned beyond: a VTK file or video frame each)


def pad3(x: np.ndarray) -> np.ndarray:
    """Vectors of length D (0 to 3) as 3-vectors, zeros after the D components."""
    if x.shape[-1] == 3:
        return x
    return np.concatenate((x, np.zeros((*x.shape[:-1], 3 - x.shape[-1]))), axis=-1)


@dataclass
class Frames:
    """T frames of one run: N spheres, and per frame the contacts pressed then.

    s, v (T, N, 3) m, m/s; w (T, N, 3) rad/s (2D spin is about z); radius (N,) m; names (N);
    dim and spin_dim say which components are real. Contacts are flat over frames: `contact_frame`
    (K,) the frame, pairs (K, 2) (j = -1 - wall), overlap (K,) m, point (K, 3) m, normal_force
    (K, 3) N and friction (K, 3) N or None (forces on the first body of the pair).
    """

    times: np.ndarray
    s: np.ndarray
    v: np.ndarray
    w: np.ndarray
    radius: np.ndarray
    names: tuple[str, ...]
    dim: int
    spin_dim: int
    contact_frame: np.ndarray
    pairs: np.ndarray
    overlap: np.ndarray
    point: np.ndarray
    normal_force: np.ndarray
    friction: np.ndarray | None
    wall_point: np.ndarray
    wall_normal: np.ndarray
    angle: np.ndarray | None = None  # (T, N) rad: 2D orientation (the video's spin markers)

    def contacts_at(self, frame: int) -> slice:
        """The rows of the contacts pressed at one frame (contacts are sorted by frame)."""
        lo, hi = np.searchsorted(self.contact_frame, [frame, frame + 1])
        return slice(int(lo), int(hi))


def export_times(run: SceneRun, fps: float = DEFAULT_FPS, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """The recording's view frames of this run (as `write_recording` picks them at `fps`),
    thinned evenly to at most `max_frames` (the first and last always kept)."""
    traj = run.result.trajectory
    if traj is None:
        raise ValueError("the run holds no trajectory to export")
    knots = traj.knots[:, layout.K_T]
    span = float(knots.max() - knots.min()) if len(knots) else 0.0
    fps = min(fps, MAX_FREE_FRAMES / span) if span > 0 else fps
    many = run.result.model.n_bodies >= MANY_BODIES
    _, view = frame_times(traj, fps, 1, CONTACT_FRAMES, many)
    if len(view) > max_frames:
        view = view[np.unique(np.round(np.linspace(0, len(view) - 1, max_frames)).astype(np.int64))]
    return view


def export_frames(run: SceneRun, times: np.ndarray) -> Frames:
    """Spheres and pressed contacts of a run at `times` (sorted)."""
    model, traj = run.result.model, run.result.trajectory
    st = dg.sample(model, traj, times, 0)
    # Friction is looked up below for the pressed contacts only: contact_series's own lookup
    # scans every record for every contact (20 s of a 1 000-sphere pile's export).
    contacts = dg.contact_series(replace(model, friction=False), traj, times, st)
    # Pressed past the engine's touching tolerance, as the recording draws contacts.
    pressed = float(layout.TOUCH_TOL) * 2.0 * float(model.radius.max())
    on = contacts.overlap[:, 0] > pressed  # (T, C)
    frame, which = np.nonzero(on)
    friction = None
    if model.friction and run.scene.has_friction:
        friction = pad3(_friction(traj.records, contacts.pairs, model, times[frame], which))
    return Frames(times=np.asarray(times, float), s=pad3(st.s[:, 0]), v=pad3(st.v[:, 0]), w=_spin3(st.w[:, 0]),
                  radius=model.radius[0].astype(float), names=tuple(model.body_names), dim=model.dim,
                  spin_dim=model.spin_dim, contact_frame=frame, pairs=contacts.pairs[which].reshape(-1, 2),
                  overlap=contacts.overlap[:, 0][frame, which], point=pad3(contacts.point[:, 0][frame, which]),
                  normal_force=pad3(contacts.normal_force[:, 0][frame, which]), friction=friction,
                  wall_point=pad3(model.wall_point.reshape(-1, model.dim)),
                  wall_normal=pad3(model.wall_normal.reshape(-1, model.dim)),
                  angle=st.q[:, 0, :, 0] if model.orient_dim == 1 else None)


def _friction(records: np.ndarray, pairs: np.ndarray, model, at: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Friction force (K, D) on the first body of contact `which` (K,) at times `at` (K,), all
    pressed then: the force of the contact's step that ends at or after the time, as
    `diagnostics.contact_series` holds it (zero after its last record)."""
    d, width = model.dim, model.n_bodies + model.n_walls
    out = np.zeros((len(at), d))
    if not len(records) or not len(at):
        return out
    keys = pairs[:, 0] * width + pairs[:, 1] + model.n_walls
    record_keys = (records[:, layout.R_I].astype(np.int64) * width + records[:, layout.R_J].astype(np.int64)
                   + model.n_walls)
    order = np.lexsort((records[:, layout.R_T], record_keys))
    records, record_keys = records[order], record_keys[order]
    starts = np.searchsorted(record_keys, keys, side="left")
    ends = np.searchsorted(record_keys, keys, side="right")
    by_contact = np.argsort(which, kind="stable")
    cuts = np.searchsorted(which[by_contact], np.arange(len(pairs) + 1))
    for c in np.flatnonzero(np.diff(cuts)):
        rows = by_contact[cuts[c]:cuts[c + 1]]
        block = records[starts[c]:ends[c]]
        if not len(block):
            continue
        k = np.searchsorted(block[:, layout.R_T], at[rows], side="left")
        force = block[np.minimum(k, len(block) - 1), layout.R_FX:layout.R_FX + d]
        out[rows] = np.where((k < len(block))[:, None], force, 0.0)
    return out


def _spin3(w: np.ndarray) -> np.ndarray:
    """Spin (T, N, K) as 3-vectors: none in 1D, about z in 2D."""
    out = np.zeros((*w.shape[:-1], 3))
    if w.shape[-1] == 1:
        out[..., 2] = w[..., 0]
    elif w.shape[-1] == 3:
        out[:] = w
    return out
