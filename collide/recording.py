"""Rerun recordings of runs: one `.rrd` per run, written in bulk and read back losslessly.

This is the only module in `collide/` that imports rerun (docs/design.md section 5). A recording
holds three things:

- what a person looks at, on one timeline `sim_time` (simulated seconds): spheres with spin
  markers and trails, contact points with normal and friction force arrows, compression,
  energies, momentum, angular momentum and their residuals, the scene and the run settings, and
  a blueprint (3D view beside the plots);
- what a program reads back: the trajectory exactly (float64 knots: each body's state at the
  ends of its steps and of its free flight, with its accelerations; each contact's forces at each
  step; the contact intervals) under `/collide/knots`, `/collide/contact_records` and
  `/collide/contact_intervals`, and the run's settings under `/collide/meta`, from which
  `read_recording` rebuilds the `SceneRun`;
- a seal, `/collide/integrity`: the SHA-256 of every byte of the file (its own 64 digits read as
  zeros), so that any changed byte, of what the viewer draws or of what is read back, makes the
  file refused.

Frames: plots (energies, momenta, compression, residuals) are drawn at the steps' ends: every
contact step (or every `stride`-th; each contact's first and last step always) and a steady
`fps` in free flight, where the motion is known in closed form. Where islands step apart, one's
step end falls inside another's step, whose bodies are interpolated there: residuals are drawn
only where every body's state is exact (`diagnostics.settled`). The 3D view adds at least
`contact_frames` frames across each contact, interpolated between steps, so a contact taken in
a few long steps still animates smoothly. Each entity is written with one `send_columns` call;
static data with one `log`. Entities a scene does not need are absent: no friction without
friction, no spin when nothing spins, no walls without walls, no angular momentum in 1D, no
contact entity for a contact that never happened.

Entity paths (`<b>` a body name, `<c>` a contact such as `ball1-ball2` or `ball1-wall0`):

============================================  ==============================================
/world/<b>                                    Ellipsoids3D: the sphere (turns with the body)
/world/<b>/spin                               LineStrips3D: centre-to-rim marker (spinning)
/world/<b>/trail                              LineStrips3D: path so far (a segment a frame)
/world/walls/wall<k>                          LineStrips3D: a wall (static)
/world/contacts/<c>/point                     Points3D: contact point while in contact
/world/contacts/<c>/normal_force              Arrows3D: force on each body (force_scale m/N)
/world/contacts/<c>/friction_force            Arrows3D: friction on each body
/contacts/<c>/compression                     Scalars m: each sphere's compression
/contacts/<c>/overlap                         Scalars m
/contacts/<c>/normal_force                    Scalars N: magnitude
/contacts/<c>/friction_force                  Scalars N: magnitude
/energy/kinetic, spring, total                Scalars J
/energy/rotational                            Scalars J (when something spins)
/energy/gravitational                         Scalars J (with gravity)
/energy/dissipated, total_plus_dissipated     Scalars J (with friction, damping or rolling resistance)
/energy/dissipated_damping, _friction, _rolling, tangential_spring   Scalars J (DEM runs: each part)
/momentum                                     Scalars kg m/s, one series per axis
/angular_momentum                             Scalars kg m^2/s about the origin (2D, 3D)
/spin/<b>                                     Scalars rad/s (when something spins)
/residuals/energy, momentum, angular_momentum  Scalars, relative, as in the JSON summary
/scene                                        TextDocument: the scene TOML (static)
/settings                                     TextDocument: run settings (static)
/world/bodies                                 Points3D: every sphere (scenes of many bodies)
/world/contacts/points, normal_force          every contact at once (scenes of many contacts)
/collide/meta                                 AnyValues: settings and shapes for read-back
/collide/knots, contact_records, ...          AnyValues float64: the trajectory, exactly
/collide/integrity                            AnyValues: sha256 of every byte of the file (last)
============================================  ==============================================
"""

from __future__ import annotations

import atexit
import contextlib
import math
import os
import pickle
import re
import select
import signal
import struct
import subprocess
import sys
import threading
import time
import tomllib
import uuid
import warnings
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.encodings import Vec3DBatch

from collide import diagnostics as dg
from collide.colours import ENERGY_COLOURS, body_colour, body_colours
from collide.engine import layout as kn
from collide.model import Model, State, compile_scenes
from collide.output import OutputError, check_file, write_atomic
from collide.run import SceneRun
from collide.scene import SceneError, parse_scene
from collide.stepper import ContactLog, RunResult, Trajectory

APP_ID = "collide"
FORMAT = "collide-recording"
# 4: as 3, and /collide/integrity, the SHA-256 of every byte of the file before it;
# 3: the trajectory's tables (knots, contact records, contact intervals) and `checksum` in
# /collide/meta (still read); 2: the same tables, no checksum (still read); 1: every step (no
# longer read).
FORMAT_VERSION = 4
INTEGRITY = "/collide/integrity"  # AnyValues sha256: the hash of every byte of the file (_seal)
MANY_BODIES = 24  # from this many bodies on, one instanced entity draws them all
MANY_CONTACTS = 24  # from this many contacts on, one entity draws them all (no per-contact plots)
TIMELINE = "sim_time"
DEFAULT_FPS = 120.0  # frames per simulated second of free flight
# Rerun's time axis counts int64 nanoseconds: a run ending later than this cannot be recorded.
MAX_RECORDED_TIME = 9.0e9
MAX_FREE_FRAMES = 100_000  # frames of free flight in one recording, at most (fps drops beyond)
CONTACT_FRAMES = 100  # least frames across one contact in the 3D view
SEAL_ATTEMPTS = 4  # writes of a recording whose seal's placeholder LZ4 did not keep verbatim
SAFE_TIMEOUT_S = 60.0  # the reader process's limits (read_recording's defaults)
SAFE_MEMORY_MB = 2048

_AXES = "xyz"


class RecordingError(ValueError):
    """A file that is not a complete collide recording. The message names the file."""


def collide_version() -> str:
    """The installed collide version (stored in every recording)."""
    try:
        from importlib.metadata import version

        return version("collide")
    except Exception:  # not installed: running from a source tree
        return "unknown"


# ---------------------------------------------------------------------------------------------
# Writing


@dataclass
class WriteStats:
    """What the last `write_recording` call wrote (for benchmarks): frames, rows and calls."""

    frames: int = 0
    exact_frames: int = 0
    fps: float = 0.0  # the free-flight frame rate used (lower than asked for a long run)
    steps: int = 0
    rows: int = 0
    calls: int = 0


last_write = WriteStats()


def write_recording(run: SceneRun, path: Path, *, stride: int = 1, fps: float = DEFAULT_FPS,
                    contact_frames: int = CONTACT_FRAMES) -> Path:
    """Write member 0 of `run` to `path` (an `.rrd`); return the path.

    `stride` keeps every n-th contact step as a frame, `fps` sets the frame rate in free flight
    (lowered so that a long run holds at most MAX_FREE_FRAMES; `last_write.fps` says what was used)
    and `contact_frames` the least number of frames across each contact in the 3D view. Every
    step is stored exactly whatever these are.

    The file appears under its final name only once whole: written beside it, its bytes checked
    against the integrity record (`_check_written`), synced, then renamed. A write that fails (a
    full disk; Rerun's writer only logs its errors) is an `OutputError` naming the file and the
    cause, and leaves nothing under either name.
    """
    if run.result.batch_size != 1:
        run = run.member(0)
    if run.result.trajectory is None:
        raise ValueError("the run was not recorded (record=False): nothing to write")
    if stride < 1:
        raise ValueError(f"stride must be at least 1, got {stride}")
    end = float(np.max(run.result.final.t))
    if not end <= MAX_RECORDED_TIME:
        raise ValueError(f"the run ends at {end:.3g} s, past the {MAX_RECORDED_TIME:.3g} s a recording's time axis "
                         "holds (Rerun counts nanoseconds): shorten duration or tail, or use --no-record")
    if not fps > 0 or not math.isfinite(fps):
        raise ValueError(f"fps must be positive, got {fps}")
    if contact_frames < 1:
        raise ValueError(f"contact_frames must be at least 1, got {contact_frames}")
    path = Path(path)
    check_file(path, "file name ending in .rrd")  # one line before the work, not an error from Rust
    writer = _Writer(run, stride, fps, contact_frames)
    write_atomic(path, writer.write, writer.check)
    return path


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


def _axis_with_zero(values: np.ndarray) -> rrb.ScalarAxis:
    """A y axis that includes zero: a conserved quantity then plots flat, not as magnified noise."""
    lo, hi = min(float(np.min(values)), 0.0), max(float(np.max(values)), 0.0)
    pad = 0.1 * (hi - lo) if hi > lo else 1.0
    return rrb.ScalarAxis(range=(lo - pad, hi + pad))


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
    contacts: dg.ContactSeries
    index: rr.TimeColumn


def _contact_segments(traj: Trajectory) -> np.ndarray:
    """(S - 1,) True where the step from row k to row k + 1 was a contact step (not free flight).

    `free[k + 1]` flags the segment that ends at row k + 1 (as `diagnostics.sample` reads it).
    """
    return ~traj.free[1:, 0]


def frame_times(traj: Trajectory, fps: float, stride: int, contact_frames: int,
                many: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Times of exact frames and of view frames for run 0 of a trajectory.

    Exact frames: every `stride`-th contact step (each contact's first and last step always),
    and a steady `fps` inside free flight, where the closed form is exact. View frames add at
    least `contact_frames` evenly spaced frames across each contact, interpolated between steps,
    so that a contact taken in a few long steps still animates smoothly. With `many` bodies the
    frames are a steady `fps` throughout (plus the start and end): every body's every step
    would be too many frames to send or draw.
    """
    if many:
        knots = traj.knots[:, kn.K_T]
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
    dense = [np.linspace(t[a], t[b], contact_frames + 1) for a, b in zip(edges[::2], edges[1::2])]
    view = np.union1d(exact, np.concatenate(dense)) if dense else exact
    return exact, view


class _Writer:
    """Computes the frames of one run and sends them, one `send_columns` call per entity."""

    seal = True  # False writes format 3 as collide did before (no integrity record): for tests

    def __init__(self, run: SceneRun, stride: int, fps: float, contact_frames: int) -> None:
        self.run = run
        self.scene = run.scene
        self.result = run.result
        self.model = run.result.model
        self.traj = run.result.trajectory
        self.stride = stride
        # A long free flight at a steady fps would be millions of frames (demo-1d for 1e6 s:
        # 1.2e8): the frame rate drops so that the run holds at most MAX_FREE_FRAMES of them.
        knots = self.traj.knots[:, kn.K_T]
        span = float(knots.max() - knots.min()) if len(knots) else 0.0
        self.fps = min(fps, MAX_FREE_FRAMES / span) if span > 0 else fps
        self.contact_frames = contact_frames
        self.rows = 0
        self.calls = 0
        self.placeholder = _placeholder()  # stands where the file's SHA-256 goes (_seal)
        self.sealed = ""
        self.spin = self.model.spin_dim > 0 and self.scene.has_spin
        self.friction = self.model.friction and self.scene.has_friction
        self.dissipative = self.model.dissipative
        self.many = self.model.n_bodies >= MANY_BODIES

    # -- frames ---------------------------------------------------------------------------

    def _frames(self, times: np.ndarray) -> _Frames:
        st = dg.sample(self.model, self.traj, times, 0)
        contacts = dg.contact_series(self.model, self.traj, times, st)
        index = rr.TimeColumn(TIMELINE, duration=times)
        return _Frames(times, _one_run(st), contacts, index)

    def _states(self, times: np.ndarray) -> State:
        return _one_run(dg.sample(self.model, self.traj, times, 0))

    def _residual_times(self) -> np.ndarray:
        """Where residuals are drawn: exact states only (every body at a knot or in free flight),
        at most as many as the plots' frames, spread evenly in time, start and end included.
        Inside another island's step a body is interpolated, and the balance there is the
        interpolation's, not the run's (a 27-sphere pile at tol 1e-4 showed 6e-4 against 1e-5 at
        exact states)."""
        frames = self.exact.times
        candidates = np.union1d(frames, self.traj.knot_times)
        exact = candidates[dg.settled(self.traj, candidates)]
        if len(exact) > len(frames):
            # The nearest to an even grid in time: exact states crowd where one island steps
            # alone (a pile's end) and thin out where many step apart.
            grid = np.linspace(exact[0], exact[-1], len(frames))
            after = np.clip(np.searchsorted(exact, grid), 1, len(exact) - 1)
            nearer = np.where(grid - exact[after - 1] < exact[after] - grid, after - 1, after)
            exact = exact[np.unique(nearer)]
        return exact

    def _prepare(self) -> None:
        exact, view = frame_times(self.traj, self.fps, self.stride, self.contact_frames, self.many)
        self.exact = self._frames(exact)
        self.view = self.exact if np.array_equal(view, exact) else self._frames(view)
        # Every contact that ever engaged (from the run's contact intervals: a frame could miss one).
        self.touched = np.arange(len(self.exact.contacts.names))
        self.many_contacts = len(self.touched) >= MANY_CONTACTS
        # A contact counts as pressed past the engine's touching tolerance: a tight rack turned
        # into a tilted plane touches with round-off overlaps (1e-17 m) that press nothing.
        self.pressed = float(kn.TOUCH_TOL) * 2.0 * float(self.model.radius.max())
        normal = self.exact.contacts.normal_force[:, 0]
        peak = float(np.max(np.linalg.norm(normal, axis=-1))) if normal.size else 0.0
        # Force arrows: the largest normal force is drawn as long as a sphere's diameter.
        self.force_scale = 2.0 * float(self.model.radius.mean()) / peak if peak > 0 else 1.0
        st = self.exact.state
        self.conserved = dg.conserved(self.model, st.t, st.s, st.v, st.w, st.work, self.exact.contacts.pairs)

    def _send(self, entity: str, columns: Any, index: rr.TimeColumn) -> None:
        self.rec.send_columns(entity, indexes=[index], columns=columns, strict=True)
        self.calls += 1
        self.rows += len(index.as_arrow_array())

    def _static(self, entity: str, archetype: Any) -> None:
        self.rec.log(entity, archetype, static=True, strict=True)

    # -- layout ---------------------------------------------------------------------------

    def _extent(self) -> tuple[np.ndarray, float]:
        """Centre and size of the region the bodies sweep (3D), for the camera and the walls."""
        knots = self.traj.knots
        s = _pad3(knots[:, kn.K_S:kn.K_S + self.model.dim])
        r = self.model.radius[0][knots[:, kn.K_BODY].astype(int)][:, None]
        lo, hi = (s - r).min(axis=0), (s + r).max(axis=0)
        return 0.5 * (lo + hi), float(max(np.max(hi - lo), 4 * self.model.radius.max()))

    def blueprint(self) -> rrb.Blueprint:
        """3D view (tabs: scene, settings) on the left, plots stacked on the right."""
        centre, size = self._extent()
        if self.model.dim < 3:
            # A 1D or 2D scene seen from above its plane, x to the right and y up.
            eye = rrb.EyeControls3D(position=centre + np.array([0.0, 0.0, 1.1 * size]),
                                    look_target=centre, eye_up=[0.0, 1.0, 0.0])
        else:
            # From the front, right and above, z up, far enough that the whole region the bodies
            # sweep (its bounding sphere, radius 0.87 size) fits the default field of view (Rerun's
            # own choice frames the origin and cut gas-box's box in half).
            direction = np.array([0.55, -0.7, 0.45]) / np.linalg.norm([0.55, -0.7, 0.45])
            eye = rrb.EyeControls3D(position=centre + 2.2 * size * direction, look_target=centre,
                                    eye_up=[0.0, 0.0, 1.0])
        overrides = {} if self.many else {f"/world/{b}/trail": rrb.VisibleTimeRanges(
            timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
            end=rrb.TimeRangeBoundary.cursor_relative()) for b in self.model.body_names}
        world = rrb.Spatial3DView(origin="/world", name="3D", eye_controls=eye, overrides=overrides)
        left = rrb.Tabs(world, rrb.TextDocumentView(origin="/scene", name="scene"),
                        rrb.TextDocumentView(origin="/settings", name="settings"), active_tab=0)
        legend = rrb.PlotLegend(corner=rrb.Corner2D.RightTop)
        axis = None
        log = self.result.contacts
        if log.count[0] > 0 and np.isfinite(log.last_end[0]):
            # Plots open on the contacts (the interesting part), with as much time either side.
            start, end = float(log.first_start[0]), float(log.last_end[0])
            span = max(end - start, 1e-9)
            axis = rrb.TimeAxis(view_range=rr.TimeRange(
                start=rr.TimeRangeBoundary.absolute(seconds=max(start - span, 0.0)),
                end=rr.TimeRangeBoundary.absolute(seconds=min(end + span, float(self.exact.times[-1])))))

        def plot(origin: str, name: str, values: np.ndarray | None = None) -> rrb.TimeSeriesView:
            return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=legend, axis_x=axis,
                                      axis_y=None if values is None else _axis_with_zero(values))

        plots = [plot("/energy", "energy (J)")]
        c = self.conserved
        motion = [plot("/momentum", "momentum (kg m/s)", c.momentum)]
        if c.angular_momentum is not None:
            motion.append(plot("/angular_momentum", "L (kg m²/s)", c.angular_momentum))
        if self.spin:
            motion.append(plot("/spin", "spin (rad/s)"))
        plots.append(rrb.Tabs(*motion, active_tab=0) if len(motion) > 1 else motion[0])
        if len(self.touched) and not self.many_contacts:
            first = self.exact.contacts.names[0]
            plots.append(rrb.Tabs(plot(f"/contacts/{first}/compression", f"compression {first} (m)"),
                                  plot("/contacts", "all contacts"), active_tab=0))
        elif len(self.touched):
            plots.append(plot("/contacts", "contacts"))
        plots.append(plot("/residuals", "residuals (relative)"))
        return rrb.Blueprint(rrb.Horizontal(left, rrb.Vertical(*plots), column_shares=[3, 2]),
                             rrb.TimePanel(timeline=TIMELINE, state="collapsed"), collapse_panels=True)

    # -- the recording --------------------------------------------------------------------

    def write(self, path: Path) -> None:
        self._prepare()
        for _ in range(SEAL_ATTEMPTS):
            self._send_all(path)
            if not self.seal:
                break
            self.sealed = _seal(path, self.placeholder)
            if self.sealed:
                break
            self.placeholder = _placeholder()  # LZ4 did not store it verbatim: again with another
        else:
            raise OutputError(f"could not write {path}: its checksum could not be stored")
        last_write.frames = len(self.view.times)
        last_write.exact_frames = len(self.exact.times)
        last_write.fps = self.fps
        last_write.steps = int(self.result.steps[0])
        last_write.rows = self.rows
        last_write.calls = self.calls

    def _send_all(self, path: Path) -> None:
        self.rows = self.calls = 0
        self.rec = rr.RecordingStream(APP_ID, recording_id=uuid.uuid4(), send_properties=False)
        try:
            self.rec.save(path, default_blueprint=self.blueprint())
            self.rec.send_recording_name(self.scene.name)
            self._write_static()
            self._write_bodies()
            self._write_contacts()
            self._write_conserved()
            self._write_steps()
            self._write_meta()  # a truncated file has no meta and is refused on reading
            if self.seal:
                # Last, a slot for the SHA-256 of the whole file: filled in once Rerun closed it.
                self._static(INTEGRITY, rr.AnyValues(sha256=self.placeholder))
            self.rec.flush()
        finally:
            self.rec.disconnect()

    def check(self, path: Path) -> None:
        """The file on disk is whole: Rerun's framing complete to its footer and every byte as
        sealed (Rerun logs its write errors, never raises them: this is where a full disk shows)."""
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise OutputError(f"could not write {path}: {exc.strerror or exc}") from None
        digest = self.sealed
        if _messages(data) is None or self.seal and _unsealed_sha256(data, digest) != digest:
            raise OutputError(f"could not write {path}: the file came out incomplete (cut short); "
                              "is the disk full?")

    def _write_static(self) -> None:
        r = self.result
        self._static("/scene", rr.TextDocument(self.scene.to_toml(), media_type=rr.MediaType.TEXT))
        lines = ["| setting | value |", "|---|---|",
                 f"| scene | {self.scene.name} |", f"| dim | {self.model.dim} |",
                 f"| integrator | {r.integrator} |", f"| dt | {float(r.dt[0]):.6g} s |",
                 f"| steps | {int(r.steps[0])} |", f"| free-flight jumps | {int(r.jumps[0])} |",
                 f"| simulated time | {float(r.final.t[0]):.6g} s |",
                 f"| wall time | {r.wall_time_s:.4g} s |",
                 f"| frames | {len(self.view.times)} (3D), {len(self.exact.times)} (plots) |",
                 f"| stride | {self.stride} |", f"| fps (free flight) | {self.fps:g} |",
                 f"| force arrows | {self.force_scale:.4g} m/N |", f"| collide | {collide_version()} |"]
        lines += [f"| warning | {w} |" for w in r.warnings]
        self._static("/settings", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN))
        self._static("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        if self.model.n_walls:
            centre, size = self._extent()
            for k in range(self.model.n_walls):
                self._static(f"/world/walls/wall{k}", rr.LineStrips3D(
                    [self._wall_outline(k, centre, size)], colors=[(160, 160, 160)], radii=0.002 * size))

    def _wall_outline(self, k: int, centre: np.ndarray, size: float) -> np.ndarray:
        """A wall drawn across the region the bodies sweep: a segment (1D, 2D) or a square (3D)."""
        n = _pad3(self.model.wall_normal[k])
        p = _pad3(self.model.wall_point[k])
        foot = centre - np.dot(centre - p, n) * n
        h = 0.6 * size
        if self.model.dim < 3:
            t = np.array([-n[1], n[0], 0.0])
            return np.stack((foot - h * t, foot + h * t))
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        corners = ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))
        return np.stack([foot + h * (i * a + j * b) for i, j in corners])

    def _write_bodies(self) -> None:
        if self.many:
            self._write_many_bodies()
            return
        view, exact = self.view, self.exact
        centres = _pad3(view.state.s)  # (T, N, 3)
        for n, name in enumerate(self.model.body_names):
            r = float(self.model.radius[0, n])
            color = body_colour(n)
            entity = f"/world/{name}"
            self._static(entity, rr.Ellipsoids3D(half_sizes=[[r, r, r]], colors=[color], labels=[name],
                                                 fill_mode=rr.components.FillMode.MajorWireframe,
                                                 line_radii=0.02 * r))
            c = centres[:, n]
            cols = [*rr.Ellipsoids3D.columns(centers=c)]
            if self.spin:
                cols += [*rr.Ellipsoids3D.columns(quaternions=_quaternion_xyzw(view.state.q[:, n]))]
            self._send(entity, cols, view.index)
            trail = np.stack((np.concatenate((c[:1], c[:-1])), c), axis=1)  # (T, 2, 3): one segment a frame
            self._static(f"{entity}/trail", rr.LineStrips3D.from_fields(colors=[color], radii=0.03 * r))
            self._send(f"{entity}/trail", [_strips_column(trail)], view.index)
            if not self.spin:
                continue
            rim = c + r * _rotate(view.state.q[:, n], np.array([1.0, 0.0, 0.0]))
            marker = rr.LineStrips3D.from_fields(colors=[(235, 235, 235)], radii=0.04 * r)
            self._static(f"{entity}/spin", marker)
            self._send(f"{entity}/spin", [_strips_column(np.stack((c, rim), axis=1))], view.index)
            names = [name] if self.model.spin_dim == 1 else [f"{name}.{a}" for a in _AXES]
            self._static(f"/spin/{name}", rr.SeriesLines(names=names))
            self._send(f"/spin/{name}", rr.Scalars.columns(scalars=exact.state.w[:, n]), exact.index)

    def _write_many_bodies(self) -> None:
        """Every sphere as an instance of one entity: positions each frame, radii and colours
        (one per body, the viewer's: `collide.colours`) once."""
        view = self.view
        centres = _pad3(view.state.s).astype(np.float32)  # (T, N, 3)
        n = self.model.n_bodies
        colors = body_colours(n)
        self._static("/world/bodies", rr.Points3D.from_fields(radii=self.model.radius[0].astype(np.float32),
                                                              colors=colors))
        cols = rr.Points3D.columns(positions=centres.reshape(-1, 3)).partition(np.full(len(view.times), n))
        self._send("/world/bodies", cols, view.index)

    def _contact_bodies(self, c: int) -> list[str]:
        i, j = self.exact.contacts.pairs[c]
        names = self.model.body_names
        return [names[i], names[j]] if j >= 0 else [names[i]]

    def _write_contacts(self) -> None:
        if self.many_contacts:
            self._write_many_contacts()
            return
        view, exact = self.view.contacts, self.exact.contacts
        radius = float(self.model.radius.mean())
        for c in self.touched:
            name = exact.names[c]
            bodies = self._contact_bodies(c)
            on = view.overlap[:, 0, c] > self.pressed
            lengths = on.astype(np.int32)
            point = _pad3(view.point[:, 0, c])[on]
            entity = f"/world/contacts/{name}"
            self._static(f"{entity}/point", rr.Points3D.from_fields(colors=[(0, 0, 0)], radii=0.05 * radius))
            points = rr.Points3D.columns(positions=point).partition(lengths)
            self._send(f"{entity}/point", points, self.view.index)
            self._arrows(f"{entity}/normal_force", _pad3(view.normal_force[:, 0, c])[on], point, lengths,
                         len(bodies), (255, 215, 0))
            if self.friction:
                self._arrows(f"{entity}/friction_force", _pad3(view.friction_force[:, 0, c])[on], point,
                             lengths, len(bodies), (255, 64, 160))
            plot = f"/contacts/{name}"
            index = self.exact.index
            self._static(f"{plot}/compression", rr.SeriesLines(names=bodies))
            compression = exact.compression[:, 0, c, :len(bodies)]
            self._send(f"{plot}/compression", rr.Scalars.columns(scalars=compression), index)
            self._send(f"{plot}/overlap", rr.Scalars.columns(scalars=exact.overlap[:, 0, c]), index)
            normal = np.linalg.norm(exact.normal_force[:, 0, c], axis=-1)
            self._send(f"{plot}/normal_force", rr.Scalars.columns(scalars=normal), index)
            if self.friction:
                friction = np.linalg.norm(exact.friction_force[:, 0, c], axis=-1)
                self._send(f"{plot}/friction_force", rr.Scalars.columns(scalars=friction), index)

    def _write_many_contacts(self) -> None:
        """Every contact at once: points and normal (and friction) force arrows of all contacts
        pressed at each frame, and how many there are as a plot."""
        view = self.view.contacts
        on = view.overlap[:, 0] > self.pressed  # (T, C)
        lengths = on.sum(axis=1).astype(np.int32)
        point = _pad3(view.point[:, 0][on])
        radius = float(self.model.radius.mean())
        self._static("/world/contacts/points", rr.Points3D.from_fields(colors=[(0, 0, 0)], radii=0.05 * radius))
        self._send("/world/contacts/points", rr.Points3D.columns(positions=point).partition(lengths), self.view.index)
        self._arrows("/world/contacts/normal_force", _pad3(view.normal_force[:, 0][on]), point, lengths, 1,
                     (255, 215, 0))
        if self.friction and view.friction_force is not None:
            self._arrows("/world/contacts/friction_force", _pad3(view.friction_force[:, 0][on]), point, lengths, 1,
                         (255, 64, 160))
        exact_on = (self.exact.contacts.overlap[:, 0] > self.pressed).sum(axis=1).astype(float)
        self._send("/contacts/count", rr.Scalars.columns(scalars=exact_on), self.exact.index)

    def _arrows(self, entity: str, force: np.ndarray, point: np.ndarray, lengths: np.ndarray,
                n_bodies: int, color: tuple[int, int, int]) -> None:
        """Force on each body of a contact, drawn from the contact point (equal and opposite)."""
        vec = self.force_scale * force
        if n_bodies == 2:
            vec = np.stack((vec, -vec), axis=1).reshape(-1, 3)
            point = np.repeat(point, 2, axis=0)
        radius = float(self.model.radius.mean())
        self._static(entity, rr.Arrows3D.from_fields(colors=[color], radii=0.06 * radius))
        columns = rr.Arrows3D.columns(origins=point, vectors=vec).partition(lengths * n_bodies)
        self._send(entity, columns, self.view.index)

    def _write_conserved(self) -> None:
        model, st, index, c = self.model, self.exact.state, self.exact.index, self.conserved
        series = {"kinetic": c.kinetic, "rotational": c.rotational if self.spin else None,
                  "spring": c.spring, "gravitational": c.gravitational, "total": c.total}
        if self.dissipative:
            series["dissipated"] = c.dissipated
            series["total_plus_dissipated"] = c.balance
        parts = self.traj.energy_parts
        if parts is not None and len(parts) > 1:
            # DEM runs: each part's work, and what the tangential springs hold (the friction
            # account, and `dissipated`, include it until the springs let go).
            at = st.t
            def part(column: int) -> np.ndarray:
                return np.interp(at, parts[:, 0], parts[:, column])
            stored = part(4)
            series["dissipated_damping"] = part(1)
            series["dissipated_friction"] = part(2) - stored
            series["dissipated_rolling"] = part(3)
            series["tangential_spring"] = stored
        for key, values in series.items():
            if values is not None:
                # Rerun's automatic colours are a hash of the path: dissipated and gravitational
                # came out the same yellow.
                colour = ENERGY_COLOURS.get(key)
                self._static(f"/energy/{key}", rr.SeriesLines(colors=None if colour is None else [colour], names=[key]))
                self._send(f"/energy/{key}", rr.Scalars.columns(scalars=values), index)
        self._static("/momentum", rr.SeriesLines(names=[f"p.{a}" for a in _AXES[:model.dim]]))
        self._send("/momentum", rr.Scalars.columns(scalars=c.momentum), index)
        if c.angular_momentum is not None:
            names = ["L.z"] if model.dim == 2 else [f"L.{a}" for a in _AXES]
            self._static("/angular_momentum", rr.SeriesLines(names=names))
            self._send("/angular_momentum", rr.Scalars.columns(scalars=c.angular_momentum), index)
        times = self._residual_times()
        res = _frame_residuals(model, self.result.initial, self._states(times))
        at = rr.TimeColumn(TIMELINE, duration=times)
        self._send("/residuals/energy", rr.Scalars.columns(scalars=res.energy), at)
        if not model.n_walls:
            self._send("/residuals/momentum", rr.Scalars.columns(scalars=res.momentum), at)
            if model.dim > 1:
                angular = rr.Scalars.columns(scalars=res.angular_momentum)
                self._send("/residuals/angular_momentum", angular, at)

    def _write_steps(self) -> None:
        """The trajectory exactly, float64, so that `read_recording` restores the run: knots,
        contact records and contact intervals, each with its row number (order on reading)."""
        traj = self.traj
        for entity, table, time_col in (("/collide/knots", traj.knots, kn.K_T),
                                         ("/collide/contact_records", traj.records, kn.R_T),
                                         ("/collide/contact_intervals", traj.intervals, kn.V_START)):
            rows, width = table.shape
            if rows == 0:
                continue
            cols = [_any_column("row", np.arange(rows, dtype=np.int64), 1, rows),
                    _any_column("values", np.ascontiguousarray(table, dtype=np.float64).reshape(-1), width, rows)]
            times = np.nan_to_num(table[:, time_col], nan=0.0)
            self._send(entity, cols, rr.TimeColumn(TIMELINE, duration=times))

    def _write_meta(self) -> None:
        r, run, model = self.result, self.run, self.model
        meta: dict[str, Any] = {
            "format": FORMAT, "format_version": FORMAT_VERSION if self.seal else min(FORMAT_VERSION, 3),
            "collide_version": collide_version(),
            "scene_name": self.scene.name, "scene_toml": self.scene.to_toml(),
            "integrator": r.integrator, "dt": float(r.dt[0]), "steps": int(r.steps[0]),
            "jumps": int(r.jumps[0]), "wall_time_s": float(r.wall_time_s),
            "dt_request": "none" if run.dt_request is None else str(run.dt_request),
            "tol": float(run.tol[0]) if run.tol is not None else float("nan"),
            "knots": int(len(self.traj.knots)), "records": int(len(self.traj.records)),
            "intervals": int(len(self.traj.intervals)), "dim": model.dim, "spin_dim": model.spin_dim,
            "n_bodies": model.n_bodies, "n_walls": model.n_walls, "friction": bool(self.friction),
            "stride": self.stride, "fps": float(self.fps), "contact_frames": self.contact_frames,
            "force_scale": float(self.force_scale), "warnings": list(r.warnings) or None,
        }
        estimate = getattr(run, "error_estimate", None)
        if estimate is not None:
            meta["error_estimate"] = float(np.asarray(estimate).reshape(-1)[0])
        auto = getattr(run, "auto", None)
        if auto is not None:
            meta["auto"] = bool(auto[0])
        method = getattr(run, "error_method", None)
        if method is not None:
            meta["error_method"] = str(method[0])
        for field in ("first_start", "last_end", "duration", "max_overlap", "max_normal_force"):
            value = getattr(r.contacts, field)
            meta[f"contact_{field}"] = float("nan") if value is None else float(value[0])
        if r.dissipation is not None:
            for part, value in zip(DISSIPATION_PARTS, r.dissipation[0]):
                meta[f"dissipation_{part}"] = float(value)
        if r.final.stored is not None:
            meta["final_stored"] = float(r.final.stored[0])
        meta["contact_count"] = int(r.contacts.count[0])
        for label, state in (("initial", r.initial), ("final", r.final)):
            meta[f"{label}_t"] = float(state.t[0])
            meta[f"{label}_work"] = float(state.work[0])
            for key in ("s", "v", "w", "q"):
                value = getattr(state, key)[0].reshape(-1)
                if value.size:
                    meta[f"{label}_{key}"] = value
        traj = self.traj
        meta["checksum"] = checksum({"knots": traj.knots, "records": traj.records,
                                     "intervals": traj.intervals}, meta)
        self._static("/collide/meta", rr.AnyValues(**meta))


class _Arrow:
    """A ready Arrow array as a component batch (skips rerun's per-row Python conversion)."""

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def _rows_of(flat: pa.Array, width: int, rows: int, type_: pa.DataType | None = None) -> pa.ListArray:
    offsets = pa.array(np.arange(rows + 1, dtype=np.int32) * width)
    return pa.ListArray.from_arrays(offsets, flat, type=type_)


def _any_column(name: str, flat: np.ndarray, width: int, rows: int) -> rr.ComponentColumn:
    """An AnyValues column of `rows` rows of `width` values each, in the array's dtype (float64)."""
    column = rr.AnyBatchValue.column(name, _rows_of(pa.array(flat), width, rows))
    assert column is not None
    return column


def _strips_column(strips: np.ndarray) -> rr.ComponentColumn:
    """LineStrips3D strips (T, P, 3): one strip of P points per row, built in numpy."""
    rows, points = strips.shape[:2]
    inner = Vec3DBatch(strips.reshape(-1, 3).astype(np.float32)).as_arrow_array()
    array = _rows_of(inner, points, rows, rr.components.LineStrip3DBatch._ARROW_DATATYPE)
    return rr.ComponentColumn(rr.LineStrips3D.descriptor_strips(), _Arrow(array))


# ---------------------------------------------------------------------------------------------
# Reading


def _fail(path: Path, reason: str) -> RecordingError:
    return RecordingError(f"{path}: {reason}")


# Rerun's .rrd framing (rerun-sdk 0.41): a 12-byte header (b"RRF2", version, options); messages,
# each a u64 kind and a u64 length then the payload (kind 0 ends the stream, its payload the
# footer); then a trailer: u64 footer offset, u64 footer length, u32 CRC, b"RRF2FOOT", u32.
_RRD_HEADER = 12
_MESSAGE = struct.Struct("<QQ")
_TRAILER = struct.Struct("<QQI8sI")
_END, _ARROW = 0, 2


def _messages(data: bytes | memoryview) -> list[tuple[int, int, int]] | None:
    """(offset, kind, length) of each message up to the end of the stream; None if the framing
    is broken (cut short, a length past the file, no end, bytes after the trailer)."""
    if len(data) < _RRD_HEADER + _TRAILER.size or bytes(data[:4]) != b"RRF2":
        return None
    out, pos = [], _RRD_HEADER
    while pos + _MESSAGE.size <= len(data):
        kind, length = _MESSAGE.unpack_from(data, pos)
        if kind > 16 or pos + _MESSAGE.size + length > len(data):
            return None
        out.append((pos, kind, length))
        pos += _MESSAGE.size + length
        if kind == _END:
            if len(data) - pos != _TRAILER.size:
                return None
            offset, size, _, magic, _ = _TRAILER.unpack_from(data, pos)
            ok = magic == b"RRF2FOOT" and offset == out[-1][0] + _MESSAGE.size and size == length
            return out if ok else None
    return None


_HEX = re.compile(rb"[0-9a-f]{64}")


def _placeholder() -> str:
    """64 letters G-Z with no 4-byte sequence twice, so that LZ4 (Rerun compresses each message)
    most likely stores them verbatim, where `_seal` can find and overwrite them."""
    import random

    letters = "GHIJKLMNOPQRSTUVWXYZ"  # not hex digits: unlike the chunk ids in Arrow's metadata
    rng = random.SystemRandom()
    while True:
        text = "".join(rng.choice(letters) for _ in range(64))
        if len({text[i:i + 4] for i in range(61)}) == 61:
            return text


def _unsealed_sha256(data: bytes, digest: str) -> str | None:
    """SHA-256 of the file with its one copy of `digest` (the seal) read as 64 zeros; None if
    the digest is not in the file exactly once."""
    key = digest.encode()
    at = data.find(key)
    if at < 0 or data.find(key, at + 1) >= 0:
        return None
    import hashlib

    h = hashlib.sha256(memoryview(data)[:at])
    h.update(b"0" * 64)
    h.update(memoryview(data)[at + 64:])
    return h.hexdigest()


def _seal(path: Path, placeholder: str) -> str:
    """Replace the placeholder (stored verbatim once) by the SHA-256 of the file as it is with
    64 zeros there: every byte of the file is then covered, the seal's own included (a changed
    seal no longer matches the rest). "" if LZ4 did not keep the placeholder verbatim."""
    data = path.read_bytes()
    key = placeholder.encode()
    at = data.find(key)
    if at < 0 or data.find(key, at + 1) >= 0:
        return ""
    data = data[:at] + b"0" * 64 + data[at + 64:]
    import hashlib

    digest = hashlib.sha256(data).hexdigest().encode()
    with open(path, "r+b") as f:
        f.seek(at)
        f.write(digest)
    return digest.decode()


def _check_integrity(path: Path, chunks: list) -> bool:
    """Refuse a file any byte of which changed since it was sealed (its SHA-256, stored in its
    integrity record, does not match); False if it has no integrity record (an older format)."""
    held = [c for c in chunks if c.entity_path == INTEGRITY]
    if not held:
        return False
    columns = _columns(held, INTEGRITY)
    try:
        if len(held) != 1 or held[0].num_rows != 1 or set(columns) != {"sha256"}:
            raise ValueError
        digest = columns["sha256"][0].to_pylist()[0][0]
        if not isinstance(digest, str) or _HEX.fullmatch(digest.encode()) is None:
            raise ValueError
    except (ValueError, IndexError, TypeError, UnicodeEncodeError):
        raise _fail(path, "damaged collide recording (its integrity record is malformed)") from None
    data = path.read_bytes()
    if _messages(data) is None or _unsealed_sha256(data, digest) != digest:
        raise _fail(path, "damaged collide recording (checksum mismatch: its bytes changed after it was "
                          "written)")
    return True


def _load_chunks(path: Path) -> list:
    from rerun.chunk import RrdReader

    if not path.exists():
        raise _fail(path, "no such file")
    if not path.is_file():
        raise _fail(path, "not a file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # rerun warns about damaged files; we raise instead
            reader = RrdReader(path)
            if not reader.recordings():
                raise _fail(path, "not a collide recording (the file holds no Rerun recording)")
            return list(reader.stream())
    except RecordingError:
        raise
    except Exception as exc:  # rerun raises several kinds for damaged input
        text = " ".join(str(exc).split()) or type(exc).__name__
        text = re.sub(r"^Failed to read RRD file at .*?: ", "", text)
        if "FourCC" in text or "Not an RRD" in text:
            raise _fail(path, f"not a Rerun recording (.rrd): {text}") from None
        raise _fail(path, f"damaged or truncated Rerun recording (.rrd): {text}") from None


def _columns(chunks: list, entity: str) -> dict[str, list]:
    """All rows of an entity's components, concatenated over its chunks (as Python lists)."""
    out: dict[str, list] = {}
    for chunk in chunks:
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.startswith("rerun."):
                continue
            out.setdefault(name, []).append(batch.column(name))
    return out


def entity_paths(path: str | Path) -> list[str]:
    """Every entity path in a recording, sorted (what tools search for `friction`, `spin`...)."""
    chunks = _load_chunks(Path(path))
    return sorted({c.entity_path for c in chunks if not c.entity_path.startswith("/__")})


def _meta(path: Path, chunks: list) -> dict[str, Any]:
    """The settings in /collide/meta, once every byte before the integrity record is checked."""
    whole = _check_integrity(path, chunks)
    columns = _columns(chunks, "/collide/meta")
    if not columns:
        if any(c.entity_path.startswith("/collide/") for c in chunks):
            raise _fail(path, "incomplete collide recording (truncated: its settings are missing)")
        raise _fail(path, "not a collide recording (no /collide/meta entity)")
    meta: dict[str, Any] = {}
    for name, arrays in columns.items():
        values = arrays[-1].to_pylist()[-1]
        listed = name == "warnings" or re.fullmatch(r"(initial|final)_[svwq]", name)
        meta[name] = values if listed else values[0]
    if meta.get("format") != FORMAT:
        raise _fail(path, "not a collide recording (unknown format)")
    version = meta.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise _fail(path, f"not a collide recording (format version {version!r})")
    if version < 2:
        raise _fail(path, f"written by an older collide (format {version}, every step) that this one "
                          "no longer reads; record the run again")
    if version > FORMAT_VERSION:
        raise _fail(path, f"made by a newer collide (format {meta['format_version']}, this one reads "
                          f"{FORMAT_VERSION}); upgrade collide")
    if version >= 4 and not whole:
        raise _fail(path, "damaged collide recording (its integrity record is missing)")
    return meta


def _flat(arrays: list) -> np.ndarray:
    """Concatenate list-typed arrow columns and flatten them into one numpy array."""
    chunked = pa.chunked_array(arrays)
    return np.concatenate([a.flatten().to_numpy(zero_copy_only=False) for a in chunked.chunks]) \
        if chunked.num_chunks else np.empty(0)


def _canonical(value: Any) -> bytes:
    """Bytes of a meta value or table that do not depend on how Arrow handed it back."""
    if value is None:
        return b"n"
    if isinstance(value, (bool, np.bool_)):
        return b"b1" if value else b"b0"
    if isinstance(value, (int, np.integer)):
        return b"i" + str(int(value)).encode()
    if isinstance(value, (float, np.floating)):
        return b"f" + float(value).hex().encode()
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        kind = {"f": "<f8", "i": "<i8", "u": "<i8", "b": "u1"}[value.dtype.kind]
        shape = ",".join(str(n) for n in value.shape).encode()
        return b"a" + kind.encode() + b"(" + shape + b")" + np.ascontiguousarray(value, dtype=kind).tobytes()
    if isinstance(value, (list, tuple, np.ndarray)):
        items = list(value)
        if items and all(isinstance(v, (float, np.floating)) for v in items):
            return _canonical(np.asarray(items, dtype=float))
        return b"l[" + b",".join(_canonical(v) for v in items) + b"]"
    raise TypeError(f"no canonical form for {type(value).__name__}")


def checksum(tables: dict[str, np.ndarray], meta: dict[str, Any]) -> str:
    """SHA-256 over what `read_recording` restores: the trajectory's tables (knots, contact
    records, contact intervals: shape and float64 values in row order) and every setting in
    `/collide/meta` but the checksum itself, in sorted key order."""
    import hashlib

    digest = hashlib.sha256()
    for label, table in ((b"tables", tables), (b"meta", meta)):
        digest.update(label)
        for key in sorted(table):
            if key == "checksum" or table[key] is None:  # AnyValues stores no None: absent
                continue
            digest.update(len(key).to_bytes(4, "little") + key.encode())
            data = _canonical(table[key])
            digest.update(len(data).to_bytes(8, "little") + data)
    return digest.hexdigest()


DISSIPATION_PARTS = ("damping", "friction", "rolling")  # RunResult.dissipation's columns
_TABLES = (("knots", "/collide/knots", int(kn.NK)), ("records", "/collide/contact_records", int(kn.NR)),
           ("intervals", "/collide/contact_intervals", 4))


def _tables(path: Path, chunks: list, meta: dict[str, Any]) -> dict[str, np.ndarray]:
    """The trajectory's tables as the writer held them (rows restored to their order)."""
    out = {}
    for name, entity, width in _TABLES:
        rows = meta.get(name)
        if isinstance(rows, bool) or not isinstance(rows, int) or rows < 0:
            raise _fail(path, f"inconsistent collide recording (its row count '{name}' is {rows!r})")
        if rows == 0:
            out[name] = np.zeros((0, width))
            continue
        columns = _columns(chunks, entity)
        if "values" not in columns or "row" not in columns:
            raise _fail(path, f"incomplete collide recording ({entity} is missing)")
        values, order = _flat(columns["values"]), _flat(columns["row"])
        if values.size != rows * width or order.size != rows:
            raise _fail(path, f"incomplete collide recording ({entity} has {order.size} of {rows} rows)")
        order = order.astype(np.int64)
        if not np.array_equal(np.sort(order), np.arange(rows)):
            raise _fail(path, f"damaged collide recording ({entity}'s row numbers are not 0..{rows - 1})")
        table = np.empty((rows, width))
        table[order] = values.reshape(rows, width)
        out[name] = table
    return out


def _verified_tables(path: Path, chunks: list, meta: dict[str, Any]) -> dict[str, np.ndarray]:
    """The trajectory's tables, refused if they or the settings differ from what the writer
    checksummed.

    A checksum present is always checked (a flipped bit could lower `format_version` too); it
    is required from format 3 on, and absent only from files written before (format 2).
    """
    stored = meta.get("checksum")
    required = int(meta["format_version"]) >= 3
    if (stored is not None or required) and not isinstance(stored, str):
        raise _fail(path, "damaged collide recording (its checksum is missing)")
    tables = _tables(path, chunks, meta)
    if stored is not None and checksum(tables, meta) != stored:
        raise _fail(path, "damaged collide recording (checksum mismatch: its trajectory or settings "
                          "changed after it was written)")
    return tables


def read_recording(path: str | Path, *, trusted: bool = False, timeout_s: float = SAFE_TIMEOUT_S,
                   memory_mb: int = SAFE_MEMORY_MB) -> SceneRun:
    """Rebuild the run stored in a recording: scene, model, trajectory, final state and settings.

    Raises `RecordingError` (a `ValueError`) naming the file, in one line, when it is not an
    `.rrd`, is truncated or damaged (a changed byte: its checksum does not match), was not
    written by collide, or crashes, hangs or floods Rerun's reader.

    By default the file is read in a child process (`read_recording_safely`, with `timeout_s`
    and `memory_mb`): Rerun's reader is Rust, and a damaged file can abort the process that
    reads it. `trusted=True` reads in this process, about a second sooner (no reader process to
    start) and without pickling the run back: for files this program has just written itself.
    """
    if not trusted:
        return read_recording_safely(path, timeout_s=timeout_s, memory_mb=memory_mb)
    path = Path(path)
    chunks = _load_chunks(path)
    try:
        meta = _meta(path, chunks)
        return _rebuild(path, _verified_tables(path, chunks, meta), meta)
    except RecordingError:
        raise
    except Exception as exc:  # anything a foreign or damaged file's contents make the parsing raise
        text = " ".join(str(exc).split())[:300]
        raise _fail(path, f"not a valid collide recording ({type(exc).__name__}: {text})") from None


def verify_recording(path: str | Path, *, trusted: bool = False, timeout_s: float = SAFE_TIMEOUT_S,
                     memory_mb: int = SAFE_MEMORY_MB) -> None:
    """Check a recording without rebuilding its run (cheaper than `read_recording`): it returns
    only if `read_recording` would read the file, else raises the same `RecordingError`."""
    path = Path(path)
    if not trusted:
        _safely(path, "verify", timeout_s, memory_mb)
        return
    chunks = _load_chunks(path)
    try:
        _verified_tables(path, chunks, _meta(path, chunks))
    except RecordingError:
        raise
    except Exception as exc:
        text = " ".join(str(exc).split())[:300]
        raise _fail(path, f"not a valid collide recording ({type(exc).__name__}: {text})") from None


def _rebuild(path: Path, tables: dict[str, np.ndarray], meta: dict[str, Any]) -> SceneRun:
    try:
        scene = parse_scene(tomllib.loads(meta["scene_toml"]), meta["scene_name"])
    except (SceneError, tomllib.TOMLDecodeError) as exc:
        raise _fail(path, f"its stored scene is invalid: {exc}") from None
    model, _ = compile_scenes([scene])
    n, d = model.n_bodies, model.dim
    k, q_dim = model.spin_dim, model.orient_dim

    traj = Trajectory(tables["knots"], tables["records"], tables["intervals"], model)

    def state(label: str) -> State:
        def vec(key: str, width: int) -> np.ndarray:
            if width == 0:
                return np.zeros((1, n, 0))
            return np.asarray(meta[f"{label}_{key}"], dtype=float).reshape(1, n, width)
        stored = meta.get(f"{label}_stored")
        return State(np.array([meta[f"{label}_t"]], float), vec("s", d), vec("v", d), vec("w", k),
                     vec("q", q_dim), np.array([meta[f"{label}_work"]], float),
                     None if stored is None else np.array([stored], float))

    log = ContactLog(*(np.array([meta[f"contact_{f}"]], float) for f in
                       ("first_start", "last_end", "duration", "max_overlap")),
                     np.array([meta["contact_count"]], np.int64),
                     np.array([meta.get("contact_max_normal_force", float("nan"))], float))
    result = RunResult(model=model, initial=state("initial"), final=state("final"),
                       integrator=str(meta["integrator"]), dt=np.array([meta["dt"]], float),
                       steps=np.array([meta["steps"]], np.int64),
                       jumps=np.array([meta["jumps"]], np.int64),
                       wall_time_s=float(meta["wall_time_s"]), contacts=log, trajectories=[traj],
                       warnings=[str(w) for w in (meta.get("warnings") or [])],
                       dissipation=None if meta.get("dissipation_damping") is None else
                       np.array([[float(meta[f"dissipation_{part}"]) for part in DISSIPATION_PARTS]]))
    request = meta.get("dt_request", "none")
    dt_request: float | str | None = None if request == "none" else \
        ("auto" if request == "auto" else float(request))
    tol = float(meta["tol"])
    run = SceneRun([scene], result, dt_request, None if math.isnan(tol) else [tol])
    if "error_estimate" in meta and hasattr(run, "error_estimate"):
        run.error_estimate = np.array([float(meta["error_estimate"])])
    if "auto" in meta and hasattr(run, "auto"):
        run.auto = [bool(meta["auto"])]
    if meta.get("error_method") in ("model", "measured"):
        run.error_method = [str(meta["error_method"])]
    return run


def write_accuracy_recording(wp: Any, path: Path) -> Path:
    """A work-precision study (`collide.accuracy.WorkPrecision`) as a recording: for each
    integrator, log10 of the error on a `run_time` timeline (seconds of wall time), and the
    table as a text document; the blueprint shows one plot with a line per integrator."""
    def produce(tmp: Path) -> None:
        _write_accuracy(wp, tmp)

    def check(tmp: Path) -> None:
        if _messages(tmp.read_bytes()) is None:
            raise OutputError(f"could not write {tmp}: the file is incomplete (cut short); is the disk full?")

    return write_atomic(Path(path), produce, check)


def _write_accuracy(wp: Any, tmp: Path) -> None:
    rec = rr.RecordingStream(f"{APP_ID}-accuracy", recording_id=uuid.uuid4(), send_properties=False)
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.TimeSeriesView(origin="/accuracy", name="log10 error against run time"),
        rrb.TextDocumentView(origin="/table", name="table")))
    try:
        rec.save(tmp, default_blueprint=blueprint)
        lines = ["| integrator | omega dt | dt (s) | steps | run time (s) | error |", "|---|---|---|---|---|---|"]
        for p in wp.points:
            err = "refused" if p.error is None else f"{p.error:.3e}"
            lines.append(f"| {p.integrator} | {p.omega_dt:g} | {p.dt:.3g} | {p.steps} | {p.wall_time_s:.4g} | {err} |")
        orders = ", ".join(f"{k}: {'-' if v is None else f'{v:.2f}'}" for k, v in wp.orders().items())
        lines += ["", f"observed orders: {orders}"]
        rec.log("/table", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
        for name in dict.fromkeys(p.integrator for p in wp.points):
            pts = sorted((p for p in wp.points if p.integrator == name and p.error and p.wall_time_s > 0),
                         key=lambda p: p.wall_time_s)
            if not pts:
                continue
            rec.send_columns(f"/accuracy/{name}",
                             indexes=[rr.TimeColumn("run_time", duration=[p.wall_time_s for p in pts])],
                             columns=rr.Scalars.columns(scalars=[math.log10(p.error) for p in pts]))
        rec.flush()
    finally:
        rec.disconnect()


# ---------------------------------------------------------------------------------------------
# Reading untrusted files in a child process

_POLL_S = 0.05
_HEADER = struct.Struct("!Q")
_IDLE_READERS = 2  # reader processes kept warm between reads


def _send_message(stream: Any, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _serve_reads() -> None:
    """The reader process: read (path, memory_mb) requests on stdin, answer on stdout.

    Started by `read_recording_safely` as a fresh interpreter (never a fork of the caller, whose
    threads or main script it must not inherit). Answers ("ok", SceneRun) or ("error", message);
    a damaged file that aborts Rerun's Rust reader kills only this process.
    """
    import resource

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing but answers on the answer channel
    warnings.simplefilter("ignore")
    while True:
        header = inp.read(_HEADER.size)
        if len(header) < _HEADER.size:
            return
        path, memory_mb, mode = pickle.loads(inp.read(_HEADER.unpack(header)[0]))
        try:
            # A backstop against one huge allocation between the parent's memory checks; a
            # process with rerun loaded reserves about 3 GB of address space before it reads.
            _, hard = resource.getrlimit(resource.RLIMIT_AS)
            limit = (4096 + 2 * memory_mb) * 1024 * 1024
            resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY
                                                    else min(limit, hard), hard))
        except (ValueError, OSError):
            pass
        try:
            message: tuple[str, Any] = ("ok", verify_recording(path, trusted=True) if mode == "verify"
                                        else read_recording(path, trusted=True))
        except RecordingError as exc:
            message = ("error", str(exc))
        except MemoryError:
            message = ("error", f"{path}: reading it needs more than {memory_mb} MB of memory")
        except Exception as exc:  # whatever a damaged file makes the reader raise
            message = ("error", f"{path}: damaged or not a collide recording ({type(exc).__name__}: {exc})")
        _send_message(out, message)


class _Reader:
    """One reader process and its pipes."""

    def __init__(self) -> None:
        code = "from collide.recording import _serve_reads; _serve_reads()"
        self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for stream in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError):
                stream.close()

    def rss_mb(self) -> float:
        try:
            with open(f"/proc/{self.proc.pid}/statm") as f:
                return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") / 2**20)
        except (OSError, ValueError, IndexError):
            return 0.0

    def read(self, path: Path, timeout_s: float, memory_mb: int, mode: str = "read") -> tuple[str, Any]:
        """Send one request; ("ok", run), ("error", message) or ("failed", reason)."""
        try:
            _send_message(self.proc.stdin, (str(path), int(memory_mb), mode))
        except OSError:
            return "failed", self._died()
        fd = self.proc.stdout.fileno()
        deadline = time.monotonic() + timeout_s
        # A bytearray grows in place: `bytes +=` copied everything read so far for every 64 kB
        # the pipe gives (a 1 000-sphere recording: 10-70 s of copying, quadratic in its size).
        data = bytearray()
        need = _HEADER.size
        length = None
        while True:
            ready, _, _ = select.select([fd], [], [], _POLL_S)
            if ready:
                chunk = os.read(fd, max(need - len(data), 1 << 16))
                if not chunk:
                    return "failed", self._died()
                data += chunk
                if length is None and len(data) >= _HEADER.size:
                    length = _HEADER.unpack(bytes(data[:_HEADER.size]))[0]
                    need = _HEADER.size + length
                if length is not None and len(data) >= need:
                    # Limits hold for reads quicker than one check too.
                    if time.monotonic() > deadline:
                        return "failed", f"reading it took longer than {timeout_s:g} s (stopped)"
                    if self.rss_mb() > memory_mb:
                        return "failed", f"reading it needs more than {memory_mb} MB of memory (stopped)"
                    try:
                        return pickle.loads(memoryview(data)[_HEADER.size:need])
                    except Exception as exc:
                        return "failed", f"its contents could not be passed back ({type(exc).__name__})"
                continue
            if time.monotonic() > deadline:
                return "failed", f"reading it took longer than {timeout_s:g} s (stopped)"
            if self.rss_mb() > memory_mb:
                return "failed", f"reading it needs more than {memory_mb} MB of memory (stopped)"

    def _died(self) -> str:
        code = self.proc.wait()
        if code < 0:
            try:
                how = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit code {code}"
        return f"damaged recording: Rerun's reader crashed on it ({how})"


_idle: list[_Reader] = []
_idle_lock = threading.Lock()


def _take_reader() -> _Reader:
    with _idle_lock:
        while _idle:
            reader = _idle.pop()
            if reader.proc.poll() is None:
                return reader
            reader.stop()
    return _Reader()


def _give_back(reader: _Reader) -> None:
    with _idle_lock:
        if len(_idle) < _IDLE_READERS:
            _idle.append(reader)
            return
    reader.stop()


def read_recording_safely(path: str | Path, *, timeout_s: float = SAFE_TIMEOUT_S,
                          memory_mb: int = SAFE_MEMORY_MB) -> SceneRun:
    """`read_recording` in a child process (its default), for files from anywhere.

    Rerun's reader is Rust: a damaged file can make it panic and abort the whole process, or
    loop. Here a crash, a hang (longer than `timeout_s`) or a read that needs more than
    `memory_mb` MB of memory costs only the child; each becomes a `RecordingError` with a
    one-line message naming the file, and the caller carries on. Readers are fresh interpreters
    (about a second to start), kept warm between reads; safe to call from several threads.
    """
    return _safely(Path(path), "read", timeout_s, memory_mb)


def _safely(path: Path, mode: str, timeout_s: float, memory_mb: int) -> Any:
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be positive, got {timeout_s}")
    if not memory_mb > 0:
        raise ValueError(f"memory_mb must be positive, got {memory_mb}")
    if not path.exists():
        raise _fail(path, "no such file")
    if not path.is_file():
        raise _fail(path, "not a file")
    reader = _take_reader()
    kind, value = "failed", "the reader stopped"
    try:
        kind, value = reader.read(path.absolute(), timeout_s, memory_mb, mode)
    finally:
        if kind == "failed":
            reader.stop()
            _give_back(_Reader())  # warm up the next one while the caller reports this one
        else:
            _give_back(reader)
    if kind == "ok":
        return value
    if kind == "error":
        raise RecordingError(" ".join(str(value).split()))
    raise _fail(path, " ".join(str(value).split()))


@atexit.register
def _stop_idle_readers() -> None:
    with _idle_lock:
        while _idle:
            _idle.pop().stop()
