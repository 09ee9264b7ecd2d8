"""Whether one run is quicker with the kernels interpreted than with the compiled ones loaded.

Loading numba and the compiled kernels costs a process about 0.6 s of CPU here before its first
step (`benchmarks/bench_startup.py`: numba's import 0.14 s, the kernels' modules and cached code
0.17 s, besides numpy), more than the interpreted kernels take for a few spheres that meet a
few times.
A command that runs one scene asks `quick` before
the engine is first imported; `prefer_interpreted` then tells the engine (`collide.engine.tier`)
to stay interpreted for that process. What decides is the steps a run can take: few bodies, no
walls and no gravity (so no resting or rolling contacts, which last), the event integrators
with an automatic step (tens of steps a contact) and a tolerance that keeps it so.
"""

from __future__ import annotations

import os
import sys

from collide.engine.hint import HINT_VARIABLE, jit_setting
from collide.integrators import INTEGRATORS
from collide.scene import Scene

QUICK_BODIES = 5  # a Newton's cradle of 5: 36 steps, 0.67 s a process interpreted
# Steps grow as tol^(-1/6) (kahan6): the bonus demo takes 13 at its own 1e-7, 16 at 1e-8. A run
# asked for a tighter tolerance is a convergence or timing check more than a quick look: it runs
# compiled, so that its wall_time_s is the engine's (the bonus demo at 1e-9: about 0.5 ms against
# 36 ms interpreted, for about 1 s more of process).
QUICK_TOL = 1e-8


def quick(scene: Scene, integrator: str | None = None, dt: float | str | None = None,
          tol: float | None = None) -> bool:
    """Whether `scene` (with these run settings, None meaning the scene's own) is a run the
    interpreted kernels finish sooner than a process loads the compiled ones."""
    integrator = integrator or scene.integrator
    dt = scene.dt if dt is None else dt
    tol = scene.tol if tol is None else tol
    still = scene.gravity is None or not any(scene.gravity)
    return (integrator in INTEGRATORS and INTEGRATORS[integrator].events and dt == "auto" and tol >= QUICK_TOL
            and len(scene.bodies) <= QUICK_BODIES and not scene.walls and still and not scene.needs_dem)


def prefer_interpreted(scene: Scene, integrator: str | None = None, dt: float | str | None = None,
                       tol: float | None = None) -> bool:
    """Ask for the interpreted kernels in this process when the run is `quick`, the engine is
    not imported yet and COLLIDE_JIT does not choose. Returns whether it asked."""
    if "collide.engine.tier" in sys.modules or jit_setting() != "auto":
        return False
    if not quick(scene, integrator, dt, tol):
        return False
    os.environ[HINT_VARIABLE] = "interpreted"
    return True
