"""Every byte of a recording checked: Rerun's .rrd framing read without Rerun, and the seal (the
SHA-256 of the whole file, stored in the file at a placeholder that is filled in last)."""

from __future__ import annotations

import hashlib
import mmap
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
# A recording is checked and sealed from its file in blocks of this many bytes: a large one (a
# 100 000-sphere pour's, 1 GB) was read whole, and sealing held three copies of it at once.
_BLOCK = 1 << 24


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


def _file_messages(path: Path) -> list[tuple[int, int, int]] | None:
    """`_messages` of a file, read where its framing is (mapped, not loaded: the file can be
    larger than the memory to spare)."""
    with open(path, "rb") as f:
        if f.seek(0, 2) == 0:
            return None
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _messages(data)


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


def _find_once(path: Path, key: bytes) -> int | None:
    """Where `key` is in the file, read in blocks; None unless it is there exactly once."""
    found: list[int] = []
    keep = len(key) - 1  # a key across two blocks is found in the second with this much before it
    with open(path, "rb") as f:
        tail, pos = b"", 0
        while block := f.read(_BLOCK):
            data = tail + block
            at = data.find(key)
            while at >= 0:
                found.append(pos - len(tail) + at)
                if len(found) > 1:
                    return None
                at = data.find(key, at + 1)
            tail, pos = data[-keep:], pos + len(block)
    return found[0] if found else None


def _zeroed_sha256(path: Path, at: int) -> str:
    """SHA-256 of the file, read in blocks, with its 64 bytes from `at` read as zeros."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        pos = 0
        while block := f.read(_BLOCK):
            lo, hi = max(at - pos, 0), min(at + 64 - pos, len(block))
            if lo < hi:
                block = block[:lo] + b"0" * (hi - lo) + block[hi:]
            h.update(block)
            pos += len(block)
    return h.hexdigest()


def _unsealed_sha256(path: Path, digest: str) -> str | None:
    """SHA-256 of the file with its one copy of `digest` (the seal) read as 64 zeros, read in
    blocks; None if the digest is not in the file exactly once."""
    at = _find_once(path, digest.encode())
    return None if at is None else _zeroed_sha256(path, at)


def _seal(path: Path, placeholder: str) -> str:
    """Replace the placeholder (stored verbatim once) by the SHA-256 of the file as it is with
    64 zeros there: every byte of the file is then covered, the seal's own included (a changed
    seal no longer matches the rest). "" if LZ4 did not keep the placeholder verbatim."""
    at = _find_once(path, placeholder.encode())
    if at is None:
        return ""
    digest = _zeroed_sha256(path, at)
    with open(path, "r+b") as f:
        f.seek(at)
        f.write(digest.encode())
    return digest
