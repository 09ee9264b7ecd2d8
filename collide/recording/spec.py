"""The recording format's names and version, its error, and the checksum of what
`read_recording` restores (docs/design.md section 5)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from collide.engine import layout

APP_ID = "collide"
FORMAT = "collide-recording"
# 4: as 3, and /collide/integrity, the SHA-256 of every byte of the file before it;
# 3: the trajectory's tables (knots, contact records, contact intervals) and `checksum` in
# /collide/meta (still read); 2: the same tables, no checksum (still read); 1: every step (no
# longer read).
FORMAT_VERSION = 4
INTEGRITY = "/collide/integrity"  # AnyValues sha256: the hash of every byte of the file (_seal)
TIMELINE = "sim_time"


class RecordingError(ValueError):
    """A file that is not a complete collide recording. The message names the file."""


def collide_version() -> str:
    """The installed collide version (stored in every recording)."""
    try:
        from importlib.metadata import version

        return version("collide")
    except Exception:  # not installed: running from a source tree
        return "unknown"


def _fail(path: Path, reason: str) -> RecordingError:
    return RecordingError(f"{path}: {reason}")


# Rerun's file header: "RRF" and the format's digit (its FourCC).
RRD_MAGIC = b"RRF"


def check_rrd_header(path: Path) -> None:
    """Refuse at once a file that does not begin as a Rerun recording, before a viewer says it
    serves it; the reader process checks the rest as it reads."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise _fail(path, f"cannot be read: {exc.strerror or exc}") from None
    if not (head.startswith(RRD_MAGIC) and head[3:4].isdigit()):
        raise _fail(path, "not a Rerun recording (.rrd): it does not begin with Rerun's header")


DISSIPATION_PARTS = ("damping", "friction", "rolling")  # RunResult.dissipation's columns
_TABLES = (("knots", "/collide/knots", int(layout.NK)), ("records", "/collide/contact_records", int(layout.NR)),
           ("intervals", "/collide/contact_intervals", 4))


def _array_head(kind: str, shape: tuple[int, ...]) -> bytes:
    return b"a" + kind.encode() + b"(" + ",".join(str(n) for n in shape).encode() + b")"


def _canonical(value: Any) -> bytes:
    """Bytes of a meta value or table that do not depend on how Arrow handed it back."""
    if value is None:
        return b"n"
    if isinstance(value, (bool, np.bool_)):
        return b"b1" if value else b"b0"
    if isinstance(value, (int, np.integer)):
        return b"i" + str(int(value)).encode()
    if isinstance(value, (float, np.floating)):
        return b"f" + float(value).hex().encode()
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
        kind = {"f": "<f8", "i": "<i8", "u": "<i8", "b": "u1"}[value.dtype.kind]
        return _array_head(kind, value.shape) + np.ascontiguousarray(value, dtype=kind).tobytes()
    if isinstance(value, (list, tuple, np.ndarray)):
        items = list(value)
        if items and all(isinstance(v, (float, np.floating)) for v in items):
            return _canonical(np.asarray(items, dtype=float))
        return b"l[" + b",".join(_canonical(v) for v in items) + b"]"
    raise TypeError(f"no canonical form for {type(value).__name__}")


def checksum(tables: dict[str, np.ndarray], meta: dict[str, Any]) -> str:
    """SHA-256 over what `read_recording` restores: the trajectory's tables (knots, contact
    records, contact intervals: shape and float64 values in row order) and every setting in
    `/collide/meta` but the checksum itself, in sorted key order."""
    import hashlib

    digest = hashlib.sha256()
    for label, table in ((b"tables", tables), (b"meta", meta)):
        digest.update(label)
        for key in sorted(table):
            if key == "checksum" or table[key] is None:  # AnyValues stores no None: absent
                continue
            digest.update(len(key).to_bytes(4, "little") + key.encode())
            value = table[key]
            if isinstance(value, np.ndarray) and value.dtype.kind == "f":
                # Hashed from the table's own memory: the bytes `_canonical` makes, not a copy of them.
                head = _array_head("<f8", value.shape)
                data = np.ascontiguousarray(value, dtype="<f8")
                digest.update((len(head) + data.nbytes).to_bytes(8, "little") + head)
                digest.update(data)
                continue
            data = _canonical(value)
            digest.update(len(data).to_bytes(8, "little") + data)
    return digest.hexdigest()
