"""A Rerun recording encoded in memory and written to its file by collide.

Rerun's own file sink (`RecordingStream.save`) can block for good after a failed write: once its
writer thread stops on an error (a full disk, a file-size limit), a flush, a disconnect and even
the interpreter's exit wait on it. Here Rerun encodes into a binary stream, read once at the end
(each read is a whole .rrd stream of its own, footer included, and a recording is one stream),
and collide writes the bytes: a failed write is an ordinary `OSError` where it failed. The cost
is the encoded recording held in memory once, which is smaller than the frames it was made from.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rerun as rr


@contextmanager
def rrd_file(rec: rr.RecordingStream, path: Path, blueprint: Any) -> Iterator[None]:
    """Stream what `rec` logs inside the block into `path`, with `blueprint` as its default;
    the file is written when the block ends without an error, and `rec` disconnected either way."""
    stream = rec.binary_stream()
    with open(path, "wb") as out:
        try:
            rec.send_blueprint(blueprint, make_active=False, make_default=True)
            yield
            rec.flush()
            out.write(stream.read(flush=True) or b"")
        finally:
            rec.disconnect()
