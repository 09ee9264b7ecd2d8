"""Reading recordings from anywhere: `read_recording` and `verify_recording` read in a child
process by default (`read_recording_safely`), so that a file that crashes, hangs or floods
Rerun's Rust reader costs only that process; `trusted=True` reads here (`reader`).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from collide.recording.spec import RecordingError, _fail

if TYPE_CHECKING:  # the reader (numpy, pyarrow, the scene's model) is imported where it reads
    from collide.run import SceneRun
    from collide.scene import Scene

SAFE_TIMEOUT_S = 60.0  # the reader process's limits (read_recording's defaults)
SAFE_MEMORY_MB = 2048


def read_recording(path: str | Path, *, trusted: bool = False, timeout_s: float = SAFE_TIMEOUT_S,
                   memory_mb: int = SAFE_MEMORY_MB) -> SceneRun:
    """Rebuild the run stored in a recording: scene, model, trajectory, final state and settings.

    Raises `RecordingError` (a `ValueError`) naming the file, in one line, when it is not an
    `.rrd`, is truncated or damaged (a changed byte: its checksum does not match), was not
    written by collide, or crashes, hangs or floods Rerun's reader.

    By default the file is read in a child process (`read_recording_safely`, with `timeout_s`
    and `memory_mb`): Rerun's reader is Rust, and a damaged file can abort the process that
    reads it. `trusted=True` reads in this process, about a second sooner (no reader process to
    start) and without pickling the run back: for files this program has just written itself.
    """
    if not trusted:
        return read_recording_safely(path, timeout_s=timeout_s, memory_mb=memory_mb)
    from collide.recording.reader import read_trusted

    return read_trusted(Path(path))


def verify_recording(path: str | Path, *, trusted: bool = False, timeout_s: float = SAFE_TIMEOUT_S,
                     memory_mb: int = SAFE_MEMORY_MB) -> None:
    """Check a recording without rebuilding its run (cheaper than `read_recording`): it returns
    only if `read_recording` would read the file, else raises the same `RecordingError`."""
    path = Path(path)
    if not trusted:
        _safely(path, "verify", timeout_s, memory_mb)
        return
    from collide.recording.reader import verify_trusted

    verify_trusted(path)


_POLL_S = 0.05
_HEADER = struct.Struct("!Q")
_IDLE_READERS = 1  # reader processes kept warm between reads
# MB: a reader that grew past this reading a large file is stopped, not kept: an idle reader
# held what it last read (360 MB after a 1 000-sphere pile; a fresh one is about 160 MB)
_IDLE_MAX_MB = 250


def _send_message(stream: Any, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


_ANSWER = struct.Struct("!QQ")  # the answer's pickle length, how many out-of-band buffers follow it


def _send_answer(stream: Any, obj: Any) -> None:
    """An answer with its arrays out of band (pickle protocol 5): each array's bytes follow the
    pickle as they are, and the parent reads them into buffers the arrays then use, so a large
    run is held once while it is passed, not twice (the message and the arrays made from it)."""
    buffers: list[pickle.PickleBuffer] = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    views = [b.raw() for b in buffers]
    stream.write(_ANSWER.pack(len(data), len(views)) + b"".join(_HEADER.pack(v.nbytes) for v in views))
    stream.write(data)
    for view in views:
        stream.write(view)
    stream.flush()


def _serve_reads() -> None:
    """The reader process: read (path, memory_mb) requests on stdin, answer on stdout.

    Started by `read_recording_safely` as a fresh interpreter (never a fork of the caller, whose
    threads or main script it must not inherit). Answers ("ok", SceneRun) or ("error", message),
    after ("scene", Scene) when the request's mode is "scene+read"; a damaged file that aborts
    Rerun's Rust reader kills only this process.
    """
    import resource

    import rerun.chunk  # noqa: F401 - imported while no request waits for it

    from collide.recording.reader import read_trusted, verify_trusted

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing but answers on the answer channel
    warnings.simplefilter("ignore")
    while True:
        header = inp.read(_HEADER.size)
        if len(header) < _HEADER.size:
            return
        path, memory_mb, mode = pickle.loads(inp.read(_HEADER.unpack(header)[0]))
        try:
            # A backstop against one huge allocation between the parent's memory checks; a
            # process with rerun loaded reserves about 3 GB of address space before it reads.
            _, hard = resource.getrlimit(resource.RLIMIT_AS)
            limit = (4096 + 2 * memory_mb) * 1024 * 1024
            resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY
                                                    else min(limit, hard), hard))
        except (ValueError, OSError):
            pass
        try:
            def scene_first(scene: Scene) -> None:
                _send_answer(out, ("scene", scene))

            message: tuple[str, Any] = ("ok", verify_trusted(Path(path)) if mode == "verify" else
                                        read_trusted(Path(path), scene_first if mode == "scene+read" else None))
        except RecordingError as exc:
            message = ("error", str(exc))
        except MemoryError:
            message = ("error", f"{path}: reading it needs more than {memory_mb} MB of memory")
        except Exception as exc:  # whatever a damaged file makes the reader raise
            message = ("error", f"{path}: damaged or not a collide recording ({type(exc).__name__}: {exc})")
        _send_answer(out, message)
        del message  # not held while idle


class _Stopped(Exception):
    """A read given up: the reader died or went past a limit (the message says which)."""


class _Reader:
    """One reader process and its pipes."""

    def __init__(self) -> None:
        code = "from collide.recording.sandbox import _serve_reads; _serve_reads()"
        self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for stream in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError):
                stream.close()

    def rss_mb(self) -> float:
        try:
            with open(f"/proc/{self.proc.pid}/statm") as f:
                return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") / 2**20)
        except (OSError, ValueError, IndexError):
            return 0.0

    def read(self, path: Path, timeout_s: float, memory_mb: int, mode: str = "read",
             on_scene: Callable[[Scene], None] | None = None) -> tuple[str, Any]:
        """Send one request; ("ok", run), ("error", message) or ("failed", reason). With
        `on_scene`, the recording's scene is handed to it as soon as the reader has it."""
        try:
            _send_message(self.proc.stdin, (str(path), int(memory_mb), "scene+read" if on_scene else mode))
        except OSError:
            return "failed", self._died()
        deadline = time.monotonic() + timeout_s
        while True:
            answer = self._answer(deadline, timeout_s, memory_mb)
            if answer[0] != "scene" or on_scene is None:
                return answer
            with contextlib.suppress(Exception):  # what the caller does with it must not stop the read
                on_scene(answer[1])

    def _answer(self, deadline: float, timeout_s: float, memory_mb: int) -> tuple[str, Any]:
        try:
            head = self._receive(bytearray(_ANSWER.size), deadline, timeout_s, memory_mb)
            length, count = _ANSWER.unpack(bytes(head))
            sizes = self._receive(bytearray(_HEADER.size * count), deadline, timeout_s, memory_mb)
            lengths = [_HEADER.unpack_from(sizes, _HEADER.size * k)[0] for k in range(count)]
            if length + sum(lengths) > memory_mb * 2**20:  # more than the reader may hold: not an answer
                return "failed", f"reading it needs more than {memory_mb} MB of memory (stopped)"
            data = self._receive(bytearray(length), deadline, timeout_s, memory_mb)
            buffers = [self._receive(bytearray(size), deadline, timeout_s, memory_mb) for size in lengths]
        except _Stopped as stop:
            return "failed", str(stop)
        try:
            return pickle.loads(data, buffers=buffers)
        except Exception as exc:
            return "failed", f"its contents could not be passed back ({type(exc).__name__})"

    def _receive(self, into: bytearray, deadline: float, timeout_s: float, memory_mb: int) -> bytearray:
        """Fill `into` from the reader's answers (read straight into it: no copies grown as it
        comes), within the time and memory limits, checked between reads and at the end."""
        fd = self.proc.stdout.fileno()
        view, filled = memoryview(into), 0
        while True:
            if filled < len(into) and select.select([fd], [], [], _POLL_S)[0]:
                got = os.readv(fd, [view[filled:]])
                if not got:
                    raise _Stopped(self._died())
                filled += got
                if filled < len(into):
                    continue
            if time.monotonic() > deadline:
                raise _Stopped(f"reading it took longer than {timeout_s:g} s (stopped)")
            if self.rss_mb() > memory_mb:
                raise _Stopped(f"reading it needs more than {memory_mb} MB of memory (stopped)")
            if filled == len(into):
                return into

    def _died(self) -> str:
        code = self.proc.wait()
        if code < 0:
            try:
                how = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit code {code}"
        return f"damaged recording: Rerun's reader crashed on it ({how})"


_idle: list[_Reader] = []
_idle_lock = threading.Lock()


def _take_reader() -> _Reader:
    with _idle_lock:
        while _idle:
            reader = _idle.pop()
            if reader.proc.poll() is None:
                return reader
            reader.stop()
    return _Reader()


def _give_back(reader: _Reader, rewarm: bool = True) -> None:
    with _idle_lock:
        if len(_idle) < _IDLE_READERS and reader.rss_mb() <= _IDLE_MAX_MB:
            _idle.append(reader)
            return
    reader.stop()
    # A fresh one in its place, starting while nothing waits for it: a cold reader spends about
    # a second importing Rerun before it reads (2 s of a 1 000-sphere pile's open under load).
    if rewarm:
        warm_reader()


def warm_reader() -> None:
    """Start a reader process now, if none is idle, so that the next `read_recording_safely`
    finds it ready (about 160 MB while idle)."""
    with _idle_lock:
        if len(_idle) < _IDLE_READERS:
            _idle.append(_Reader())


def read_recording_safely(path: str | Path, *, timeout_s: float = SAFE_TIMEOUT_S,
                          memory_mb: int = SAFE_MEMORY_MB,
                          on_scene: Callable[[Scene], None] | None = None, rewarm: bool = True) -> SceneRun:
    """`read_recording` in a child process (its default), for files from anywhere.

    Rerun's reader is Rust: a damaged file can make it panic and abort the whole process, or
    loop. Here a crash, a hang (longer than `timeout_s`) or a read that needs more than
    `memory_mb` MB of memory costs only the child; each becomes a `RecordingError` with a
    one-line message naming the file, and the caller carries on. Readers are fresh interpreters
    (about a second to start); one is kept warm between reads unless a large read grew it past
    _IDLE_MAX_MB (then it is stopped: its memory is not held for the session); safe to call
    from several threads. `on_scene`, if given, is called with the recording's scene as soon as
    the file's seal is checked, before its trajectory is decoded and passed back (sealed files:
    format 4 on). `rewarm=False`: a reader grown by this file is stopped but not replaced at
    once; the caller calls `warm_reader()` when the cores are free (the viewer, once the run is
    shown: a replacement's import of Rerun took 1.4 s of CPU from a pile's opening).
    """
    return _safely(Path(path), "read", timeout_s, memory_mb, on_scene, rewarm)


def _safely(path: Path, mode: str, timeout_s: float, memory_mb: int,
            on_scene: Callable[[Scene], None] | None = None, rewarm: bool = True) -> Any:
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be positive, got {timeout_s}")
    if not memory_mb > 0:
        raise ValueError(f"memory_mb must be positive, got {memory_mb}")
    if not path.exists():
        raise _fail(path, "no such file")
    if not path.is_file():
        raise _fail(path, "not a file")
    reader = _take_reader()
    kind, value = "failed", "the reader stopped"
    try:
        kind, value = reader.read(path.absolute(), timeout_s, memory_mb, mode, on_scene)
    finally:
        if kind == "failed":
            reader.stop()
            _give_back(_Reader())  # warm up the next one while the caller reports this one
        else:
            _give_back(reader, rewarm)
    if kind == "ok":
        return value
    if kind == "error":
        raise RecordingError(" ".join(str(value).split()))
    raise _fail(path, " ".join(str(value).split()))


@atexit.register
def _stop_idle_readers() -> None:
    with _idle_lock:
        while _idle:
            _idle.pop().stop()
