"""Options and helpers shared by the CLI commands."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, NoReturn

import typer


class UserError(Exception):
    """A mistake in the command line: reported as one line, exit code 2."""


def fail(message: str, code: int = 2) -> NoReturn:
    """Report an error as one line on stderr (whatever the message holds) and exit."""
    line = " ".join(str(message).splitlines())  # \n, \r, \u2028...: a scene can hold any of them
    typer.echo(f"error: {line}", err=True)
    raise SystemExit(code)


SetOption = Annotated[
    list[str] | None,
    typer.Option("--set", help="Override a scene key: --set contact.mu=0.3 --set body.ball1.velocity=[1,0] "
                 "(repeatable; TOML values; bodies by name; vector components as .x/.y/.z)."),
]
IntegratorOption = Annotated[
    str | None, typer.Option(help="seed (the report's update), verlet, yoshida4 or kahan6.", show_default="the scene's")
]
DtOption = Annotated[str | None, typer.Option(help="Time step in seconds, or 'auto'.", show_default="the scene's")]
TolOption = Annotated[
    float | None,
    typer.Option(help="With --dt auto: the error allowed in the final velocities and spins, relative to "
                 "the fastest initial speed.", show_default="the scene's, 1e-6"),
]


def parse_dt(text: str | None) -> float | str | None:
    if text is None or text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise UserError(f"--dt must be a number of seconds or 'auto', got '{text}'") from None
    if not value > 0 or value == float("inf"):
        raise UserError(f"--dt must be positive and finite, got '{text}'")
    return value


def spawn_viewer(path: Path) -> None:
    """Open a recording in the Rerun viewer if one is installed, else say how."""
    rerun = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    if not Path(rerun).exists():
        typer.echo(f"  no Rerun viewer found; open the file with: rerun {path}")
        return
    try:
        subprocess.Popen([rerun, str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        typer.echo(f"  opened in the Rerun viewer: rerun {path}")
    except OSError as exc:
        typer.echo(f"  could not start the Rerun viewer ({exc.strerror}); open the file with: rerun {path}")


PROGRESS_AFTER = 2.0  # s: a run shorter than this shows no progress


@contextmanager
def progress_display(name: str, rest: float | None = None):
    """A progress line on stderr (never stdout: `--json` keeps stdout pure) for a run that takes
    more than PROGRESS_AFTER seconds: a bar, simulated time reached, steps, rate; for a run to
    rest (`rest`: the fraction of its peak kinetic energy it ends below) the kinetic energy's fall
    towards it too. Shown when stderr is a terminal, or with COLLIDE_PROGRESS=1; erased when the
    run ends."""
    wanted = os.environ.get("COLLIDE_PROGRESS", "").strip() == "1" or sys.stderr.isatty()
    try:
        after = float(os.environ.get("COLLIDE_PROGRESS_AFTER", PROGRESS_AFTER))
    except ValueError:
        after = PROGRESS_AFTER
    shown = [False]

    def show(member: int, members: int, t_now: float, t_end: float, steps: int, elapsed: float,
             settling: float = math.nan) -> None:
        if elapsed < after:
            return
        part = progress_part(t_now, t_end, settling, rest)
        who = f" member {member + 1}/{members}" if members > 1 else ""
        rate = steps / elapsed if elapsed > 0 else 0.0
        sys.stderr.write(f"\r{name}{who}: {part}, {steps:,} steps, {rate:,.0f} steps/s, {elapsed:.0f} s ")
        sys.stderr.flush()
        shown[0] = True

    with _status_line(show if wanted else None, shown) as shown_line:
        yield shown_line


def progress_part(t_now: float, t_end: float, settling: float, rest: float | None) -> str:
    """How far a run is: a bar of the share done and the figures behind it. A run to rest is as
    far as the larger of its time against its duration and its kinetic energy's fall from the
    peak towards `rest` times it, on a log scale (it ends at whichever comes first)."""
    timed = math.isfinite(t_end) and t_end > 0
    done = t_now / t_end if timed else math.nan
    text = (f"{t_now:.4g} s of {'at most ' if rest else ''}{t_end:.4g} s" if timed else f"{t_now:.4g} s")
    if rest and 0.0 < rest < 1.0 and math.isfinite(settling) and settling > 0.0:
        fallen = math.log(min(settling, 1.0)) / math.log(rest)
        done = max(done, fallen) if timed else fallen
        text += f", kinetic energy {settling:.1e} of its peak (at rest below {rest:.0e})"
    if not math.isfinite(done):
        return text
    filled = round(BAR * min(max(done, 0.0), 1.0))
    return f"[{'#' * filled}{'-' * (BAR - filled)}] {100 * min(done, 1.0):.0f} % {text}"


BAR = 20  # characters of the progress bar


@contextmanager
def _status_line(show, shown: list[bool]):
    """Yields `show`; at the end clears the line it wrote on stderr (`shown[0]`: whether it did)."""
    try:
        yield show
    finally:
        if shown[0]:
            sys.stderr.write("\r\033[K" if sys.stderr.isatty() else "\n")
            sys.stderr.flush()


@contextmanager
def loading_display(name: str):
    """A line on stderr while a scene that takes more than PROGRESS_AFTER seconds loads (a large
    fill or body table): what it is doing and how far. Shown as `progress_display` is."""
    import time

    wanted = os.environ.get("COLLIDE_PROGRESS", "").strip() == "1" or sys.stderr.isatty()
    started, shown = time.perf_counter(), [False]

    def show(what: str, done: int, total: int) -> None:
        elapsed = time.perf_counter() - started
        if elapsed < PROGRESS_AFTER:
            return
        part = f" {100 * done / total:.0f} % ({done:,} of {total:,})" if total else ""
        sys.stderr.write(f"\rloading {name}: {what}{part}, {elapsed:.0f} s \033[K" if sys.stderr.isatty() else
                         f"\rloading {name}: {what}{part}, {elapsed:.0f} s ")
        sys.stderr.flush()
        shown[0] = True

    with _status_line(show if wanted else None, shown) as shown_line:
        yield shown_line


LARGE_SCENE = 16  # bodies: above this, interpreted kernels would take minutes to hours


def compiled_for_large(bodies: int) -> None:
    """On the first runs after install the kernels run interpreted while they compile in the
    background (fine for a few spheres); a large scene would take hours that way, so the command
    waits for that compile (showing how far it is) and starts again on the compiled kernels. When
    the compile failed, the run is refused with the cause."""
    from collide.engine import tier

    command = os.path.basename(sys.argv[0]) if sys.argv else ""
    if tier.COMPILED or bodies <= LARGE_SCENE or tier.jit_setting() == "interpreted":
        return
    state = tier.engine_state()
    if state.state == "failed":
        raise tier.EngineUnavailable(
            f"{bodies} bodies need the compiled engine, and {state.describe()}; `collide engine --compile` tries "
            "again (COLLIDE_JIT=0 runs it interpreted, for hours)")
    if command not in ("collide", "main.py"):
        return
    sys.stderr.write(f"{bodies} bodies: waiting for the engine's compile (once after install; "
                     "`collide engine` shows how far)\n")
    sys.stderr.flush()
    from cli.engine import progress_line

    tier.start_compile()
    tier.wait_compiled(progress_line, every=2.0 if sys.stderr.isatty() else 15.0)
    os.execve(sys.executable, [sys.executable, "-m", "cli.main", *sys.argv[1:]], dict(os.environ, COLLIDE_JIT="1"))
