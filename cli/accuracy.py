"""`collide accuracy` (error against run time) and `collide stress` (stiff and extreme cases)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from cli.common import SetOption, UserError


def _fmt(x: float | None, spec: str = ".2e") -> str:
    return "-" if x is None else format(x, spec)


def accuracy(
    scene: Annotated[str, typer.Argument(help="A built-in scene name or a .toml file.")],
    set_: SetOption = None,
    integrators: Annotated[str, typer.Option(help="Comma-separated integrators.")] = "seed,verlet,yoshida4,kahan6",
    repeats: Annotated[int, typer.Option(help="Timed repeats per point (median).", min=1)] = 3,
    budget: Annotated[float, typer.Option(help="Stop an integrator's ladder after a run this long (s).")] = 2.0,
    plot: Annotated[
        Path | None, typer.Option(help="Work-precision PNG.", show_default="recordings/<scene>-accuracy.png")
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="Rerun recording.", show_default="recordings/<scene>-accuracy.rrd")
    ] = None,
    json_: Annotated[bool, typer.Option("--json", help="Print the table as JSON.")] = False,
) -> None:
    """Error against run time for each integrator over decades and half-decades of omega dt.

    The error is that of the final velocities and spins (times radius) against a converged run,
    relative to the fastest initial speed (the measure --tol sets). Time is the median of
    repeats after a warm-up. Prints the table and the observed orders, saves a work-precision
    plot (log error against log time) and writes the same as a Rerun recording.

    Examples:

      collide accuracy demo-bonus

      collide accuracy demo-2d-moving --integrators verlet,kahan6 --repeats 5
    """
    from collide.accuracy import plot_work_precision, work_precision
    from collide.scene import load_scene

    names = tuple(n.strip() for n in integrators.split(",") if n.strip())
    from collide.integrators import INTEGRATORS

    unknown = [n for n in names if n not in INTEGRATORS]
    if unknown:
        raise UserError(f"--integrators: unknown '{unknown[0]}' (choose from {', '.join(INTEGRATORS)})")
    loaded = load_scene(scene, set_ or [])
    plot = plot or Path("recordings") / f"{loaded.name}-accuracy.png"
    out = out or Path("recordings") / f"{loaded.name}-accuracy.rrd"
    from collide.output import OutputError, check_file

    try:  # said before the study, not after it
        check_file(plot)
        check_file(out, "file name ending in .rrd")
    except OutputError as exc:
        raise UserError(str(exc)) from None

    def progress(name: str, omega_dt: float, wall: float, error: float) -> None:
        if not json_:
            typer.echo(f"  {name:<9} omega dt {omega_dt:<7g} {wall * 1e3:9.2f} ms  error {error:.2e}", err=True)

    wp = work_precision(loaded, names, repeats=repeats, time_budget_s=budget, progress=progress)
    plot.parent.mkdir(parents=True, exist_ok=True)
    plot_work_precision(wp, plot)
    try:
        from collide.recording import write_accuracy_recording
    except ImportError:
        write_accuracy_recording = None
    if write_accuracy_recording is not None:
        write_accuracy_recording(wp, out)
    if json_:
        typer.echo(json.dumps(wp.to_dict()))
        return
    typer.echo(f"{wp.scene}: omega = {wp.omega:.4g} rad/s; reference kahan6 at omega dt = 0.01 "
               f"(changes by {wp.reference_check:.1e} when halved)")
    typer.echo(f"  {'integrator':<10} {'omega dt':>9} {'dt (s)':>10} {'steps':>7} {'time (ms)':>10} {'error':>9}")
    for p in wp.points:
        err = _fmt(p.error) if p.error is not None else "refused"
        typer.echo(f"  {p.integrator:<10} {p.omega_dt:>9g} {p.dt:>10.3g} {p.steps:>7} "
                   f"{p.wall_time_s * 1e3:>10.2f} {err:>9}")
    orders = ", ".join(f"{k} {_fmt(v, '.2f')}" for k, v in wp.orders().items())
    typer.echo(f"  observed order (slope of log error on log dt): {orders}")
    typer.echo(f"  plot: {plot}")
    if write_accuracy_recording is not None:
        typer.echo(f"  recording: {out}")


def stress(
    tol: Annotated[float, typer.Option(help="Accuracy target of every run (dt = auto).")] = 1e-7,
    json_: Annotated[bool, typer.Option("--json", help="Print the table as JSON.")] = False,
) -> None:
    """Stiff and extreme cases, each checked against a closed form or the rigid limit, or
    required to refuse with a clear message. Exit 1 if any case fails.

    Examples:

      collide stress

      collide stress --tol 1e-9 --json
    """
    from collide.stress import cost_per_contact, run_all

    results = run_all(tol)
    costs = cost_per_contact(tol=tol)
    failed = [r for r in results if r.verdict != "PASS"]
    if json_:
        typer.echo(json.dumps({"cases": [r.__dict__ for r in results],
                               "cost_per_contact": {str(k): {"steps": s, "wall_time_s": t}
                                                    for k, (s, t) in costs.items()},
                               "passed": not failed}))
    else:
        typer.echo(f"  {'case':<15} {'setting':<26} {'error':>9} {'tolerance':>9} {'steps':>6} "
                   f"{'time (ms)':>9}  verdict  outcome")
        for r in results:
            typer.echo(f"  {r.group:<15} {r.setting:<26} {_fmt(r.error):>9} {_fmt(r.tolerance):>9} {r.steps:>6} "
                       f"{r.wall_time_s * 1e3:>9.2f}  {r.verdict:<7}  {r.outcome}")
        (s1, t1), (s2, t2) = costs[1500.0], costs[1e12]
        typer.echo(f"  cost per contact, dt = auto: k = 1500 N/m {s1} steps {t1 * 1e3:.2f} ms; "
                   f"k = 1e12 N/m {s2} steps {t2 * 1e3:.2f} ms (ratio {t2 / t1:.2f})")
        typer.echo(f"  {len(results) - len(failed)} of {len(results)} cases pass")
    if failed:
        raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    app.command()(accuracy)
    app.command()(stress)
