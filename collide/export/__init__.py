"""`collide export`: a recording's run out to other tools (docs/export.md).

- `vtk`: a `.pvd` collection and a folder of `.vtp` PolyData files, one a frame (`vtk`);
- `csv`: long form, a row per body per frame, and a contacts table beside it (`table`);
- `mp4`: a video of the spheres and walls with the time (`video`);
- `toml`: the scene with the run's integrator, step and tolerance: `collide run` on it runs the
  same run again (`scene_toml`).

Frames are the recording's view frames (`frames`). Every file is written under a temporary name
and renamed into place once whole (collide.output): a failed export leaves nothing under the
final names. No CLI code here: `cli/export.py` is the command.
"""

from __future__ import annotations

import io
import shutil
import tomllib
from pathlib import Path

from collide.export.frames import MAX_FRAMES, Frames, export_frames, export_times
from collide.output import OutputError, failed, sync_folder, temporary, write_atomic, write_text_atomic
from collide.recording import DEFAULT_FPS
from collide.run import SceneRun
from collide.scene import dump_toml, parse_scene, with_settings

FORMATS = ("vtk", "csv", "mp4", "toml")
SUFFIX = {"vtk": ".pvd", "csv": ".csv", "mp4": ".mp4", "toml": ".toml"}


def default_out(recording: Path, fmt: str) -> Path:
    """Beside the recording, its name with the format's suffix (recordings/pile.rrd -> recordings/pile.pvd)."""
    return Path(recording).with_suffix(SUFFIX[fmt])


def contacts_path(out: Path) -> Path:
    """The contacts table beside the bodies' CSV: pile.csv -> pile-contacts.csv."""
    return out.with_name(f"{out.stem}-contacts{out.suffix}")


def frames_folder(out: Path) -> Path:
    """The `.vtp` files' folder beside the `.pvd`: pile.pvd -> pile/."""
    return out.with_suffix("")


def outputs(fmt: str, out: Path) -> list[Path]:
    """Every path an export writes (the CLI checks them before reading the recording)."""
    if fmt not in FORMATS:
        raise ValueError(f"--format: unknown '{fmt}' (choose from {', '.join(FORMATS)})")
    if fmt == "vtk":
        if out.suffix != ".pvd":
            raise ValueError(f"--out {out}: a VTK series is a .pvd file (its frames go in a folder beside it)")
        return [out, frames_folder(out)]
    if fmt == "csv":
        return [out, contacts_path(out)]
    return [out]


def scene_toml(run: SceneRun) -> str:
    """The run's scene as TOML, with the integrator, step request and tolerance the run used."""
    scene = run.scene
    dt = scene.dt if run.dt_request is None else run.dt_request
    tol = scene.tol if not run.tol else float(run.tol[0])
    source = with_settings(scene, integrator=run.result.integrator, dt=dt, tol=tol).source
    return f"# {scene.name}: exported by collide export (collide run this file runs the same run)\n" + \
        dump_toml(source)


def export_run(run: SceneRun, fmt: str, out: Path, *, fps: float = DEFAULT_FPS, max_frames: int = MAX_FRAMES,
               ascii: bool = False, title: str | None = None) -> list[Path]:
    """Write a run (read from a recording) in `fmt` to `out`; returns the paths written."""
    out = Path(out)
    outputs(fmt, out)
    if fmt == "toml":
        text = scene_toml(run)
        parse_scene(tomllib.loads(text), run.scene.name)  # what is written reads back as a scene
        return [write_text_atomic(out, text)]
    frames = export_frames(run, export_times(run, fps, max_frames))
    if fmt == "csv":
        from collide.export.table import bodies_csv, contacts_csv

        return [write_text_atomic(out, bodies_csv(frames)), write_text_atomic(contacts_path(out), contacts_csv(frames))]
    if fmt == "mp4":
        return [_write_video(frames, out, title or run.scene.name)]
    return _write_vtk(frames, out, ascii)


def export_download(run: SceneRun, fmt: str, stem: str, *, max_frames: int = MAX_FRAMES) -> tuple[str, bytes]:
    """The export as one file to send to a browser: the `.mp4` or `.toml` itself, or a zip of the
    VTK series (the `.pvd` and its folder) or of the two CSV tables. Returns (file name, bytes)."""
    import tempfile
    import zipfile

    with tempfile.TemporaryDirectory(prefix="collide-export-") as tmp:
        out = Path(tmp) / f"{stem}{SUFFIX[fmt]}"
        written = export_run(run, fmt, out, max_frames=max_frames)
        if fmt in ("mp4", "toml"):
            return out.name, out.read_bytes()
        files = [p for path in written for p in (sorted(path.iterdir()) if path.is_dir() else [path])]
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
            for path in files:
                archive.write(path, path.relative_to(tmp).as_posix())
        return f"{stem}-{fmt}.zip", buffer.getvalue()


def _write_video(frames: Frames, out: Path, title: str) -> Path:
    from collide.export.video import write_video

    def check(tmp: Path) -> None:
        with open(tmp, "rb") as f:
            head = f.read(12)
        if len(head) < 12 or head[4:8] != b"ftyp":
            raise failed(tmp, "ffmpeg wrote no MP4")

    return write_atomic(out, lambda tmp: write_video(frames, tmp, title), check)


def _write_vtk(frames: Frames, out: Path, ascii: bool) -> list[Path]:
    """The frames' folder first (built under a temporary name, then renamed), the `.pvd` last."""
    from collide.export.vtk import collection, write_frames

    folder = frames_folder(out)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"could not write {folder}: it is a file (the VTK frames' folder goes there)")
    tmp = temporary(folder)
    old = temporary(folder)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp.mkdir()
        write_frames(frames, tmp, ascii)
        if folder.exists():
            folder.rename(old)
        tmp.rename(folder)
        sync_folder(folder.parent)
    except OSError as exc:
        raise failed(folder, exc) from None
    finally:
        for leftover in (tmp, old):
            if leftover.exists():
                shutil.rmtree(leftover, ignore_errors=True)
    return [write_text_atomic(out, collection(frames, folder.name)), folder]


__all__ = ["FORMATS", "MAX_FRAMES", "SUFFIX", "contacts_path", "default_out", "export_download", "export_run",
           "frames_folder", "outputs", "scene_toml"]
