"""Every byte of a recording checked: Rerun's .rrd framing read without Rerun, and the seal (the
SHA-256 of the whole file, stored in the file at a placeholder that is filled in last)."""

from __future__ import annotations

import re
import struct
from pathlib import Path

# Rerun's .rrd framing (rerun-sdk 0.41): a 12-byte header (b"RRF2", version, options); messages,
# each a u64 kind and a u64 length then the payload (kind 0 ends the stream, its payload the
# footer); then a trailer: u64 footer offset, u64 footer length, u32 CRC, b"RRF2FOOT", u32.
_RRD_HEADER = 12
_MESSAGE = struct.Struct("<QQ")
_TRAILER = struct.Struct("<QQI8sI")
_END, _ARROW = 0, 2


def _messages(data: bytes | memoryview) -> list[tuple[int, int, int]] | None:
    """(offset, kind, length) of each message up to the end of the stream; None if the framing
    is broken (cut short, a length past the file, no end, bytes after the trailer)."""
    if len(data) < _RRD_HEADER + _TRAILER.size or bytes(data[:4]) != b"RRF2":
        return None
    out, pos = [], _RRD_HEADER
    while pos + _MESSAGE.size <= len(data):
        kind, length = _MESSAGE.unpack_from(data, pos)
        if kind > 16 or pos + _MESSAGE.size + length > len(data):
            return None
        out.append((pos, kind, length))
        pos += _MESSAGE.size + length
        if kind == _END:
            if len(data) - pos != _TRAILER.size:
                return None
            offset, size, _, magic, _ = _TRAILER.unpack_from(data, pos)
            ok = magic == b"RRF2FOOT" and offset == out[-1][0] + _MESSAGE.size and size == length
            return out if ok else None
    return None


_HEX = re.compile(rb"[0-9a-f]{64}")


def _placeholder() -> str:
    """64 letters G-Z with no 4-byte sequence twice, so that LZ4 (Rerun compresses each message)
    most likely stores them verbatim, where `_seal` can find and overwrite them."""
    import random

    letters = "GHIJKLMNOPQRSTUVWXYZ"  # not hex digits: unlike the chunk ids in Arrow's metadata
    rng = random.SystemRandom()
    while True:
        text = "".join(rng.choice(letters) for _ in range(64))
        if len({text[i:i + 4] for i in range(61)}) == 61:
            return text


def _unsealed_sha256(data: bytes, digest: str) -> str | None:
    """SHA-256 of the file with its one copy of `digest` (the seal) read as 64 zeros; None if
    the digest is not in the file exactly once."""
    key = digest.encode()
    at = data.find(key)
    if at < 0 or data.find(key, at + 1) >= 0:
        return None
    import hashlib

    h = hashlib.sha256(memoryview(data)[:at])
    h.update(b"0" * 64)
    h.update(memoryview(data)[at + 64:])
    return h.hexdigest()


def _seal(path: Path, placeholder: str) -> str:
    """Replace the placeholder (stored verbatim once) by the SHA-256 of the file as it is with
    64 zeros there: every byte of the file is then covered, the seal's own included (a changed
    seal no longer matches the rest). "" if LZ4 did not keep the placeholder verbatim."""
    data = path.read_bytes()
    key = placeholder.encode()
    at = data.find(key)
    if at < 0 or data.find(key, at + 1) >= 0:
        return ""
    data = data[:at] + b"0" * 64 + data[at + 64:]
    import hashlib

    digest = hashlib.sha256(data).hexdigest().encode()
    with open(path, "r+b") as f:
        f.seek(at)
        f.write(digest)
    return digest.decode()
