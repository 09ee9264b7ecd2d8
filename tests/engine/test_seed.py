"""The report's update (collide/engine/seed.py), the `seed` integrator: its free flights count
against the step limit. Its outcomes against every printed digit of the report's tables:
tests/test_seed_report.py."""

from __future__ import annotations

import numpy as np

from collide.run import run_scene
from collide.stepper import RunError


def test_the_seed_update_never_steps_forever_far_out_in_time() -> None:
    """The seed at tol 3e-4 leaves the cradle's balls closing again at a speed it does not resolve;
    they meet again at t = 1.5e5 s, where positions no longer resolve one step's approach. The
    run ends at once, answered or refused in one line, never looping (it stepped without end)."""
    from collide.scene import load_scene

    try:
        run = run_scene(load_scene("newtons-cradle"), integrator="seed", tol=3e-4, record=False)
    except RunError as exc:
        assert "duration" in str(exc) and "\n" not in str(exc)
    else:
        final = run.result.final.v[0][:, 0]
        assert abs(final[-1] - 1.0) < 0.01 and np.all(np.abs(final[:-1]) < 0.01)
