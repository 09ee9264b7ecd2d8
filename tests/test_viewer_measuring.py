"""A run whose error is measured (collide.measure: the scene again at a tenth of the tolerance)
is shown as soon as its own run is done, the status saying plainly that the estimate is
pending; the measured run follows and replaces it, as `run_scene` returns it."""

from __future__ import annotations

import numpy as np
import pytest

from collide.run import run_scene
from viewer.state import MEASURING
from viewer.testing import ServerClient


@pytest.fixture
def session(tmp_path):
    from viewer.app import ViewerApp
    from viewer.session import Session

    app = ViewerApp("demo-1d", port=0, recordings_dir=tmp_path)
    app.start()
    session = Session(app.session_config(), ServerClient(app.server))  # type: ignore[arg-type]
    session.fit_camera = lambda *a, **k: None  # no camera without a browser
    session.worker.wait_idle(60)
    yield session
    session.close()
    app.stop()


@pytest.fixture
def measurements(monkeypatch) -> list[int]:
    """One entry per error measurement started (collide.measure.measured, which runs the scene
    again at a tenth of the tolerance)."""
    import collide.measure as measure

    started: list[int] = []
    real = measure.measured

    def counting(*args, **kwargs):
        started.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(measure, "measured", counting)
    return started


def _shown(session, measuring_runs: list[int]) -> list[tuple]:
    """(view, status text, measurements started by then) for each run the tab draws."""
    shown: list[tuple] = []
    real = session.show_live

    def record(view, **kwargs):
        real(view, **kwargs)
        shown.append((view, session.messages._status.content, len(measuring_runs)))

    session.show_live = record
    return shown


def test_a_measured_run_is_shown_first_with_its_estimate_pending(session, measurements):
    shown = _shown(session, measurements)
    session.load_scene("newtons-cradle")
    assert session.worker.wait_idle(120)
    assert len(shown) == 2, [v.measuring for v, _, _ in shown]
    (first, first_text, runs_before), (last, last_text, runs_after) = shown
    # Drawn before any run at a tighter tolerance started, and said to be pending.
    assert first.measuring and runs_before == 0 and MEASURING in first_text
    assert first.run.error_method == ["model"]
    # Then the measured run: the tighter runs happened, and the page says it is measured.
    assert not last.measuring and runs_after > 0 and MEASURING not in last_text
    assert last.run.error_method == ["measured"] and "(measured" in last_text
    reference = run_scene(last.scene, record=True)
    assert np.array_equal(last.run.error_estimate, reference.error_estimate)
    assert f"{float(reference.error_estimate[0]):.2g}" in last_text
    assert int(last.result.steps[0]) == int(reference.result.steps[0])
    assert last.result.warnings == reference.result.warnings


def test_a_run_the_model_covers_is_shown_once_as_run_scene_returns_it(session, measurements):
    shown = _shown(session, measurements)
    session.load_scene("demo-bonus")
    assert session.worker.wait_idle(60)
    assert len(shown) == 1 and measurements == []
    view, text, _ = shown[0]
    reference = run_scene(view.scene, record=True)
    assert not view.measuring and MEASURING not in text and "the error model's" in text
    assert view.run.error_method == reference.error_method == ["model"]
    assert np.array_equal(view.run.error_estimate, reference.error_estimate)
    assert view.result.warnings == reference.result.warnings


def test_a_scene_picked_again_starts_from_its_last_cost(session, measurements):
    """A scene's first pick in a tab draws its own run first (what it costs is unknown); picked
    again after a run that took longer than the preview budget, it is drawn first from a coarse
    preview, as a slider's move is, and its own run follows."""
    from viewer.live import LONG_RUN_S, PREVIEW_BUDGET

    shown = _shown(session, measurements)
    session.load_scene("break-3d")
    assert session.worker.wait_idle(300)
    assert not shown[0][0].preview and session.live.costs["break-3d"] > 0
    session.load_scene("demo-1d")
    assert session.worker.wait_idle(120)
    # As if its run had taken half a second here (a slower machine, or one under load).
    session.live.costs["break-3d"] = 0.5 * (PREVIEW_BUDGET + LONG_RUN_S)
    shown.clear()
    session.load_scene("break-3d")
    assert session.worker.wait_idle(300)
    assert shown[0][0].preview and shown[0][0].scene.name == "break-3d"
    assert not shown[-1][0].preview and not shown[-1][0].measuring
