"""Reading recordings the viewer did not write itself, without risking the server.

A damaged `.rrd` can make rerun's reader panic inside its Rust code and abort the whole
process (issue 14, item 3), or hang. `read_untrusted` reads through the core's
`read_recording_safely` (a child process with a time and memory limit), so a crash or a hang
costs that child only; the caller gets a `RecordingError` with one line that names the file as
the user knows it (never a temporary path).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from collide.recording import RecordingError, read_recording_safely
from collide.run import SceneRun
from collide.scene import Scene

TIMEOUT_S = 60.0
# And this many seconds more per byte of the file: a 100 000-sphere pour's recording (1.1 GB)
# takes minutes to read on a loaded machine, where a small one's hang is still caught in a minute.
TIMEOUT_PER_BYTE = 1.0 / 5e6
MEMORY_MB = 6144  # address space of the child: rerun and numpy reserve much more than they use


def read_untrusted(path: str | Path, *, name: str | None = None, timeout_s: float | None = None,
                   memory_mb: int = MEMORY_MB, on_scene: Callable[[Scene], None] | None = None,
                   rewarm: bool = True) -> SceneRun:
    """Read a recording in a child process. `name` is how the file is shown in messages
    (default: its file name); `timeout_s` defaults to TIMEOUT_S and TIMEOUT_PER_BYTE of the
    file's size. Raises `RecordingError` (one line) for anything that goes wrong: not a
    recording, damaged, a reader crash, a hang, too much memory. `on_scene` is handed the
    recording's scene before its run is decoded; `rewarm=False` leaves a grown reader's
    replacement to the caller (`read_recording_safely`)."""
    path = Path(path)
    if timeout_s is None:
        try:
            timeout_s = TIMEOUT_S + path.stat().st_size * TIMEOUT_PER_BYTE
        except OSError:
            timeout_s = TIMEOUT_S  # the reader says what is wrong with it
    try:
        return read_recording_safely(path, timeout_s=timeout_s, memory_mb=memory_mb, on_scene=on_scene,
                                     rewarm=rewarm)
    except RecordingError as exc:
        raise RecordingError(_rename(str(exc), path, name or path.name)) from None


def _rename(text: str, path: Path, shown: str) -> str:
    """The reader's message with the file named as the user knows it."""
    for form in (str(path.resolve()), str(path), path.name):
        text = text.replace(form, shown)
    return " ".join(text.split())
