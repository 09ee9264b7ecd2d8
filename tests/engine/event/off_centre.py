"""The off-centre billiards break at tol 1e-6 with the interpreted kernels, its flips, trials and
releases counted, with a gate switched off or not (tests/engine/event/test_modes.py,
test_locate.py)."""

from __future__ import annotations

import functools

import numpy as np

from collide import stepper
from collide.scene import load_scene

_FLIP_RUN = """
import math
import sys
import collide.engine.event.island as island
import collide.engine.event.locate as locate
import collide.engine.event.modes as modes
from collide.engine import layout
# Read at run time by the interpreted kernels (from the modules that use them), as are the wrapped
# functions below.
if sys.argv[1] == "no-flips":
    modes.FLIP_SHARE = 0.0
if sys.argv[1] == "no-late":
    locate.LATE_SAFETY = math.inf
from collide.accuracy import outcome
from collide.run import run_scene
from collide.scene import load_scene
count = {"flips": 0, "trials": 0, "released": 0}
decide, step = island.decide, locate.step
def counted_decide(X, C, CI, na, nc, *rest):
    count["flips"] += int((CI[:nc, layout.CI_EDGE] == layout.FLIP).sum())
    stuck = CI[:nc, layout.CI_MODE] == layout.STICK
    result = decide(X, C, CI, na, nc, *rest)
    count["released"] += int((stuck & (CI[:nc, layout.CI_MODE] != layout.STICK)).sum())
    return result
def counted_step(*args):
    count["trials"] += 1
    return step(*args)
island.decide, locate.step = counted_decide, counted_step
r = run_scene(load_scene("billiards-break", ["body.cue.position.y=0.01"]), tol=1e-6, record=False, measure=False).result
print(int(r.steps[0]), count["flips"], count["trials"], count["released"], *outcome(r))
"""


@functools.cache
def _flip_run(setting: str) -> tuple[int, int, int, int, np.ndarray]:
    """The off-centre break at tol 1e-6 with the interpreted kernels: (steps, flips, step calls,
    stuck contacts released, outcome). Cached: both tests below compare with the "on" run."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, COLLIDE_JIT="0")
    out = subprocess.run([sys.executable, "-c", _FLIP_RUN, setting], env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    return int(out[0]), int(out[1]), int(out[2]), int(out[3]), np.array(out[4:], dtype=float)


def _flip_runs(*settings: str) -> dict[str, tuple[int, int, int, int, np.ndarray]]:
    return {setting: _flip_run(setting) for setting in settings}


def _off_centre_scales() -> tuple[float, float]:
    """The off-centre break's speed scale and event tolerance at tol 1e-6 (as `simulate` sets it)."""
    from collide.accuracy import speed_scale

    scene = load_scene("billiards-break", ["body.cue.position.y=0.01"])
    speed = speed_scale(scene)
    return speed, min(0.1 * 1e-6, stepper.EDGE_BAND_SHARE * scene.contact.eps / speed)
