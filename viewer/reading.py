"""Reading recordings the viewer did not write itself, without risking the server.

A damaged `.rrd` can make rerun's reader panic inside its Rust code and abort the whole
process (issue 14, item 3), or hang. `read_untrusted` reads in a child process with a time and
memory limit, so a crash or a hang costs that child only; the caller gets a `RecordingError`
with one line that names the file as the user knows it (never a temporary path).

When the core has `collide.recording.read_recording_safely` (the hardening work), that is used;
until then the child process here does the same job.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
from pathlib import Path

from collide.recording import RecordingError
from collide.run import SceneRun

TIMEOUT_S = 60.0
MEMORY_MB = 6144  # address space of the child: rerun and numpy reserve much more than they use


def _child(path: str, memory_mb: int) -> None:  # pragma: no cover - runs in the child
    """`python -m viewer.reading PATH MEMORY_MB`: read, and write the pickled outcome to stdout."""
    import resource
    import sys

    limit = memory_mb * 2**20
    try:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    except (ValueError, OSError):
        pass
    try:
        from collide.recording import read_recording

        outcome = ("ok", read_recording(path))
    except MemoryError:
        outcome = ("error", f"needs more than {memory_mb} MB to read")
    except Exception as exc:  # noqa: BLE001 - whatever the reader raises becomes one line
        outcome = ("error", " ".join(str(exc).split()) or type(exc).__name__)
    sys.stdout.buffer.write(pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL))
    sys.stdout.flush()


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


def read_untrusted(path: str | Path, *, name: str | None = None, timeout_s: float = TIMEOUT_S,
                   memory_mb: int = MEMORY_MB) -> SceneRun:
    """Read a recording in a child process. `name` is how the file is shown in messages
    (default: its file name). Raises `RecordingError` (one line) for anything that goes wrong:
    not a recording, damaged, a reader crash, a hang, too much memory."""
    path = Path(path)
    shown = name or path.name
    try:
        from collide.recording import read_recording_safely  # the core's own, once it lands
    except ImportError:
        read_recording_safely = None
    if read_recording_safely is not None:
        try:
            return read_recording_safely(path, timeout_s=timeout_s, memory_mb=memory_mb)
        except RecordingError as exc:
            raise RecordingError(_rename(str(exc), path, shown)) from None
    if not path.is_file():
        raise RecordingError(f"{shown}: no such file")
    root = str(Path(__file__).resolve().parent.parent)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
           "RUST_BACKTRACE": "0"}
    try:
        # stderr is dropped: a reader that panics prints a Rust backtrace.
        proc = subprocess.run([sys.executable, "-m", "viewer.reading", str(path.resolve()), str(memory_mb)],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                              timeout=timeout_s, env=env, check=False)
    except subprocess.TimeoutExpired:
        raise RecordingError(f"{shown}: reading took longer than {timeout_s:g} s; given up") from None
    try:
        status, payload = pickle.loads(proc.stdout)
    except Exception:  # noqa: BLE001 - no outcome: the child died before writing one
        code = proc.returncode
        how = f"crashed ({_signal_name(code)})" if code < 0 else f"stopped (exit code {code})"
        raise RecordingError(f"{shown}: the recording reader {how}: the file is damaged") from None
    if status != "ok":
        raise RecordingError(_rename(str(payload), path, shown))
    return payload


def _rename(text: str, path: Path, shown: str) -> str:
    """The reader's message with the file named as the user knows it."""
    for form in (str(path.resolve()), str(path), path.name):
        text = text.replace(form, shown)
    return " ".join(text.split())


if __name__ == "__main__":  # pragma: no cover - the child process
    _child(sys.argv[1], int(sys.argv[2]))
