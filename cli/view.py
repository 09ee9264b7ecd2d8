"""`collide view`: the viser web viewer (live parameter scrubbing, replay of recordings)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from cli.common import UserError
from collide.recording.spec import RecordingError


def view(
    source: Annotated[str, typer.Argument(
        help="A built-in scene name, a .toml scene file, or a .rrd recording made by collide.")] = "demo-bonus",
    port: Annotated[int, typer.Option(help="Port to serve on; 0 picks any free port.", min=0, max=65535)] = 8080,
    host: Annotated[str, typer.Option(
        help="Address to listen on. The default serves this machine only; 0.0.0.0 exposes the viewer to "
        "your network, deliberately.")] = "127.0.0.1",
    recordings: Annotated[Path, typer.Option(
        "--recordings", help="Folder of .rrd files to open; uploads and saved runs go here.")] = Path("recordings"),
    scenes_dir: Annotated[Path | None, typer.Option(
        "--scenes-dir", help="Folder of .toml scenes to add to the scene picker; by default ./scenes when it "
        "exists.")] = None,
) -> None:
    """Serve the live viewer in the browser, or replay a recording.

    The page has a 3D view, a slider and a text box for every parameter (the run is redone
    while you drag), a timeline with step buttons, live plots, a values table, replay and
    upload of .rrd recordings, ensembles, and CSV and PNG downloads.

    Examples:

      collide view                          # demo-bonus on http://127.0.0.1:8080

      collide view demo-1d --port 0         # any free port

      collide view recordings/demo-bonus.rrd

      collide view my_scene.toml --scenes-dir scenes/
    """
    if source.lower().endswith(".rrd") and Path(source).is_file():
        from collide.recording.spec import check_rrd_header

        try:
            check_rrd_header(Path(source))  # a file that is no recording at all: one line, no banner
        except RecordingError as exc:
            raise UserError(str(exc)) from None
        # The reader process starts now and imports Rerun while this one imports the viewer.
        from collide.recording.sandbox import warm_reader

        warm_reader()
    from viewer.app import ViewerApp, check_listen_address

    if scenes_dir is not None and not scenes_dir.is_dir():
        raise UserError(f"--scenes-dir {scenes_dir} is not a folder")
    if scenes_dir is None and Path("scenes").is_dir():
        scenes_dir = Path("scenes")
    if source.lower().endswith(".rrd") and not Path(source).is_file():
        raise UserError(f"recording '{source}' does not exist")
    _refuse_heavy(source)
    try:
        check_listen_address(host)  # before any work: a wrong --host must not hang
    except OSError as exc:
        raise UserError(f"--host {host}: {exc}") from None
    app = ViewerApp(source, host=host, port=port, recordings_dir=recordings, scenes_dir=scenes_dir)
    # A recording is read in a child process (a damaged file can make Rerun's reader abort the
    # process that reads it) while the server starts: the page shows it as it comes. A file that
    # cannot be read is one line and exit code 2 (refused later, the server stops). A bad scene is
    # one line before serving.
    app.begin_reading()
    app.prepare()
    if app.opening is not None:
        # Serve once the page has the recording's start to show (its seal checked), so that a file
        # refused by then is its one line, with no banner before it.
        app.opening.wait_begun()
        if app.opening.error is not None:
            raise UserError(app.opening.error)
    try:
        app.start()
    except OSError as exc:
        raise UserError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    shown = f"recording {source}" if app.initial_recording is not None else (app.initial_label or source)
    typer.echo(f"collide view: {shown} at {app.url}  (Ctrl+C to stop)")
    if host not in ("127.0.0.1", "localhost", "::1"):
        typer.echo(f"  listening on {host}: anyone who can reach this address can use the viewer", err=True)
    if app.opening is not None:
        try:
            app.wait_for_recording()
        except RecordingError as exc:
            app.stop()
            raise UserError(str(exc)) from None
        except KeyboardInterrupt:
            app.stop()
            return
    app.serve_forever()


def _refuse_heavy(source: str) -> None:
    """A heavy built-in runs for minutes and draws too many spheres for a live view: the viewer
    opens its recording (level of detail for many bodies) instead."""
    from collide.scene import HEAVY_BODIES, builtin_names, is_heavy

    if source in builtin_names() and is_heavy(source):
        raise UserError(f"'{source}' is a heavy built-in (more than {HEAVY_BODIES:,} bodies, a run of minutes): "
                        f"record it with `collide run {source}` and open the recording with "
                        f"`collide view recordings/{source}.rrd`")


def register(app: typer.Typer) -> None:
    """Add `collide view` to the app."""
    app.command()(view)
