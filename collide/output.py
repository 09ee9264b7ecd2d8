"""Files collide writes: checked before a run, whole or absent after it.

Every output (recordings, summary and report CSVs) is written under a temporary name in its own
folder (`.<name>.<hex>.tmp`), checked, synced to disk and only then renamed into place. A
failure (a full disk, a read-only folder, a write error inside Rerun) is an `OutputError`: one
line naming the file and the cause, with nothing left under the final name. `check_file` and
`check_folder` find an unwritable place before a run spends minutes on results it cannot keep.
"""

from __future__ import annotations

import errno
import os
import re
import uuid
from collections.abc import Callable
from pathlib import Path


class OutputError(OSError):
    """A file collide could not write: the message names the file and the cause."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "could not write a file"


def cause(exc: BaseException) -> str:
    """The cause of a failed write in a few words: `no space left on device`, `permission denied`.

    Rerun reports its write errors as a RuntimeError whose text ends `(os error N)`.
    """
    code = getattr(exc, "errno", None)
    if not isinstance(code, int):
        found = re.search(r"os error (\d+)", str(exc))
        code = int(found.group(1)) if found else None
    if isinstance(code, int) and code in errno.errorcode:
        return os.strerror(code).lower()
    text = " ".join(str(exc).split())
    return text[:200] or type(exc).__name__


def _diagnosis(tmp: Path) -> str | None:
    """Why a write into `tmp` stopped when the writer did not say (Rerun's writer thread often
    reports only that it stopped): the disk is full, or the file reached the process's size limit."""
    try:
        st = os.statvfs(tmp.parent)
        if st.f_bavail * st.f_frsize < 1 << 16:
            return os.strerror(errno.ENOSPC).lower()
        import resource

        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if limit != resource.RLIM_INFINITY and tmp.exists() and tmp.stat().st_size >= limit - (1 << 16):
            return os.strerror(errno.EFBIG).lower()
    except (OSError, ImportError, ValueError):
        pass
    return None


def failed(path: Path, exc: BaseException | str) -> OutputError:
    reason = exc if isinstance(exc, str) else cause(exc)
    return OutputError(f"could not write {path}: {reason}")


def temporary(path: Path) -> Path:
    """A new temporary name beside `path` (the batch's --resume removes the ones a kill left)."""
    return path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.tmp"


def check_folder(folder: Path) -> None:
    """`folder` can take files: it exists and a file can be created in it, or the nearest folder
    above it that exists can (where it would be made); else `OutputError`. Nothing is left
    behind, not even the folder (it is made when the first file is written)."""
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"could not write into {folder}: {existing} is a file, not a folder")
    probe = temporary(existing / "probe")
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.close(fd)
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"could not write into {folder}: {cause(exc)}") from None


def check_file(path: Path, what: str = "file name") -> None:
    """`path` can be written: not a folder, and its folder exists and is writable, or can be made."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"could not write {path}: it is a folder; give a {what}")
    try:
        check_folder(path.parent)
    except OutputError as exc:
        raise OutputError(f"could not write {path}: {str(exc).split(': ', 1)[-1]}") from None


def sync_folder(folder: Path) -> None:
    """fsync a folder, so that a file just renamed into it survives a power loss too."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot sync a folder; the rename itself is still atomic
    finally:
        os.close(fd)


def publish(tmp: Path, path: Path) -> None:
    """Sync a checked temporary file to disk and rename it to `path` (atomic on one file system)."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    sync_folder(path.parent)


def write_atomic(path: Path, produce: Callable[[Path], None], check: Callable[[Path], None] | None = None) -> Path:
    """`produce(tmp)` writes the file under a temporary name, `check(tmp)` raises if it is not
    whole; then it is synced and renamed to `path`. On any failure nothing is left under either
    name and the error is an `OutputError` naming `path` (an `OutputError` from `check` too)."""
    path = Path(path)
    tmp = temporary(path)
    try:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            produce(tmp)
            if check is not None:
                check(tmp)
            publish(tmp, path)
        except OutputError as exc:
            found = _diagnosis(tmp)
            raise (failed(path, found) if found else OutputError(str(exc).replace(str(tmp), str(path)))) from None
        except (OSError, RuntimeError) as exc:  # RuntimeError: Rerun's writer
            said = cause(exc)
            if getattr(exc, "errno", None) is None and "os error" not in str(exc):
                said = _diagnosis(tmp) or f"the writer stopped ({said})"
            raise failed(path, said) from None
    finally:
        if tmp.exists():
            try:
                tmp.unlink()
            except OSError:
                pass
    return path


def write_text_atomic(path: Path, text: str) -> Path:
    """A text file, whole or absent (its length on disk checked against what was written)."""
    data = text.encode("utf-8")

    def produce(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())

    def check(tmp: Path) -> None:
        size = tmp.stat().st_size
        if size != len(data):
            raise failed(tmp, f"{size} of {len(data)} bytes reached the disk")

    return write_atomic(path, produce, check)
