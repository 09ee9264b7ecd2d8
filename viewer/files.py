"""Files the viewer reads and writes: scene TOMLs, recordings, uploads, saved runs.

Everything written lands inside the recordings folder under a sanitised name; uploads must be
`.rrd` files below a size limit. Pure Python (no viser).
"""

from __future__ import annotations

import os
import re
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from collide.scene import builtin_names

MAX_UPLOAD_BYTES = 200 * 1024 * 1024
_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


class UploadError(ValueError):
    """An upload refused before it is read: wrong type, too large, empty."""


def safe_stem(name: str, default: str = "run") -> str:
    """A file stem of letters, digits, '.', '_' and '-' only: no separators, no leading dot."""
    stem = Path(name.replace("\\", "/")).name
    for suffix in (".rrd", ".RRD"):
        stem = stem.removesuffix(suffix)
    stem = _SAFE.sub("-", stem).strip(".-_")[:80]
    return stem or default


def unique_path(folder: Path, stem: str, suffix: str = ".rrd") -> Path:
    """folder/stem.rrd, or folder/stem-2.rrd, ... if taken. Always inside `folder`."""
    folder = folder.resolve()
    stem = safe_stem(stem)
    path = folder / f"{stem}{suffix}"
    n = 2
    while path.exists():
        path = folder / f"{stem}-{n}{suffix}"
        n += 1
    if path.parent != folder:
        raise UploadError(f"refusing to write outside {folder}")
    return path


def save_name(scene_name: str, when: float | None = None) -> str:
    """A stem for 'save this run': scene name and local time."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(time.time() if when is None else when))
    return safe_stem(f"{scene_name}-{stamp}")


def list_recordings(folder: Path) -> list[str]:
    """Names of the .rrd files directly in `folder`, newest first."""
    if not folder.is_dir():
        return []
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".rrd"
             and not p.name.startswith(".")]
    files.sort(key=lambda p: (-p.stat().st_mtime, p.name))
    return [p.name for p in files]


def recording_path(folder: Path, name: str) -> Path:
    """The path of a recording listed by `list_recordings` (never outside `folder`)."""
    folder = folder.resolve()
    path = (folder / Path(name).name).resolve()
    if path.parent != folder or path.suffix.lower() != ".rrd":
        raise UploadError(f"'{name}' is not a recording in {folder}")
    return path


def check_upload(name: str, size: int, limit: int = MAX_UPLOAD_BYTES) -> None:
    """Refuse uploads that are not .rrd, are empty, or exceed the size limit."""
    if not name.lower().endswith(".rrd"):
        raise UploadError(f"'{Path(name).name}' is not a .rrd recording (only .rrd files can be opened)")
    if size == 0:
        raise UploadError(f"'{Path(name).name}' is empty")
    if size > limit:
        raise UploadError(f"'{Path(name).name}' is {size / 2**20:.1f} MB, above the {limit / 2**20:.0f} MB limit")


def staging_path(folder: Path) -> Path:
    """A hidden temporary file inside `folder` for an upload being checked."""
    return folder.resolve() / f".upload-{uuid.uuid4().hex}.rrd.part"


def write_staged(folder: Path, content: bytes) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = staging_path(folder)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(content)
    return path


@dataclass(frozen=True)
class SceneChoice:
    """An entry of the scene picker: its label and what `load_scene` takes."""

    label: str
    source: str


def scene_choices(scenes_dir: Path | None, extra: list[str] | None = None) -> list[SceneChoice]:
    """Built-in scenes, then the .toml files of `scenes_dir`, then any extra paths."""
    choices = [SceneChoice(name, name) for name in builtin_names(heavy=False)]
    seen = {c.source for c in choices}
    paths: list[Path] = []
    if scenes_dir is not None and scenes_dir.is_dir():
        paths += sorted(p for p in scenes_dir.iterdir() if p.suffix == ".toml" and p.is_file())
    paths += [Path(p) for p in extra or []]
    labels = {c.label for c in choices}
    for path in paths:
        source = str(path)
        if source in seen:
            continue
        label = path.name
        if label in labels:
            label = source
        choices.append(SceneChoice(label, source))
        seen.add(source)
        labels.add(label)
    return choices
