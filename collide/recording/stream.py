"""A Rerun recording streamed to its file by collide while it is logged.

Rerun's own file sink (`RecordingStream.save`) can block for good after a failed write: once its
writer thread stops on an error (a full disk, a file-size limit), a flush, a disconnect and even
the interpreter's exit wait on it. Its in-memory sink (`binary_stream`) holds every chunk logged,
uncompressed, until it is read, and each read is a whole .rrd stream of its own (footer included)
that Rerun's reader does not take concatenated: a 100 000-sphere pour's recording held gigabytes
there. Here Rerun's file sink writes into a pipe, which it can always write to, and a thread of
collide's copies the pipe into the file: a failed write is an ordinary `OSError` where it
failed, the thread reads on to the end so Rerun never waits, and `flush` (after each large call)
lets Rerun encode and hand on what it holds, so that it holds one call's columns at a time.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rerun as rr

_READ = 1 << 20  # bytes read from the pipe at a time


class _Copy(threading.Thread):
    """Copies the pipe into the file until Rerun closes its end; keeps reading after an error."""

    def __init__(self, pipe: int, path: Path) -> None:
        super().__init__(daemon=True)
        self.pipe, self.path = pipe, path
        self.error: BaseException | None = None

    def run(self) -> None:
        out = None
        try:
            out = open(self.path, "wb")
        except OSError as exc:
            self.error = exc
        while data := os.read(self.pipe, _READ):
            if out is None or self.error is not None:
                continue
            try:
                out.write(data)
            except OSError as exc:
                self.error = exc
        if out is not None:
            try:
                out.close()
            except OSError as exc:
                self.error = self.error or exc


@contextmanager
def rrd_file(rec: rr.RecordingStream, path: Path, blueprint: Any) -> Iterator[None]:
    """Stream what `rec` logs inside the block into `path`, with `blueprint` as its default; `rec`
    is disconnected either way, and a failed write raises its `OSError` when the block ends."""
    with tempfile.TemporaryDirectory(prefix="collide-rrd-") as folder:
        fifo = os.path.join(folder, "pipe")
        os.mkfifo(fifo, 0o600)
        # The read end first (a non-blocking open needs no writer), then a write end of our own,
        # so that the reader sees the end only once Rerun's end and ours are both closed.
        reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        keeper = os.open(fifo, os.O_WRONLY)
        fcntl.fcntl(reader, fcntl.F_SETFL, fcntl.fcntl(reader, fcntl.F_GETFL) & ~os.O_NONBLOCK)
        copy = _Copy(reader, Path(path))
        copy.start()
        try:
            rec.save(fifo, default_blueprint=blueprint)
            yield
            rec.flush()
        finally:
            rec.disconnect()
            os.close(keeper)
            copy.join()
            os.close(reader)
    if copy.error is not None:
        raise copy.error
