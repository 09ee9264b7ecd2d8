"""The session without a browser (`viewer.testing.ServerClient`): long runs (many bodies) in a
child process, with progress while they go and a stop that stops them (issue 12: a slider on
gas-box or pile must never freeze the page or start a minute-long run it cannot take back), and
controls that change nothing disabled (issue 12, item 5)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest

from collide.run import run_scene
from collide.scene import SceneError, parse_scene
from viewer.background import BackgroundRunner, RunStopped
from viewer.testing import ServerClient, wait_until


def _pile(n: int, duration: float) -> object:
    """n spheres dropped into an open box (DEM, Hertz): the built-in pile's recipe, smaller."""
    rng = np.random.default_rng(2)
    per = 6
    cells = [(i, j, k) for k in range(n // per**2 + 1) for i in range(per) for j in range(per)][:n]
    bodies = [{"name": f"g{m + 1}", "material": "glass", "radius": 0.005,
               "position": [(i + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4), (j + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4),
                            0.007 + k * 0.011],
               "velocity": [0.0, 0.0, 0.0]} for m, (i, j, k) in enumerate(cells)]
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    walls += [{"point": [0.066 * (s < 0) if a == c else 0.0 for c in range(3)],
               "normal": [float(s) if a == c else 0.0 for c in range(3)]} for a in range(2) for s in (1, -1)]
    return parse_scene({"name": "small-pile", "dim": 3, "dt": "auto", "integrator": "dem", "tol": 4e-2,
                        "duration": duration, "gravity": [0.0, 0.0, -9.81],
                        "contact": {"model": "hertz", "restitution": 0.3, "mu": 0.5},
                        "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6,
                                      "poisson_ratio": 0.25}],
                        "body": bodies, "wall": walls}, "small-pile")


@contextmanager
def _headless_session(tmp_path) -> Iterator[object]:
    """A viewer session without a browser (no camera to fit), closed and stopped after."""
    from viewer.app import ViewerApp
    from viewer.session import Session

    app = ViewerApp("demo-1d", port=0, recordings_dir=tmp_path)
    app.start()
    session = Session(app.session_config(), ServerClient(app.server))  # type: ignore[arg-type]
    session.fit_camera = lambda *a, **k: None  # no camera without a browser
    try:
        yield session
    finally:
        session.close()
        app.stop()

def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_a_background_run_reports_progress_and_gives_the_same_run():
    scene = _pile(216, 0.3)  # a second or more of run: progress comes every 0.25 s
    runner = BackgroundRunner()
    seen: list[tuple[float, float, int, float]] = []
    try:
        run = runner.run(scene, progress=lambda *p: seen.append(p), record=True)
        here = run_scene(scene, record=True)
        assert np.array_equal(run.result.final.s, here.result.final.s)
        assert len(run.result.trajectory.knots) == len(here.result.trajectory.knots)
        # Progress came while it ran: the time reached grows towards the end.
        assert seen and all(0 <= p[0] <= p[1] for p in seen) and seen[-1][2] > 0
        # The same process serves the next run; a scene the core refuses is refused as in-process.
        pid = runner.pid
        with pytest.raises(SceneError):
            runner.run(replace(scene, integrator="euler"))
        assert runner.pid == pid and _alive(pid)
    finally:
        runner.close()


def test_stopping_a_background_run_kills_its_process_at_once():
    scene = _pile(216, 2.0)  # about half a minute of run
    runner = BackgroundRunner()
    seen: list[float] = []
    try:
        runner.warm()
        pid = runner.pid
        with pytest.raises(RunStopped):
            runner.run(scene, progress=lambda *p: seen.append(p[0]), stop=lambda: len(seen) >= 2)
        assert len(seen) == 2 and seen[-1] < 2.0
        wait_until(lambda: not _alive(pid), 5, "the run's process to end")
        assert runner.pid is None
        # The next run starts a fresh process.
        run = runner.run(_pile(216, 0.01))
        assert run.result.final.t[0] == pytest.approx(0.01, rel=0.2) and runner.pid != pid
    finally:
        runner.close()


def test_a_slider_on_a_many_body_scene_runs_in_the_background_with_a_stop(tmp_path):
    """More than MANY_BODIES bodies: a moved slider draws the scene's new start at once, then,
    once the slider rests, runs in the child process with a progress line and a Stop button;
    Stop keeps the start on screen; a run let finish is drawn."""
    from viewer.frames import StartFrames
    from viewer.live import MANY_BODIES

    long, short = _pile(216, 2.0), _pile(216, 0.03)
    assert len(long.bodies) > MANY_BODIES
    with _headless_session(tmp_path) as session:
        # The long scene, shown with a short run of it (its own takes half a minute).
        session.load_scene(long, run=run_scene(replace(long, duration=0.01)))
        assert session.runs_drawn == 1
        session.values["contact.mu"] = 0.4
        session.request_run()
        wait_until(lambda: "simulated" in session.progress.content, 60, "the run's progress")
        # The new values' start was drawn first (a preview), the run goes behind it.
        start = session.view
        assert isinstance(start, StartFrames) and session.runs_drawn == 2 and session.stop_button.visible
        assert start.duration == 0 and start.n_bodies == len(long.bodies)
        pid = session.runner.pid
        session.stop_run()
        assert session.worker.wait_idle(30)
        assert "stopped" in session.progress.content and not session.stop_button.visible
        assert session.view is start and session.runs_drawn == 2 and not _alive(pid)
        # A run let finish is drawn (after its start), and the progress line goes.
        session.load_scene(short, run=run_scene(short))
        session.values["contact.mu"] = 0.4
        session.request_run()
        wait_until(lambda: session.runs_drawn == 5, 60, "the new run drawn")
        assert session.worker.wait_idle(30)
        assert session.view.scene.contact.mu == pytest.approx(0.4) and session.progress.content == ""
        assert session.runner.pid is None  # its process is not kept with the tab after a run of many bodies


def test_a_slider_the_materials_override_is_disabled_with_the_reason(tmp_path):
    """break-3d: [contact]'s restitution and mu reach no contact; their controls are disabled
    and say why, and the material's and pair's own sliders are live."""
    with _headless_session(tmp_path) as session:
        session.load_scene("break-3d")
        assert session.worker.wait_idle(120) and session.view is not None
        for ident in ("contact.restitution", "contact.mu"):
            assert session._param_handles[ident].disabled and session._param_boxes[ident].disabled
            assert "materials and pairs" in session._param_handles[ident].hint
        for ident in ("pair.0.restitution", "material.phenolic.restitution", "pair.0.mu"):
            assert not session._param_handles[ident].disabled
        before = session.view
        assert session.apply_typed("pair.0.restitution", "0.5")
        wait_until(lambda: session.view is not before and session.worker.idle(), 120, "the run with e = 0.5")
        assert session.view.scene.pairs[0].restitution == 0.5


def test_a_slow_scene_with_a_quick_preview_previews_while_dragging(tmp_path):
    """break-3d on a loaded machine: its run took over LONG_RUN_S, so the final run goes to the
    background once the slider rests; its DEM preview (a sixth of the steps) is still drawn at
    once while dragging (it was skipped: every change waited for the background run)."""
    from viewer.live import LONG_RUN_S

    with _headless_session(tmp_path) as session:
        session.load_scene("break-3d")
        assert session.worker.wait_idle(120)
        session._full_cost = 2 * LONG_RUN_S  # as measured under load
        n = len(session.timings)
        session.values["pair.0.restitution"] = 0.9
        session.request_run()
        wait_until(lambda: len(session.timings) >= n + 2 and session.worker.idle(), 120, "preview and final run")
        first, final = list(session.timings)[n:n + 2]
        assert first["preview"] and not final["preview"]
        assert session.view.scene.pairs[0].restitution == 0.9 and not session.view.preview
