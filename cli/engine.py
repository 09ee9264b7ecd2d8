"""`collide engine`: the compiled engine's state, and its compile."""

from __future__ import annotations

import json
import os
import sys
from typing import Annotated

import typer


def _state():
    # Importing the tier decides this process's kernels; this command never runs a scene, so it
    # asks for the interpreted ones and starts no compile by looking.
    os.environ.setdefault("COLLIDE_JIT", "0")
    from collide.engine import tier

    return tier


def _show(state, as_json: bool) -> None:
    if as_json:
        typer.echo(json.dumps({"state": state.state, "fraction": round(state.fraction(), 3), "seconds": state.seconds,
                               "functions": state.done, "reason": state.reason or None,
                               "cache": str(state.cache)}))
    else:
        typer.echo(f"engine: {state.describe()}")


def progress_line(state) -> None:
    """How far the compile is, on stderr: one line rewritten on a terminal, a line each time elsewhere."""
    line = f"engine: {state.describe()}"
    sys.stderr.write(f"\r{line}\033[K" if sys.stderr.isatty() else f"{line}\n")
    sys.stderr.flush()


def engine(
    wait: Annotated[bool, typer.Option("--wait", help="Wait for a running compile, showing how far it is.")] = False,
    compile_: Annotated[bool, typer.Option(
        "--compile", help="Compile now, in the foreground (or wait for the compile that is running); "
        "tries again after a failed compile.")] = False,
    json_: Annotated[bool, typer.Option("--json", help="Print the state as one JSON object.")] = False,
) -> None:
    """Show the compiled engine's state: compiled, compiling (how far), failed (why) or not yet.

    The first `collide` command after install compiles the engine's kernels in the background,
    once (a few minutes; runs meanwhile use the same kernels interpreted, slower). Exit code
    with --wait or --compile: 0 when the compiled engine is ready, 1 when its compile failed.

    Examples:

      collide engine

      collide engine --wait

      collide engine --compile
    """
    tier = _state()
    state = tier.engine_state()
    if compile_ and state.state != "ready":
        # The compile runs detached, holding the lock from its start: stopping this wait (Ctrl-C)
        # leaves it running, and no other command compiles beside it.
        tier.start_compile(force=True)
        wait = True
    if wait:
        state = tier.wait_compiled(progress_line, every=2.0 if sys.stderr.isatty() else 15.0)
        if sys.stderr.isatty():
            sys.stderr.write("\r\033[K")
    _show(state, json_)
    if (wait or compile_) and state.state != "ready":
        raise SystemExit(1)


def register(app: typer.Typer) -> None:
    app.command()(engine)
