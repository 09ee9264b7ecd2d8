"""The recording given to `collide view FILE`, read while the server starts and the first tabs
connect: a tab shows its scene's start as soon as the reader has checked the file's seal
(`StartOfRecording`, its status saying the run is still loading), and the run once it is read
and prepared for display.

The reader is a child process (a damaged file must not abort the server, `viewer.reading`);
it starts before the server's own imports are done and decodes while the server starts
listening, so the page and the file's reading overlap rather than follow each other.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from collide.recording import RecordingError
from collide.scene import Scene
from viewer.frames import StartFrames, start_frames


class StartOfRecording(StartFrames):
    """A recording's first frame (its scene's start) while its run is being read."""

    preview_note = "the recording is still loading"
    recording_name = ""

    def status_lines(self) -> list[str]:
        return [f"{self.n_bodies} bodies at the start (t = {self.t0:.4g} s): {self.recording_name} is still "
                "loading; its run replaces this when read"]


def start_of_recording(scene: Scene, name: str) -> StartOfRecording:
    """The recording's scene at its start, drawn while the rest is read (O(N), no stepping)."""
    start = start_frames(scene, StartOfRecording)
    start.recording_name = name
    return start


class OpeningRecording:
    """A recording read on a thread: its scene when the reader has it, then its prepared run
    (`view`) or the one-line reason it cannot be read (`error`). `follow(callback)` calls
    `callback(self)` now and at each of those two steps (from the reading thread)."""

    def __init__(self, path: Path, name: str) -> None:
        self.path, self.name, self.shown = path, path.name, name
        self.scene: Scene | None = None
        self.view: Any = None  # a ViewRun once prepared
        self.error: str | None = None
        self.begun = threading.Event()  # the scene, the run or the error: something to show
        self.done = threading.Event()
        self._lock = threading.Lock()
        self._followers: list[Callable[[OpeningRecording], None]] = []
        self._thread = threading.Thread(target=self._read, name="collide-open-recording", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        from viewer.reading import read_untrusted

        try:
            run = read_untrusted(self.path, name=self.shown, on_scene=self._scene_read, rewarm=False)
            from viewer.state import ViewRun

            view = ViewRun(run, origin=f"recording {self.name}")
        except (RecordingError, ValueError, OSError) as exc:
            self._step(error=" ".join(str(exc).split()) or type(exc).__name__)
        except Exception as exc:  # noqa: BLE001 - whatever preparing it raised: said, never a hang
            self._step(error=f"{self.shown}: cannot be shown ({type(exc).__name__}: {exc})")
        else:
            self._step(view=view, scene=run.scene)
        finally:
            # A reader grown by the file is replaced now that the tabs have the run (or its
            # error), not while they were being sent it.
            from collide.recording.sandbox import warm_reader

            warm_reader()
            self.done.set()

    def _scene_read(self, scene: Scene) -> None:
        self._step(scene=scene)

    def _step(self, **change: Any) -> None:
        with self._lock:
            for key, value in change.items():
                setattr(self, key, value)
            followers = list(self._followers)
        self.begun.set()
        for callback in followers:
            callback(self)

    def follow(self, callback: Callable[[OpeningRecording], None]) -> None:
        """Call `callback(self)` now and whenever the scene or the run (or an error) arrives."""
        with self._lock:
            self._followers.append(callback)
        callback(self)

    def wait_begun(self, timeout: float | None = None) -> bool:
        """Wait until the recording's start can be shown, or it is refused; True if so."""
        return self.begun.wait(timeout)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the recording is read or refused; True if done."""
        return self.done.wait(timeout)
