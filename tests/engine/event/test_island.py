"""An island over a window (collide/engine/event/island.py): its phase's settings, where a trial
soon after a step's start is one Yoshida step."""

from __future__ import annotations

import numpy as np

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import load_scene


def test_an_asymmetric_break_meets_its_tolerance_with_short_trials_as_yoshida_steps():
    """The cue ball 1 cm off the rack's line: every friction mode changes at its own time (143
    steps at tol 1e-6, 83 for the symmetric rack), many soon after a step's start, where a trial
    from the start is one Yoshida step if its error there is at most a tenth of a whole kahan6
    step's. The outcome at tol 1e-6 is within the tolerance of the run at 1e-9 (2.1e-7 of the
    cue ball's speed; with every trial a Yoshida step, 2e-4)."""
    scene = load_scene("billiards-break", ["body.cue.position.y=0.01"])
    speed = 6.0
    runs = {tol: run_scene(scene, tol=tol, record=False, measure=False).result for tol in (1e-6, 1e-9)}
    outcome = {tol: np.concatenate([r.final.v[0].ravel(), r.final.w[0].ravel() * scene.bodies[0].radius])
               for tol, r in runs.items()}
    assert np.abs(outcome[1e-6] - outcome[1e-9]).max() / speed < 1e-6
    assert dg.residuals(runs[1e-6]).energy[0] < 10 * 1e-6
