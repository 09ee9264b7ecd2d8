"""What a run returns (`RunResult`, its `ContactLog` and `Trajectory`s): the seam between the
engines that produce runs (`collide.stepper`, `collide.dem`) and everything that shows them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from collide.model import Model, State, select_model, select_state
from collide.trajectory import Trajectory

__all__ = ["ContactLog", "RunResult", "Trajectory"]


@dataclass
class ContactLog:
    """Per run (B,): first contact start, last contact end, time in contact (any contact
    engaged), largest overlap, and the number of contacts that began."""

    first_start: np.ndarray
    last_end: np.ndarray
    duration: np.ndarray
    max_overlap: np.ndarray
    count: np.ndarray
    max_normal_force: np.ndarray | None = None  # N; NaN where not known (the seed's grid with walls)
    # The longest single contact in collision times (pi / omega of its pair): a collision lasts
    # about one, a contact that rests or rolls many. None where not known (DEM runs, recordings).
    longest: np.ndarray | None = None


@dataclass
class RunResult:
    """What a run produced: the seam between the physics and everything that shows it."""

    model: Model
    initial: State
    final: State
    integrator: str
    dt: np.ndarray
    steps: np.ndarray
    jumps: np.ndarray
    wall_time_s: float
    contacts: ContactLog
    trajectories: list[Trajectory] | None = None
    warnings: list[str] = field(default_factory=list)
    dt_min: np.ndarray | None = None  # (B,) the smallest step any island took
    windows: np.ndarray | None = None  # (B,) windows of islands the run took
    dissipation: np.ndarray | None = None  # (B, 3) DEM: J taken out by damping, friction, rolling
    closed_steps: np.ndarray | None = None  # (B,) of the steps, intervals run in closed form (a sphere on a wall)
    attempts: np.ndarray | None = None  # (B,) whole steps tried from a step's start (events cost more than one)
    free_since: np.ndarray | None = None  # (B, N) when each body's last contact ended (0: none; the end: open)
    threads: int = 1  # the threads one DEM run stepped on (collide.dem.run_threads)
    frame_steps: int = 0  # a recorded DEM run: the least steps between its frames (collide.dem.frame_steps)
    engine: str = ""  # which engine ran it ("event", "dem", "seed"; collide.alone.engine_choice)
    engine_reason: str = ""  # and why

    @property
    def batch_size(self) -> int:
        return self.model.batch

    @property
    def trajectory(self) -> Trajectory | None:
        """Member 0's trajectory (a batch of one's), or None when not recorded."""
        return self.trajectories[0] if self.trajectories else None

    def member(self, index: int) -> RunResult:
        """Batch member `index` as a run of batch 1."""
        def pick(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[index:index + 1]

        log = ContactLog(*(pick(getattr(self.contacts, f)) for f in
                           ("first_start", "last_end", "duration", "max_overlap", "count", "max_normal_force",
                            "longest")))
        trajectories = None
        if self.trajectories is not None:
            traj = self.trajectories[index]
            trajectories = [Trajectory(traj.knots, traj.records, traj.intervals, select_model(self.model, index),
                                       traj.energy_parts)]
        return RunResult(select_model(self.model, index), select_state(self.initial, index),
                         select_state(self.final, index), self.integrator, pick(self.dt), pick(self.steps),
                         pick(self.jumps), self.wall_time_s, log, trajectories, list(self.warnings),
                         pick(self.dt_min), pick(self.windows), pick(self.dissipation), pick(self.closed_steps),
                         pick(self.attempts), pick(self.free_since), engine=self.engine,
                         engine_reason=self.engine_reason, frame_steps=self.frame_steps)
