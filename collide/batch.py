"""Batches: many scenes, parameter sweeps and ensembles, run vectorised and summarised.

A batch is a list of `RunSpec`s (scene + the parameter values that made it). `run_batch`
groups same-shaped scenes, runs them in chunks through the batch stepper (`run_scenes`), and
after every chunk rewrites the summary CSV atomically (temporary file + `os.replace`), so a
batch stopped by Ctrl-C keeps every finished run, and `resume=True` skips exactly those.

Syntax (the CLI passes the user's strings straight here):

- sweep `key=start:stop:num`: `num` values from start to stop inclusive (numpy linspace);
  several sweeps make a grid, the last one varying fastest;
- vary `key=mean+-std` (or `mean±std`): normal draws, `samples` of them; a draw that makes the
  scene invalid (e.g. a negative `contact.k`) is drawn again, and the batch says how often.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import os
import re
import time
import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from collide.diagnostics import Residuals, residuals
from collide.model import shape_key
from collide.run import SceneRun, run_scenes
from collide.scene import Scene, SceneError, apply_overrides, parse_scene, read_raw
from collide.stepper import RunError

DEFAULT_CHUNK = 1000
MAX_DRAW_FACTOR = 100  # give up after this many invalid draws per requested sample


class BatchError(ValueError):
    """Bad batch input (sweep syntax, a folder without scenes, a summary from another batch)."""


# ---------------------------------------------------------------------------------------------
# Parsing


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class Sweep:
    """`key=start:stop:num`: `num` evenly spaced values, both ends included."""

    key: str
    start: float
    stop: float
    num: int

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.num)


@dataclass(frozen=True)
class Vary:
    """`key=mean+-std`: draws from a normal distribution."""

    key: str
    mean: float
    std: float


def _split(text: str, what: str, example: str) -> tuple[str, str]:
    if "=" not in text:
        raise BatchError(f"{what} '{text}' is not key=value (example: {example})")
    key, value = (part.strip() for part in text.split("=", 1))
    if not key or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", key):
        raise BatchError(f"{what} '{text}': bad key '{key}' (example: {example})")
    return key, value


def parse_sweep(text: str) -> Sweep:
    """Parse `key=start:stop:num` (num >= 1 values, start and stop included)."""
    example = "contact.mu=0:1:11"
    key, value = _split(text, "sweep", example)
    parts = value.split(":")
    if len(parts) != 3:
        raise BatchError(f"sweep '{text}': expected start:stop:num (example: {example})")
    try:
        start, stop = float(parts[0]), float(parts[1])
    except ValueError:
        raise BatchError(f"sweep '{text}': start and stop must be numbers (example: {example})") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise BatchError(f"sweep '{text}': start and stop must be finite")
    if not re.fullmatch(r"\s*\d+\s*", parts[2]):
        raise BatchError(f"sweep '{text}': num must be a whole number of values, got '{parts[2].strip()}'")
    num = int(parts[2])
    if num < 1:
        raise BatchError(f"sweep '{text}': num must be at least 1, got {num}")
    return Sweep(key, start, stop, num)


def parse_vary(text: str) -> Vary:
    """Parse `key=mean+-std` (also `mean±std`); std must not be negative."""
    example = "contact.k=1500+-30"
    key, value = _split(text, "vary", example)
    match = re.fullmatch(rf"\s*({_NUMBER})\s*(?:\+-|±|\+/-)\s*({_NUMBER})\s*", value)
    if not match:
        raise BatchError(f"vary '{text}': expected mean+-std (example: {example})")
    mean, std = float(match.group(1)), float(match.group(2))
    if std < 0:
        raise BatchError(f"vary '{text}': the standard deviation must not be negative")
    return Vary(key, mean, std)


# ---------------------------------------------------------------------------------------------
# Expanding sources, sweeps and draws into runs


@dataclass(frozen=True)
class RunSpec:
    """One run of a batch: its id, the scene and the swept or drawn values that made it."""

    run_id: str
    scene: Scene
    params: dict[str, float] = field(default_factory=dict)


@dataclass
class Plan:
    """The runs of a batch, plus what was done to get them (resampled draws)."""

    specs: list[RunSpec]
    param_keys: list[str]
    notes: list[str] = field(default_factory=list)


def scene_sources(items: Iterable[str]) -> list[str]:
    """Built-in names and .toml files as given; a folder becomes its .toml files, sorted."""
    out: list[str] = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix == ".toml" and p.is_file())
            if not files:
                raise BatchError(f"folder '{item}' holds no .toml scene files")
            out += [str(p) for p in files]
        else:
            out.append(item)
    if not out:
        raise BatchError("no scenes given: name built-in scenes, .toml files or folders of them")
    return out


def _scene(raw: dict, default_name: str, overrides: list[str]) -> Scene:
    return parse_scene(apply_overrides(raw, overrides), default_name)


def _value_text(value: float) -> str:
    """Override text for a swept or drawn value (TOML float syntax, exact)."""
    return repr(float(value))


def plan_batch(sources: list[str], *, sets: list[str] | None = None, sweeps: list[Sweep] | None = None,
               varies: list[Vary] | None = None, samples: int = 100, seed: int = 0) -> Plan:
    """Every run of a batch, validated before anything runs (bad keys fail here, once)."""
    sets = list(sets or [])
    sweeps = list(sweeps or [])
    varies = list(varies or [])
    if sweeps and varies:
        raise BatchError("use --sweep or --vary, not both")
    if varies and samples < 1:
        raise BatchError(f"--samples must be at least 1, got {samples}")
    keys = [s.key for s in sweeps] + [v.key for v in varies]
    duplicate = next((k for k in keys if keys.count(k) > 1), None)
    if duplicate:
        raise BatchError(f"'{duplicate}' is swept or varied twice")
    specs: list[RunSpec] = []
    notes: list[str] = []
    raws = [(src, *read_raw(src)) for src in scene_sources(sources)]
    if sweeps:
        grid = list(itertools.product(*(s.values for s in sweeps)))
    else:
        grid = [()]
    total = len(raws) * (samples if varies else len(grid))
    width = max(len(str(total - 1)), 4)
    for src, raw, default_name in raws:
        base = _scene(raw, default_name, sets)  # the scene itself must be valid
        if varies:
            specs += _draws(raw, default_name, sets, varies, samples, seed, len(specs), width, notes, src)
            continue
        for values in grid:
            params = {s.key: float(v) for s, v in zip(sweeps, values)}
            overrides = sets + [f"{k}={_value_text(v)}" for k, v in params.items()]
            try:
                scene = _scene(raw, default_name, overrides) if params else base
            except SceneError as exc:
                where = ", ".join(f"{k}={v:g}" for k, v in params.items())
                raise SceneError(f"{src} with {where}: {exc}") from None
            specs.append(RunSpec(f"{len(specs):0{width}d}", scene, params))
    return Plan(specs, keys, notes)


def _draws(raw: dict, default_name: str, sets: list[str], varies: list[Vary], samples: int, seed: int,
           first: int, width: int, notes: list[str], src: str) -> list[RunSpec]:
    """`samples` valid draws; invalid ones are drawn again (and counted in `notes`)."""
    rng = np.random.default_rng(seed)
    specs: list[RunSpec] = []
    rejected = 0
    reasons: dict[str, int] = {}
    while len(specs) < samples:
        values = [rng.normal(v.mean, v.std) for v in varies]
        params = {v.key: float(x) for v, x in zip(varies, values)}
        overrides = sets + [f"{k}={_value_text(x)}" for k, x in params.items()]
        try:
            scene = _scene(raw, default_name, overrides)
        except SceneError as exc:
            rejected += 1
            reasons[str(exc)] = reasons.get(str(exc), 0) + 1
            if rejected > MAX_DRAW_FACTOR * samples:
                raise BatchError(f"{src}: {rejected} draws made the scene invalid (e.g. {exc}); "
                                 "narrow the --vary distributions") from None
            continue
        specs.append(RunSpec(f"{first + len(specs):0{width}d}", scene, params))
    if rejected:
        example = max(reasons, key=reasons.get)
        notes.append(f"{src}: drew {rejected} invalid parameter set(s) again (e.g. {example})")
    return specs


# ---------------------------------------------------------------------------------------------
# Outcomes of runs: one summary row each


@dataclass
class Columns:
    """Summary columns: ids, parameters, outcomes per body, residuals and costs."""

    params: list[str]
    outcomes: list[str]

    @property
    def all(self) -> list[str]:
        return ["run_id", "scene", *self.params, *self.outcomes,
                "residual.energy", "residual.momentum", "residual.angular_momentum",
                "steps", "dt", "sim_time", "wall_time_s", "error"]


def outcome_columns(scene: Scene) -> list[str]:
    """`ball1.velocity.x`, ..., `ball1.spin` (2D) or `ball1.spin.x` (3D), `ball1.deflection_deg`."""
    cols = []
    for body in scene.bodies:
        cols += [f"{body.name}.velocity.{a}" for a in "xyz"[:scene.dim]]
        if scene.dim == 2:
            cols.append(f"{body.name}.spin")
        elif scene.dim == 3:
            cols += [f"{body.name}.spin.{a}" for a in "xyz"]
        cols.append(f"{body.name}.deflection_deg")
    return cols


def summary_columns(plan: Plan) -> Columns:
    outcomes: list[str] = []
    seen: set[str] = set()
    for spec in plan.specs:
        for col in outcome_columns(spec.scene):
            if col not in seen:
                seen.add(col)
                outcomes.append(col)
    return Columns(plan.param_keys, outcomes)


def _text(value: float | int | str | None) -> str:
    """Exact CSV text: repr for floats (reads back bit for bit), empty for none or NaN."""
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ""
    return str(value)


def deflection_deg(v0: np.ndarray, v1: np.ndarray) -> float:
    """Angle between initial and final velocity in degrees; NaN when either is zero.

    atan2 of the cross and dot products keeps small angles exact (acos loses them).
    """
    if not np.any(v0) or not np.any(v1):
        return math.nan
    if len(v0) == 1:
        return 0.0 if v0[0] * v1[0] > 0 else 180.0
    if len(v0) == 2:
        cross = abs(float(v0[0] * v1[1] - v0[1] * v1[0]))
    else:
        cross = float(np.linalg.norm(np.cross(v0, v1)))
    return math.degrees(math.atan2(cross, float(np.dot(v0, v1))))


def outcome_row(spec: RunSpec, run: SceneRun, member: int, wall_time_s: float,
                res: Residuals | None = None) -> dict[str, str]:
    """The summary row of one member of a batch run (`res`: the run's residuals, if known)."""
    r = run.result
    scene = spec.scene
    row: dict[str, str] = {"run_id": spec.run_id, "scene": scene.name}
    row.update({k: _text(v) for k, v in spec.params.items()})
    for n, body in enumerate(scene.bodies):
        v1 = r.final.v[member, n]
        for a, x in zip("xyz", v1):
            row[f"{body.name}.velocity.{a}"] = _text(x)
        if scene.dim > 1:
            w = r.final.w[member, n] if r.model.spin_dim else np.zeros(scene.spin_dim)
            if scene.dim == 2:
                row[f"{body.name}.spin"] = _text(w[0])
            else:
                for a, x in zip("xyz", w):
                    row[f"{body.name}.spin.{a}"] = _text(x)
        row[f"{body.name}.deflection_deg"] = _text(deflection_deg(r.initial.v[member, n], v1))
    res = residuals(r) if res is None else res
    row["residual.energy"] = _text(res.energy[member])
    row["residual.momentum"] = _text(res.momentum[member])
    row["residual.angular_momentum"] = _text(res.angular_momentum[member])
    row["steps"] = _text(int(r.steps[member]))
    row["dt"] = _text(r.dt[member])
    row["sim_time"] = _text(r.final.t[member])
    row["wall_time_s"] = _text(wall_time_s)
    row["error"] = ""
    return row


def failure_row(spec: RunSpec, error: str) -> dict[str, str]:
    row = {"run_id": spec.run_id, "scene": spec.scene.name, "error": error}
    row.update({k: _text(v) for k, v in spec.params.items()})
    return row


# ---------------------------------------------------------------------------------------------
# The summary file: rewritten whole and atomically after every chunk


def write_csv_atomic(path: Path, header: list[str], rows: list[dict[str, str]]) -> None:
    """Write a CSV beside `path` and move it into place: readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=header, restval="", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.tmp"
    try:
        with open(tmp, "w", newline="") as f:
            f.write(buf.getvalue())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_summary(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    """Header and rows of a summary CSV."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def _identity(row: dict[str, str], params: list[str]) -> tuple[str, ...]:
    """What makes a row the same run: id, scene and the exact parameter texts."""
    return (row.get("run_id", ""), row.get("scene", ""), *(row.get(k, "") for k in params))


def safe_name(text: str, limit: int = 180) -> str:
    """A file-name-safe version of `text` (letters, digits, . _ - = only)."""
    name = re.sub(r"[^A-Za-z0-9._=\-]+", "_", text).strip("._")
    return name[:limit] or "run"


def recording_name(spec: RunSpec) -> str:
    """`<run_id>_<scene>[_key=value...].rrd`: unique by run id, readable by its parameters."""
    parts = [spec.run_id, spec.scene.name] + [f"{k}={v:.6g}" for k, v in spec.params.items()]
    return safe_name("_".join(parts)) + ".rrd"


# ---------------------------------------------------------------------------------------------
# Running


@dataclass
class BatchResult:
    """What `run_batch` did: all rows (sorted by run id), counts and where things went."""

    header: list[str]
    rows: list[dict[str, str]]
    ran: int
    skipped: int
    failed: int
    summary: Path | None
    recordings: list[Path]
    wall_time_s: float
    notes: list[str] = field(default_factory=list)


ProgressCallback = Callable[[int, int], None]


def _groups(specs: list[RunSpec], integrator: str | None) -> list[list[RunSpec]]:
    """Specs that can share one vectorised run: same shape and integrator, in first-seen order."""
    groups: dict[tuple, list[RunSpec]] = {}
    for spec in specs:
        key = (shape_key(spec.scene), integrator or spec.scene.integrator)
        groups.setdefault(key, []).append(spec)
    return list(groups.values())


def run_batch(plan: Plan, *, integrator: str | None = None, dt: float | str | None = None,
              tol: float | None = None, summary: Path | None = None, record_dir: Path | None = None,
              resume: bool = False, chunk_size: int = DEFAULT_CHUNK, stride: int = 1,
              progress: ProgressCallback | None = None) -> BatchResult:
    """Run every spec of the plan in vectorised chunks; save rows (and recordings) per chunk.

    `progress(done, total)` is called after each chunk is saved; raising from it (or Ctrl-C)
    stops the batch with everything finished so far on disk. With `resume`, runs whose row is
    already in `summary` (same run id, scene and parameter values) are skipped.
    """
    if chunk_size < 1:
        raise BatchError(f"chunk size must be at least 1, got {chunk_size}")
    columns = summary_columns(plan)
    header = columns.all
    done: dict[str, dict[str, str]] = {}
    if resume and summary is not None and summary.exists():
        done = _resumable(summary, header, plan)
    todo = [s for s in plan.specs if s.run_id not in done]
    total = len(plan.specs)
    rows = dict(done)
    recordings: list[Path] = []
    started = time.perf_counter()
    failed = 0
    order = {s.run_id: i for i, s in enumerate(plan.specs)}

    def save() -> None:
        if summary is not None:
            write_csv_atomic(summary, header, sorted(rows.values(), key=lambda r: order[r["run_id"]]))

    save()
    if progress is not None:
        progress(len(rows), total)
    saved = len(rows)
    try:
        for group in _groups(todo, integrator):
            for start in range(0, len(group), chunk_size):
                chunk = group[start:start + chunk_size]
                for spec, row, run, member in _run_chunk(chunk, integrator, dt, tol, record_dir is not None):
                    if run is not None and record_dir is not None:
                        from collide.recording import write_recording

                        path = record_dir / recording_name(spec)
                        recordings.append(write_recording(run.member(member), path, stride=stride))
                    failed += bool(row["error"])
                    rows[spec.run_id] = row
                save()
                saved = len(rows)
                if progress is not None:
                    progress(len(rows), total)
    finally:
        if len(rows) != saved:
            save()  # interrupted inside a chunk: keep the runs whose recordings are written
    ordered = sorted(rows.values(), key=lambda r: order[r["run_id"]])
    return BatchResult(header, ordered, len(todo), len(done), failed, summary, recordings,
                       time.perf_counter() - started, list(plan.notes))


def _resumable(summary: Path, header: list[str], plan: Plan) -> dict[str, dict[str, str]]:
    """Rows of an earlier, interrupted run of the same batch (refuses another batch's file)."""
    old_header, old_rows = read_summary(summary)
    if old_header != header:
        raise BatchError(f"--resume: {summary} has other columns than this batch; "
                         "use the same arguments, or a new --summary file")
    wanted = {_identity({"run_id": s.run_id, "scene": s.scene.name,
                         **{k: _text(v) for k, v in s.params.items()}}, plan.param_keys): s.run_id
              for s in plan.specs}
    done = {}
    for row in old_rows:
        ident = _identity(row, plan.param_keys)
        if ident not in wanted:
            raise BatchError(f"--resume: {summary} has run {row.get('run_id')} with other parameters "
                             "than this batch; use the same arguments, or a new --summary file")
        done[row["run_id"]] = dict(row)
    return done


def _run_chunk(chunk: list[RunSpec], integrator: str | None, dt: float | str | None, tol: float | None,
               record: bool) -> Iterable[tuple[RunSpec, dict[str, str], SceneRun | None, int]]:
    """Run a chunk in one vectorised call; if one member fails, split to find it (bisection)."""
    try:
        run = run_scenes([s.scene for s in chunk], integrator=integrator, dt=dt, tol=tol, record=record)
    except (RunError, SceneError) as exc:
        if len(chunk) == 1:
            yield chunk[0], failure_row(chunk[0], str(exc)), None, 0
            return
        half = len(chunk) // 2
        yield from _run_chunk(chunk[:half], integrator, dt, tol, record)
        yield from _run_chunk(chunk[half:], integrator, dt, tol, record)
        return
    per_run = run.result.wall_time_s / len(chunk)
    res = residuals(run.result)
    for i, spec in enumerate(chunk):
        yield spec, outcome_row(spec, run, i, per_run, res), run, i


# ---------------------------------------------------------------------------------------------
# Ensembles


@dataclass(frozen=True)
class Stat:
    column: str
    mean: float
    std: float
    count: int


def ensemble_stats(rows: list[dict[str, str]], columns: list[str]) -> list[Stat]:
    """Mean and sample standard deviation of each outcome column over the runs that finished."""
    stats = []
    for col in columns:
        values = np.array([float(r[col]) for r in rows if r.get(col, "") not in ("", None)])
        if len(values) == 0:
            continue
        std = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
        stats.append(Stat(col, float(np.mean(values)), std, len(values)))
    return stats
