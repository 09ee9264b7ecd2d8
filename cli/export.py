"""`collide export`: a recording out to ParaView (VTK), a spreadsheet (long CSV), a video (MP4)
or a scene file (TOML). The work is `collide.export`'s; this parses options and says what it wrote."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from cli.common import UserError


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.iterdir())
    return path.stat().st_size


def export(
    recording: Annotated[Path, typer.Argument(help="A .rrd recording made by collide (collide run writes one).")],
    format_: Annotated[str, typer.Option(
        "--format", "-f", help="vtk (a .pvd series of .vtp files for ParaView), csv (long form: a row per body "
        "per frame, and a contacts table), mp4 (a video) or toml (the scene, to run again).")] = "vtk",
    out: Annotated[Path | None, typer.Option(
        help="File to write.", show_default="the recording's name with .pvd, .csv, .mp4 or .toml")] = None,
    fps: Annotated[float, typer.Option(
        help="Frames per simulated second in free flight (contacts get more), as the recording's.")] = 60.0,
    max_frames: Annotated[int, typer.Option(
        "--max-frames", min=2, help="Frames at most (evenly thinned beyond).")] = 2000,
    ascii: Annotated[bool, typer.Option("--ascii", help="VTK: numbers as text (default: base64 binary).")] = False,
) -> None:
    """Export a recording to other tools: VTK for ParaView, long-form CSV, an MP4 video or the scene's TOML.

    A damaged recording is refused in one line and nothing is written.

    Examples:

      collide export recordings/demo-bonus.rrd --format vtk      # recordings/demo-bonus.pvd + demo-bonus/

      collide export recordings/demo-bonus.rrd --format csv --out bonus.csv   # and bonus-contacts.csv

      collide export recordings/pile.rrd --format mp4

      collide export recordings/demo-bonus.rrd --format toml --out again.toml && collide run again.toml
    """
    from collide.export import FORMATS, default_out, export_run, outputs
    from collide.output import OutputError, check_file

    fmt = format_.lower()
    if not fps > 0:
        raise UserError(f"--fps must be positive, got {fps}")
    if not recording.is_file():
        raise UserError(f"recording '{recording}' does not exist")
    if fmt not in FORMATS:
        raise UserError(f"--format: unknown '{format_}' (choose from {', '.join(FORMATS)})")
    target = out if out is not None else default_out(recording, fmt)
    try:
        for path in outputs(fmt, target):
            if fmt != "vtk" or path == target:  # the frames' folder may exist: it is replaced
                check_file(path)  # before the recording is read: a place that cannot be written is said first
    except OutputError as exc:
        raise UserError(str(exc)) from None
    if fmt == "mp4":
        from collide.export.video import ffmpeg_path

        ffmpeg_path()  # before reading: no ffmpeg is said at once
    from collide.recording import read_recording

    start = time.perf_counter()
    run = read_recording(recording)  # in a child process: a damaged file is one line, exit 2
    written = export_run(run, fmt, target, fps=fps, max_frames=max_frames, ascii=ascii)
    took = time.perf_counter() - start
    for path in written:
        kind = "folder" if path.is_dir() else "file"
        typer.echo(f"  {kind} {path} ({_size(path) / 1e6:.3g} MB)")
    typer.echo(f"exported {recording} as {fmt} in {took:.3g} s")


def register(app: typer.Typer) -> None:
    """Add `collide export` to the app."""
    app.command()(export)
