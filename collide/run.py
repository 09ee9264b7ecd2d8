"""Run scenes: choose the step, compile, simulate. The entry point for the CLI and the viewer."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from collide import diagnostics as dg
from collide import measure as measure_mod
from collide.alone import TOL_FLOOR as ALONE_TOL_FLOOR
from collide.alone import AloneError, PairTurns, alone_step, contact_steps, contact_tol, engine_choice, simulate_alone
from collide.errors import SawtoothError
from collide.integrators import INTEGRATORS
from collide.invariant import check_invariant
from collide.limits import step_limit
from collide.model import compile_scenes, hertz_bound, reference_frequency, select_model, select_state
from collide.results import RunResult
from collide.scene import Scene, SceneError, alone_blocker, dem_reason, island_blocker
from collide.stepper import EDGE_TOL, Progress, RunError, approach_bound, check_pass_through, simulate


@dataclass
class SceneRun:
    """A run together with the scenes it came from (B scenes, one per batch member)."""

    scenes: list[Scene]
    result: RunResult
    dt_request: float | str | None = None
    tol: list[float] | None = None
    error_estimate: np.ndarray | None = None  # (B,) predicted relative error of the outcome
    auto: list[bool] | None = None  # whether each member's step was chosen automatically
    # (B,) how error_estimate was found: "model" (the integrator's error model at this step) or
    # "measured" (against the same run at a tenth of the tolerance; see collide.measure).
    error_method: list[str] | None = None
    # The tolerance the run's steps were chosen for, where a measurement made a tighter run the
    # answer (its `tol` stays the user's).
    step_tol: float | None = None

    @property
    def scene(self) -> Scene:
        return self.scenes[0]

    def member(self, index: int) -> SceneRun:
        """Batch member `index` as a run of its own."""
        tol = None if self.tol is None else [self.tol[index]]
        estimate = None if self.error_estimate is None else self.error_estimate[index:index + 1]
        auto = None if self.auto is None else [self.auto[min(index, len(self.auto) - 1)]]
        method = None if self.error_method is None else [self.error_method[index]]
        return SceneRun([self.scenes[index]], self.result.member(index), self.dt_request, tol, estimate, auto,
                        method)


# Error of the outcome (final velocities and spins times radius, relative to the fastest initial
# speed) against omega h, omega the stiffest contact's frequency: (constant, power) terms, summed,
# per regime. Measured on demo-2d-moving and demo-bonus (benchmarks/bench_time_to_accuracy.py
# prints the errors), padded by about 2x. Friction keeps the compositions' order in every mode,
# in 3D as in 2D: a stuck contact is held symmetrically and a sliding one follows its slip.
ERROR_MODELS: dict[str, dict[str, tuple[tuple[float, int], ...]]] = {
    "seed": {"smooth": ((1.5, 1),), "friction": ((1.5, 1),)},
    "verlet": {"smooth": ((6e-3, 2),), "friction": ((1.5e-2, 2),)},
    "yoshida4": {"smooth": ((1e-2, 4),), "friction": ((1e-2, 4),)},
    "kahan6": {"smooth": ((3e-5, 6),), "friction": ((6e-5, 6),)},
}
MAX_AUTO_STEPS_PER_CONTACT = 1e5
# An energy balance this many times the step's tolerance means the error estimate failed (a
# frictionless gas of 1000 spheres over 5000 collisions stays within 10 times).
BALANCE_SLACK = 100.0
MAX_OMEGA_H = {"seed": 0.5, "verlet": 0.5, "yoshida4": 0.6, "kahan6": 1.0}
# Below these the outcome's error is round-off, not the step (measured: kahan6 1.4e-13 at
# omega dt = 0.03 on the bonus demo): a tighter --tol cannot be met and is refused.
TOL_FLOOR = {"seed": 1e-9, "verlet": 1e-11, "yoshida4": 1e-12, "kahan6": 1e-12}
def error_regime(scene: Scene) -> str:
    """Which error model applies to a scene: no friction, or friction."""
    return "friction" if scene.has_friction else "smooth"


def _error_model(integrator: str, regimes: list[str]) -> Callable[[np.ndarray], np.ndarray]:
    """The error model of `predicted_error` for these scenes, as a function of omega h (B,): the
    scenes grouped by regime once (the auto step's bisection asks it 60 times a run)."""
    names = np.array(regimes)
    groups = [(names == regime, ERROR_MODELS[integrator][regime]) for regime in set(regimes)]

    def model(omega_h: np.ndarray) -> np.ndarray:
        out = np.empty(len(regimes))
        for mine, terms in groups:
            x = omega_h[mine]
            out[mine] = sum(c * x**p for c, p in terms)
        return out

    return model


def predicted_error(integrator: str, regimes: list[str], omega_h: np.ndarray) -> np.ndarray:
    """The error model: expected relative error (B,) of the outcome at this omega h, for scenes in
    these regimes (`error_regime`)."""
    omega_h = np.broadcast_to(np.asarray(omega_h, dtype=float), (len(regimes),))
    return _error_model(integrator, regimes)(omega_h)


def check_tol_floor(integrator: str, tol: np.ndarray) -> None:
    """Refuse a tolerance below float64's round-off for this integrator: no step meets it (a
    given step as little as an automatic one; its error model would quote 1e-20 at dt = 1e-5 while
    the outcome moves by 5e-13 from step to step)."""
    floor = TOL_FLOOR[integrator]
    if (tol < floor).any():
        b = int(np.argmax(tol < floor))
        raise RunError(f"--tol {tol[b]:.3g} is below what '{integrator}' reaches in float64 at any step (round-off); "
                       f"the finest reachable is about {floor:.0e}: use --tol {floor:.0e} or looser")


# The outcome's round-off was measured at 0.1 to 1 times `float_resolution`'s figure: a contact is
# refused where it is beyond this many times the tolerance (its error then past the tolerance for
# certain); a head-on pair at tol 1e-6 kept it up to k = 2e20 (1e-6) and lost 4 % at 1e25.
ROUND_OFF_SLACK = 10.0


def impact_speed(model, state) -> np.ndarray:
    """The fastest approach a contact can see (B,): `approach_bound` between bodies, and on a wall,
    which stays put, a sphere's own speed too."""
    speed = approach_bound(model, state)
    if model.n_walls:
        speed = np.maximum(speed, np.sqrt((state.v ** 2).sum(-1)).max(axis=1))
    return speed


def float_resolution(model, state, durations: np.ndarray, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """What float64 resolves of the scene's stiffest collision (B,), its contact frequency
    scaled by `scale`: (positions, clock). Positions: the collision's overlap, about v / omega
    (v the fastest approach, `approach_bound`) plus g / omega^2 (resting under gravity), is
    known to an ulp of the coordinates where contacts happen (the bodies' and the walls'
    distances from the origin), and each step's force errs by that share: the outcome's
    velocities err by about ulp / overlap (measured: 0.1 to 1 times it, a head-on pair at
    k = 1e16 to 1e24). Clock: a contact begun a tick of the clock late (at the run's end,
    its duration) starts at an overlap of v x tick, whose energy is (omega tick)^2 of the
    collision's: the clock limits the outcome to the square of omega x tick."""
    omega = reference_frequency(model) * scale
    fastest = np.sqrt((state.v ** 2).sum(-1)).max(axis=1)
    speed = impact_speed(model, state)
    # Under 1e-9 of the fastest body's speed an approach is round-off (bodies moving together), as
    # the engine takes it (`simulate`'s FP_SLOW).
    speed = np.where(speed > 1e-9 * fastest, speed, 0.0)
    g = np.zeros(model.batch) if model.gravity is None else np.sqrt((model.gravity ** 2).sum(-1))
    reach = (np.sqrt((state.s ** 2).sum(-1)) + model.radius).max(axis=1)
    if model.n_walls:
        offset = np.abs((model.wall_point * model.wall_normal).sum(-1)).max()
        reach = np.maximum(reach, offset)
    with np.errstate(divide="ignore", invalid="ignore"):
        overlap = speed / omega + g / omega ** 2
        positions = np.where(overlap > 0, np.spacing(reach) / overlap, 0.0)
        clock = (omega * np.spacing(np.where(np.isfinite(durations), durations, 0.0))) ** 2
    return np.nan_to_num(positions), np.nan_to_num(clock)


def check_stiffness(scenes: list[Scene], model, state, tols: np.ndarray) -> np.ndarray:
    """Refuse a contact too stiff for float64 at the run's tolerance (`float_resolution`),
    with the stiffest this scene takes; else return the outcome's round-off figure (B,)."""
    durations = np.array([np.nan if s.duration is None else s.duration for s in scenes])
    positions, clock = float_resolution(model, state, durations)
    bad = np.maximum(positions, clock) > ROUND_OFF_SLACK * tols
    if not bad.any():
        return np.maximum(positions, clock)
    b = int(np.argmax(bad))
    lo, hi = 1e-30, 1.0  # the frequency's scale that meets tol: resolution grows with it
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        p, c = float_resolution(select_model(model, b), select_state(state, b), durations[b:b + 1], mid)
        lo, hi = (mid, hi) if max(p[0], c[0]) <= ROUND_OFF_SLACK * tols[b] else (lo, mid)
    k = scenes[b].contact.k
    if positions[b] >= clock[b]:
        what = (f"a collision's overlap (about {_overlap(model, state, b):.2g} m) is resolved by the positions "
                f"to {positions[b]:.2g} of itself")
    else:
        what = f"the clock's tick at t = {durations[b]:.6g} s resolves a contact to {clock[b]:.2g}"
    who = f"{scenes[b].name}: " if len(scenes) > 1 else ""
    raise RunError(f"{who}contact.k = {k:.3g} is too stiff to integrate in float64 at --tol {tols[b]:.3g}: {what}; "
                   f"this scene takes at most k = {k * lo * lo:.2g} (or a --tol of "
                   f"{max(positions[b], clock[b]) / ROUND_OFF_SLACK:.1g})")


def _overlap(model, state, b: int) -> float:
    """The stiffest collision's overlap of member b (see `float_resolution`)."""
    omega = float(reference_frequency(model)[b])
    g = 0.0 if model.gravity is None else float(np.sqrt((model.gravity[b] ** 2).sum()))
    return float(approach_bound(model, state)[b]) / omega + g / omega ** 2


def auto_omega_h(scenes: list[Scene], integrator: str, tol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The largest omega h (B,) whose predicted error meets tol, within the integrator's
    stability limit, and that prediction. Each island steps by it over its own stiffest
    frequency; with contact start and end located exactly, the approach speed does not set
    the step (a linear-spring contact lasts pi / omega at any speed)."""
    check_tol_floor(integrator, tol)
    regimes = [error_regime(scene) for scene in scenes]
    ceiling = min(MAX_OMEGA_H[integrator], 0.5 * INTEGRATORS[integrator].stability)
    model = _error_model(integrator, regimes)
    lo, hi = np.full(len(scenes), 1e-6), np.full(len(scenes), ceiling)
    for _ in range(60):  # bisection in log(omega h): the model is monotonic
        mid = np.sqrt(lo * hi)
        ok = model(mid) <= tol
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    omega_h = np.where(model(hi) <= tol, hi, lo)
    steps = np.pi / omega_h
    if (steps > MAX_AUTO_STEPS_PER_CONTACT).any():
        b = int(np.argmax(steps))
        advice = "use a looser --tol" if integrator == "kahan6" else \
            "use --integrator kahan6, a looser --tol, or give a step with --dt"
        if integrator == "seed":
            advice = "give the seed integrator a step with --dt (the report's steps are in the README)"
        raise RunError(f"--tol {tol[b]:.3g} would need about {steps[b]:.2g} steps per contact with "
                       f"'{integrator}' (order {INTEGRATORS[integrator].order}); {advice}")
    return omega_h, model(omega_h)


def auto_dt(scenes: list[Scene], integrator: str, tol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The auto step of the stiffest single contact (B,) and the predicted error."""
    model, _ = compile_scenes(scenes)
    omega_h, estimate = auto_omega_h(scenes, integrator, tol)
    return omega_h / reference_frequency(model), estimate


def run_scenes(scenes: list[Scene], *, integrator: str | None = None, dt: float | str | None = None,
               tol: float | None = None, record: bool = True,
               max_steps: int | None = None, progress: Progress | None = None,
               measure: bool = True) -> SceneRun:
    """Run B same-shaped scenes in one batch. `integrator`, `dt` and `tol` override the scenes'.
    `max_steps` bounds each member's steps (by default `limits.step_limit`: fewer for a run with
    no duration); a measured run's tighter runs share it.

    A single run whose error the model does not cover (collide.measure) has it measured
    (`measure`; `error_method` says which)."""
    names = {s.integrator for s in scenes} if integrator is None else {integrator}
    if len(names) != 1:
        raise SceneError("scenes in one batch must use the same integrator")
    integ = names.pop()
    if max_steps is not None and max_steps < 1:
        raise SceneError(f"--max-steps must be a positive number of steps, got {max_steps}")
    durations = [scene.duration for scene in scenes]
    if integ not in INTEGRATORS:
        raise SceneError(f"integrator: unknown '{integ}' (choose from {', '.join(INTEGRATORS)})")
    model, state = compile_scenes(scenes)
    if tol is not None and not (np.isfinite(tol) and tol > 0):
        raise SceneError(f"--tol must be a positive number, got {tol!r}")
    tols = np.array([scene.tol if tol is None else tol for scene in scenes])
    requested = [scene.dt if dt is None else dt for scene in scenes]
    auto_used = [step == "auto" for step in requested]
    needs = next((scene for scene in scenes if scene.needs_dem), None)
    forced = integrator is not None or "integrator" in scenes[0].source
    blocker = None
    in_islands = False
    if needs is not None and integ != "dem":
        blocker = alone_blocker(needs) or ("the report's update runs its contact law only" if integ == "seed" else
                                           "a batch of them is DEM's" if len(scenes) > 1 else
                                           "a given dt is DEM's (the event engine takes its steps from --tol)"
                                           if not auto_used[0] else None)
        if blocker is None:
            try:
                return _run_alone(scenes[0], integ, model, state, float(tols[0]), record, max_steps, measure, forced)
            except PairTurns as exc:
                blocker = str(exc)  # two spheres met off-centre: the islands take the turning line
        islands = None if integ == "seed" else next(
            (why for why in (island_blocker(s) for s in scenes if s.needs_dem) if why is not None), "")
        if islands == "" and model.hertz:
            # The islands step Hertz by a linear spring's frequencies: the stiffness it reaches.
            model = hertz_bound(model, impact_speed(model, state))
        if islands == "":
            islands = _islands_pass(model, state, forced)
        if islands == "":
            needs = None  # the islands take it: the restitution's dashpot or Hertz in their steps
            in_islands = True
        elif forced:
            raise SceneError(f"integrator: '{integ}' cannot run {needs.name}'s contact law ({dem_reason(needs)}): "
                             f"{blocker}; it runs with --integrator dem")
        else:
            blocker = f"{blocker}; {islands}" if islands else blocker
            integ = "dem"
    if integ == "dem":
        run = _run_dem(scenes, model, state, requested, auto_used, tols, dt, record, max_steps, progress, measure)
        return _engine(run, scenes[0], "dem", forced, blocker if needs is not None else None)
    check_tol_floor(integ, tols)
    round_off = check_stiffness(scenes, model, state, tols)
    omega = reference_frequency(model)
    omega_h = np.zeros(len(scenes))
    if any(auto_used):
        chosen, _ = auto_omega_h(scenes, integ, tols)
        omega_h = np.where(auto_used, chosen, 0.0)
    with np.errstate(divide="ignore"):
        dt_arr = np.array([omega_h[i] / omega[i] if auto_used[i] else step for i, step in enumerate(requested)],
                          dtype=float)
    if not np.all(np.isfinite(dt_arr)) or np.any(dt_arr <= 0):
        if len(scenes[0].bodies) < 2 and not scenes[0].walls:
            raise SceneError("body: a scene of one sphere and no walls has no contact to step; add a body or a wall")
        raise SceneError(f"dt: must be a positive number or 'auto', got {dt!r}")
    omega_h = np.where(auto_used, omega_h, dt_arr * omega)
    max_steps = step_limit(durations, max_steps, _steps_per_contact(np.pi / np.where(omega_h > 0, omega_h, np.inf)),
                           every_body=model.n_bodies if integ == "seed" else 0)
    # No step leaves the outcome finer than round-off, whatever the model says of a tiny one (nor
    # than the positions resolve of a stiff contact's overlap).
    estimate = np.maximum(predicted_error(integ, [error_regime(scene) for scene in scenes], omega_h),
                          np.maximum(TOL_FLOOR[integ], round_off))
    duration = np.array([np.nan if s.duration is None else s.duration for s in scenes])
    tail = np.array([np.nan if s.tail is None else s.tail for s in scenes])
    if model.gravity is not None and model.n_walls and np.isnan(duration).any():
        raise SceneError("duration: required when a scene has both gravity and walls "
                         "(a bouncing sphere never stops)")
    # A step chosen for tol lands friction mode changes to a tenth of it (their error is about
    # that much; at a hundredth the breaks' errors against tol 1e-9 were the same to two digits
    # at tol 1e-6 to 1e-8, and they took 5-8 % longer); a given step lands them as closely as
    # they can be. `simulate` keeps either within half the dead band (EDGE_BAND_SHARE).
    event_tol = np.where(auto_used, np.maximum(EDGE_TOL, 0.1 * tols), EDGE_TOL)
    # With no contact possible (one sphere, no walls) the stability limit and the steps per
    # contact are a division by a zero frequency: infinite by design, nothing to warn about (and
    # `check_finite` below still refuses a result that is not finite).
    contactless = model.n_bodies < 2 and not model.n_walls
    try:
        with np.errstate(divide="ignore") if contactless else contextlib.nullcontext():
            result = simulate(model, state, integrator=integ, dt=dt_arr, duration=duration, tail=tail,
                              record=record, max_steps=max_steps, event_tol=event_tol, auto=np.array(auto_used),
                              omega_h=omega_h, progress=progress, resolved=np.where(auto_used, tols, estimate))
    except SawtoothError as exc:
        if not (in_islands and measure and len(scenes) == 1):
            raise  # a measuring run: its caller hands the scene on
        return _in_dem(scenes[0], float(tols[0]), record, max_steps, measure, forced, AloneError(str(exc)))
    check_finite(result, scenes)
    check_invariant(result)
    run = _engine(SceneRun(list(scenes), result, dt, [float(x) for x in tols], estimate, auto_used,
                           ["model"] * len(scenes)), scenes[0], integ, forced, islands=in_islands)
    if not measure:
        return run  # a measuring run: its caller judges it
    # The error model is the undamped law's: a damped run's error is measured.
    if len(scenes) == 1 and (measure_mod.outside_model(run.result) or scenes[0].needs_dem):
        if measure_mod.measurable(scenes[0], run.auto[0]):
            try:
                run = measure_mod.measured(run, _event_rerun(scenes[0], integ, record), max_steps)
            except SawtoothError as exc:  # met by a tighter run
                return _in_dem(scenes[0], float(tols[0]), record, max_steps, measure, forced, AloneError(str(exc)))
        else:
            run.result.warnings.append(measure_mod.unmeasured_warning(run))
        if in_islands and _rubs(scenes[0]) and (run.error_method[0] != "measured"
                                                or float(run.error_estimate[0]) > tols[0]):
            # The spring's law near zero slip has a sliding mode (stick and slip alternating
            # without end) that the islands do not take: a run that does not confirm at a tenth of
            # --tol is DEM's, as a sphere alone's is (`_run_alone`).
            differ = (f" (they differ by {float(run.error_estimate[0]):.2g})" if run.error_method[0] == "measured"
                      else "")
            return _in_dem(scenes[0], float(tols[0]), record, max_steps, measure, forced, AloneError(
                f"the islands' stick and slip could not be confirmed by a run at a tenth of --tol{differ}"))
    run.result.warnings.extend(balance_warnings(run.result, scenes, np.maximum(tols, run.error_estimate),
                                                auto_used))
    return run


def _engine(run: SceneRun, scene: Scene, integ: str, forced: bool, blocker: str | None = None,
            islands: bool = False) -> SceneRun:
    """The run with its engine and why it ran there (the JSON's `engine`, `engine_reason`)."""
    run.result.engine, run.result.engine_reason = engine_choice(scene, integ, forced, blocker, islands)
    return run


def _run_alone(scene: Scene, integ: str, model, state, tol: float, record: bool, max_steps: int | None,
               measure: bool, forced: bool) -> SceneRun:
    """A sphere alone among walls under Hertz or a dashpot, in the event engine
    (`collide.alone`); where it meets what only DEM takes (two walls at once), DEM runs it
    instead, unless the event engine was asked for."""
    from collide.dem import contact_time

    if scene.gravity is not None and scene.walls and scene.duration is None:
        raise SceneError("duration: required when a scene has both gravity and walls (a bouncing sphere never stops)")
    duration = math.nan if scene.duration is None else scene.duration
    share = contact_tol(model, state, tol, duration)
    n_end, n_mid, rub_end, rub_mid = contact_steps(model, share)
    limit = step_limit([scene.duration], max_steps, max(2 * n_end + n_mid, 2 * rub_end + rub_mid))
    try:
        result = simulate_alone(model, state, tol=tol, duration=duration,
                                tail=np.nan if scene.tail is None else scene.tail, record=record, max_steps=limit)
    except AloneError as exc:
        if isinstance(exc, PairTurns) and island_blocker(scene) is None:
            raise  # the islands take it (run_scenes)
        return _in_dem(scene, tol, record, max_steps, measure, forced, exc)
    result.integrator = integ
    check_finite(result, [scene])
    check_invariant(result)
    run = _engine(SceneRun([scene], result, "auto", [tol], np.array([tol]), [True], ["model"]), scene, integ, forced)
    if not measure:
        return run
    t_c = float(contact_time(model, state)[0][0]) if model.n_walls or model.n_bodies > 1 else math.inf
    # A contact with stick and slip is always measured: near zero slip its law's limit is a
    # sliding mode that a tighter run can resolve differently (one switch at one tol, endless
    # ones at a tighter), which no single run's model shows.
    lasting = float(result.contacts.duration[0]) > measure_mod.LASTING_CONTACT * t_c or _rubs(scene)
    at_rest = not np.any(state.v)  # --tol is relative to the fastest initial speed: none to measure against
    if measure_mod.outside_model(result, lasting) and at_rest:
        result.warnings.append(measure_mod.unmeasured_warning(run, "every body starts at rest, and --tol is relative "
                                                                   "to the fastest initial speed; each contact is "
                                                                   "within it of its approach speed"))
    elif measure_mod.outside_model(result, lasting):
        # The measurement compares final states: its runs record nothing (recording took a third of
        # a run's time), unless one of them becomes the answer (below).
        def finer_run(finer: float, steps: int) -> SceneRun:
            return run_scenes([scene], integrator=integ, tol=finer, record=False, max_steps=steps, measure=False)

        rerun = measure_mod.Rerun(run=finer_run, step=lambda finer: alone_step(model, state, finer, duration),
                                  floor=ALONE_TOL_FLOOR)
        run = measure_mod.measured(run, rerun, limit)
        if record and run.result.trajectories is None:  # a tighter run is the answer: its trajectory
            again = run_scenes([scene], integrator=integ, tol=run.step_tol, record=True,
                               max_steps=limit, measure=False).result
            run.result.trajectories = again.trajectories
            run.result.wall_time_s += again.wall_time_s
        if _rubs(scene) and (run.error_method[0] != "measured" or float(run.error_estimate[0]) > tol):
            differ = (f" (they differ by {float(run.error_estimate[0]):.2g})" if run.error_method[0] == "measured"
                      else "")
            return _in_dem(scene, tol, record, max_steps, measure, forced, AloneError(
                f"its stick and slip could not be confirmed by a run at a tenth of --tol{differ}"))
    run.result.warnings.extend(balance_warnings(run.result, [scene], np.maximum([tol], run.error_estimate), [True]))
    return run


def _rubs(scene: Scene) -> bool:
    """Whether a scene's contacts have friction with a tangential spring (event/oblique.py)."""
    return scene.has_friction and scene.contact.tangential == "spring"


def _in_dem(scene: Scene, tol: float, record: bool, max_steps: int | None, measure: bool, forced: bool,
            exc: AloneError) -> SceneRun:
    """The scene in DEM since the event engine could not take it (`exc`), or refused if forced."""
    if forced:
        raise RunError(f"{exc}; run it with --integrator dem") from None
    try:
        run = run_scenes([scene], integrator="dem", tol=tol, record=record, max_steps=max_steps, measure=measure)
    except RunError as dem_exc:
        raise RunError(f"in the event engine {exc}; in DEM instead: {dem_exc}") from None
    run.result.engine_reason = (f"{dem_reason(scene)}: the fixed-step DEM kernel (first order), since in the "
                                f"event engine {exc}")
    return run


def _steps_per_contact(steps: np.ndarray) -> float:
    """The most steps one contact takes over a batch (0 where no contact can happen)."""
    finite = steps[np.isfinite(steps)]
    return float(finite.max()) if finite.size else 0.0


def _event_rerun(scene: Scene, integ: str, record: bool) -> measure_mod.Rerun:
    """How a measurement runs an event-engine scene again."""
    return measure_mod.Rerun(
        run=lambda tol, steps: run_scenes([scene], integrator=integ, tol=tol, record=record, max_steps=steps,
                                          measure=False),
        step=lambda tol: float(auto_dt([scene], integ, np.array([tol]))[0][0]),
        floor=TOL_FLOOR[integ])


def _dem_rerun(scene: Scene, model, state, record: bool) -> measure_mod.Rerun:
    """How a measurement runs a DEM scene again."""
    from collide import dem

    return measure_mod.Rerun(
        run=lambda tol, steps: run_scenes([scene], integrator="dem", tol=tol, record=record, max_steps=steps,
                                          measure=False),
        step=lambda tol: float(dem.auto_dt(model, state, np.array([tol]))[0]),
        floor=dem.TOL_FLOOR)


def _run_dem(scenes: list[Scene], model, state, requested: list, auto_used: list[bool], tols: np.ndarray,
             dt_request: float | str | None, record: bool, max_steps: int | None,
             progress: Progress | None = None, measure: bool = True) -> SceneRun:
    """A batch through the fixed-step DEM kernel (`collide.dem`)."""
    from collide import dem

    steps = np.array([np.nan if a else s for a, s in zip(auto_used, requested)], dtype=float)
    if any(auto_used):
        steps = np.where(auto_used, dem.auto_dt(model, state, tols), steps)
    if not np.all(np.isfinite(steps)) or np.any(steps <= 0):
        raise SceneError(f"dt: must be a positive number or 'auto', got {dt_request!r}")
    duration = np.array([np.nan if s.duration is None else s.duration for s in scenes])
    tail = np.array([np.nan if s.tail is None else s.tail for s in scenes])
    rest = np.array([np.nan if s.rest is None else s.rest for s in scenes])
    t_c, _, _ = dem.contact_time(model, state)
    max_steps = step_limit([s.duration for s in scenes], max_steps, _steps_per_contact(t_c / steps))
    result = dem.simulate_dem(model, state, dt=steps, duration=duration, tail=tail, rest=rest, record=record,
                              max_steps=max_steps, progress=progress)
    check_finite(result, scenes)
    check_invariant(result)
    estimate = dem.predicted_error(t_c / steps)
    run = SceneRun(list(scenes), result, dt_request, [float(x) for x in tols], estimate, auto_used,
                   ["model"] * len(scenes))
    if not measure:  # a measuring run: its caller judges it
        result.warnings.extend(balance_warnings(result, scenes, np.maximum(tols, estimate), auto_used))
        return run
    # DEM's model is one impact's error; a chain of contacts, or one lasting many contact times
    # (t_c: the shortest the scene can produce), is measured as event runs are.
    lasting = float(result.contacts.duration[0]) > measure_mod.LASTING_CONTACT * float(t_c[0])
    if len(scenes) == 1 and measure_mod.outside_model(result, lasting):
        if measure_mod.measurable(scenes[0], auto_used[0]):
            run = measure_mod.measured(run, _dem_rerun(scenes[0], model, state, record), max_steps)
        else:
            result.warnings.append(measure_mod.unmeasured_warning(run, engine="the DEM error model"))
    run.result.warnings.extend(balance_warnings(run.result, scenes, np.maximum(tols, run.error_estimate),
                                                auto_used))
    return run


def balance_warnings(result: RunResult, scenes: list[Scene], tols: np.ndarray, auto_used: list[bool]) -> list[str]:
    """Warnings for runs whose energy balance is far off the tolerance they were stepped for:
    the error estimate did not hold (so far: friction mode events among several contacts of a
    3D or many-body island), and the user must not take the result at the tolerance's word."""
    energy = dg.residuals(result).energy
    out = []
    for b, scene in enumerate(scenes):
        off = float(energy[b])
        if auto_used[b] and math.isfinite(off) and off > BALANCE_SLACK * float(tols[b]):
            who = f"{scene.name}: " if len(scenes) > 1 else ""
            out.append(f"{who}the energy balance is off by {off:.2g}, {off / float(tols[b]):.0f} times "
                       f"the tolerance {float(tols[b]):.2g}: the error estimate did not hold for this run; "
                       "compare with a run at a smaller --tol before trusting it")
    return out


def check_finite(result: RunResult, scenes: list[Scene]) -> None:
    """Refuse a run whose final state holds a non-finite number: it is no result (an overflowing
    free flight would otherwise be printed as one). Names the first such member, body and field."""
    final = result.final
    fields = {"position": final.s, "velocity": final.v, "spin": final.w, "orientation": final.q}
    if np.isfinite(final.t).all() and np.isfinite(final.work).all() and all(
            np.isfinite(values).all() for values in fields.values()):
        return  # checked at once: naming the culprit is for when there is one
    for b, scene in enumerate(scenes):
        if not math.isfinite(float(final.t[b])) or not math.isfinite(float(final.work[b])):
            raise RunError(f"{scene.name}: the run ended with a non-finite time or dissipated work; "
                           "no result to report")
        for what, values in fields.items():
            bad = ~np.isfinite(values[b]).all(axis=-1) if values.shape[-1] else np.zeros(values.shape[1], bool)
            if bad.any():
                body = scene.bodies[int(np.argmax(bad))].name
                raise RunError(f"{scene.name}: body.{body}'s final {what} is not finite (at t = "
                               f"{float(final.t[b]):.6g} s): float64 overflowed; use a shorter duration or "
                               "smaller values")


def _islands_pass(model, state, forced: bool) -> str:
    """Why the islands' own pass-through bound refuses a damped scene ("" when it does not).
    That bound takes the largest approach speed any two bodies could reach, DEM's the pairs' own:
    such a scene runs in DEM, unless the event engine was asked for (then its refusal stands)."""
    try:
        check_pass_through(model, state)
    except RunError as soft:
        if forced:
            raise
        return f"the event engine's pass-through bound refuses it ({soft})"
    return ""


def run_scene(scene: Scene, **kwargs) -> SceneRun:
    """Run one scene (a batch of one)."""
    return run_scenes([scene], **kwargs)
