"""An outcome's error against a reference run, and a scene file's errors at a ladder of
tolerances (tests/test_error_estimate.py, tests/engine/event/)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from collide.accuracy import outcome, speed_scale
from collide.run import run_scene
from collide.scene import load_scene


def _error(run, reference, scene) -> float:
    return float(np.abs(outcome(run.result) - outcome(reference.result)).max() / speed_scale(scene))


def _tolerance_ladder(name: str, tols: tuple[float, ...]) -> list[float]:
    """Outcome errors of runs at `tols` against one at 1e-11 (no measuring: the steps' own)."""
    scene = load_scene(str(Path(__file__).parent / "data" / f"{name}.toml"))
    reference = run_scene(scene, tol=1e-11, record=False, measure=False)
    return [_error(run_scene(scene, tol=tol, record=False, measure=False), reference, scene) for tol in tols]
