"""`collide batch`: many scenes, sweeps and ensembles, vectorised, with a progress bar."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from cli.common import DtOption, IntegratorOption, SetOption, TolOption, UserError, parse_dt

DEFAULT_SUMMARY = Path("recordings") / "batch-summary.csv"


def batch(
    scenes: Annotated[list[str] | None, typer.Argument(
        help="Built-in scene names, .toml files, or folders of .toml files.", show_default=False)] = None,
    sweep: Annotated[list[str] | None, typer.Option(
        "--sweep", help="Sweep a scene key: KEY=START:STOP:NUM, NUM values with both ends included "
        "(repeatable: a grid).", show_default=False)] = None,
    vary: Annotated[list[str] | None, typer.Option(
        "--vary", help="Draw a scene key from a normal distribution: KEY=MEAN+-STD (repeatable).",
        show_default=False)] = None,
    samples: Annotated[int | None, typer.Option(
        help="Draws per scene with --vary (default: 100).", min=1, show_default=False)] = None,
    seed: Annotated[int | None, typer.Option(
        help="Random seed for --vary (same seed, same draws) (default: 0).", show_default=False)] = None,
    set_: SetOption = None,
    integrator: IntegratorOption = None,
    dt: DtOption = None,
    tol: TolOption = None,
    summary: Annotated[Path, typer.Option(help="Summary CSV: one row per run.")] = DEFAULT_SUMMARY,
    record: Annotated[Path | None, typer.Option(
        help="Write one .rrd per run into this folder, named after its parameters.",
        show_default=False)] = None,
    resume: Annotated[bool, typer.Option(
        "--resume", help="Skip runs already in the summary (after an interrupted batch) and add the rest."
    )] = False,
    chunk: Annotated[int, typer.Option(
        help="Most runs per call to the stepper (calls are sized to about a second each, so finished runs "
        "reach the disk that often).", min=1)] = 1000,
    stride: Annotated[int, typer.Option(
        help="With --record: record every n-th contact step.", min=1)] = 1,
    progress: Annotated[bool, typer.Option(help="Show a progress bar on stderr.")] = True,
    scheduler: Annotated[str | None, typer.Option(
        help="Run the chunks on a Dask cluster: its scheduler's address (tcp://HOST:8786), or 'local' to "
        "start one on this machine. Needs Dask (collide's 'dask' extra); workers need collide, and --record "
        "a folder every worker can reach.", show_default=False)] = None,
    workers: Annotated[int | None, typer.Option(
        help="With --scheduler local: worker processes (default: one per core).", min=1,
        show_default=False)] = None,
    threads: Annotated[int | None, typer.Option(
        help="With --scheduler local: threads per worker (default: 1).", min=1, show_default=False)] = None,
) -> None:
    """Run many scenes or a parameter sweep, vectorised; write a summary CSV (and recordings).

    Each run's row is on disk (synced) as soon as it finishes, before its recording, so Ctrl-C,
    a kill or a power loss keeps every finished run.

    After an interruption, run the same command with --resume to finish: complete rows are kept,
    a row cut short is run again. Output paths are printed.

    Examples:

      collide batch demo-bonus --sweep contact.mu=0:1:11

      collide batch demo-bonus --sweep contact.mu=0:1:11 --sweep body.ball1.velocity.y=-0.5:0.5:101

      collide batch demo-2d-moving --sweep body.ball1.position.y=0:0.06:7 --record recordings/offsets

      collide batch demo-bonus --vary contact.k=1500+-30 --vary contact.mu=0.5+-0.05 --samples 1000 --seed 1

      collide batch my_scenes/ textbook-glancing --dt auto --tol 1e-8

      collide batch demo-bonus --sweep contact.mu=0:1:100000 --scheduler tcp://HOST:8786
    """
    from collide import batch as lib

    if not vary and (samples is not None or seed is not None):
        raise UserError("--samples and --seed go with --vary")
    if scheduler is None and (workers is not None or threads is not None):
        raise UserError("--workers and --threads go with --scheduler local")
    plan = lib.plan_batch(scenes or [], sets=set_ or [], sweeps=[lib.parse_sweep(s) for s in sweep or []],
                          varies=[lib.parse_vary(v) for v in vary or []],
                          samples=100 if samples is None else samples, seed=0 if seed is None else seed)
    for note in plan.notes:
        typer.echo(f"note: {note}", err=True)
    total = len(plan.specs)
    step = parse_dt(dt)
    from collide.output import OutputError, check_file, check_folder

    try:  # where the results go: said before the first run (exit 2), not after the last
        check_file(summary, "file name for the summary CSV")
        if record is not None:
            check_folder(record)
    except OutputError as exc:
        raise UserError(str(exc)) from None

    cluster = None
    try:
        if scheduler is not None:
            from collide.distributed import DaskExecutor, connect

            cluster = connect(scheduler, workers=workers, threads=threads)
        bar = _Progress(total, enabled=progress)
        with bar:
            result = lib.run_batch(plan, integrator=integrator, dt=step, tol=tol, summary=summary,
                                   record_dir=record, resume=resume, chunk_size=chunk, stride=stride,
                                   progress=bar.update,
                                   executor=None if cluster is None else DaskExecutor(cluster))
    except KeyboardInterrupt:
        if cluster is None and scheduler is not None:  # while connecting: nothing ran
            typer.echo(f"\ninterrupted while connecting to the Dask scheduler at {scheduler}", err=True)
        else:
            typer.echo(f"\ninterrupted: finished runs are kept in {summary}; run the same command with "
                       "--resume to finish the rest", err=True)
        if cluster is not None:
            # Dask's futures still pending at exit print a traceback from their __del__ while the
            # interpreter tears down (now and then): the rows are synced, so end here, quietly.
            with contextlib.suppress(Exception):
                cluster.close()
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(130)
        raise SystemExit(130) from None
    except OutputError as exc:
        if summary.exists():  # a write failed mid-batch: the finished runs' rows are on disk
            raise OutputError(f"{exc}; finished runs are kept in {summary}: make room and run the same "
                              "command with --resume to finish the rest") from None
        raise
    except lib.BatchError as exc:
        if cluster is not None and "lost the Dask scheduler" in str(exc):
            raise lib.BatchError(f"{exc}; finished runs are kept in {summary}: run the same command with "
                                 "--resume to finish the rest") from None
        raise
    finally:
        if cluster is not None:
            cluster.close()
    for note in result.notes[len(plan.notes):]:
        typer.echo(f"note: {note}", err=True)
    # Loading the compiled engine is a process's one-time cost, not the runs': said apart.
    per_run = (result.wall_time_s - result.load_s) / result.ran if result.ran else 0.0
    loaded = f", after {result.load_s:.2g} s loading the compiled engine" if result.load_s >= 0.01 else ""
    timing = f"in {result.wall_time_s:.3g} s ({per_run * 1e3:.3g} ms each{loaded})"
    if result.skipped:
        done = f"{total} runs: {result.ran} {timing}, {result.skipped} already in the summary"
    else:
        done = f"{total} runs {timing}"
    typer.echo(f"{done}, {result.failed} failed")
    for row in [r for r in result.rows if r.get("error")][:5]:
        typer.echo(f"  failed: run {row['run_id']} ({row['scene']}): {row['error']}")
    if vary:
        _print_stats(result, plan)
    typer.echo(f"summary: {summary}")
    if record is not None:
        typer.echo(f"recordings: {record}/ ({len(result.recordings)} written)")


def _print_stats(result, plan) -> None:  # noqa: ANN001 - library types, imported lazily
    from collide import batch as lib

    columns = lib.summary_columns(plan)
    stats = lib.ensemble_stats(result.rows, plan.param_keys + columns.outcomes)
    if not stats:
        return
    width = max(len(s.column) for s in stats)
    typer.echo(f"  {'':<{width}}  {'mean':>14}  {'std':>12}  {'n':>6}")
    for s in stats:
        typer.echo(f"  {s.column:<{width}}  {s.mean:>14.8g}  {s.std:>12.4g}  {s.count:>6}")


class _Progress:
    """A rich progress bar on stderr; without a terminal, one plain line per chunk."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total = total
        self.enabled = enabled
        self.bar = None

    def __enter__(self) -> _Progress:
        if self.enabled and sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.bar = Progress(TextColumn("runs"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                                console=Console(stderr=True), transient=True)
            self.bar.start()
            self.task = self.bar.add_task("runs", total=self.total)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()

    def update(self, done: int, total: int) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=done, total=total)
        elif self.enabled:
            sys.stderr.write(f"runs: {done}/{total}\n")
            sys.stderr.flush()


def register(app: typer.Typer) -> None:
    """Add `collide batch` to the app."""
    app.command()(batch)

