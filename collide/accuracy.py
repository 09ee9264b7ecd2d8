"""Error against run time (work-precision), the way SciML's diagrams present it.

For each integrator and a ladder of time steps (decades and half-decades of omega dt), run the
scene, time it (median of repeats after a warm-up run) and measure the error of the final state
(velocities, and spins times radius) against a converged reference, relative to the fastest
initial speed: the same measure `--tol` sets. The observed order is the slope of log error
against log dt where the error is above round-off.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

import numpy as np

from collide.model import compile_scenes, reference_frequency
from collide.run import run_scene
from collide.scene import Scene
from collide.stepper import RunError

INTEGRATOR_ORDER = ("seed", "verlet", "yoshida4", "kahan6")
# omega dt ladders: decades and half-decades, from each integrator's largest sensible step.
OMEGA_DT = (1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001, 3e-4, 1e-4)
REFERENCE_OMEGA_DT = 0.01  # kahan6 here is converged to round-off on the built-ins


def outcome(run_result, member: int = 0) -> np.ndarray:
    """Final velocities and spins times radius (m/s): the quantities the error is taken of."""
    v = run_result.final.v[member].ravel()
    w = (run_result.final.w[member] * run_result.model.radius[member][:, None]).ravel()
    return np.concatenate((v, w))


def speed_scale(scene: Scene) -> float:
    return max(max(float(np.linalg.norm(b.velocity)) for b in scene.bodies), 1e-300)


@dataclass
class Point:
    integrator: str
    dt: float
    omega_dt: float
    steps: int
    wall_time_s: float
    error: float | None  # None: the run was refused
    note: str = ""


@dataclass
class WorkPrecision:
    scene: str
    omega: float
    reference: np.ndarray
    reference_check: float  # change of the reference when its step is halved
    points: list[Point] = field(default_factory=list)

    def orders(self) -> dict[str, float | None]:
        """Observed order per integrator: least-squares slope of log error on log dt over the
        points that converge: from the largest step down to the integrator's smallest error
        (below it round-off grows with the steps), between the scene's round-off (30 times the
        study's smallest error, at least 1e-12) and the pre-asymptotic range (1e-2). A Newton's
        cradle levels off at 1e-11 and rises to 1e-10 at a million steps: with that tail in the
        fit kahan6's slope read 0.87 and Verlet's 1.1."""
        errors = [p.error for p in self.points if p.error]
        floor = 30.0 * max(min(errors, default=0.0), 1e-12 / 30.0)
        out: dict[str, float | None] = {}
        for name in dict.fromkeys(p.integrator for p in self.points):
            mine = sorted((p for p in self.points if p.integrator == name and p.error), key=lambda p: -p.dt)
            best = min(range(len(mine)), key=lambda i: mine[i].error, default=-1)
            pts = [p for p in mine[:best + 1] if floor < p.error < 1e-2]
            if len(pts) < 2:
                out[name] = None
                continue
            x = np.log10([p.dt for p in pts])
            y = np.log10([p.error for p in pts])
            out[name] = float(np.polyfit(x, y, 1)[0])
        return out

    def to_dict(self) -> dict:
        return {"scene": self.scene, "omega": self.omega, "reference_check": self.reference_check,
                "orders": self.orders(),
                "points": [p.__dict__ for p in self.points]}


def _timed(scene: Scene, integrator: str, dt: float, repeats: int) -> tuple[float, object]:
    times = []
    result = None
    for _ in range(repeats):
        result = run_scene(scene, integrator=integrator, dt=dt, record=False).result
        times.append(result.wall_time_s)
    return statistics.median(times), result


def work_precision(scene: Scene, integrators: tuple[str, ...] = INTEGRATOR_ORDER, repeats: int = 3,
                   time_budget_s: float = 2.0, progress=None) -> WorkPrecision:
    """Run the ladder. An integrator's ladder stops once a run takes longer than the budget
    (a finer step would only take longer) or its error reaches round-off."""
    model, _ = compile_scenes([scene])
    omega = float(reference_frequency(model)[0])
    scale = speed_scale(scene)
    ref_run = run_scene(scene, integrator="kahan6", dt=REFERENCE_OMEGA_DT / omega, record=False).result
    check_run = run_scene(scene, integrator="kahan6", dt=0.5 * REFERENCE_OMEGA_DT / omega, record=False).result
    reference = outcome(check_run)
    wp = WorkPrecision(scene.name, omega, reference,
                       float(np.abs(outcome(ref_run) - reference).max() / scale))
    for name in integrators:
        run_scene(scene, integrator=name, dt=0.1 / omega, record=False)  # warm-up
        for omega_dt in OMEGA_DT:
            dt = omega_dt / omega
            try:
                wall, result = _timed(scene, name, dt, repeats)
            except RunError as exc:
                wp.points.append(Point(name, dt, omega_dt, 0, 0.0, None, str(exc)))
                continue
            error = float(np.abs(outcome(result) - reference).max() / scale)
            wp.points.append(Point(name, dt, omega_dt, int(result.steps[0]), wall, error))
            if progress is not None:
                progress(name, omega_dt, wall, error)
            if wall > time_budget_s or error < 1e-13:
                break
    return wp


def plot_work_precision(wp: WorkPrecision, path) -> None:
    """Log error against log run time, one line per integrator (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.8), dpi=120)
    markers = {"seed": "s", "verlet": "o", "yoshida4": "^", "kahan6": "D"}
    for name in dict.fromkeys(p.integrator for p in wp.points):
        pts = [p for p in wp.points if p.integrator == name and p.error is not None and p.wall_time_s > 0]
        if not pts:
            continue
        err = [max(p.error, 1e-16) for p in pts]
        ax.loglog([p.wall_time_s for p in pts], err, marker=markers.get(name, "o"), label=name)
    ax.set_xlabel("run time (s, median of repeats)")
    ax.set_ylabel("error of final velocities and spins\n(relative to fastest initial speed)")
    ax.set_title(f"work-precision: {wp.scene}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
