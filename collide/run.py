"""Run scenes: choose the step, compile, simulate. The entry point for the CLI and the viewer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide.integrators import INTEGRATORS
from collide.model import compile_scenes
from collide.scene import Scene, SceneError
from collide.stepper import MAX_STEPS_DEFAULT, RunResult, max_frequency, simulate


@dataclass
class SceneRun:
    """A run together with the scenes it came from (B scenes, one per batch member)."""

    scenes: list[Scene]
    result: RunResult
    dt_request: float | str | None = None
    tol: list[float] | None = None

    @property
    def scene(self) -> Scene:
        return self.scenes[0]

    def member(self, index: int) -> SceneRun:
        """Batch member `index` as a run of its own."""
        tol = None if self.tol is None else [self.tol[index]]
        return SceneRun([self.scenes[index]], self.result.member(index), self.dt_request, tol)


def auto_dt(scenes: list[Scene], integrator: str, tol: np.ndarray) -> np.ndarray:
    """Step from the stiffest contact: omega h chosen so the integrator's error meets tol.

    The error of an order-p method over one contact scales as (omega h)^p; the constant is
    taken as 1, which measurements on the built-ins show to be conservative.
    """
    model, _ = compile_scenes(scenes)
    omega = max_frequency(model)
    order = INTEGRATORS[integrator].order
    stability = INTEGRATORS[integrator].stability
    omega_h = np.minimum(tol ** (1.0 / order), 0.5 * stability)
    return omega_h / omega


def run_scenes(scenes: list[Scene], *, integrator: str | None = None, dt: float | str | None = None,
               tol: float | None = None, record: bool = True,
               max_steps: int = MAX_STEPS_DEFAULT) -> SceneRun:
    """Run B same-shaped scenes in one batch. `integrator`, `dt` and `tol` override the scenes'."""
    names = {s.integrator for s in scenes} if integrator is None else {integrator}
    if len(names) != 1:
        raise SceneError("scenes in one batch must use the same integrator")
    integ = names.pop()
    if integ not in INTEGRATORS:
        raise SceneError(f"integrator: unknown '{integ}' (choose from {', '.join(INTEGRATORS)})")
    model, state = compile_scenes(scenes)
    steps = []
    for scene in scenes:
        step = scene.dt if dt is None else dt
        steps.append(step)
    tols = np.array([scene.tol if tol is None else tol for scene in scenes])
    if any(step == "auto" for step in steps):
        auto = auto_dt(scenes, integ, tols)
        steps = [auto[i] if step == "auto" else step for i, step in enumerate(steps)]
    dt_arr = np.array(steps, dtype=float)
    if not np.all(np.isfinite(dt_arr)) or np.any(dt_arr <= 0):
        raise SceneError(f"dt: must be a positive number or 'auto', got {dt!r}")
    duration = np.array([np.nan if s.duration is None else s.duration for s in scenes])
    tail = np.array([np.nan if s.tail is None else s.tail for s in scenes])
    if model.gravity is not None and model.n_walls and np.isnan(duration).any():
        raise SceneError("duration: required when a scene has both gravity and walls "
                         "(a bouncing sphere never stops)")
    result = simulate(model, state, integrator=integ, dt=dt_arr, duration=duration, tail=tail,
                      record=record, max_steps=max_steps)
    return SceneRun(list(scenes), result, dt, [float(x) for x in tols])


def run_scene(scene: Scene, **kwargs) -> SceneRun:
    """Run one scene (a batch of one)."""
    return run_scenes([scene], **kwargs)
