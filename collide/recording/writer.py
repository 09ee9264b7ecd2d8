"""Writing a run's recording: `write_recording` (docs/design.md section 5).

A `_Writer` computes the run's frames and sends every entity with one `send_columns` call, the
trajectory's tables in calls of TABLE_ROWS rows (what a person looks at: `draw._Drawing`; what a
program reads back, the trajectory's tables and the settings: here), then seals the file
(`integrity`); the file takes its name once checked whole.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from collide import diagnostics as dg
from collide.contact_forces import peak_normal_force
from collide.contact_index import ContactIndex, Engaged
from collide.engine import layout
from collide.model import State
from collide.output import OutputError, check_file, write_atomic
from collide.recording.columns import _any_column
from collide.recording.draw import _Drawing
from collide.recording.frames import _Frames, _one_run, frame_times
from collide.recording.integrity import _file_messages, _placeholder, _seal, _unsealed_sha256
from collide.recording.spec import (
    APP_ID,
    DISSIPATION_PARTS,
    FORMAT,
    FORMAT_VERSION,
    INTEGRITY,
    TIMELINE,
    checksum,
    collide_version,
)
from collide.recording.stream import rrd_file
from collide.run import SceneRun

MANY_BODIES = 24  # from this many bodies on, one instanced entity draws them all
MANY_CONTACTS = 24  # from this many contacts on, one entity draws them all (no per-contact plots)
DEFAULT_FPS = 120.0  # frames per simulated second of free flight
# Rerun's time axis counts int64 nanoseconds: a run ending later than this cannot be recorded.
MAX_RECORDED_TIME = 9.0e9
MAX_FREE_FRAMES = 100_000  # frames of free flight in one recording, at most (fps drops beyond)
# Body positions in the 3D view's frames (frames x bodies), at most: a recording of many bodies
# keeps every k-th frame of the fps grid beyond this (100 000 bodies: about a hundred frames),
# and says so (`frame_every` in its settings and meta, `last_write.frame_every`). The trajectory
# (/collide/knots ...) is stored whole whatever this is.
MAX_BODY_FRAMES = 10_000_000
CONTACT_FRAMES = 100  # least frames across one contact in the 3D view
# Contacts engaged evaluated and sent at once, at most (or one frame's): a recording of many
# contacts draws its frames a block at a time.
BLOCK_ENTRIES = 1 << 20
TABLE_ROWS = 1 << 16  # rows of a trajectory table sent in one call (/collide/knots ...)
SEAL_ATTEMPTS = 4  # writes of a recording whose seal's placeholder LZ4 did not keep verbatim


@dataclass
class WriteStats:
    """What the last `write_recording` call wrote (for benchmarks): frames, rows and calls."""

    frames: int = 0
    exact_frames: int = 0
    fps: float = 0.0  # the free-flight frame rate used (lower than asked for a long run)
    frame_every: int = 1  # many bodies: every k-th frame of the asked rate kept (MAX_BODY_FRAMES)
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
    against the integrity record (`check`), synced, then renamed. A write that fails (a full disk,
    a file-size limit) is an `OutputError` naming the file and the cause, and leaves nothing under
    either name.
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


class _Writer(_Drawing):
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
        knots = self.traj.knots[:, layout.K_T]
        span = float(knots.max() - knots.min()) if len(knots) else 0.0
        self.fps = min(fps, MAX_FREE_FRAMES / span) if span > 0 else fps
        self.many = self.model.n_bodies >= MANY_BODIES
        # Many bodies: the frames are a steady fps (frame_times); every k-th is kept so that the
        # 3D view holds at most MAX_BODY_FRAMES body positions.
        self.frame_every = 1
        if self.many and span > 0:
            self.frame_every = max(1, math.ceil(span * self.fps * self.model.n_bodies / MAX_BODY_FRAMES))
            self.fps /= self.frame_every
        self.contact_frames = contact_frames
        self.rows = 0
        self.calls = 0
        self.placeholder = _placeholder()  # stands where the file's SHA-256 goes (_seal)
        self.sealed = ""
        self.spin = self.model.spin_dim > 0 and self.scene.has_spin
        self.friction = self.model.friction and self.scene.has_friction
        self.dissipative = self.model.dissipative
        self.engaged_counts: np.ndarray | None = None  # `_engaged`'s contacts a frame, per frames

    # -- frames ---------------------------------------------------------------------------

    def _frames(self, times: np.ndarray) -> _Frames:
        st = dg.sample(self.model, self.traj, times, 0)
        index = rr.TimeColumn(TIMELINE, duration=times)
        if self.many_contacts:
            # The contacts engaged at each frame come a block of frames at a time (`_engaged`):
            # every frame's at once (a 100 000-sphere bed: a million contacts a frame) held
            # gigabytes through the write.
            return _Frames(times, _one_run(st), None, index)
        return _Frames(times, _one_run(st), dg.contact_series(self.model, self.traj, times, st), index)

    def _engaged(self, frames: _Frames) -> Iterator[tuple[slice, Engaged]]:
        """The contacts engaged at `frames`' times, a block of frames at a time: each block
        (a slice of the frames; `tk` counts from its start) holds at most BLOCK_ENTRIES
        contacts engaged, or one frame."""
        index = self.contact_index
        if self.engaged_counts is None or len(self.engaged_counts) != len(frames.times):
            starts, ends = np.sort(index.iv_start), np.sort(index.iv_end)
            times = frames.times
            # Intervals begun by each frame less those ended before it: at least the entries there.
            self.engaged_counts = np.searchsorted(starts, times, "right") - np.searchsorted(ends, times, "left")
        counts = self.engaged_counts
        start = 0
        while start < len(frames.times):
            stop = start + 1
            total = counts[start]
            while stop < len(frames.times) and total + counts[stop] <= BLOCK_ENTRIES:
                total += counts[stop]
                stop += 1
            block = slice(start, stop)
            yield block, index.at(frames.times[block], frames.state.s[block])
            start = stop

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
        # Every contact that ever engaged (from the run's contact intervals: a frame could miss one).
        pairs = self.traj.contacts_touched()
        self.touched = np.arange(len(pairs))
        self.many_contacts = len(self.touched) >= MANY_CONTACTS
        exact, view = frame_times(self.traj, self.fps, self.stride, self.contact_frames, self.many)
        self.exact = self._frames(exact)
        self.view = self.exact if np.array_equal(view, exact) else self._frames(view)
        # A contact counts as pressed past the engine's touching tolerance: a tight rack turned
        # into a tilted plane touches with round-off overlaps (1e-17 m) that press nothing.
        self.pressed = float(layout.TOUCH_TOL) * 2.0 * float(self.model.radius.max())
        # Force arrows: the run's largest normal force (the engine's, as the JSON summary's
        # max_normal_force) is drawn as long as a sphere's diameter; the arrows are the recorded
        # forces (collide.contact_forces), none above it.
        drawn = 0.0
        if self.many_contacts:
            self.contact_index = ContactIndex(self.model, self.traj, self.traj.index)
            self.pressed_count = np.zeros(len(exact))
            for block, engaged in self._engaged(self.exact):
                if len(engaged.tk):
                    drawn = max(drawn, float(np.max(np.linalg.norm(engaged.normal_force, axis=-1))))
                on = engaged.tk[engaged.overlap > self.pressed]
                self.pressed_count[block] = np.bincount(on, minlength=block.stop - block.start)
        else:
            normal = self.exact.contacts.normal_force[:, 0]
            drawn = float(np.max(np.linalg.norm(normal, axis=-1))) if normal.size else 0.0
        peak = max(peak_normal_force(self.result), drawn)
        self.force_scale = 2.0 * float(self.model.radius.mean()) / peak if peak > 0 else 1.0
        self.conserved = self._conserved(self.exact.state, pairs)

    def _conserved(self, st: State, pairs: np.ndarray) -> dg.Conserved:
        """`diagnostics.conserved` at every frame, a block of frames at a time: its spring energy
        is a number a contact a frame (a 100 000-sphere pour: two million contacts touched)."""
        per = max(1, BLOCK_ENTRIES // max(len(pairs), 1))
        blocks = [dg.conserved(self.model, st.t[a:a + per], st.s[a:a + per], st.v[a:a + per], st.w[a:a + per],
                               st.work[a:a + per], pairs) for a in range(0, max(len(st.t), 1), per)]
        if len(blocks) == 1:
            return blocks[0]
        fields = {name: None if getattr(blocks[0], name) is None else
                  np.concatenate([getattr(b, name) for b in blocks]) for name in blocks[0].__dataclass_fields__}
        return dg.Conserved(**fields)

    def _send(self, entity: str, columns: Any, index: rr.TimeColumn) -> None:
        self.rec.send_columns(entity, indexes=[index], columns=columns, strict=True)
        self.rec.flush()  # encoded and written now: Rerun holds one call's columns at a time
        self.calls += 1
        self.rows += len(index.as_arrow_array())

    def _static(self, entity: str, archetype: Any) -> None:
        self.rec.log(entity, archetype, static=True, strict=True)

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
        last_write.frame_every = self.frame_every
        last_write.steps = int(self.result.steps[0])
        last_write.rows = self.rows
        last_write.calls = self.calls

    def _send_all(self, path: Path) -> None:
        self.rows = self.calls = 0
        self.rec = rr.RecordingStream(APP_ID, recording_id=uuid.uuid4(), send_properties=False)
        with rrd_file(self.rec, path, self.blueprint()):
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

    def check(self, path: Path) -> None:
        """The file on disk is whole: Rerun's framing complete to its footer and every byte as
        sealed (a write that failed without an error is refused here)."""
        digest = self.sealed
        try:
            whole = _file_messages(path) is not None and not (self.seal and _unsealed_sha256(path, digest) != digest)
        except OSError as exc:
            raise OutputError(f"could not write {path}: {exc.strerror or exc}") from None
        if not whole:
            raise OutputError(f"could not write {path}: the file came out incomplete (cut short); "
                              "is the disk full?")

    def _write_steps(self) -> None:
        """The trajectory exactly, float64, so that `read_recording` restores the run: knots,
        contact records and contact intervals, each with its row number (order on reading), sent
        TABLE_ROWS rows at a time (one call for a run of many bodies' frames held Rerun's copies
        of them all at once while it encoded them)."""
        traj = self.traj
        for entity, table, time_col in (("/collide/knots", traj.knots, layout.K_T),
                                         ("/collide/contact_records", traj.records, layout.R_T),
                                         ("/collide/contact_intervals", traj.intervals, layout.V_START)):
            rows, width = table.shape
            for start in range(0, rows, TABLE_ROWS):
                part = table[start:start + TABLE_ROWS]
                count = len(part)
                cols = [_any_column("row", np.arange(start, start + count, dtype=np.int64), 1, count),
                        _any_column("values", np.ascontiguousarray(part, dtype=np.float64).reshape(-1), width,
                                    count)]
                times = np.nan_to_num(part[:, time_col], nan=0.0)
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
            "frame_every": self.frame_every, "frame_steps": int(r.frame_steps),
            "force_scale": float(self.force_scale),
        }
        if r.warnings:
            # Left out when there are none: Rerun writes a None it has seen as a list before (in an
            # earlier recording of this process) as an empty list, which the checksum did not cover.
            meta["warnings"] = list(r.warnings)
        estimate = getattr(run, "error_estimate", None)
        if estimate is not None:
            meta["error_estimate"] = float(np.asarray(estimate).reshape(-1)[0])
        auto = getattr(run, "auto", None)
        if auto is not None:
            meta["auto"] = bool(auto[0])
        method = getattr(run, "error_method", None)
        if method is not None:
            meta["error_method"] = str(method[0])
        if r.engine:  # which engine ran it and why (collide.alone.engine_choice)
            meta["engine"], meta["engine_reason"] = r.engine, r.engine_reason
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
