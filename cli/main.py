"""`collide`: the command line. Commands parse options and call one library function each."""

from __future__ import annotations

import inspect
import math
import os
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from typer import Abort, TyperException

from cli.coercion import skip_needless_conversion
from cli.common import (
    DtOption,
    IntegratorOption,
    SetOption,
    TolOption,
    UserError,
    fail,
    parse_dt,
)
from collide.limits import MAX_STEPS_DEFAULT, OPEN_RUN_STEPS, SEED_BODY_STEPS

skip_needless_conversion()
_app = typer.Typer(
    name="collide",
    help="Collisions of spheres with springs, Coulomb friction and spin: run scenes, record them "
    "to Rerun, batch and sweep them, validate against textbooks, and view them live.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def interpreted_why() -> str:
    """Why this process ran the interpreted kernels (its wall time is theirs)."""
    from collide.engine import tier

    if tier.jit_setting() == "interpreted":
        return "interpreted kernels: COLLIDE_JIT=0"
    state = tier.engine_state()
    if state.state == "compiling":
        return ("interpreted kernels: the compiled ones are being built in the background, once; "
                "`collide engine` shows how far")
    if state.state == "failed":
        return f"interpreted kernels: {state.describe()}; `collide engine --compile` tries again"
    return "interpreted kernels: quicker for a run this small; COLLIDE_JIT=1 compiles"


def wall_text(seconds: float) -> str:
    """A wall time as people read it: 1.47 ms, 25.7 s (not 2.57e+04 ms)."""
    return f"{seconds * 1e3:.3g} ms" if seconds < 1.0 else f"{seconds:.3g} s"


def _fmt(x: Any) -> str:
    if x is None:
        return "n/a"
    if isinstance(x, float):
        return f"{x:.6g}" if math.isfinite(x) else "n/a"
    if isinstance(x, list):
        return "(" + ", ".join(_fmt(v) for v in x) + ")"
    return str(x)


def _check_outputs(*paths: Path | None) -> None:
    """Every file the command will write can be written: said before the run, not after it."""
    from collide.output import OutputError, check_file

    for path in paths:
        if path is not None:
            try:
                check_file(path)
            except OutputError as exc:
                raise UserError(str(exc)) from None


SHOWN_BODIES = 8  # a summary lists this many bodies; more are totals (--all-bodies lists every one)


def _print_bodies(bodies: list[dict[str, Any]], every: bool) -> None:
    """Each body's final velocity and spin; for a large scene the first few and the speeds' spread."""
    shown = bodies if every or len(bodies) <= SHOWN_BODIES else bodies[:SHOWN_BODIES // 2]
    width = max(len(b["name"]) for b in shown)
    for body in shown:
        spin = f"  spin {_fmt(body['spin'])} rad/s" if "spin" in body else ""
        typer.echo(f"  {body['name']:<{width}}  velocity {_fmt(body['velocity'])} m/s{spin}")
    if len(shown) < len(bodies):
        speeds = [math.hypot(*b["velocity"]) if isinstance(b["velocity"], list) else abs(b["velocity"])
                  for b in bodies]
        typer.echo(f"  ... and {len(bodies) - len(shown)} more bodies ({len(bodies)} in all; final speeds "
                   f"{min(speeds):.4g} to {max(speeds):.4g} m/s, mean {sum(speeds) / len(speeds):.4g}); "
                   "--all-bodies lists every one, --json holds every one")


def print_summary(summary: dict[str, Any], recording: str | None, every_body: bool = False) -> None:
    """A readable summary: final state, residuals, cost (`recording`: the file and what it took)."""
    auto = " (auto)" if summary.get("dt_auto") else ""
    typer.echo(f"{summary['scene']}: {summary['dim']}D, integrator {summary['integrator']}, "
               f"dt {summary['dt']:.3g} s{auto}")
    _print_bodies(summary["bodies"], every_body)
    res = summary["residuals"]
    typer.echo(f"  residuals: energy {_fmt(res['energy'])}, momentum {_fmt(res['momentum'])}, "
               f"angular momentum {_fmt(res['angular_momentum'])} (relative)")
    contact = summary["contact"]
    if contact["count"]:
        typer.echo(f"  contacts: {contact['count']}, {contact['duration'] * 1e3:.4g} ms in contact, "
                   f"max compression {contact['max_compression'] * 1e3:.4g} mm")
    else:
        typer.echo("  contacts: none")
    typer.echo(f"  {summary['steps']} steps, {summary['jumps']} free-flight jumps, "
               f"{summary['sim_time']:.6g} s simulated in {wall_text(summary['wall_time_s'])}"
               + (f" ({interpreted_why()})" if summary.get("kernels") == "interpreted" else ""))
    for warning in summary.get("warnings", []):
        typer.echo(f"  warning: {warning}")
    if recording is not None:
        typer.echo(f"  recording: {recording}")


@_app.command()
def run(
    scene: Annotated[str, typer.Argument(help="A built-in scene name (see `collide scenes`) or a .toml file.")],
    set_: SetOption = None,
    integrator: IntegratorOption = None,
    dt: DtOption = None,
    tol: TolOption = None,
    json_: Annotated[bool, typer.Option(
        "--json", help="Print the JSON summary (docs/design.md section 4) only.")] = False,
    csv: Annotated[Path | None, typer.Option(help="Write the report's CSV columns to this file.")] = None,
    csv_every: Annotated[float | None, typer.Option(
        help="CSV row interval in seconds.", show_default="100 steps, as the report printed")] = None,
    csv_layout: Annotated[str, typer.Option(
        help="'aligned' (every column at the row's time) or 'report' (the report program's own "
        "output: positions one step ahead, %f numbers)")] = "aligned",
    out: Annotated[Path | None, typer.Option(help="Recording file.", show_default="recordings/<scene>.rrd")] = None,
    save_state: Annotated[Path | None, typer.Option(
        "--save-state", help="Write the final state as a body table (.csv or .npz): the start of another "
        "scene through [bodies] file = ...")] = None,
    no_record: Annotated[bool, typer.Option("--no-record", help="Do not write a recording.")] = False,
    stride: Annotated[int, typer.Option(help="Record every n-th contact step.", min=1)] = 1,
    spawn: Annotated[bool, typer.Option(help="Open the recording in the Rerun viewer.")] = False,
    all_bodies: Annotated[bool, typer.Option(
        "--all-bodies", help=f"List every body in the summary (by default a scene of more than {SHOWN_BODIES} "
        "lists a few and the spread of speeds).")] = False,
    max_steps: Annotated[int | None, typer.Option(
        "--max-steps", min=1, help="Refuse the run past this many steps.",
        show_default=f"{MAX_STEPS_DEFAULT:.0e} with a duration, {OPEN_RUN_STEPS:.0e} without one; the seed at "
                     f"most {SEED_BODY_STEPS:.0e} body-steps")] = None,
    threads: Annotated[int | None, typer.Option(
        "--threads", min=1, help="Threads a DEM run steps on, the same result whatever the number (also "
        "COLLIDE_THREADS=N).", show_default="every core from 4 000 bodies, 1 below")] = None,
    frame_steps: Annotated[int | None, typer.Option(
        "--frame-steps", min=1, help="A DEM run's recording: a frame each K steps (1: every step; also "
        "COLLIDE_FRAME_STEPS=K).", show_default="the scene's duration in 100-1 500 frames, from 1 000 bodies at "
        "most one each 100 steps")] = None,
) -> None:
    """Run one scene, print a summary and write a Rerun recording.

    Examples:

      collide run demo-bonus

      collide run demo-1d --integrator seed --dt 2e-5 --csv demo1d.csv --csv-layout report

      collide run demo-bonus --set contact.mu=0.3 --set body.ball1.velocity=[1.5,0] --json

      collide run my_scene.toml --dt auto --tol 1e-9 --no-record
    """
    from cli.common import compiled_for_large, loading_display, progress_display
    from collide.hint import prefer_interpreted
    from collide.scene import load_scene

    with loading_display(scene) as show:
        loaded = load_scene(scene, set_ or [], progress=show)
    step = parse_dt(dt)
    if threads is not None:
        os.environ["COLLIDE_THREADS"] = str(threads)  # read by collide.dem.run_threads
    if frame_steps is not None:
        os.environ["COLLIDE_FRAME_STEPS"] = str(frame_steps)  # read by collide.dem.frame_steps
    recording = None
    if not no_record:
        from collide.batch import safe_name

        # The scene's name is the user's text: it names a file in recordings/, never a path elsewhere.
        recording = out if out is not None else Path("recordings") / f"{safe_name(loaded.name)}.rrd"
    if save_state is not None and save_state.suffix not in (".csv", ".npz"):
        raise UserError(f"--save-state: a .csv or .npz file, got '{save_state}'")
    _check_outputs(recording, csv, save_state)
    # A few spheres meeting a few times run sooner interpreted than a process loads numba.
    prefer_interpreted(loaded, integrator, step, tol)
    compiled_for_large(len(loaded.bodies))
    from collide.run import run_scene  # the engine: compiled or interpreted from here on
    from collide.summary import report_csv, run_summary, write_summary_json

    # The trajectory is kept only for what uses it: the recording and the CSV.
    keep = not no_record or csv is not None
    with progress_display(loaded.name, loaded.rest) as show:
        result = run_scene(loaded, integrator=integrator, dt=step, tol=tol, record=keep, progress=show,
                           max_steps=max_steps)
    summary = run_summary(result, bodies=not json_)  # (--json writes the bodies a chunk at a time)
    if csv is not None:
        every = csv_every if csv_every is not None else 100 * float(result.result.dt[0])
        if not every > 0:
            raise UserError(f"--csv-every must be positive, got {every}")
        from collide.output import write_text_atomic

        write_text_atomic(csv, report_csv(result, every, csv_layout))
    if save_state is not None:
        import numpy as np

        from collide.bodies_file import write_state
        from collide.periodic import wrap

        final, model = result.result.final, result.result.model
        placed, _ = wrap(final.s[0], np.array(model.box_lower), np.array(model.period))  # (into a periodic box)
        write_state(save_state, loaded, placed, final.v[0], final.w[0])
    written = None  # the recording, its size and write time, as the summary says them
    if recording is not None:
        import time

        from collide.recording import DEFAULT_FPS, last_write, write_recording

        started = time.perf_counter()
        write_recording(result, recording, stride=stride)
        written = f"{recording} ({recording.stat().st_size / 1e6:.3g} MB, written in " \
            f"{wall_text(time.perf_counter() - started)})"
        frames = summary.get("frames")
        if frames and frames["every_steps"] > 1:
            written += f"; {frames['recorded']} frames, one each {frames['every_steps']} steps " \
                "(--frame-steps K for one each K)"
        if last_write.frame_every > 1:
            summary["warnings"].append(f"the recording's 3D view keeps every k-th frame, k = {last_write.frame_every} "
                                       f"({last_write.fps:.3g} frames per simulated second: "
                                       f"{len(loaded.bodies)} bodies); its trajectory is stored whole")
        elif last_write.fps < DEFAULT_FPS:
            summary["warnings"].append(f"the recording draws free flight at {last_write.fps:.3g} frames per "
                                       "simulated second (a long run: the frames are capped)")
    if json_:
        write_summary_json(summary, result, sys.stdout)
    else:
        print_summary(summary, written, all_bodies)
        if csv is not None:
            typer.echo(f"  csv: {csv}")
        if save_state is not None:
            typer.echo(f"  state: {save_state}")
    if spawn and recording is not None:
        from cli.common import spawn_viewer

        spawn_viewer(recording)


@_app.command()
def scenes(
    show: Annotated[
        str | None, typer.Option(help="Print this built-in scene's TOML (copy it to start your own).")
    ] = None,
) -> None:
    """List the built-in scenes, or print one as TOML.

    Examples:

      collide scenes

      collide scenes --show demo-bonus > my_scene.toml
    """
    from collide.scene import builtin_names, builtin_text, read_raw

    if show is not None:
        typer.echo(builtin_text(show), nl=False)
        return
    for name in builtin_names():  # (read, not loaded: a heavy one's fill would be placed)
        typer.echo(f"{name:<20} {read_raw(name)[0].get('description', '')}")


# Commands main.py defines itself; the others live in their own modules (OPTIONAL), imported only
# when the command line may need them: they import much (validation, fitting, the viewer) that
# `collide run` does not use.
OWN_COMMANDS = ("run", "scenes")
OPTIONAL = ("cli.numerics", "cli.batch", "cli.accuracy", "cli.view", "cli.bench", "cli.engine", "cli.export")
_registered = [False]


def _register_optional() -> None:
    """Commands that live in their own modules (once)."""
    import importlib

    if _registered[0]:
        return
    _registered[0] = True
    for module in OPTIONAL:
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
            continue
        mod.register(_app)
    _one_line_summaries()


def _one_line_summaries() -> None:
    """Each command's line in `collide --help` is its docstring's first paragraph as one
    sentence: typer keeps the docstring's line breaks there (issue 12: sentences broken in the
    command list); a command's own --help reflows them."""
    for info in _app.registered_commands:
        if info.short_help is None and info.help is None and info.callback is not None:
            doc = inspect.getdoc(info.callback) or ""
            info.short_help = " ".join(doc.split("\n\n")[0].split())


def command_app(args: list[str]) -> typer.Typer:
    """The app for this command line: every command, unless its first word names one of main.py's
    own (nothing else is then looked up: not the command list, not another command's help)."""
    if not args or args[0] not in OWN_COMMANDS:
        _register_optional()
    return _app


def __getattr__(name: str) -> typer.Typer:
    """`cli.main.app`: the app with every command (for callers that invoke it themselves)."""
    if name == "app":
        _register_optional()
        return _app
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main() -> None:
    """Entry point: every error is one line `error: ...` on stderr and a non-zero exit.

    Known errors (bad input, a run that cannot be trusted, usage mistakes) exit with 2. A numpy
    floating-point warning is raised as an error rather than printed above the result: a number
    that overflowed is no result. Anything else is a bug in collide: one line too (exit 1), with
    the traceback only when COLLIDE_DEBUG is set. A file that could not be written (a full
    disk) is one line naming it and the cause, exit 1.
    """
    import os
    import sys
    import warnings

    # Rerun's Rust log lines (a write error it also reports to us) are not for the terminal:
    # collide says what went wrong in its own line. RUST_LOG set by the user still wins.
    os.environ.setdefault("RUST_LOG", "off")
    from collide.errors import RunError
    from collide.output import OutputError
    from collide.scene import SceneError
    from collide.settings import check_count_settings

    try:
        check_count_settings()
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            code = command_app(sys.argv[1:])(standalone_mode=False)
    except TyperException as exc:  # usage errors: unknown option, bad option value, missing argument
        if type(exc).__name__ == "NoArgsIsHelpError":
            exc.show()  # `collide` alone: the help text, as before
            raise SystemExit(exc.exit_code) from None
        command = getattr(getattr(exc, "ctx", None), "command_path", "collide")
        fail(f"{exc.format_message()} (see '{command} --help')")
    except (SceneError, RunError, UserError, ValueError) as exc:
        fail(str(exc))
    except OutputError as exc:
        fail(str(exc), code=1)
    except OSError as exc:
        where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
        fail(f"{exc.strerror or exc}{where}")
    except RuntimeWarning as exc:
        fail(f"a number overflowed float64 during the run ({exc}); use smaller values")
    except MemoryError:
        fail("out of memory: the run is too large for this machine; use fewer bodies or steps, or --no-record")
    except RecursionError:
        fail("input nested too deeply")
    except Abort:
        fail("aborted")
    except Exception as exc:
        if os.environ.get("COLLIDE_DEBUG"):
            raise
        fail(f"internal error ({type(exc).__name__}: {exc}); please report it with the command line "
             "(COLLIDE_DEBUG=1 shows the traceback)", code=1)
    raise SystemExit(code if isinstance(code, int) else 0)  # as click's standalone mode ends


if __name__ == "__main__":
    main()
