"""Live runs of a tab: the scene re-simulated with the controls' values, on the tab's worker
thread (`LatestWorker`: the newest request wins). While the user drags, a run that costs more
than PREVIEW_BUDGET is first drawn from a coarse preview and redrawn by the real run once the
slider rests. A run expected to take longer than LONG_RUN_S (its last run did), or of more
bodies than MANY_BODIES, goes to a child process with a progress line and a Stop button
(`viewer.background`), and starts once the slider rests: a drag does not start a minute-long
run for every value it passes. A scene of many bodies shows its start at once meanwhile (its
bodies where the new values put them, `viewer.frames.start_frames`: milliseconds for a
thousand), when it is opened and at every slider change.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import math
import os
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from collide import dem as cdem
from collide import measure as cmeasure
from collide.model import compile_scenes
from collide.run import SceneRun, auto_dt, balance_warnings, run_scene
from collide.scene import Scene, SceneError
from collide.stepper import RunError
from viewer.background import BackgroundRunner, RunStopped
from viewer.frames import StartFrames, start_frames
from viewer.guard import FAILURES
from viewer.messages import Messages, one_line
from viewer.params import AUTO, Controls, Settings, build_scene
from viewer.state import ViewRun
from viewer.worker import LatestWorker

# s: when a full run takes longer, a coarse preview is drawn first; the run's share of a 100 ms
# answer (preparing and drawing a run take 10-40 ms more)
PREVIEW_BUDGET = 0.05
PREVIEW_TOL = 1e-3  # the preview's accuracy (auto dt)
LONG_RUN_S = 1.0
MEASURE_NICE = 10  # a measuring run's thread: below the server's and the browser's
MANY_BODIES = 200
STAGES = {"seed": 1, "verlet": 1, "yoshida4": 3, "kahan6": 9, "dem": 1}  # force evaluations per step
DEM_PREVIEW_STEPS = 8  # a DEM preview's steps per contact time (a full run takes at least 50)
DEM_PREVIEW_MARGIN = 0.7  # of the DEM step's stability limit, at most


@dataclass
class Request:
    """Parameters to simulate: control values (display units) and run settings."""

    controls: Controls
    values: dict[str, float]
    settings: Settings
    refit: bool = False
    stamp: float = 0.0


class Preview(NamedTuple):
    """A cheaper run drawn while the user drags: integrator, step (AUTO or seconds), tolerance."""

    integrator: str
    dt: float | str
    tol: float


def preview_settings(scene: Scene) -> Preview | None:
    """A cheaper run for a first, coarse answer while the user drags, or None when none costs
    less than half the scene's own run (force evaluations per contact: stages / dt). A preview
    that costs more than the real run (issue 12, item 3) is never used."""
    if scene.integrator == "dem":
        return _dem_preview(scene)

    def cost(integrator: str, tol: float) -> float:
        if scene.dt != AUTO and integrator == scene.integrator and tol == scene.tol:
            return STAGES[integrator] / float(scene.dt)
        dt, _ = auto_dt([scene], integrator, np.array([tol]))
        return STAGES[integrator] / float(dt[0])

    try:
        full = cost(scene.integrator, scene.tol)
        candidates = [("verlet", max(PREVIEW_TOL, scene.tol)), (scene.integrator, max(PREVIEW_TOL, scene.tol))]
        best = min(candidates, key=lambda c: cost(*c))
        return Preview(best[0], AUTO, best[1]) if cost(*best) < 0.5 * full else None
    except (RunError, SceneError, ValueError, ZeroDivisionError):
        return None


def _dem_preview(scene: Scene) -> Preview | None:
    """DEM_PREVIEW_STEPS steps per contact time, where the scene's own run takes at least 50
    (the kernel's floor): the DEM step's error is first order, so the preview's outcome is off
    by some per cent. The step keeps a margin to the kernel's stability limit, or no preview."""
    if scene.dt != AUTO:
        return None
    try:
        model, state = compile_scenes([scene])
        t_c = float(cdem.contact_time(model, state)[0][0])
        full = float(cdem.auto_dt(model, state, np.array([scene.tol]))[0])
        for steps in (DEM_PREVIEW_STEPS, 2 * DEM_PREVIEW_STEPS):
            dt = t_c / steps
            if dt < 2 * full:
                return None
            try:
                cdem.check_dem(model, state, np.array([dt / DEM_PREVIEW_MARGIN]), 2**62, np.array([np.inf]))
            except RunError:
                continue
            return Preview("dem", float(dt), scene.tol)
    except (RunError, SceneError, ValueError, ZeroDivisionError):
        return None
    return None


def release_memory() -> None:
    """Hand the heap freed by a replaced run of many bodies back to the system. glibc keeps freed
    memory for reuse, and a pile's view arrays (tens of MB, freed by the worker thread while
    the next are built) stayed resident: the live pile's server grew by 30-60 MB a slider change
    (375 to 473 MB in four; 377 MB once trimmed). A no-op where the C library is not glibc."""
    gc.collect()  # a replaced view in a reference cycle is freed now, before the trim
    trim = getattr(_libc(), "malloc_trim", None)
    if trim is not None:
        trim(0)


def _libc() -> Any:
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None


def _yielding(work: Any) -> Any:
    """`work()` on a thread of lower priority (Linux nices threads one by one): a measurement
    runs while the page draws the run it measures, and on a machine of few cores it took the
    CPU the browser's first frame needed (break-3d: 0.6 s to draw, 3.5 s beside it)."""
    out: list[Any] = []
    errors: list[BaseException] = []

    def target() -> None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), MEASURE_NICE)
        except (AttributeError, OSError):
            pass
        try:
            out.append(work())
        except BaseException as exc:  # re-raised on the worker thread
            errors.append(exc)

    thread = threading.Thread(target=target, name="collide-measure", daemon=True)
    thread.start()
    thread.join()
    if errors:
        raise errors[0]
    return out[0]


def may_be_measured(scene: Scene) -> bool:
    """Whether a run of `scene` can have its error measured (collide.measure: an automatic step
    and at most MEASURED_MAX_BODIES bodies). Such a run is shown as soon as it is done, its
    estimate pending, and measured after (the scene again at a tenth of the tolerance: 1.8 s
    against the billiards break's 0.26 s run)."""
    return cmeasure.measurable(scene, scene.dt == AUTO)


def needs_measuring(scene: Scene, run: SceneRun) -> bool:
    """Whether `run_scene` would measure this unmeasured run's error (collide.run's rule: an
    outcome outside the error model: contacts in a chain, or one lasting, in DEM judged against
    the shortest contact time the scene can produce)."""
    if not cmeasure.measurable(scene, bool(run.auto[0])):
        return False
    lasting = None
    if run.result.integrator == "dem":
        model, state = compile_scenes([scene])
        t_c = float(cdem.contact_time(model, state)[0][0])
        lasting = float(run.result.contacts.duration[0]) > cmeasure.LASTING_CONTACT * t_c
    return cmeasure.outside_model(run.result, lasting)


def as_measured(scene: Scene, run: SceneRun) -> SceneRun:
    """An unmeasured run that needs no measuring, as `run_scene` returns it (the event engine adds
    its energy-balance warnings after the measuring step; DEM's unmeasured run has them)."""
    if run.result.integrator != "dem":
        tols = np.maximum(np.asarray(run.tol, float), np.asarray(run.error_estimate, float))
        run.result.warnings.extend(balance_warnings(run.result, [scene], tols, list(run.auto)))
    return run


class LiveTab(Protocol):
    """What live runs need from their tab."""

    @property
    def controls(self) -> Controls | None:
        """The controls shown now: a request made for others is stale."""

    def show_live(self, view: ViewRun, *, refit: bool, stamp: float) -> None:
        """Draw a finished run."""

    def show_error(self, message: str) -> None:
        """Say why the run was not made."""

    def after_run(self, scene: Scene, preview: Preview | None) -> None:
        """A run has been drawn (and no newer request waits)."""


class LiveRuns:
    """The worker thread, the background runner and what the scene's runs cost."""

    def __init__(self, tab: LiveTab, messages: Messages, stop_button: Any, closed: threading.Event,
                 initial_cost: float | None, name: str) -> None:
        self._tab = tab
        self._messages = messages
        self._stop_button = stop_button
        self._closed = closed
        # s: what the scene's runs cost, known from its own run only (chooses previews and
        # background runs)
        self.full_cost = initial_cost
        # s: each scene's last run in this tab, by name: a scene picked again starts from it (a
        # coarse preview first when its run is slow, as a slider's move does)
        self.costs: dict[str, float] = {}
        self.timings: deque[dict[str, float]] = deque(maxlen=200)  # per drawn run, for benchmarks
        self.worker: LatestWorker[Request] = LatestWorker(self._job, on_error=self._job_failed, name=name)
        self.runner = BackgroundRunner()  # long runs (many bodies) in a child process
        self._stop_run = threading.Event()
        self._measuring = False  # the run drawn last has its error measured in the final pass

    def submit(self, request: Request) -> None:
        self.worker.submit(request)

    def stop_run(self) -> None:
        """Stop the run going in the background (the Stop button)."""
        self._stop_run.set()

    def warm_for(self, view: ViewRun) -> None:
        """Start the child process now if the next run will go to it: a long run's, or, with
        many bodies, while their start is shown (the run follows once the slider rests; after
        a run of many bodies the child is not kept, see `_job`)."""
        if isinstance(view, StartFrames) or (view.n_bodies <= MANY_BODIES and (self.full_cost or 0.0) > LONG_RUN_S):
            self.runner.warm()

    def close(self) -> None:
        self.worker.close(timeout=2.0)
        self.runner.close()

    # -- the worker thread ------------------------------------------------------------------------

    def _job(self, req: Request, final: bool) -> bool:
        if req.controls is not self._tab.controls or self._closed.is_set():
            return False
        clock = [time.perf_counter()]

        def lap() -> float:
            now = time.perf_counter()
            clock.append(now)
            return now - clock[-2]

        try:
            scene = build_scene(req.controls, req.values, req.settings)
            long = self._expect_long(scene)
            preview = None
            if (not final and self.full_cost is not None and self.full_cost > PREVIEW_BUDGET
                    and len(scene.bodies) <= MANY_BODIES):
                preview = preview_settings(scene)
            if long and preview is None and not final:
                if len(scene.bodies) > MANY_BODIES:
                    # Many bodies: their start with these values at once (O(N), milliseconds),
                    # the run in the background after it.
                    start = start_frames(scene)
                    t_start = lap()
                    if req.controls is not self._tab.controls:
                        return False
                    self._tab.show_live(start, refit=req.refit, stamp=req.stamp)
                    self._record(req, clock, preview=True, simulate=0.0, core=0.0, prepare=t_start)
                if not req.refit:
                    # Seconds to a minute of run and no quick preview: only once the slider rests
                    # (the worker calls back with final=True after its settle time, unless a
                    # newer value came).
                    self._messages.show_progress(f"*{scene.name}: the run starts when the slider rests...*")
                    return True
            t_build = lap()
            measuring = False  # shown with its error estimate pending, measured in the final pass
            if preview is not None:
                # A preview is a coarse first answer, redrawn by the real run once the slider rests:
                # its error is not measured (that runs the scene again at a tenth of the
                # tolerance: 23 -> 8 ms for the billiards break's preview).
                run = run_scene(scene, integrator=preview.integrator, dt=preview.dt, tol=preview.tol, record=True,
                                measure=False)
            elif long:
                run = self._run_in_background(scene)
                if run is None:
                    return False
                if len(scene.bodies) > MANY_BODIES:
                    # Not kept for the next run: its kernels and working memory (about 240 MB
                    # after a pile) would stay with the tab; the next run starts a fresh one.
                    self.runner.close()
            elif not final and may_be_measured(scene):
                run = run_scene(scene, record=True, measure=False)
                measuring = needs_measuring(scene, run)
                if not measuring:
                    run = as_measured(scene, run)
            elif final and self._measuring:
                run = _yielding(lambda: run_scene(scene, record=True))
            else:
                run = run_scene(scene, record=True)
            t_run = lap()
            if preview is None:
                self.full_cost = self.costs[scene.name] = t_run
            view = ViewRun(run, origin="live run", preview=preview is not None, measuring=measuring)
            t_view = lap()
        except (SceneError, RunError) as exc:
            self._messages.show_progress("")
            self._tab.show_error(one_line(exc))
            return False
        if req.controls is not self._tab.controls:
            return False
        self._tab.show_live(view, refit=req.refit, stamp=req.stamp)
        if long:
            self._messages.show_progress("")
        if len(scene.bodies) > MANY_BODIES:
            release_memory()  # the run it replaced
        self._record(req, clock, preview=preview is not None or measuring, simulate=t_run,
                     core=run.result.wall_time_s, prepare=t_view, build=t_build)
        self._measuring = measuring
        if measuring:
            return True  # the final pass measures it (unless a newer value comes first)
        if not self.worker.pending():
            self._tab.after_run(scene, preview)
        return preview is not None

    def _record(self, req: Request, clock: list[float], *, preview: bool, simulate: float, core: float,
                prepare: float, build: float = 0.0) -> None:
        """What a drawn run cost (for benchmarks): the last lap is its drawing."""
        draw = time.perf_counter() - clock[-1]
        clock.append(time.perf_counter())
        self.timings.append({"stamp": req.stamp, "preview": preview, "queued": clock[0] - req.stamp,
                             "build": build, "simulate": simulate, "core_wall": core, "prepare": prepare,
                             "draw": draw, "total": time.perf_counter() - req.stamp})

    def _expect_long(self, scene: Scene) -> bool:
        return len(scene.bodies) > MANY_BODIES or (self.full_cost is not None and self.full_cost > LONG_RUN_S)

    def _run_in_background(self, scene: Scene) -> SceneRun | None:
        """Run in the child process with a progress line; None when stopped (the Stop button,
        a newer value, the tab closing)."""
        self._stop_run.clear()
        self._stop_button.visible = True
        name = scene.name
        show = self._messages.show_progress
        at_rest = " (or sooner, at rest)" if scene.rest is not None else ""

        def progress(t: float, t_end: float, steps: int, seconds: float) -> None:
            done = f" ({100 * t / t_end:.0f} %)" if math.isfinite(t_end) and t_end > 0 and not at_rest else ""
            show(f"**Running {name}** in the background: {t:.4g} of {t_end:.4g} s{at_rest} "
                 f"simulated{done}, {steps:,} steps, {seconds:.1f} s. The last run stays shown; "
                 "moving a slider restarts it.")

        show(f"**Running {name}** in the background: starting...")
        try:
            run = self.runner.run(scene, progress=progress, record=True, stop=self._run_should_stop)
        except RunStopped:
            if self._stop_run.is_set():
                show(f"*{name}: run stopped; the last run is shown.*")
            return None
        finally:
            self._stop_button.visible = False
        self.full_cost = self.costs[name] = run.result.wall_time_s
        show(f"*{name}: run done in {run.result.wall_time_s:.1f} s; preparing the view...*")
        return run

    def _run_should_stop(self) -> bool:
        return self._stop_run.is_set() or self.worker.pending() or self._closed.is_set()

    def _job_failed(self, exc: BaseException) -> None:
        FAILURES.report(exc, "a tab's run")  # one line, each distinct one once: values can repeat it
        self._tab.show_error(f"internal error: {one_line(exc)}")
