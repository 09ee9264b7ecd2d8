"""The Files and export folder: open a recording from recordings/ or an upload (read in a child
process: a damaged file cannot take the server down), save the run shown, and download it as
CSV, as `collide export` writes it (VTK, long CSV, MP4, TOML), or the 3D view as PNG."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import viser
from viser import _messages

from collide.recording import RecordingError
from collide.run import run_scene
from collide.scene import SceneError
from collide.stepper import RunError
from viewer import files
from viewer.config import SessionConfig
from viewer.exports import png_bytes, run_csv
from viewer.messages import Messages, one_line, strip_name
from viewer.panel import CHOOSE, Panel
from viewer.reading import read_untrusted
from viewer.state import ViewRun
from viewer.uploads import UploadSink

# The panel's download buttons that `collide export` makes, and their format.
EXPORTS = {"VTK": "vtk", "CSV long": "csv", "MP4": "mp4", "TOML": "toml"}
VIEWER_EXPORT_FRAMES = 600  # frames at most in a download (a video of 20 s; the CLI's --max-frames is 2 000)

# s after an upload's outcome when viser's own "uploaded successfully" is removed again: a
# loaded browser may show it seconds late.
UPLOAD_TOAST_REMOVALS = (0.4, 1.5, 4.0, 10.0)


class FileActions:
    """Recordings in and out for one tab. `show_recording(view, name)` shows a recording read;
    `shown()` is the run and time shown now."""

    def __init__(self, client: viser.ClientHandle, config: SessionConfig, panel: Panel, messages: Messages,
                 closed: threading.Event, show_recording: Callable[[ViewRun, str], None],
                 shown: Callable[[], tuple[ViewRun | None, float]]) -> None:
        self._client = client
        self._folder = config.recordings_dir
        self._max_bytes = config.max_upload_bytes
        self._panel = panel
        self._messages = messages
        self._closed = closed
        self._show_recording = show_recording
        self._shown = shown
        self.downloads: list[tuple[str, int]] = []  # (file name, bytes) sent to the browser
        self._upload_ids: dict[str, str] = {}
        self.uploads = UploadSink(client, panel.upload._impl.uuid, self._folder, self._max_bytes,
                                  self._upload_started, self._upload_done) \
            if hasattr(client, "_websock_connection") else None
        panel.recording.on_update(self._on_recording)
        panel.refresh_button.on_click(lambda _e: panel.refresh_recordings())
        panel.upload.on_upload(self._on_upload)
        panel.save_button.on_click(lambda _e: self.save_run())
        panel.export_buttons.on_click(lambda e: self._on_export(e))

    def close(self) -> None:
        """Drop unfinished uploads."""
        if self.uploads is not None:
            self.uploads.close()

    def _say(self, message: str, error: bool = False) -> None:
        self._messages.file_message(message, error)

    # -- opening ----------------------------------------------------------------------------------

    def _on_recording(self, event: viser.GuiEvent) -> None:
        if event.client is None or self._panel.recording.value == CHOOSE:
            return
        try:
            path = files.recording_path(self._folder, self._panel.recording.value)
        except files.UploadError as exc:
            self._say(str(exc), error=True)
            return
        self.open_recording(path)

    def open_recording(self, path: Path, name: str | None = None) -> bool:
        """Replay a recording; a file that cannot be read leaves a message and changes nothing."""
        shown = name or path.name
        self._say(f"Reading {shown}...")
        try:
            run = read_untrusted(path, name=shown)
            view = ViewRun(run, origin=f"recording {shown}")
        except (RecordingError, ValueError, OSError) as exc:
            self._say(f"Cannot open {shown}: {strip_name(one_line(exc), shown)}", error=True)
            self._messages.show_notice(f"Cannot open {shown}: {strip_name(one_line(exc), shown)}", error=True)
            return False
        self._show_recording(view, shown)
        return True

    # -- uploads ----------------------------------------------------------------------------------

    def _on_upload(self, event: viser.GuiEvent) -> None:
        # Only reached when uploads are not streamed (no client connection to hook).
        uploaded = self._panel.upload.value
        self.receive_upload(uploaded.name, uploaded.content)

    def _upload_started(self, name: str, transfer_uuid: str) -> None:
        self._upload_ids[name] = transfer_uuid
        self._say(f"Receiving {Path(name).name}...")

    def _upload_done(self, name: str, staged: Path | None, error: str | None) -> None:
        transfer = self._upload_ids.pop(name, None)
        if error is not None:
            message = f"Upload refused: {error}"
            self._say(message, error=True)
            self._messages.show_notice(message, error=True)
            self._upload_toast(transfer, "Upload refused", error, ok=False)
            return
        assert staged is not None
        self._open_staged(name, staged, transfer)

    def receive_upload(self, name: str, content: bytes) -> bool:
        """Check, stage and open an uploaded recording given as bytes (tests; the page streams
        uploads through `UploadSink`). Keeps it in recordings/ if it reads."""
        try:
            files.check_upload(name, len(content), self._max_bytes)
            staged = files.write_staged(self._folder, content)
        except (files.UploadError, OSError) as exc:
            self._say(f"Upload refused: {one_line(exc)}", error=True)
            self._messages.show_notice(f"Upload refused: {one_line(exc)}", error=True)
            return False
        return self._open_staged(name, staged, None)

    def _open_staged(self, name: str, staged: Path, transfer: str | None) -> bool:
        folder = self._folder
        shown = f"{files.safe_stem(name)}.rrd"
        self._say(f"Checking {shown}...")
        try:
            run = read_untrusted(staged, name=shown)
            view = ViewRun(run, origin=f"recording {shown}")
        except (RecordingError, ValueError, OSError) as exc:
            staged.unlink(missing_ok=True)
            reason = strip_name(one_line(exc), shown)
            self._say(f"Cannot open {shown}: {reason}", error=True)
            self._messages.show_notice(f"Cannot open {shown}: {reason}", error=True)
            self._upload_toast(transfer, f"Cannot open {shown}", reason, ok=False)
            return False
        final = files.unique_path(folder, name)
        staged.rename(final)
        self._panel.refresh_recordings(select=final.name)
        view.origin = f"recording {final.name}"
        self._show_recording(view, final.name)
        self._upload_toast(transfer, f"Opened {final.name}", f"kept in {folder.name}/", ok=True)
        return True

    def _upload_toast(self, transfer: str | None, title: str, body: str, ok: bool) -> None:
        """Replace viser's own upload notification ("File uploaded successfully", shown for any
        file once its bytes arrive, even one that cannot be opened) with what became of the file.
        The removal is sent again later: the browser may show its notification after the first."""
        if not self._closed.is_set():
            self._client.add_notification(title, body, with_close_button=True,
                                          auto_close_seconds=8.0 if ok else 20.0, color="green" if ok else "red")
        if transfer is None:
            return
        message = _messages.RemoveNotificationMessage(uuid=f"upload-{transfer}")

        def send() -> None:
            if not self._closed.is_set():
                self._client._websock_connection.queue_message(message)

        send()
        for delay in UPLOAD_TOAST_REMOVALS:
            timer = threading.Timer(delay, send)
            timer.daemon = True
            timer.start()

    # -- saving and exports -----------------------------------------------------------------------

    def save_run(self) -> Path | None:
        """Write the run shown (at full quality) to recordings/ under a safe, new name."""
        view, _ = self._shown()
        if view is None or getattr(view, "run", None) is None:
            self._say("Nothing to save yet.", error=True)
            return None
        run = view.run
        try:
            if view.preview or getattr(view, "measuring", False):
                run = run_scene(view.scene, record=True)  # the scene's own run, its error measured
            self._folder.mkdir(parents=True, exist_ok=True)
            path = files.unique_path(self._folder, files.save_name(view.scene.name))
            from collide.recording import write_recording  # Rerun's writer: imported when first saving

            write_recording(run, path)
        except (SceneError, RunError, OSError, ValueError) as exc:
            self._say(f"Not saved: {one_line(exc)}", error=True)
            return None
        self._panel.refresh_recordings()
        self._say(f"Saved **{path.name}** in {self._folder.name}/.")
        return path

    def _on_export(self, event: viser.GuiEvent) -> None:
        choice = self._panel.export_buttons.value
        if choice == "CSV":
            self.export_csv()
        elif choice in EXPORTS:
            self.export_file(EXPORTS[choice])
        else:
            self.export_png()

    def export_file(self, fmt: str) -> str | None:
        """Send the run shown as `collide export --format fmt` writes it (a zip for VTK and the
        long CSV's two tables) to the browser as a download."""
        view, _ = self._shown()
        if view is None or getattr(view, "run", None) is None:
            self._say("No run to export.", error=True)
            return None
        from collide.export import export_download  # imports Rerun's writer: not at start-up

        try:
            name, content = export_download(view.run, fmt, files.safe_stem(view.scene.name),
                                            max_frames=VIEWER_EXPORT_FRAMES)
        except (ValueError, RunError, OSError) as exc:
            self._say(f"{fmt.upper()} not made: {one_line(exc)}", error=True)
            return None
        self._client.send_file_download(name, content, save_immediately=True)
        self.downloads.append((name, len(content)))
        self._say(f"Downloaded **{name}** ({len(content) / 1e6:.3g} MB).")
        return name

    def export_csv(self) -> str | None:
        """Send the run's CSV (the `collide run --csv` columns) to the browser as a download."""
        view, _ = self._shown()
        if view is None or getattr(view, "run", None) is None:
            self._say("No run to export.", error=True)
            return None
        try:
            content, every = run_csv(view.run)
        except (ValueError, RunError) as exc:
            self._say(f"CSV not made: {one_line(exc)}", error=True)
            return None
        name = f"{files.safe_stem(view.scene.name)}.csv"
        self._client.send_file_download(name, content, save_immediately=True)
        self.downloads.append((name, len(content)))
        rows = content.count(b"\n") - 1
        self._say(f"Downloaded **{name}**: {rows} rows, every {every * 1e3:.3g} ms.")
        return name

    def export_png(self) -> str | None:
        """Render the 3D view in the browser and send it back as a PNG download."""
        view, _ = self._shown()
        cam = self._client.camera
        try:
            width, height = int(cam.image_width), int(cam.image_height)
        except (AttributeError, AssertionError):
            width = height = 0
        if view is None or width <= 0 or height <= 0:
            self._say("No view to capture yet.", error=True)
            return None
        try:
            pixels = self._client.get_render(height, width, transport_format="png", timeout=30.0)
        except (TimeoutError, RuntimeError) as exc:
            self._say(f"Screenshot failed: {one_line(exc)}", error=True)
            return None
        content = png_bytes(pixels)
        _, t = self._shown()
        name = f"{files.safe_stem(view.scene.name if view.scene is not None else 'view')}-{t * 1e3:.4g}ms.png"
        self._client.send_file_download(name, content, save_immediately=True)
        self.downloads.append((name, len(content)))
        self._say(f"Downloaded **{name}** ({width}x{height}).")
        return name
