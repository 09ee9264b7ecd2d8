"""Reading a recording in this process: Rerun's chunks, the integrity record, the settings and
the trajectory's tables checked against their checksum, and the `SceneRun` rebuilt from them.

Rerun's reader is Rust, and a damaged file can abort the process that reads it: files from
anywhere are read through `sandbox` (a child process), which calls `read_trusted` there.
"""

from __future__ import annotations

import math
import re
import tomllib
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from collide.model import State, compile_scenes
from collide.recording.integrity import _HEX, _file_messages, _unsealed_sha256
from collide.recording.spec import (
    _TABLES,
    DISSIPATION_PARTS,
    FORMAT,
    FORMAT_VERSION,
    INTEGRITY,
    RecordingError,
    _fail,
    checksum,
)
from collide.results import ContactLog, RunResult, Trajectory
from collide.run import SceneRun
from collide.scene import Scene, SceneError, parse_scene


def _load_chunks(path: Path, under: str = "") -> list:
    """The recording's chunks (those of entities under `under` only, when given: reading a run
    back keeps /collide/ and lets what is drawn go as it is read)."""
    from rerun.chunk import RrdReader

    if not path.exists():
        raise _fail(path, "no such file")
    if not path.is_file():
        raise _fail(path, "not a file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # rerun warns about damaged files; we raise instead
            reader = RrdReader(path)
            if not reader.recordings():
                raise _fail(path, "not a collide recording (the file holds no Rerun recording)")
            return [c for c in reader.stream() if c.entity_path.startswith(under)]
    except RecordingError:
        raise
    except Exception as exc:  # rerun raises several kinds for damaged input
        text = " ".join(str(exc).split()) or type(exc).__name__
        text = re.sub(r"^Failed to read RRD file at .*?: ", "", text)
        if "FourCC" in text or "Not an RRD" in text:
            raise _fail(path, f"not a Rerun recording (.rrd): {text}") from None
        raise _fail(path, f"damaged or truncated Rerun recording (.rrd): {text}") from None


def _columns(chunks: list, entity: str) -> dict[str, list]:
    """All rows of an entity's components, concatenated over its chunks (as Python lists)."""
    out: dict[str, list] = {}
    for chunk in chunks:
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.startswith("rerun."):
                continue
            out.setdefault(name, []).append(batch.column(name))
    return out


def entity_paths(path: str | Path) -> list[str]:
    """Every entity path in a recording, sorted (what tools search for `friction`, `spin`...)."""
    chunks = _load_chunks(Path(path))
    return sorted({c.entity_path for c in chunks if not c.entity_path.startswith("/__")})


def _check_integrity(path: Path, chunks: list) -> bool:
    """Refuse a file any byte of which changed since it was sealed (its SHA-256, stored in its
    integrity record, does not match); False if it has no integrity record (an older format)."""
    held = [c for c in chunks if c.entity_path == INTEGRITY]
    if not held:
        return False
    columns = _columns(held, INTEGRITY)
    try:
        if len(held) != 1 or held[0].num_rows != 1 or set(columns) != {"sha256"}:
            raise ValueError
        digest = columns["sha256"][0].to_pylist()[0][0]
        if not isinstance(digest, str) or _HEX.fullmatch(digest.encode()) is None:
            raise ValueError
    except (ValueError, IndexError, TypeError, UnicodeEncodeError):
        raise _fail(path, "damaged collide recording (its integrity record is malformed)") from None
    if _file_messages(path) is None or _unsealed_sha256(path, digest) != digest:
        raise _fail(path, "damaged collide recording (checksum mismatch: its bytes changed after it was "
                          "written)")
    return True


def _meta(path: Path, chunks: list) -> dict[str, Any]:
    """The settings in /collide/meta, once every byte before the integrity record is checked."""
    whole = _check_integrity(path, chunks)
    columns = _columns(chunks, "/collide/meta")
    if not columns:
        if any(c.entity_path.startswith("/collide/") for c in chunks):
            raise _fail(path, "incomplete collide recording (truncated: its settings are missing)")
        raise _fail(path, "not a collide recording (no /collide/meta entity)")
    meta: dict[str, Any] = {}
    for name, arrays in columns.items():
        values = arrays[-1].to_pylist()[-1]
        listed = name == "warnings" or re.fullmatch(r"(initial|final)_[svwq]", name)
        meta[name] = values if listed else values[0]
    if meta.get("format") != FORMAT:
        raise _fail(path, "not a collide recording (unknown format)")
    version = meta.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise _fail(path, f"not a collide recording (format version {version!r})")
    if version < 2:
        raise _fail(path, f"written by an older collide (format {version}, every step) that this one "
                          "no longer reads; record the run again")
    if version > FORMAT_VERSION:
        raise _fail(path, f"made by a newer collide (format {meta['format_version']}, this one reads "
                          f"{FORMAT_VERSION}); upgrade collide")
    if version >= 4 and not whole:
        raise _fail(path, "damaged collide recording (its integrity record is missing)")
    return meta


def _flat(arrays: list) -> np.ndarray:
    """Concatenate list-typed arrow columns and flatten them into one numpy array."""
    chunked = pa.chunked_array(arrays)
    return np.concatenate([a.flatten().to_numpy(zero_copy_only=False) for a in chunked.chunks]) \
        if chunked.num_chunks else np.empty(0)


def _tables(path: Path, chunks: list, meta: dict[str, Any]) -> dict[str, np.ndarray]:
    """The trajectory's tables as the writer held them (rows restored to their order)."""
    out = {}
    for name, entity, width in _TABLES:
        rows = meta.get(name)
        if isinstance(rows, bool) or not isinstance(rows, int) or rows < 0:
            raise _fail(path, f"inconsistent collide recording (its row count '{name}' is {rows!r})")
        if rows == 0:
            out[name] = np.zeros((0, width))
            continue
        columns = _columns(chunks, entity)
        if "values" not in columns or "row" not in columns or len(columns["values"]) != len(columns["row"]):
            raise _fail(path, f"incomplete collide recording ({entity} is missing)")
        # Each chunk's rows put in place as they come (no copy of the whole table beside it).
        table = np.empty((rows, width))
        seen = np.zeros(rows, bool)
        found = 0
        for values, order in zip(columns["values"], columns["row"]):
            values, order = _flat([values]), _flat([order]).astype(np.int64)
            if values.size != order.size * width or order.size and (order.min() < 0 or order.max() >= rows):
                raise _fail(path, f"damaged collide recording ({entity}'s row numbers are not 0..{rows - 1})")
            if seen[order].any():
                raise _fail(path, f"damaged collide recording ({entity}'s row numbers are not 0..{rows - 1})")
            seen[order] = True
            found += order.size
            table[order] = values.reshape(-1, width)
        # A row number twice within one chunk: more rows than the table, or as many with one unseen.
        if found > rows or not seen.all() and found == rows:
            raise _fail(path, f"damaged collide recording ({entity}'s row numbers are not 0..{rows - 1})")
        if found != rows:
            raise _fail(path, f"incomplete collide recording ({entity} has {found} of {rows} rows)")
        out[name] = table
    return out


def _verified_tables(path: Path, chunks: list, meta: dict[str, Any]) -> dict[str, np.ndarray]:
    """The trajectory's tables, refused if they or the settings differ from what the writer
    checksummed.

    A checksum present is always checked (a flipped bit could lower `format_version` too); it
    is required from format 3 on, and absent only from files written before (format 2).
    """
    stored = meta.get("checksum")
    required = int(meta["format_version"]) >= 3
    if (stored is not None or required) and not isinstance(stored, str):
        raise _fail(path, "damaged collide recording (its checksum is missing)")
    tables = _tables(path, chunks, meta)
    if stored is not None and checksum(tables, meta) != stored:
        raise _fail(path, "damaged collide recording (checksum mismatch: its trajectory or settings "
                          "changed after it was written)")
    return tables


def read_trusted(path: Path, on_scene: Callable[[Scene], None] | None = None) -> SceneRun:
    """`read_recording` in this process (its `trusted=True`): for files this program has just
    written itself, and in the reader process (`sandbox`), where a crash costs only that process.
    `on_scene`, if given, is handed the recording's scene as soon as the file's seal is checked,
    before its trajectory is decoded (a viewer shows the scene's start meanwhile)."""
    chunks = _load_chunks(path, "/collide/")
    try:
        meta = _meta(path, chunks)
        # A sealed file's every byte is checked by now: its scene can be shown before the rest
        # is decoded. An older one's scene waits for the trajectory's checksum.
        scene = _scene(path, meta) if int(meta["format_version"]) >= 4 else None
        if scene is not None and on_scene is not None:
            on_scene(scene)
        tables = _verified_tables(path, chunks, meta)
        return _rebuild(path, scene or _scene(path, meta), tables, meta)
    except RecordingError:
        raise
    except Exception as exc:  # anything a foreign or damaged file's contents make the parsing raise
        text = " ".join(str(exc).split())[:300]
        raise _fail(path, f"not a valid collide recording ({type(exc).__name__}: {text})") from None


def verify_trusted(path: Path) -> None:
    """`verify_recording` in this process (its `trusted=True`)."""
    chunks = _load_chunks(path, "/collide/")
    try:
        _verified_tables(path, chunks, _meta(path, chunks))
    except RecordingError:
        raise
    except Exception as exc:
        text = " ".join(str(exc).split())[:300]
        raise _fail(path, f"not a valid collide recording ({type(exc).__name__}: {text})") from None


def _scene(path: Path, meta: dict[str, Any]) -> Scene:
    try:
        return parse_scene(tomllib.loads(meta["scene_toml"]), meta["scene_name"])
    except (SceneError, tomllib.TOMLDecodeError) as exc:
        raise _fail(path, f"its stored scene is invalid: {exc}") from None


def _rebuild(path: Path, scene: Scene, tables: dict[str, np.ndarray], meta: dict[str, Any]) -> SceneRun:
    model, _ = compile_scenes([scene])
    n, d = model.n_bodies, model.dim
    k, q_dim = model.spin_dim, model.orient_dim

    traj = Trajectory(tables["knots"], tables["records"], tables["intervals"], model)

    def state(label: str) -> State:
        def vec(key: str, width: int) -> np.ndarray:
            if width == 0:
                return np.zeros((1, n, 0))
            return np.asarray(meta[f"{label}_{key}"], dtype=float).reshape(1, n, width)
        stored = meta.get(f"{label}_stored")
        return State(np.array([meta[f"{label}_t"]], float), vec("s", d), vec("v", d), vec("w", k),
                     vec("q", q_dim), np.array([meta[f"{label}_work"]], float),
                     None if stored is None else np.array([stored], float))

    log = ContactLog(*(np.array([meta[f"contact_{f}"]], float) for f in
                       ("first_start", "last_end", "duration", "max_overlap")),
                     np.array([meta["contact_count"]], np.int64),
                     np.array([meta.get("contact_max_normal_force", float("nan"))], float))
    result = RunResult(model=model, initial=state("initial"), final=state("final"),
                       integrator=str(meta["integrator"]), dt=np.array([meta["dt"]], float),
                       steps=np.array([meta["steps"]], np.int64),
                       jumps=np.array([meta["jumps"]], np.int64),
                       wall_time_s=float(meta["wall_time_s"]), contacts=log, trajectories=[traj],
                       warnings=[str(w) for w in (meta.get("warnings") or [])],
                       dissipation=None if meta.get("dissipation_damping") is None else
                       np.array([[float(meta[f"dissipation_{part}"]) for part in DISSIPATION_PARTS]]),
                       engine=str(meta.get("engine") or ""), engine_reason=str(meta.get("engine_reason") or ""),
                       frame_steps=int(meta.get("frame_steps") or 0))
    request = meta.get("dt_request", "none")
    dt_request: float | str | None = None if request == "none" else \
        ("auto" if request == "auto" else float(request))
    tol = float(meta["tol"])
    run = SceneRun([scene], result, dt_request, None if math.isnan(tol) else [tol])
    if "error_estimate" in meta and hasattr(run, "error_estimate"):
        run.error_estimate = np.array([float(meta["error_estimate"])])
    if "auto" in meta and hasattr(run, "auto"):
        run.auto = [bool(meta["auto"])]
    if meta.get("error_method") in ("model", "measured"):
        run.error_method = [str(meta["error_method"])]
    return run
