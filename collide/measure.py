"""A run's error measured rather than modelled: the same scene again at a tenth of its tolerance,
the difference of the outcomes taken as the error (docs/design.md section 4, `error_method`).

An integrator's error model covers one contact. Where contacts follow one another or one lasts,
the outcome's error can exceed it by orders of magnitude, so such runs of few enough bodies are
measured, in the event engine and in DEM alike; the caller says how to run the scene again and
which step an automatic choice takes at a tolerance (`Rerun`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from collide import diagnostics as dg
from collide.errors import SawtoothError
from collide.results import RunResult
from collide.scene import Scene
from collide.stepper import RunError

# The error model covers one contact at a time. Where contacts follow one another (a ball
# bouncing on, a rack, balls on a floor), each contact's error feeds the next and the outcome's
# error can exceed the model's by 1e3, with friction or without (measured: random scenes of 2-6
# balls with a floor, tol 1e-6; without friction 37 of 150 were beyond 10 times the model, the
# worst 3 700 times; DEM's bouncing ball at tol 1e-2 and 1e-3: 4.5 and 7.9 times). Such runs
# (more than one contact, at most this many bodies) are run again at a tenth of the tolerance and
# the difference is their estimate; the tolerance is tightened (up to MEASURE_REFINEMENTS times)
# until the measured error meets it.
MEASURED_MAX_BODIES = 64
# The model counts one collision's error. A contact that lasts many collision times (a ball
# resting, rolling or sliding on a floor, bobbing on its spring) gathers the step's error over
# every period: a ball rolling 0.5 s on a floor at k = 1e6 N/m (500 collision times) ended 2e-5
# away from a run at a 1000 times tighter tolerance against the model's 1e-6, with or without
# friction. Runs with a contact longer than this many collision times (a rack's longest in a
# break: 3) are measured too; below it an error growing with the contact's length stays within
# 10 times the model's.
LASTING_CONTACT = 8.0
MEASURE_REFINEMENTS = 3
SAME_RUNS_LIMIT = 3  # tighter runs with the candidate's step, passed over in a measurement
NOT_CONVERGING = 0.5  # see measured
UNMEASURED_BALANCE = 3.0  # see check_unmeasured_balance


@dataclass
class Rerun:
    """How to run a scene again: `run(tol, max_steps)` runs it unmeasured at `tol` within
    `max_steps`; `step(tol)` is the step an automatic choice takes there (raising RunError where
    the integrator cannot reach it); `floor` is the finest tolerance the integrator reaches."""

    run: Callable[[float, int], object]  # -> collide.run.SceneRun
    step: Callable[[float], float]
    floor: float


def measurable(scene: Scene, auto: bool) -> bool:
    """Whether a run of the scene may have its error measured: an automatic step (a given dt is
    the user's) and at most MEASURED_MAX_BODIES bodies (beyond, final states decorrelate)."""
    return auto and len(scene.bodies) <= MEASURED_MAX_BODIES


def outside_model(result: RunResult, lasting: bool | None = None) -> bool:
    """Whether a single run's outcome is outside what the error model covers: contacts in a
    chain, or one that lasts (`lasting` where the caller judged it; else from the contact log's
    longest contact)."""
    closed, steps = result.closed_steps, int(result.steps[0])
    if closed is not None and steps > 0 and int(closed[0]) == steps:
        return False  # every contact ran in closed form: no step error to compound or gather
    contacts = result.contacts
    chained = int(contacts.count[0]) > 1
    if lasting is None:
        lasting = contacts.longest is not None and float(contacts.longest[0]) > LASTING_CONTACT
    return chained or lasting


def unmeasured_warning(run, why: str | None = None, engine: str = "the model") -> str:
    """Why a run outside the model quotes it (a given dt, too many bodies to run again, or `why`),
    and what it does not cover."""
    n, count = len(run.scenes[0].bodies), int(run.result.contacts.count[0])
    if why is None:
        why = "a given dt" if not run.auto[0] else f"{n} bodies; runs of up to {MEASURED_MAX_BODIES} are"
    what = f"{count} contacts in a chain compound it" if count > 1 else "a contact that lasts gathers it every period"
    return (f"the error was not measured ({why}): {float(run.error_estimate[0]):.2g} is {engine}'s estimate for "
            f"one collision, and {what} (2-6 balls on a floor: up to 3 700 times; a 1000-sphere gas's final states "
            "decorrelate); the balances (residuals) are the check")


def check_unmeasured_balance(run, tol: float) -> None:
    """Refuse a run outside the error model whose error could not be measured when its energy
    balance says the model's estimate does not hold: a relative balance off by e moves the
    velocities by about e / 2. A run whose estimate holds sits near twice the tolerance (the seed's
    cradle: 2.1 times at every tol); past UNMEASURED_BALANCE times, the outcome is off by more than
    half again what would be quoted (the seed at tol 2e-4, a ball bouncing 24 times: 4e-3; at tol
    1.7e-4, 10 bounces: 1.5e-3, 8.4 times)."""
    off = float(dg.residuals(run.result).energy[0])
    if math.isfinite(off) and off > UNMEASURED_BALANCE * tol:
        raise RunError(f"the energy balance is off by {off:.2g}, {off / tol:.0f} times --tol {tol:.2g}, and the "
                       "error could not be measured: the "
                       "estimate does not hold; give a smaller --dt, or use an integrator of higher order")


def outcome_distance(a: RunResult, b: RunResult, scene: Scene) -> float:
    """Largest difference of final velocities and spins times radius, over the fastest initial
    speed (the quantity --tol bounds)."""
    radius = a.model.radius[0][:, None]
    dv = np.abs(a.final.v[0] - b.final.v[0]).max(initial=0.0)
    dw = np.abs((a.final.w[0] - b.final.w[0]) * radius).max(initial=0.0) if a.final.w.shape[-1] else 0.0
    speed = max(max(float(np.linalg.norm(body.velocity)) for body in scene.bodies), 1e-300)
    return float(max(dv, dw) / speed)


def _forecast_steps(candidate, rerun: Rerun, finer_tol: float) -> float:
    """The steps a run at `finer_tol` would take: the candidate's, times the ratio of the steps
    (steps go as 1 / dt where contacts are stepped; free flights are jumped either way). A run
    forecast past the step limit is not started only to be refused there, minutes later."""
    return float(candidate.result.steps[0]) * float(candidate.result.dt[0]) / rerun.step(finer_tol)


def _finer_tolerance(candidate, rerun: Rerun, step_tol: float, same: int) -> tuple[float, int]:
    """A tenth of `step_tol`, or tighter still while that keeps the candidate's step (at its
    ceiling, MAX_OMEGA_H, half the stability limit or DEM's fewest steps per contact): such a run
    measures the events' landing at most, not the step's error. Taken as the measurement, it quoted
    the model's 3e-5 for six balls on a floor whose outcome was 0.1 off (random scenes at tol 1e-3:
    21 in 100 beyond 10 times the estimate without friction, 2-30 with)."""
    finer_tol = step_tol / 10
    while (same < SAME_RUNS_LIMIT and finer_tol >= rerun.floor
           and rerun.step(finer_tol) == float(candidate.result.dt[0])):
        finer_tol /= 10
        same += 1
    return finer_tol, same


def measured(run, rerun: Rerun, max_steps: int):
    """The run's error measured against the same scene at a tenth of its tolerance; while that
    exceeds the tolerance, the tighter run becomes the candidate (the step choice must meet tol)."""
    tol = float(run.tol[0])
    candidate, step_tol = run, tol
    candidate_model = float(run.error_estimate[0])  # the model's estimate for the candidate
    spent = run.result.wall_time_s
    budget = max_steps - int(run.result.steps[0])  # the tighter runs share the run's step limit
    same = refined = 0
    previous = math.inf  # the last measured difference
    while refined < MEASURE_REFINEMENTS:
        finer_tol = step_tol / 10
        try:
            # A tighter tolerance the integrator cannot reach (the seed's first order) is refused
            # by the step choice as by the run: the run's answer stands, unmeasured.
            finer_tol, same = _finer_tolerance(candidate, rerun, step_tol, same)
            if finer_tol < rerun.floor and not refined:
                candidate.result.warnings.append(unmeasured_warning(
                    candidate, f"a tenth of --tol is finer than the integrator reaches, about {rerun.floor:.0e}"))
            if finer_tol < rerun.floor or budget < 1:
                break
            forecast = _forecast_steps(candidate, rerun, finer_tol)
            if forecast > budget:
                candidate.result.warnings.append(
                    f"the error could not be measured: a run at --tol {finer_tol:.2g} would take about "
                    f"{forecast:.2g} steps, more than the {budget:.2g} left of the step limit (--max-steps); "
                    "the estimate is the model's")
                break
            finer = rerun.run(finer_tol, budget)
        except SawtoothError:
            raise  # the islands cannot take the scene: its caller hands it on
        except RunError as exc:
            candidate.result.warnings.append(f"the error could not be measured (a run at --tol {finer_tol:.2g}: "
                                             f"{exc}); the estimate is the model's")
            break
        spent += finer.result.wall_time_s
        budget -= int(finer.result.steps[0])
        refined += 1
        model_estimate = float(candidate_model)
        candidate_model = float(finer.error_estimate[0])
        error = max(outcome_distance(candidate.result, finer.result, run.scenes[0]), model_estimate)
        candidate.error_estimate = np.array([error])
        candidate.error_method = ["measured"]
        if error <= tol:
            break
        # A difference that did not halve with a step choice ten times tighter is not the step's
        # error shrinking but the outcome's own sensitivity (contacts feeding one another without
        # end: twelve spheres bouncing on a floor for two hours part by 300 times their start
        # speed between any two step choices): a tighter run still would only repeat it.
        converging = error <= NOT_CONVERGING * previous
        previous = error
        # The tighter run is the candidate. Unless measured in turn, its estimate is the last
        # difference (the coarser run's error): pessimistic, since extrapolating a shrinking
        # series of differences failed where a tighter step changes an event's outcome.
        finer.error_estimate = np.array([max(error, float(finer.error_estimate[0]))])
        finer.error_method = ["measured"]
        candidate, step_tol = finer, finer_tol
        if not converging:
            break
    if not refined:
        check_unmeasured_balance(candidate, tol)
    return _settled(candidate, tol, step_tol, spent)


def _settled(candidate, tol: float, step_tol: float, spent: float):
    """The measured run as reported: the user's tolerance, the steps of the run returned, the wall
    time of every run it took, and a warning where even the tightest run did not meet tol."""
    candidate.tol = [tol]
    candidate.step_tol = step_tol
    candidate.result.wall_time_s = spent
    if float(candidate.error_estimate[0]) > tol:
        candidate.result.warnings.append(
            f"the measured error {float(candidate.error_estimate[0]):.2g} exceeds --tol {tol:.2g} even at a "
            f"{tol / step_tol:.0f} times tighter step choice (the outcome moves with the step more than one "
            "contact's error: contacts that feed one another, or a friction mode that changes at another "
            "time with each step); the estimate is measured, not modelled")
    return candidate
