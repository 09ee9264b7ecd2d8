"""Validation: the report's textbook tables (Figs 3-6), a rigid-limit cross-check (Fig 35 style) of
the scenes the rigid reference handles, and the scene checks (`collide.scene_checks`: closed
forms, conservation, energy balance, self-convergence) of every scene, in one table.

Errors of a run's outcome (final velocities and spins) are split in two, because they have
different cures:

* discretisation error: the scene's own run against a converged run of the same soft model
  (velocity Verlet at dt/2, dt/4, ... until two successive runs differ by less than a tenth of
  the tolerance). Cure: a smaller dt or a better integrator.
* model softness: the converged soft run against the rigid limit (`collide.rigid`). Cure: a
  stiffer k; it shrinks as k^(-1/2) (`softness_scan` shows it).

Every error is relative to the scene's fastest initial speed (max |v| + r |w|); spin errors are
surface speeds r |dw|. Tolerances are stated per row: discretisation `tol` (default 1e-4), and
softness `rigid.softness_estimate(scene) + tol` (an a-priori bound from the contact's duration
and depth, not a fit to the result).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from collide.rigid import reference_speed, rigid_outcome, softness_estimate
from collide.scene import Scene, apply_overrides, builtin_names, load_scene, parse_scene, with_settings
from collide.scene_checks import Check, SceneReport, rigid_reason, scene_checks

# collide.run (the engine) is imported by the functions that run scenes: the command line imports
# this module to list its commands, before a run decides compiled or interpreted kernels
# (collide.hint).

DEFAULT_TOL = 1e-4
MAX_HALVINGS = 4
SCAN_FACTORS = (1.0, 10.0, 100.0)
SCAN_OMEGA_H = 0.01  # omega dt for the k scan: ~300 steps per contact, error far below the softness
EXPONENT_TOL = 0.05  # |observed exponent - (-1/2)| allowed between the two stiffest runs
SCAN_FLOOR = 1e-9  # softness below this is round-off: the soft model is exact there

# ---------------------------------------------------------------------------------------------
# The textbook problems (report section II; exact answers from docs/design.md section 8)

_M2_1D = 0.340 * 0.54 / 1.86  # the cart mass the textbook's part (a) gives
_DEG37 = math.radians(37.0)


@dataclass(frozen=True)
class _Problem:
    figure: str
    scene: str
    quantity: str
    unit: str
    printed: float
    exact: float
    kind: str  # "speed" or "angle"
    body: int
    decimals: int  # as printed by the textbook
    per_vi: bool = False  # quoted in units of object 1's initial speed v_i


TEXTBOOK: tuple[_Problem, ...] = (
    # 1D elastic: v1' = (m1 - m2)/(m1 + m2) v, v2' = 2 m1/(m1 + m2) v.
    _Problem("Fig 3", "textbook-1d", "Final speed of object 1", "m/s", 0.66,
             abs((0.340 - _M2_1D) / (0.340 + _M2_1D) * 1.2), "speed", 0, 2),
    _Problem("Fig 3", "textbook-1d", "Final speed of object 2", "m/s", 1.86,
             2 * 0.340 / (0.340 + _M2_1D) * 1.2, "speed", 1, 2),
    # Equal masses, target at rest: the two exit at right angles, 5 cos 37 and 5 sin 37.
    _Problem("Fig 4", "textbook-glancing", "Final speed of object 1", "m/s", 4.00,
             5.0 * math.cos(_DEG37), "speed", 0, 2),
    _Problem("Fig 4", "textbook-glancing", "Final speed of object 2", "m/s", 3.01,
             5.0 * math.sin(_DEG37), "speed", 1, 2),
    # 1 kg and 3 kg head-on at v_i: object 1 leaves perpendicular at sqrt(2) v_i.
    _Problem("Fig 5", "textbook-unequal", "Final speed of object 1", "v_i", 1.4142, math.sqrt(2.0),
             "speed", 0, 4, per_vi=True),
    _Problem("Fig 5", "textbook-unequal", "Final speed of object 2", "v_i", 0.8165, math.sqrt(6.0) / 3.0,
             "speed", 1, 4, per_vi=True),
    _Problem("Fig 6", "textbook-unequal", "Direction of final velocity of object 2", "deg", 54.7,
             math.degrees(math.atan(math.sqrt(2.0))), "angle", 1, 1),
)


@dataclass
class TextbookRow:
    """One line of Figs 3-6. Residuals in percent; only the exact one is pass/fail (the
    textbook rounds, and prints 4.00 for 3.993 = 5 cos 37 deg, i.e. cos 37 deg taken as 0.8)."""

    figure: str
    scene: str
    quantity: str
    unit: str
    printed: float
    printed_decimals: int
    exact: float
    simulated: float
    residual_printed_pct: float
    residual_exact_pct: float
    tolerance_pct: float
    passed: bool


def exit_angle_deg(v: np.ndarray) -> float:
    """Direction of a 2D velocity measured from the y axis (the line object 1 leaves along in
    problem 73), in degrees: the textbook's 54.7 = arctan(sqrt 2) for v2 = (-2/3, -sqrt(2)/3) v_i."""
    return math.degrees(math.atan2(abs(float(v[0])), abs(float(v[1]))))


def textbook_table(scenes: list[str] | None = None, *, tol: float = DEFAULT_TOL,
                   finals: dict[str, np.ndarray] | None = None) -> list[TextbookRow]:
    """Rows of Figs 3-6: our stepper's value (the built-in scene, its own dt and integrator)
    against the textbook's printed and exact answers.

    The tolerance vs the exact answer is the scene's softness bound plus `tol`, both relative to
    the fastest initial speed, turned into a percentage of the quantity. `scenes` limits the
    table to those scene names. `finals` maps scene name
    to final velocities (N, D) already computed (e.g. by `cross_check`); others are run here.
    """
    from collide.run import run_scene

    finals = dict(finals or {})
    rows = []
    for problem in TEXTBOOK:
        if scenes is not None and problem.scene not in scenes:
            continue
        scene = load_scene(problem.scene)
        if problem.scene not in finals:
            finals[problem.scene] = run_scene(scene, record=False).result.final.v[0]
        v = np.asarray(finals[problem.scene])
        v_ref = reference_speed(scene)
        allowed = (softness_estimate(scene) + tol) * v_ref  # m/s
        v_i = float(np.linalg.norm(scene.bodies[0].velocity))
        if problem.kind == "speed":
            value = float(np.linalg.norm(v[problem.body]))
            exact_abs = problem.exact * (v_i if problem.per_vi else 1.0)
            if problem.per_vi:
                value /= v_i
            tolerance = 100.0 * allowed / exact_abs
        else:
            value = exit_angle_deg(v[problem.body])
            # A velocity error dv turns the direction by at most dv / |v| radians.
            speed = float(np.linalg.norm(v[problem.body]))
            tolerance = 100.0 * (allowed / speed) / math.radians(problem.exact)
        res_exact = 100.0 * abs(value - problem.exact) / abs(problem.exact)
        rows.append(TextbookRow(problem.figure, problem.scene, problem.quantity, problem.unit,
                                problem.printed, problem.decimals, problem.exact, value,
                                100.0 * abs(value - problem.printed) / abs(problem.printed),
                                res_exact, tolerance, bool(res_exact <= tolerance)))
    return rows


# ---------------------------------------------------------------------------------------------
# Cross-check against the rigid limit


@dataclass
class CrossCheckRow:
    """One body's final velocity or spin: stepper vs converged soft run vs rigid limit.

    Errors are relative to the fastest initial speed (spin: r |dw|)."""

    scene: str
    quantity: str
    simulated: list[float]
    converged: list[float]
    rigid: list[float]
    discretisation: float
    discretisation_tol: float
    softness: float
    softness_tol: float
    passed: bool


@dataclass
class SceneCheck:
    """The cross-check of one scene, with the dt ladder that showed convergence."""

    scene: str
    regime: str
    integrator: str
    dt: float
    ladder_dt: list[float]
    ladder_change: list[float]
    converged: bool
    rows: list[CrossCheckRow]
    final_v: list[list[float]] = field(repr=False, default_factory=list)
    wall_time_s: float = 0.0

    @property
    def passed(self) -> bool:
        return self.converged and all(r.passed for r in self.rows)


def _spins(w: np.ndarray, scene: Scene) -> np.ndarray:
    """Final spins as (N, K) in the scene's spin dimension (a run where nothing spins has K = 0)."""
    if w.shape[-1] == scene.spin_dim:
        return w
    return np.array([b.spin for b in scene.bodies], dtype=float).reshape(len(scene.bodies), scene.spin_dim)


def _errors(scene: Scene, va: np.ndarray, wa: np.ndarray, vb: np.ndarray, wb: np.ndarray,
            v_ref: float) -> tuple[np.ndarray, np.ndarray]:
    """Per body: |dv| / v_ref and r |dw| / v_ref."""
    radii = np.array([b.radius for b in scene.bodies])
    dv = np.linalg.norm(va - vb, axis=1) / v_ref
    dw = np.linalg.norm(wa - wb, axis=1) * radii / v_ref if scene.spin_dim else np.zeros(len(radii))
    return dv, dw


def _max_error(scene: Scene, a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray],
               v_ref: float) -> float:
    dv, dw = _errors(scene, a[0], a[1], b[0], b[1], v_ref)
    return float(max(dv.max(), dw.max()))


LADDER_INTEGRATOR = "kahan6"


def cross_check(scene: Scene, *, tol: float = DEFAULT_TOL, max_halvings: int = MAX_HALVINGS) -> SceneCheck:
    """Compare the scene's run with a converged soft run and with the rigid limit.

    The converged run: `kahan6` (LADDER_INTEGRATOR) at dt/2, dt/4, ... (dt = the scene's step)
    until two successive runs differ by less than tol/10; its own error is then below that
    change (order >= 1; kahan6 converges at sixth order, first order only for friction whose slip
    turns out of its plane, so its error is far below the change).
    """
    from collide.run import run_scene, run_scenes

    if max_halvings < 2:
        raise ValueError(f"max_halvings: need at least 2 to see convergence, got {max_halvings}")
    started = time.perf_counter()
    rigid = rigid_outcome(scene)
    v_ref = reference_speed(scene)
    outcomes: list[tuple[np.ndarray, np.ndarray]] = []
    if scene.integrator == LADDER_INTEGRATOR and scene.dt != "auto":
        # The scene's own run is the first rung: run it and dt/2 in one lock-step batch.
        dt = float(scene.dt)
        run = run_scenes([scene, with_settings(scene, dt=dt / 2)], record=False).result
        own = (run.final.v[0], _spins(run.final.w[0], scene))
        outcomes = [own, (run.final.v[1], _spins(run.final.w[1], scene))]
        ladder = [dt, dt / 2]
    else:
        run = run_scene(scene, record=False).result
        dt = float(run.dt[0])
        own = (run.final.v[0], _spins(run.final.w[0], scene))
        # A run of the ladder's integrator is its first rung; another integrator's is not.
        outcomes, ladder = ([own], [dt]) if scene.integrator == LADDER_INTEGRATOR else ([], [])
    changes = [_max_error(scene, outcomes[i], outcomes[i + 1], v_ref) for i in range(len(outcomes) - 1)]
    converged = bool(changes and changes[-1] < tol / 10)
    halvings = len(ladder) - 1 if ladder else 0
    while not converged and halvings < max_halvings:
        halvings += 1
        h = dt / 2**halvings
        fine = run_scene(with_settings(scene, integrator=LADDER_INTEGRATOR, dt=h), record=False).result
        outcomes.append((fine.final.v[0], _spins(fine.final.w[0], scene)))
        ladder.append(h)
        if len(outcomes) > 1:
            changes.append(_max_error(scene, outcomes[-2], outcomes[-1], v_ref))
            converged = changes[-1] < tol / 10
            if not converged and _hopeless(changes, tol / 10, max_halvings - halvings):
                break
    conv = outcomes[-1]
    soft_tol = softness_estimate(scene) + tol
    d_disc = _errors(scene, own[0], own[1], conv[0], conv[1], v_ref)
    d_soft = _errors(scene, conv[0], conv[1], rigid.v, rigid.w, v_ref)
    rows = []
    for i, body in enumerate(scene.bodies):
        parts = [("velocity", 0)]
        if scene.has_spin:
            parts.append(("spin", 1))
        for label, j in parts:
            sim = own[j][i]
            disc, soft = float(d_disc[j][i]), float(d_soft[j][i])
            rows.append(CrossCheckRow(scene.name, f"{body.name}.{label}", sim.tolist(), conv[j][i].tolist(),
                                      (rigid.v if j == 0 else rigid.w)[i].tolist(), disc, tol, soft,
                                      soft_tol, bool(converged and disc <= tol and soft <= soft_tol)))
    return SceneCheck(scene.name, rigid.regime, scene.integrator, dt, ladder, changes, bool(converged), rows,
                      own[0].tolist(), time.perf_counter() - started)


def _hopeless(changes: list[float], target: float, left: int) -> bool:
    """True when the observed order of convergence cannot reach `target` in `left` halvings
    (each halving costs twice the one before: stop rather than grind)."""
    if len(changes) < 2 or changes[-1] == 0.0:
        return False
    ratio = changes[-2] / changes[-1]
    if ratio <= 1.0:
        return True
    return math.log(changes[-1] / target) / math.log(ratio) > left


# ---------------------------------------------------------------------------------------------
# Softness against k


@dataclass
class SoftnessPoint:
    k: float
    dt: float
    softness: float
    estimate: float


@dataclass
class SoftnessScan:
    """Distance from the rigid limit at k x factors; `exponent` is d log(softness) / d log(k)
    between the two stiffest runs (-1/2 expected)."""

    scene: str
    points: list[SoftnessPoint]
    exponent: float
    passed: bool


def _contact_omega(scene: Scene) -> float:
    """Angular frequency of the contact spring: sqrt(k_eff / m_red)."""
    bodies = scene.bodies
    if len(bodies) == 2:
        m_red = 1.0 / (1.0 / bodies[0].mass + 1.0 / bodies[1].mass)
        return math.sqrt(scene.contact.k / 2.0 / m_red)
    return math.sqrt(scene.contact.k / bodies[0].mass)


def softness_scan(scene: Scene | str, factors: tuple[float, ...] = SCAN_FACTORS) -> SoftnessScan:
    """Rerun a scene at k x factors (overrides `contact.k=...`) with omega dt fixed, in one batch,
    and measure the distance of the outcome from the rigid limit at each k."""
    from collide.run import run_scenes

    base = load_scene(scene) if isinstance(scene, str) else scene
    scenes = []
    for factor in factors:
        stiff = base if factor == 1.0 else _with_k(base, base.contact.k * factor)
        scenes.append(with_settings(stiff, integrator="verlet", dt=SCAN_OMEGA_H / _contact_omega(stiff)))
    result = run_scenes(scenes, record=False).result
    points = []
    for b, sc in enumerate(scenes):
        rigid = rigid_outcome(sc)
        v_ref = reference_speed(sc)
        err = _max_error(sc, (result.final.v[b], _spins(result.final.w[b], sc)), (rigid.v, rigid.w), v_ref)
        points.append(SoftnessPoint(sc.contact.k, float(result.dt[b]), err, softness_estimate(sc)))
    a, b = points[-2], points[-1]
    if min(a.softness, b.softness) < SCAN_FLOOR:
        # The soft model already gives the rigid answer (head-on): nothing to scale.
        return SoftnessScan(base.name, points, float("nan"), True)
    exponent = math.log(b.softness / a.softness) / math.log(b.k / a.k)
    passed = bool(abs(exponent + 0.5) <= EXPONENT_TOL)
    return SoftnessScan(base.name, points, exponent, passed)


def _with_k(scene: Scene, k: float) -> Scene:
    return parse_scene(apply_overrides(scene.source, [f"contact.k={k!r}"]), scene.name)


# ---------------------------------------------------------------------------------------------
# Everything


@dataclass
class Validation:
    """The whole validation: textbook tables, cross-checks, softness scans and the scene checks
    (`collide.scene_checks`); passed = all rows."""

    textbook: list[TextbookRow]
    checks: list[SceneCheck]
    scans: list[SoftnessScan]
    tol: float
    wall_time_s: float
    scenes: list[SceneReport] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return (all(r.passed for r in self.textbook) and all(c.passed for c in self.checks)
                and all(s.passed for s in self.scans) and all(s.passed for s in self.scenes))

    def to_dict(self) -> dict:
        """Plain data for JSON."""
        checks = []
        for c in self.checks:
            d = asdict(c)
            d.pop("final_v")
            d["passed"] = c.passed
            checks.append(d)
        return {"passed": self.passed, "tol": self.tol, "wall_time_s": self.wall_time_s,
                "textbook": [asdict(r) for r in self.textbook], "cross_check": checks,
                "softness_scan": [asdict(s) for s in self.scans],
                "scene_checks": [s.to_dict() for s in self.scenes]}


def rigid_rows(check: SceneCheck) -> list[Check]:
    """The rigid cross-check of one scene as two rows of the scene table: the converged soft run
    against the rigid limit, and the scene's run against the converged one."""
    soft = max(check.rows, key=lambda r: r.softness / r.softness_tol)
    disc = max(check.rows, key=lambda r: r.discretisation / r.discretisation_tol)
    ladder = ", ".join(f"{dt:.2g}" for dt in check.ladder_dt)
    return [
        Check(check.scene, "rigid limit", f"converged soft run's final velocities and spins vs the rigid "
              f"impact ({check.regime}), / fastest initial speed", soft.softness, soft.softness_tol,
              "a-priori softness of the contact (k^(-1/2), rigid.softness_estimate) + tol", bool(
                  check.converged and soft.softness <= soft.softness_tol)),
        Check(check.scene, "step ladder", f"scene's run vs converged {LADDER_INTEGRATOR} run (dt {ladder} s), "
              "/ fastest initial speed", disc.discretisation, disc.discretisation_tol,
              "tol of the rigid cross-check (--tol)" + ("" if check.converged else "; the ladder did NOT converge"),
              bool(check.converged and disc.discretisation <= disc.discretisation_tol)),
    ]


def check_scene(scene: Scene, *, tol: float = DEFAULT_TOL, scan: bool = True,
                duration: float | None = None) -> tuple[SceneCheck | None, SoftnessScan | None, SceneReport]:
    """Every check that applies to one scene: the rigid cross-check (and softness scan) where the
    rigid reference applies, and the scene checks (`collide.scene_checks`)."""
    started = time.perf_counter()
    reason = rigid_reason(scene)
    if reason is None and rigid_outcome(scene).impact is None:
        reason = "rigid reference: the bodies never touch"
    check = scan_result = None
    if reason is None:
        check = cross_check(scene, tol=tol)
        if scan and softness_estimate(scene) > 0.0:
            scan_result = softness_scan(scene)
    # The rigid reference needs the whole impact (and two spheres are no heavy run): no cut.
    report = scene_checks(scene, duration=None if check else duration, skip=("ladder",) if check else ())
    if check is not None:
        report.checks[:0] = rigid_rows(check)
    elif reason is not None:
        report.not_applicable.insert(0, reason)
    report.wall_time_s = time.perf_counter() - started
    return check, scan_result, report


def validate(scenes: list[str] | None = None, *, tol: float = DEFAULT_TOL,
             scan: bool = True, duration: float | None = None) -> Validation:
    """Run the textbook tables and every check that applies to each given scene (default: every
    built-in but the heavy ones, `collide.scene.HEAVY_BODIES`): the rigid
    cross-check and softness scan where the rigid reference applies, the scene checks of
    `collide.scene_checks` on all, over the first `duration` seconds if given."""
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"--duration: must be a positive number of seconds, got {duration}")
    started = time.perf_counter()
    names = list(scenes) if scenes else builtin_names(heavy=False)
    checks, scans, reports = [], [], []
    for name in names:
        scene = load_scene(name)
        check, scan_result, report = check_scene(scene, tol=tol, scan=scan, duration=duration)
        checks += [check] if check else []
        scans += [scan_result] if scan_result else []
        reports.append(report)
    finals = {c.scene: np.array(c.final_v) for c in checks}
    textbook = textbook_table(names, tol=tol, finals=finals)
    return Validation(textbook, checks, scans, tol, time.perf_counter() - started, reports)
