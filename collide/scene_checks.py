"""Checks of whole scenes beyond the rigid reference: closed forms, conservation laws and
self-convergence (the scene table of `collide validate`).

The rigid reference (`collide.validate.cross_check`) answers one impact of two spheres or a sphere
on a wall. Every other scene is checked by what its physics guarantees:

* conservation: with nothing dissipating, energy is conserved; with no walls, momentum and
  angular momentum are (pairwise forces cancel exactly: only round-off remains);
* energy balance: with friction or damping, energy + dissipated work is conserved;
* closed forms: a chain of equal spheres exchanges velocities (the cradle), a ball bouncing with
  restitution e peaks at e^2 of its last apex, a pile run to rest ends with a kinetic energy below
  its `rest` share of the energy it released;
* self-convergence: the outcome at the scene's tolerance against a 100x tighter one (a given
  step: against a 10x smaller step) agrees within the error the run reports.

Every check states what it compares, the deviation, the bound and why that bound.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field

import numpy as np

from collide.model import TABLE_REST
from collide.scene import Scene, dem_reason, with_settings

# collide.diagnostics and collide.run (the engine) are imported where runs are judged: the command
# line imports this module (through collide.validate) before a run decides compiled or interpreted
# kernels (collide.hint).

LADDER_FACTOR = 100.0  # the tighter tolerance of the ladder (a given step: divided by 10)
LADDER_STEP_FACTOR = 10.0
# Pairwise forces cancel exactly: momentum moves by round-off only, a few units of float64's
# 2.2e-16 per step and body at most (summed, not cancelled).
ROUNDOFF_PER_STEP = 4.0 * np.finfo(float).eps
ROUNDOFF_FLOOR = 1e-13  # a run of a few steps: the residual's own sums are round-off of this size
MIN_BOUNCES = 2  # apex ratios the bounce check needs
LADDER_MAX_BODIES = 64  # as collide.measure.MEASURED_MAX_BODIES: beyond it final states decorrelate


@dataclass
class Check:
    """One check of a scene: what it compares, the deviation, the bound and why."""

    scene: str
    check: str
    compares: str
    deviation: float
    bound: float
    why: str
    passed: bool


@dataclass
class SceneReport:
    """The checks of one scene; `span` says what part of the run they cover."""

    scene: str
    span: str
    checks: list[Check] = field(default_factory=list)
    not_applicable: list[str] = field(default_factory=list)  # why a check does not apply
    wall_time_s: float = 0.0

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def add(self, out: Check | str) -> None:
        """A check, or why one does not apply."""
        (self.checks if isinstance(out, Check) else self.not_applicable).append(out)

    def to_dict(self) -> dict:
        return {"scene": self.scene, "span": self.span, "passed": self.passed,
                "checks": [asdict(c) for c in self.checks], "not_applicable": self.not_applicable,
                "wall_time_s": self.wall_time_s}


def _count(n: int, one: str, many: str | None = None) -> str:
    return f"{n} {one if n == 1 else many or one + 's'}"


def _check(scene: Scene, name: str, compares: str, deviation: float, bound: float, why: str) -> Check:
    ok = bool(math.isfinite(deviation) and deviation <= bound)
    return Check(scene.name, name, compares, float(deviation), float(bound), why, ok)


# ---------------------------------------------------------------------------------------------
# Which checks apply


def rigid_reason(scene: Scene) -> str | None:
    """Why the rigid reference does not apply to a scene, or None when it does."""
    n, w = len(scene.bodies), len(scene.walls)
    if not ((n == 2 and w == 0) or (n == 1 and w == 1)):
        return (f"rigid reference: handles 2 spheres, or 1 sphere and 1 wall ({_count(n, 'body', 'bodies')}, "
                f"{_count(w, 'wall')})")
    if scene.gravity is not None and any(g != 0.0 for g in scene.gravity):
        return "rigid reference: one impact without gravity (this scene has gravity)"
    if scene.needs_dem:
        return f"rigid reference: the report's elastic law (this scene's has {dem_reason(scene)})"
    return None


# ---------------------------------------------------------------------------------------------
# Conservation and energy balance


def _tol_basis(scene: Scene, run) -> float:
    """The relative error of one contact's outcome the scene asks for: its tolerance (relative to
    the fastest speed). A run at a given step is held to it too: an error estimate beyond it is
    a run that misses its tolerance."""
    return float(run.tol[0])


def _speed_scale(scene: Scene, result) -> float:
    """Fastest speed the run can reach, from its start: the fastest initial speed (centre plus
    surface from spin, what --tol is relative to) and a fall from the highest sphere to the
    floor under gravity (without a floor: the fastest final speed)."""
    from collide.rigid import reference_speed

    speed = reference_speed(scene)
    if scene.gravity is not None and any(scene.gravity):
        g_vec = np.asarray(scene.gravity, dtype=float)
        g = float(np.linalg.norm(g_vec))
        up = -g_vec / g
        floors = [float(np.dot(w.point, up)) for w in scene.walls if float(np.dot(w.normal, up)) > 0.999]
        if floors:
            drop = max(float(np.dot(b.position, up)) for b in scene.bodies) - min(floors)
            speed = math.hypot(speed, math.sqrt(2 * g * max(drop, 0.0)))
        else:
            speed = max(speed, float(np.linalg.norm(result.final.v[0], axis=-1).max()))
    return max(speed, 1e-300)


def energy_check(scene: Scene, run) -> Check | str:
    """Energy (+ dissipated work) at the end against the start: the run's own residual.

    Event engine: each contact's outcome is within tol of the fastest speed v, so it moves the
    energy of its two bodies by at most 2 tol m_max v^2 (first order); C contacts at most C times
    that, over the energy E0. DEM: the work taken out is booked exactly at each kick, so what
    remains is velocity Verlet's error in the conservative forces, (omega dt)^2 of the energy a
    contact holds at most (omega the stiffest contact's frequency), which a symplectic step does
    not let grow."""
    from collide import diagnostics as dg

    result = run.result
    residual = float(dg.residuals(result).energy[0])
    e0 = float(abs(dg.state_conserved(result.model, result.initial).balance[0]))
    if not e0 > 0:
        return "energy: the scene starts with no energy to compare with (E0 = 0)"
    dissipates = result.model.dissipative
    name = "energy balance" if dissipates else "energy conservation"
    compares = ("|E + W - E0| / E0, W the work dissipated (friction, damping, rolling)" if dissipates
                else "|E - E0| / E0 (nothing dissipates)")
    if result.integrator == "dem":
        from collide import dem

        _, omega, _ = dem.contact_time(result.model, result.initial)
        omega_h = float(omega[0] * result.dt[0])
        why = (f"velocity Verlet's energy error (omega dt)^2 at the stiffest contact (omega dt = {omega_h:.3g}); "
               "the dissipated work is booked exactly at each kick")
        return _check(scene, name, compares, residual, omega_h**2, why)
    count = max(int(result.contacts.count[0]), 1)
    basis = _tol_basis(scene, run)
    speed = _speed_scale(scene, result)
    m_max = float(result.model.mass[0].max())
    bound = count * 2.0 * basis * m_max * speed**2 / e0
    why = (f"{_count(count, 'contact')} x 2 tol m v^2 / E0 (tol {basis:.2g} per contact's outcome, v = {speed:.3g} m/s "
           f"the fastest speed)")
    return _check(scene, name, compares, residual, bound, why)


def momentum_check(scene: Scene, run) -> Check:
    """Momentum and angular momentum (gravity's impulse and torque taken out): no walls, so only
    round-off moves them."""
    from collide import diagnostics as dg

    result = run.result
    res = dg.residuals(result)
    values = [float(res.momentum[0])]
    if scene.dim > 1:
        values.append(float(res.angular_momentum[0]))
    deviation = max(values)
    steps = max(int(result.steps[0]), 1)
    bound = max(ROUNDOFF_FLOOR, ROUNDOFF_PER_STEP * steps * len(scene.bodies))
    compares = "|P - P0| / sum m|v|" + (", |L - L0| / sum |s x m v| + I|w|" if scene.dim > 1 else "")
    why = f"round-off: pairwise forces cancel exactly; 4 eps per step and body over {steps} steps"
    return _check(scene, "momentum" if scene.dim == 1 else "momentum, angular momentum", compares, deviation,
                  bound, why)


# ---------------------------------------------------------------------------------------------
# Closed forms


def exchange_reason(scene: Scene) -> str | None:
    """Why the velocity exchange of a Newton's cradle does not apply, or None when it does: a 1D
    row of equal spheres on the same law, the first moving into the others at rest, no walls, no
    gravity, each contact over before the next can begin."""
    bodies = scene.bodies
    if scene.dim != 1 or len(bodies) < 3 or scene.walls or scene.needs_dem:
        return "velocity exchange: needs a 1D row of 3 or more spheres, no walls, the report's elastic law"
    if scene.gravity is not None and any(g != 0.0 for g in scene.gravity):
        return "velocity exchange: needs no gravity"
    if len({b.mass for b in bodies}) != 1 or len({b.radius for b in bodies}) != 1:
        return "velocity exchange: needs equal spheres"
    x = [b.position[0] for b in bodies]
    if x != sorted(x) or bodies[0].velocity[0] <= 0 or any(b.velocity[0] != 0.0 for b in bodies[1:]):
        return "velocity exchange: needs the first sphere moving into the others at rest, in order"
    gap = min(x[i + 1] - x[i] - 2 * bodies[0].radius for i in range(len(x) - 1))
    travel = _cradle_travel(scene)
    if gap <= travel:
        return (f"velocity exchange: the spheres are {gap:.3g} m apart, within the {travel:.3g} m a sphere moves "
                "during one contact: contacts overlap and the soft chain disperses")
    return None


def _cradle_travel(scene: Scene) -> float:
    """How far the struck sphere moves during one contact: v T, T = pi sqrt(m_red / k_eff)."""
    body = scene.bodies[0]
    duration = math.pi * math.sqrt((body.mass / 2) / (scene.contact.k / 2))
    return body.velocity[0] * duration


def exchange_check(scene: Scene, run) -> Check:
    """The last sphere leaves with the first one's speed, the others at rest. Head-on, a linear
    spring gives the rigid answer at any k (rigid.py), and the contacts do not overlap: the soft
    model's exchange is exact, and the step's error is all there is."""
    v = run.result.final.v[0][:, 0]
    v0 = scene.bodies[0].velocity[0]
    deviation = max(abs(v[-1] - v0), float(np.abs(v[:-1]).max())) / v0
    bound = _tol_basis(scene, run) * (len(v) - 1)
    gap = min(b.position[0] - a.position[0] - a.radius - b.radius for a, b in zip(scene.bodies, scene.bodies[1:]))
    travel = _cradle_travel(scene)
    why = (f"the soft model's exchange is exact at any k (head-on linear springs; a sphere moves {travel:.2g} m in a "
           f"contact, under the {gap:.2g} m gaps: contacts one at a time), so tol {_tol_basis(scene, run):.2g} "
           f"per contact x {_count(len(v) - 1, 'contact')} in the chain")
    return _check(scene, "velocity exchange", f"last sphere's speed vs first's ({v0:g} m/s), others' speeds, / v0",
                  deviation, bound, why)


def bounce_reason(scene: Scene) -> str | None:
    """Why the restitution law's apex ratio does not apply, or None: one sphere on one floor (a
    wall facing up against gravity), no friction (a spinning, sliding ball trades bounce for spin)."""
    gravity = scene.gravity is not None and any(g != 0.0 for g in scene.gravity)
    if len(scene.bodies) != 1 or len(scene.walls) != 1 or not gravity:
        return "bounce heights: needs one sphere bouncing on one wall under gravity"
    up = -np.asarray(scene.gravity, dtype=float) / float(np.linalg.norm(scene.gravity))
    if float(np.dot(scene.walls[0].normal, up)) < 0.999:
        return "bounce heights: needs the wall to be a floor (facing up, against gravity)"
    if scene.has_friction:
        return "bounce heights: needs no friction (it trades bounce for spin)"
    return None


def _apexes(scene: Scene, run) -> tuple[list[float], list[float], list[float]]:
    """Apex heights above the floor of each flight, with each impact's approach speed and contact
    time. Each flight's apex comes from a frame inside it in closed form (h + v_up^2 / 2g), so
    the frames' spacing does not matter."""
    result = run.result
    traj = result.trajectory
    g_vec = np.asarray(scene.gravity, dtype=float)
    g = float(np.linalg.norm(g_vec))
    up = -g_vec / g
    base = float(np.dot(scene.walls[0].point, up))  # the floor (bounce_reason)
    radius = scene.bodies[0].radius
    times = traj.t[:, 0]
    heights = traj.s[:, 0, 0] @ up - base - radius
    rises = traj.v[:, 0, 0] @ up
    spans = traj.intervals[traj.intervals[:, 1] < 0][:, 2:4]
    apexes, speeds, durations = [], [], []
    start = float(times[0])
    for begin, end in list(spans) + [(math.inf, math.inf)]:
        # (From the flight's first state on: an event run's knot where the contact ended.)
        inside = np.nonzero((times >= start) & (times < begin))[0]
        if not len(inside) or not math.isfinite(start):
            break
        k = int(inside[len(inside) // 2])
        apexes.append(float(heights[k] + rises[k] ** 2 / (2 * g)))  # the flight's parabola
        if math.isfinite(begin):
            speeds.append(math.sqrt(2 * g * apexes[-1]))
            durations.append(float(end - begin))
        start = float(end)
        if not math.isfinite(begin):
            break
    return apexes, speeds, durations


def bounce_check(scene: Scene, run) -> Check | str:
    """Successive apex heights in ratio e^2 (each rebound speed e times the impact's, and free
    flight returns a ball at the speed it left with)."""
    e = float(run.result.model.wall_column(TABLE_REST)[0, 0])
    apexes, speeds, durations = _apexes(scene, run)
    if len(apexes) < MIN_BOUNCES + 1:
        return f"bounce heights: only {len(apexes)} flights seen in the run (needs {MIN_BOUNCES + 1})"
    g = float(np.linalg.norm(scene.gravity))
    estimate = float(run.error_estimate[0])
    worst = None
    for k in range(len(apexes) - 1):
        if not apexes[k + 1] > 0 or k >= len(speeds):
            break
        deviation = abs(apexes[k + 1] / apexes[k] / e**2 - 1.0)
        # Ratio of squared speeds: twice the rebound speed's relative error, which is the step's
        # (the run's estimate) plus gravity's impulse over the contact, g T / v.
        bound = 2.0 * (estimate + g * durations[k] / speeds[k])
        if worst is None or deviation / bound > worst[0] / worst[1]:
            worst = (deviation, bound, k)
    deviation, bound, k = worst
    why = (f"2 x (the step's error {estimate:.2g} + gravity's impulse in contact g T / v = "
           f"{g * durations[k] / speeds[k]:.2g}), worst of {len(apexes) - 1} ratios at bounce {k + 1}")
    return _check(scene, "bounce heights", f"successive apex heights / e^2 (e = {e:g}), |ratio - 1|",
                  deviation, bound, why)


def rest_check(scene: Scene, run) -> Check | str:
    """A run with `rest` ends at rest: its final kinetic energy is below `rest` times its peak, and
    the peak is at most the starting kinetic energy plus the potential energy released."""
    from collide import diagnostics as dg

    result = run.result
    c0 = dg.state_conserved(result.model, result.initial)
    c1 = dg.state_conserved(result.model, result.final)

    def kinetic(c: dg.Conserved) -> float:
        return float(c.kinetic[0] + (c.rotational[0] if c.rotational is not None else 0.0))

    released = float(c0.gravitational[0] - c1.gravitational[0]) if c0.gravitational is not None else 0.0
    if not released > 0:
        return "at rest: the run released no potential energy to compare with"
    k0, k1 = kinetic(c0), kinetic(c1)
    deviation, bound = k1 / released, scene.rest * (k0 + released) / released
    why = (f"the run stops at rest: kinetic energy below rest = {scene.rest:g} of its peak, and the peak is at most "
           f"K0 + released ({k0:.3g} + {released:.3g} J)")
    return _check(scene, "at rest", "final kinetic energy / potential energy released", deviation, bound, why)


# ---------------------------------------------------------------------------------------------
# Self-convergence


def ladder_reason(scene: Scene) -> str | None:
    """Why the tolerance ladder does not apply, or None: its outcome must be a converging
    quantity, which the final state of a many-sphere DEM run is not (chaos: a pile's or gas's
    final states decorrelate), and the event engine measures its own error up to that size."""
    if scene.integrator == "dem" and len(scene.bodies) > LADDER_MAX_BODIES:
        return (f"tolerance ladder: {len(scene.bodies)} spheres in the DEM kernel, whose final states decorrelate "
                "between steps (chaos); the balances are the check")
    if scene.integrator != "dem" and len(scene.bodies) > LADDER_MAX_BODIES:
        return (f"tolerance ladder: {len(scene.bodies)} spheres, whose final states decorrelate between "
                "tolerances (chaos); the balances are the check")
    return None


def _ladder_distance(scene: Scene, a, b) -> float:
    """Largest difference of final velocities and spins times radius over the speed scale
    (`_speed_scale`: the fastest initial speed, or a fall's)."""
    radius = a.model.radius[0][:, None]
    dv = np.abs(a.final.v[0] - b.final.v[0]).max(initial=0.0)
    dw = np.abs((a.final.w[0] - b.final.w[0]) * radius).max(initial=0.0) if a.final.w.shape[-1] else 0.0
    return float(max(dv, dw) / _speed_scale(scene, a))


def ladder_check(scene: Scene, run) -> Check | str:
    """The outcome at the scene's tolerance against a 100x tighter one (a given step: 10x smaller).

    If each run's reported error estimate holds, the two outcomes differ by at most the sum of
    the two. The event engine's estimate covers the whole outcome (measured where contacts
    chain); the DEM's is its error model's at the steps per shortest contact."""
    from collide.run import TOL_FLOOR, run_scene
    from collide.stepper import RunError

    try:
        if run.auto[0]:
            tol = float(run.tol[0])
            if scene.integrator == "dem":
                from collide import dem

                floor = 2 * dem.ERROR_CONSTANT / dem.MAX_STEPS_PER_CONTACT
            else:
                floor = TOL_FLOOR[scene.integrator]
            tight_tol = max(tol / LADDER_FACTOR, floor)
            if tight_tol > tol / 2:
                return f"tolerance ladder: tol {tol:.2g} is at what '{scene.integrator}' reaches; no tighter run"
            tight = run_scene(scene, tol=tight_tol, record=False)
            how = f"tol {tol:.2g} vs {tight_tol:.2g}"
        else:
            step = float(run.result.dt[0]) / LADDER_STEP_FACTOR
            tight = run_scene(with_settings(scene, dt=step), record=False)
            how = f"dt {float(run.result.dt[0]):.3g} vs {step:.3g} s"
    except RunError as exc:
        return f"tolerance ladder: the tighter run cannot be made ({exc})"
    deviation = _ladder_distance(scene, run.result, tight.result)
    own, fine = float(run.error_estimate[0]), float(tight.error_estimate[0])
    method = run.error_method[0] if run.error_method else "model"
    why = f"sum of the two runs' reported errors ({own:.2g} {method} + {fine:.2g})"
    floor = 0.0 if scene.integrator == "dem" else TOL_FLOOR[scene.integrator]
    if min(own, fine) < floor:
        # The error model knows the step's error only: below this the outcome's error is round-off.
        own, fine = max(own, floor), max(fine, floor)
        why += f", each at least the round-off floor {floor:.0e} of '{scene.integrator}'"
    return _check(scene, "tolerance ladder", f"final velocities and spins x r, {how}, / fastest speed",
                  deviation, own + fine, why)


# ---------------------------------------------------------------------------------------------
# A scene's checks


def idle_reason(scene: Scene) -> str | None:
    """Why nothing can happen in a scene (so no check applies), or None."""
    if len(scene.bodies) < 2 and not scene.walls:
        return "one sphere and no walls: nothing to collide with"
    gravity = scene.gravity is not None and any(g != 0.0 for g in scene.gravity)
    moving = any(any(c != 0.0 for c in b.velocity) or any(c != 0.0 for c in b.spin) for b in scene.bodies)
    if not moving and not gravity:
        return "nothing moves and no gravity acts: the scene stays as it starts"
    return None


def scene_checks(scene: Scene, *, duration: float | None = None, skip: tuple[str, ...] = ()) -> SceneReport:
    """Run a scene (cut to `duration` if given) and the checks that apply to it. `skip` names
    checks left to another table ("ladder": the rigid cross-check's own step ladder)."""
    from collide.run import run_scene

    started = time.perf_counter()
    cut = duration is not None and (scene.duration is None or duration < scene.duration)
    if cut:
        scene = with_settings(scene, duration=duration)
    report = SceneReport(scene.name, f"first {duration:g} s" if cut else "whole run")
    idle = idle_reason(scene)
    if idle is not None:
        report.add(idle)
        return report
    run = run_scene(scene, record=bounce_reason(scene) is None)
    if not cut:
        report.span += f" ({float(run.result.final.t[0]):.3g} s)"
    if int(run.result.contacts.count[0]) == 0:
        report.add("the bodies never touch in the run: free flight is closed form, nothing to check")
    else:
        for out in _outcomes(scene, run, cut, skip):
            report.add(out)
    report.wall_time_s = time.perf_counter() - started
    return report


def _outcomes(scene: Scene, run, cut: bool, skip: tuple[str, ...]) -> Iterator[Check | str]:
    """Each check that applies to the run, or why one that might does not."""
    yield energy_check(scene, run)
    yield momentum_check(scene, run) if not scene.walls else "momentum: walls push the spheres"
    if exchange_reason(scene) is None:
        yield exchange_check(scene, run)
    if bounce_reason(scene) is None:
        yield bounce_check(scene, run)
    if scene.rest is not None and scene.gravity is not None:
        yield f"at rest: needs the whole run (this is the first {scene.duration:g} s)" if cut else \
            rest_check(scene, run)
    if "ladder" not in skip:
        why = ladder_reason(scene)
        yield why if why is not None else ladder_check(scene, run)
