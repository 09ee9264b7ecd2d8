"""Long runs in a child process: progress while they go, and a stop that really stops them.

A slider on a 1 000-sphere scene asks for a run of seconds (gas-box) to a minute (pile). The
compiled kernels cannot be interrupted from Python, so such a run goes to a child process
(`BackgroundRunner`): the child reports how far it got about four times a second (the core's
`progress` callback), and stopping it (the Stop button, or a newer value) kills the child; a
fresh one is started for the next run. The page stays live throughout and the last good run
stays on screen.

The child is a fresh interpreter (`python -c ...`, never a fork of the server with its threads),
kept between runs so that only the first run pays for its start (about two seconds).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import struct
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import Any

from collide.run import SceneRun
from collide.scene import Scene, SceneError
from collide.stepper import RunError

_HEADER = struct.Struct("<Q")
POLL_S = 0.05  # s between checks for a stop while waiting on the child

# (simulated time reached, simulated end (inf if open), steps so far, seconds since it started)
Progress = Callable[[float, float, int, float], None]


class RunStopped(Exception):
    """The run was stopped before it finished (the child was killed)."""


def _send(stream: Any, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _serve() -> None:
    """The child: run ("run", scene, options) requests from stdin; answer on stdout with
    ("progress", t, t_end, steps, seconds) messages while a run goes, then ("ok", SceneRun)
    or ("error", kind, message)."""
    from collide.run import run_scene

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing but answers on the answer channel
    lock = threading.Lock()

    def answer(message: tuple) -> None:
        with lock:
            _send(out, message)

    def progress(member: int, members: int, t: float, t_end: float, steps: int, seconds: float,
                 settling: float) -> None:
        answer(("progress", t, t_end, steps, seconds))

    while True:
        header = inp.read(_HEADER.size)
        if len(header) < _HEADER.size:
            return
        _, scene, options = pickle.loads(inp.read(_HEADER.unpack(header)[0]))
        try:
            message: tuple = ("ok", run_scene(scene, progress=progress, **options))
        except (SceneError, RunError) as exc:
            message = ("error", type(exc).__name__, str(exc))
        except Exception as exc:  # noqa: BLE001 - anything else is reported, the child lives on
            message = ("error", "RunError", f"{type(exc).__name__}: {exc}")
        answer(message)
        # The run is the server's now: not held here while the child waits (a pile's trajectory
        # is some 70 MB, and the tab keeps its child between runs).
        del message, scene


class BackgroundRunner:
    """Runs scenes in one child process at a time; `run` blocks its caller (a worker thread)."""

    def __init__(self) -> None:
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()

    def warm(self) -> None:
        """Start the child now, so that the first run does not wait for it."""
        with self._lock:
            self._start()

    def _start(self) -> subprocess.Popen:
        if self._proc is None or self._proc.poll() is not None:
            code = "from viewer.background import _serve; _serve()"
            self._proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                          stderr=subprocess.DEVNULL)
        return self._proc

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def run(self, scene: Scene, *, progress: Progress | None = None, stop: Callable[[], bool] = lambda: False,
            **options: Any) -> SceneRun:
        """`run_scene(scene, **options)` in the child. Raises RunStopped as soon as `stop()`
        turns true (the child is killed), SceneError or RunError as the run would."""
        with self._lock:
            proc = self._start()
            try:
                _send(proc.stdin, ("run", scene, options))
            except OSError:
                self._kill()
                raise RunError("the run's process could not be started") from None
            data = bytearray()
            fd = proc.stdout.fileno()
            while True:
                if stop():
                    self._kill()
                    raise RunStopped()
                ready, _, _ = select.select([fd], [], [], POLL_S)
                if not ready:
                    continue
                chunk = os.read(fd, 1 << 20)
                if not chunk:
                    code = proc.wait()
                    self._kill()
                    raise RunError(f"the run's process stopped (exit code {code})")
                data += chunk
                while len(data) >= _HEADER.size:
                    need = _HEADER.size + _HEADER.unpack(bytes(data[:_HEADER.size]))[0]
                    if len(data) < need:
                        break
                    message = pickle.loads(memoryview(data)[_HEADER.size:need])
                    del data[:need]
                    if message[0] == "progress":
                        if progress is not None:
                            progress(*message[1:])
                        continue
                    if message[0] == "ok":
                        return message[1]
                    kind, text = message[1], message[2]
                    raise SceneError(text) if kind == "SceneError" else RunError(text)

    def _kill(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        for stream in (proc.stdin, proc.stdout):
            with contextlib.suppress(OSError):
                stream.close()

    def close(self) -> None:
        """Stop the child (the tab closed)."""
        self._kill()
