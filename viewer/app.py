"""`collide view`: a viser web app for live parameter scrubbing and replaying recordings.

    from viewer.app import ViewerApp
    app = ViewerApp("demo-bonus", port=8080)   # or a .toml path, or a .rrd recording
    app.start()                               # binds 127.0.0.1 unless host= says otherwise
    print(app.url)
    app.serve_forever()                       # until Ctrl+C

Each browser tab gets its own `Session` (controls, 3D scene, plots, timeline, worker); the
first scene's run is computed once at start and shared. Tabs are set up two at a time, in the
order they open, and torn down however viser orders their open and close (`viewer.tabs`); what
a client sends cannot flood the log (`viewer.guard`). A scene given at start that cannot be
read raises (`SceneError`, `RunError`) before the server starts, so the CLI can turn it into a
one-line error; a recording is read while the server starts (`viewer.opening`: the page shows
its start, then its run) and `wait_for_recording` raises its `RecordingError`.
"""

from __future__ import annotations

import contextlib
import io
import ipaddress
import re
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

import viser

from collide.model import compile_scenes
from collide.recording import RecordingError
from collide.run import SceneRun, run_scene
from collide.scene import Scene, load_scene
from viewer import files
from viewer.config import SessionConfig
from viewer.guard import guard_connections
from viewer.live import MANY_BODIES
from viewer.opening import OpeningRecording
from viewer.params import for_viewing
from viewer.session import Session
from viewer.state import ViewRun
from viewer.tabs import Tabs


def check_listen_address(host: str, timeout: float = 3.0) -> None:
    """Raise OSError with a one-line reason unless this machine can listen on `host` (an IP
    address or a name that resolves to one of its own addresses)."""
    try:
        addresses = [str(ipaddress.ip_address(host))]
    except ValueError:
        addresses = []
    if not addresses:
        if re.fullmatch(r"[0-9.]+|[0-9a-fA-F:.]*:[0-9a-fA-F:.]*", host):
            raise OSError(f"'{host}' is not a valid IP address")
        found: list = []

        def resolve() -> None:
            try:
                found.extend(socket.getaddrinfo(host, None, type=socket.SOCK_STREAM))
            except OSError as exc:
                found.append(exc)

        thread = threading.Thread(target=resolve, daemon=True)
        thread.start()
        thread.join(timeout)
        if not found:
            raise OSError(f"cannot resolve '{host}' (no answer in {timeout:g} s)")
        if isinstance(found[0], OSError):
            raise OSError(f"cannot resolve '{host}': {found[0].strerror or found[0]}")
        addresses = sorted({info[4][0] for info in found})
    errors = []
    for address in addresses:
        family = socket.AF_INET6 if ":" in address else socket.AF_INET
        try:
            with socket.socket(family, socket.SOCK_STREAM) as probe:
                probe.bind((address, 0))
            return
        except OSError as exc:
            errors.append(exc)
    reason = errors[0].strerror if errors and errors[0].strerror else "cannot bind"
    raise OSError(f"{host} is not an address of this machine ({reason})")


class ViewerApp:
    """The viewer server: one viser server, one `Session` per connected tab."""

    def __init__(self, initial: str | Path | None = None, *, host: str = "127.0.0.1", port: int = 8080,
                 recordings_dir: str | Path = "recordings", scenes_dir: str | Path | None = None,
                 max_upload_bytes: int = files.MAX_UPLOAD_BYTES, point_bodies: int | None = None) -> None:
        self.initial = str(initial) if initial is not None else "demo-bonus"
        self.host = host
        self.port = port
        self.recordings_dir = Path(recordings_dir)
        self.scenes_dir = Path(scenes_dir) if scenes_dir is not None else None
        self.max_upload_bytes = max_upload_bytes
        self.point_bodies = point_bodies  # bodies above which "auto" draws points (None: the viewer's default)
        self.server: viser.ViserServer | None = None
        self.tabs = Tabs(self._build_session)
        self.initial_scene: Scene | None = None
        self.initial_run: SceneRun | None = None
        self.initial_view: ViewRun | None = None
        self.initial_recording: str | None = None
        self.initial_cost: float | None = None  # s: wall time of the initial run
        self.scene_choices: list[files.SceneChoice] = []
        self.initial_label = ""
        self.opening: OpeningRecording | None = None  # the recording given at start, while it is read

    def begin_reading(self) -> None:
        """Start reading the recording given at start now (before `prepare`): its reader
        process imports and decodes while this process goes on."""
        if self.initial.lower().endswith(".rrd") and self.opening is None:
            self.opening = OpeningRecording(Path(self.initial), self.initial)

    def wait_for_recording(self, timeout: float | None = None) -> None:
        """Wait until the recording given at start is read and prepared; raises its
        `RecordingError` if it cannot be (tests, benchmarks, the CLI)."""
        if self.opening is None:
            return
        self.opening.wait(timeout)
        if self.opening.error is not None:
            raise RecordingError(self.opening.error)

    @property
    def initial_view(self) -> ViewRun | None:
        """The initial run prepared for display (a recording's once it is read)."""
        if self.opening is not None:
            return self.opening.view
        return self._initial_view

    @initial_view.setter
    def initial_view(self, view: ViewRun | None) -> None:
        self._initial_view = view

    # ------------------------------------------------------------------------------------------

    def prepare(self) -> None:
        """Read the initial scene and run it once (raises on a bad one), or start reading the
        initial recording (its errors: `wait_for_recording`, and each tab's status)."""
        source = self.initial
        extra = []
        run: SceneRun | None = None
        if source.lower().endswith(".rrd"):
            path = Path(source)
            # Read in a child process (a damaged file must not abort the CLI, issue 14, item 3),
            # while the server starts: tabs show the recording as it comes (`viewer.opening`).
            if self.opening is None or self.opening.path != path:
                self.opening = OpeningRecording(path, str(path))
            self.initial_recording = path.name
        else:
            scene = for_viewing(load_scene(source))
            self.initial_scene = scene
            if len(scene.bodies) > MANY_BODIES:
                # Seconds to minutes of run: each tab shows the scene's start at once and runs it
                # in the background (viewer.live). Its model is built here: a bad scene is
                # refused before the server starts.
                compile_scenes([scene])
                run = None
            else:
                run = run_scene(scene, record=True)
                self.initial_view = ViewRun(run, origin=scene.name)
            if source.endswith(".toml"):
                extra.append(source)
        self.initial_run = run
        self.initial_cost = run.result.wall_time_s if run is not None else None
        self.scene_choices = files.scene_choices(self.scenes_dir, extra)
        for choice in self.scene_choices:
            if choice.source == source:
                self.initial_label = choice.label
        if self.initial_recording is not None:
            self.initial_label = f"rec: {self.initial_recording}"
        elif not self.initial_label:
            self.initial_label = self.scene_choices[0].label

    def start(self) -> None:
        """Prepare the initial run and start serving (non-blocking)."""
        if self.initial_scene is None and self.initial_recording is None:
            self.prepare()
        # viser retries the next port on any bind error and waits forever when none works: an
        # address this machine does not have hung `collide view --host 10.255.255.1`.
        check_listen_address(self.host)
        # viser prints its own banner; the CLI prints the URL itself.
        with contextlib.redirect_stdout(io.StringIO()):
            server = viser.ViserServer(host=self.host, port=self.port, label="collide view", verbose=False)
        self.server = server
        server.gui.configure_theme(show_share_button=False, brand_color=(66, 133, 244))
        guard_connections(server)
        server.on_client_connect(self.tabs.connect)
        server.on_client_disconnect(self.tabs.disconnect)

    @property
    def url(self) -> str:
        assert self.server is not None, "start() first"
        host = self.server.get_host()
        shown = "localhost" if host in ("0.0.0.0", "::") else host
        return f"http://{shown}:{self.server.get_port()}"

    def serve_forever(self) -> None:
        """Block until Ctrl+C, then stop."""
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def stop(self) -> None:
        self.tabs.close()
        if self.server is not None:
            self.server.stop()
            self.server = None

    # ------------------------------------------------------------------------------------------

    @property
    def sessions(self) -> dict[int, Session]:
        """The connected tabs' sessions by client id (a copy; tabs still being set up are not
        in it)."""
        return self.tabs.sessions()

    def session_config(self) -> SessionConfig:
        """What each tab's session needs from the app (after `prepare`)."""
        return SessionConfig(self.recordings_dir, self.max_upload_bytes, tuple(self.scene_choices), self.initial_cost,
                             self.point_bodies)

    def _build_session(self, client: viser.ClientHandle, closed: Callable[[], bool]) -> Session:
        """A new tab's session, showing the initial scene or recording (on a set-up thread);
        the drawing is skipped once the tab has closed."""
        session = Session(self.session_config(), client)
        if closed():
            return session
        if self.opening is not None:
            session.follow_opening(self.opening)
        else:
            session.load_scene(self.initial_scene, run=self.initial_run, label=self.initial_label)
        return session

    def wait_for_session(self, count: int = 1, timeout: float = 20.0) -> list[Session]:
        """Wait until at least `count` tabs are connected (tests, benchmarks)."""
        return self.tabs.wait(count, timeout)
