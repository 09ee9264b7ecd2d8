"""The DEM step (collide/engine/dem/verlet.py): one pass over the bodies between force passes changes
no bit."""

from __future__ import annotations

import numpy as np

from collide.run import run_scene
from collide.scene import parse_scene
from tests.dem_scenes import _pile


def test_one_pass_between_force_passes_changes_no_bit():
    """Between two force passes the DEM kernel makes one pass over the bodies (a step's closing
    kick, the next one's opening kick and drift) unless it must read the velocities at the step's
    end, as a scene that ends at rest does after every step. The same settling pile (rolling
    resistance and tangential springs: every part of the work booked) run both ways, its rest
    test never met, ends with the same state and work to the last bit."""
    fused = _pile(3, 3)
    fused["duration"] = 0.3
    del fused["rest"]
    unfused = dict(fused, rest=1e-30)
    runs = [run_scene(parse_scene(raw), record=False).result for raw in (fused, unfused)]
    assert runs[0].steps[0] == runs[1].steps[0] > 1000 and runs[0].final.t[0] == 0.3
    first, second = runs
    for name in ("s", "v", "w", "q", "work"):
        assert np.array_equal(getattr(first.final, name), getattr(second.final, name)), name
    assert np.array_equal(first.dissipation, second.dissipation)
    assert np.abs(first.final.v).max() > 1e-3  # still moving: the passes had work to do
