"""CLI commands for the numerics: `collide validate` and `collide fit-spring`.

The lead's `cli/main.py` calls `register(app)`. Commands only parse options, call
`collide.validate` / `collide.fitting` and print; bad input is one `error: ...` line on stderr
and exit code 2 (exit code 1 from `validate` means a residual exceeded its tolerance).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from collide import fitting
from collide import validate as validation
from collide.scene import SceneError


def _fail(message: str) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(2)


def _clean(value: Any) -> Any:
    """JSON has no NaN or infinity: write them as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def table(headers: list[str], rows: list[list[str]], right: set[int] | None = None) -> str:
    """Plain text table with aligned columns (numbers right-aligned)."""
    right = set(range(len(headers))) if right is None else right
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()

    return "\n".join([line(headers), line(["-" * w for w in widths])] + [line(r) for r in rows])


def _num(x: float, digits: int = 6) -> str:
    return f"{x:.{digits}g}"


def _vec(values: list[float]) -> str:
    return "(" + ", ".join(f"{v:+.6f}" for v in values) + ")" if len(values) != 1 else f"{values[0]:+.6f}"


def _ok(passed: bool) -> str:
    return "ok" if passed else "FAIL"


def format_validation(result: validation.Validation) -> str:
    """The three tables of `collide validate` as text."""
    out = []
    if result.textbook:
        out.append("Textbook problems (report Figs 3-6). Residuals in %; only the exact one is pass/fail.")
        rows = [[r.figure, r.quantity, r.unit, f"{r.printed:.{r.printed_decimals}f}", _num(r.exact, 7),
                 _num(r.simulated, 7), f"{r.residual_printed_pct:.3f}", f"{r.residual_exact_pct:.3g}",
                 f"{r.tolerance_pct:.3g}", _ok(r.passed)] for r in result.textbook]
        out.append(table(["FIG", "QUANTITY", "UNIT", "TEXTBOOK", "EXACT", "SIMULATOR", "RES PRINTED %",
                          "RES EXACT %", "TOL %", ""], rows, right={3, 4, 5, 6, 7, 8}))
        out.append("")
    if result.checks:
        out += _cross_check_lines(result)
    if result.scans:
        out += _scan_lines(result)
    if result.scenes:
        out.append("")
        out += format_scene_checks(result.scenes)
    out.append("")
    out.append(f"{'PASS' if result.passed else 'FAIL'} ({result.wall_time_s:.1f} s)")
    return "\n".join(out)


def format_scene_checks(reports: list) -> list[str]:
    """The scene table: one row per check of every scene (deviations and bounds relative), what it
    compares and why its bound; a scene no check applies to gets a line saying why."""
    out = ["Scene checks: the rigid reference where it applies; else closed forms, conservation and "
           "self-convergence.", "Deviations and bounds are relative (the COMPARES column says to what)."]
    rows = []
    for report in reports:
        for i, c in enumerate(report.checks):
            rows.append([report.scene if i == 0 else "", report.span if i == 0 else "", c.check,
                         f"{c.deviation:.2e}", f"{c.bound:.2e}", _ok(c.passed), f"{c.compares}; bound: {c.why}"])
        if not report.checks:
            rows.append([report.scene, report.span, "(none)", "-", "-", "-",
                         "no check applies: " + "; ".join(report.not_applicable)])
    out.append(table(["SCENE", "RUN", "CHECK", "DEVIATION", "BOUND", "", "COMPARES; BOUND BECAUSE"], rows,
                     right={3, 4}))
    skipped = [r for r in reports if r.checks and r.not_applicable]
    if skipped:
        out.append("Not applicable (why):")
        out += [f"  {r.scene}: {'; '.join(r.not_applicable)}" for r in skipped]
    return out


def _cross_check_lines(result: validation.Validation) -> list[str]:
    out = ["Rigid-limit cross-check (report Fig 35 style). Errors relative to the fastest initial speed;",
           "discretisation = scene's run vs converged soft run, softness = converged run vs rigid limit."]
    rows = []
    for check in result.checks:
        for r in check.rows:
            rows.append([r.scene, r.quantity, _vec(r.simulated), _vec(r.converged), _vec(r.rigid),
                         f"{r.discretisation:.2e}", f"{r.discretisation_tol:.1e}", f"{r.softness:.2e}",
                         f"{r.softness_tol:.2e}", _ok(r.passed)])
    out.append(table(["SCENE", "QUANTITY", "SIMULATOR", "CONVERGED", "RIGID", "DISCRET.", "TOL",
                      "SOFTNESS", "TOL", ""], rows, right={2, 3, 4, 5, 6, 7, 8}))
    for check in result.checks:
        ladder = ", ".join(f"{dt:.3g}" for dt in check.ladder_dt)
        changes = ", ".join(f"{c:.1e}" for c in check.ladder_change)
        out.append(f"  {check.scene}: {check.regime}; {check.integrator} dt = {check.dt:.3g} s; "
                   f"{validation.LADDER_INTEGRATOR} ladder dt = {ladder} s, changes {changes}"
                   f"{'' if check.converged else ' (NOT CONVERGED)'}; {check.wall_time_s:.2f} s")
    return out


def _scan_lines(result: validation.Validation) -> list[str]:
    out = ["", "Model softness against k (the rigid limit is approached as k^(-1/2); bound = a-priori estimate)."]
    rows = []
    for scan in result.scans:
        for i, p in enumerate(scan.points):
            last = i == len(scan.points) - 1
            rows.append([scan.scene, _num(p.k, 4), f"{p.dt:.3g}", f"{p.softness:.3e}",
                         f"{p.estimate:.3e}", f"{scan.exponent:+.3f}" if last else "",
                         _ok(scan.passed) if last else ""])
    out.append(table(["SCENE", "K (N/m)", "DT (s)", "SOFTNESS", "BOUND", "EXPONENT", ""], rows,
                     right={1, 2, 3, 4, 5}))
    out.append(f"  exponent: d log(softness) / d log(k) between the two stiffest runs; "
               f"pass if within {validation.EXPONENT_TOL} of -0.5")
    return out


def format_spring_fit(fit: fitting.SpringFit) -> str:
    """Per-run table and average, like the report's Fig 2."""
    rows = []
    for i, r in enumerate(fit.runs):
        rows.append([str(i + 1), r.name, fitting.format_pm(r.fit.slope, r.fit.slope_se),
                     fitting.format_pm(r.fit.intercept, r.fit.intercept_se), f"{r.fit.r2:.3f}", str(r.fit.n),
                     str(r.outside)])
    rows.append(["AVERAGE", "", fitting.format_pm(fit.k_mean, fit.k_uncertainty), "", "", "", ""])
    text = table(["INDEX", "RUN", "K (N/m)", "INTERCEPT (N)", "R^2", "POINTS", "OUTSIDE 6-50 N"], rows,
                 right={2, 3, 4, 5, 6})
    return "\n".join([
        "Spring constant: F = k x + b per run (least squares, +- standard errors), x from the position",
        "at the smallest force.", text,
        f"Average k = {fit.k_mean:.1f} N/m; uncertainty of the mean {fit.k_uncertainty:.1f} N/m = larger of "
        f"the scatter's standard error {fit.k_sem:.1f} and the propagated fit errors {fit.k_fit_error:.1f}; "
        f"spread of the runs (sd) {fit.k_spread:.1f} N/m."])


def _parse_range(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(x) for x in text.split(":"))
    except ValueError:
        raise ValueError(f"--range: expected LOW:HIGH in newtons, e.g. 6:50, got '{text}'") from None
    if not lo < hi:
        raise ValueError(f"--range: LOW must be below HIGH, got '{text}'")
    return lo, hi


def validate_command(
    scenes: Annotated[list[str] | None, typer.Argument(
        help="Scenes to check: built-in names (see `collide scenes`) or .toml files; default: all built-ins.",
        show_default=False, metavar="SCENE")] = None,
    scene: Annotated[list[str] | None, typer.Option(
        "--scene", "-s", help="Only this scene: a built-in name or a .toml path (repeatable); "
        "default: all built-ins.")] = None,
    tol: Annotated[float, typer.Option(help="Allowed discretisation error of the rigid-limit cross-check, "
                                       "relative to the fastest initial speed (the other checks hold each "
                                       "scene to its own tol).")] = validation.DEFAULT_TOL,
    scan: Annotated[bool, typer.Option("--scan/--no-scan", help="Rerun at k x 10, x 100 to show the "
                                       "softness shrink.")] = True,
    duration: Annotated[float | None, typer.Option(help="Check each scene over its first SECONDS only (a "
                                                   "heavy scene; the table says so).", show_default=False)] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the rows as one JSON object.")] = False,
    suite: Annotated[str, typer.Option(help="'report' (the textbook tables and the checks of every scene) "
                                       "or 'chung-ooi' (the eight DEM impact benchmarks of Chung & Ooi "
                                       "2011).")] = "report",
    plots: Annotated[Path | None, typer.Option(help="chung-ooi: write one PNG per test to this folder "
                                               "(default recordings/chung-ooi).")] = None,
    test: Annotated[list[int] | None, typer.Option("--test", help="chung-ooi: only this test, 1-8 "
                                                   "(repeatable).")] = None,
) -> None:
    """Check the simulator: the report's textbook tables (Figs 3-6) and every built-in scene but the
    heavy ones (or the scenes given: `collide validate pour` runs the heavy one, for minutes) by
    the checks that fit it: the rigid-body limit where it applies, else closed forms,
    conservation, energy balance and self-convergence, one row per check; or, with --suite
    chung-ooi, the Chung & Ooi (2011) impact benchmarks against their closed forms.

    Exit code 0: every residual within its stated bound; 1: some residual beyond it.

    Example: collide validate; collide validate newtons-cradle my_scene.toml;
    collide validate --scene demo-bonus --json; collide validate --suite chung-ooi
    """
    scene = [*(scenes or []), *(scene or [])] or None
    if suite == "chung-ooi":
        if scene:
            _fail("--scene: the chung-ooi suite runs its own scenes; drop the scenes")
        _chung_ooi(plots, test, as_json)
        return
    if suite != "report":
        _fail(f"--suite: unknown '{suite}' (choose from report, chung-ooi)")
    if plots is not None or test:
        _fail("--plots/--test: only with --suite chung-ooi")
    if not tol > 0:
        _fail(f"--tol: must be positive, got {tol}")
    try:
        result = validation.validate(scene, tol=tol, scan=scan, duration=duration)
    except (SceneError, ValueError, RuntimeError) as exc:
        _fail(str(exc))
        return
    _emit(result, as_json, format_validation)
    if not result.passed:
        raise typer.Exit(1)


def format_chung_ooi(result) -> str:
    """The Chung & Ooi table: one row per check, relative error against the closed form."""
    rows = []
    for r in result.rows:
        trend = r.passed is not None and not math.isfinite(r.tolerance)
        rows.append([str(r.test), r.case, r.quantity, _num(r.measured), _num(r.expected),
                     "-" if trend else f"{100 * r.rel_error:.3g}", "-" if trend else f"{100 * r.tolerance:.3g}",
                     ("ok" if r.passed else "FAIL") + (" (trend)" if trend else "")])
    text = table(["test", "case", "quantity", "measured", "expected", "err %", "tol %", ""], rows,
                 right={0, 3, 4, 5, 6})
    notes = sorted({f"test {r.test}: {r.note}" for r in result.rows if r.note})
    footer = [f"dt = contact time / {result.steps_per_contact} (Hertz closed form of each impact), to 2 digits"] + notes
    verdict = "all within tolerance" if result.passed else "SOME ROWS BEYOND TOLERANCE"
    return "\n".join([text, "", *footer, "", f"Chung & Ooi: {verdict}"])


def _chung_ooi(plots: Path | None, tests: list[int] | None, as_json: bool) -> None:
    from collide import chung_ooi

    bad = [t for t in tests or [] if not 1 <= t <= 8]
    if bad:
        _fail(f"--test: Chung & Ooi has tests 1 to 8, got {bad[0]}")
    result = chung_ooi.run_suite(sorted(set(tests)) if tests else None)
    folder = plots if plots is not None else chung_ooi.DEFAULT_PLOTS
    try:
        paths = chung_ooi.plot_suite(result, folder)
    except OSError as exc:
        _fail(f"--plots: cannot write to {folder}: {exc.strerror or exc}")
        return
    if as_json:
        data = result.to_dict()
        data["plots"] = [str(p) for p in paths]
        typer.echo(json.dumps(_clean(data), indent=2))
    else:
        typer.echo(format_chung_ooi(result))
        typer.echo(f"plots: {', '.join(str(p) for p in paths)}")
    if not result.passed:
        raise typer.Exit(1)


def fit_spring_command(
    files: Annotated[list[Path] | None, typer.Argument(help="Vernier CSV exports (time, force, "
                                                       "position); default: the SYNTHETIC sample runs.",
                                                       show_default=False)] = None,
    force_range: Annotated[str | None, typer.Option("--range", help="Keep only forces LOW:HIGH (N), "
                                                    "e.g. 6:50 (biases k low when noisy).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the fits as one JSON object.")] = False,
) -> None:
    """Spring constant of the stress ball from force probe + motion detector runs (report
    section I): a least-squares line F = k x + b per run, then the average.

    Example: collide fit-spring run1.csv run2.csv --json
    """
    try:
        fit = fitting.fit_runs([str(f) for f in files] if files else None, _parse_range(force_range))
    except ValueError as exc:
        _fail(str(exc))
        return
    _emit(fit, as_json, format_spring_fit)


def _emit(result, as_json: bool, as_text) -> None:
    """Print a result as one JSON object or as its text table."""
    typer.echo(json.dumps(_clean(result.to_dict()), indent=2) if as_json else as_text(result))


def register(app: typer.Typer) -> None:
    """Add `validate` and `fit-spring` to the app."""
    app.command("validate")(validate_command)
    app.command("fit-spring")(fit_spring_command)
