"""Batches: many scenes, parameter sweeps and ensembles, run vectorised and summarised.

A batch is a list of `RunSpec`s (scene + the parameter values that made it). `run_batch`
groups same-shaped scenes and runs them through the batch stepper (`run_scenes`) in sub-chunks
of about a second each. Each finished run's row is appended to the summary CSV and flushed to
disk (fsync) before its recording is written, so whatever stops the batch (Ctrl-C, SIGKILL,
power loss) every complete recording has its row, and at most a second or two of work is lost.
`resume=True` trusts only complete, well-formed rows of the same batch (a row cut short is run
again, as is a row whose recording is missing), removes the temporary files a killed run left,
and at the end the summary is rewritten in run order, as an uninterrupted batch writes it.

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
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from collide.diagnostics import residuals
from collide.engine import tier
from collide.model import shape_key
from collide.output import OutputError, check_file, check_folder, failed, write_text_atomic
from collide.run import SceneRun, run_scenes
from collide.scene import Scene, SceneError, apply_overrides, parse_scene, read_raw
from collide.stepper import RunError

DEFAULT_CHUNK = 1000
MAX_DRAW_FACTOR = 100  # give up after this many invalid draws per requested sample
SUBCHUNK_SECONDS = 1.0  # finished runs reach the disk at least this often (sub-chunks sized to it)
MAX_RUNS = 1_000_000  # runs in one batch: each holds its scene in memory (about 8 KB) before it runs


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
    total = len(raws) * (samples if varies else math.prod(s.num for s in sweeps))
    if total > MAX_RUNS:
        raise BatchError(f"the batch would have {total:.3g} runs; at most {MAX_RUNS:.0e} fit in memory at once "
                         "(each run's scene is built before any runs): split the sweep into several batches")
    if sweeps:
        grid = list(itertools.product(*(s.values for s in sweeps)))
    else:
        grid = [()]
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


def _float_text(value: float) -> str:
    """A Python float's exact CSV text (empty for NaN and infinities)."""
    return repr(value) if math.isfinite(value) else ""


def _text(value: float | int | str | None) -> str:
    """Exact CSV text: repr for floats (reads back bit for bit), empty for none or NaN."""
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return _float_text(float(value))
    return str(value)


def deflection_deg(v0: np.ndarray, v1: np.ndarray) -> np.ndarray:
    """Angle between initial and final velocities (..., dim) in degrees (...); NaN where either
    is zero. atan2 of the cross and dot products keeps small angles exact (acos loses them)."""
    v0, v1 = np.asarray(v0, dtype=float), np.asarray(v1, dtype=float)
    dot = np.einsum("...i,...i->...", v0, v1)
    if v0.shape[-1] == 1:
        angle = np.where(dot > 0, 0.0, 180.0)
    else:
        if v0.shape[-1] == 2:
            cross = np.abs(v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0])
        else:
            normal = np.cross(v0, v1)
            cross = np.sqrt(np.einsum("...i,...i->...", normal, normal))
        # math's atan2 and degrees, as the summaries of earlier versions (numpy's differ in the
        # last bit).
        angle = np.array([math.degrees(math.atan2(c, d)) for c, d in zip(cross.ravel().tolist(),
                                                                       dot.ravel().tolist())]).reshape(dot.shape)
    return np.where(v0.any(-1) & v1.any(-1), angle, np.nan)


def outcome_rows(specs: list[RunSpec], run: SceneRun, wall_time_s: float) -> list[dict[str, str]]:
    """The summary rows of a batch run's members, one per spec (`wall_time_s`: each run's
    share). Columns are filled from whole arrays, turned into Python floats once (per value,
    numpy scalars cost a row as much as its run)."""
    r = run.result
    scene = specs[0].scene
    text, num = _text, _float_text
    v = r.final.v.tolist()
    w = r.final.w.tolist() if r.model.spin_dim else None
    angle = deflection_deg(r.initial.v, r.final.v).tolist()
    res = residuals(r)  # kept on the result: computed once per run
    energy, momentum, angular = res.energy.tolist(), res.momentum.tolist(), res.angular_momentum.tolist()
    steps, dt, sim_time = r.steps.tolist(), r.dt.tolist(), r.final.t.tolist()
    share = text(wall_time_s)
    rows = []
    for m, spec in enumerate(specs):
        row: dict[str, str] = {"run_id": spec.run_id, "scene": spec.scene.name}
        row.update({k: text(x) for k, x in spec.params.items()})
        for n, body in enumerate(scene.bodies):
            for axis, x in zip("xyz", v[m][n]):
                row[f"{body.name}.velocity.{axis}"] = num(x)
            if scene.dim > 1:
                spin = w[m][n] if w is not None else [0.0] * scene.spin_dim
                if scene.dim == 2:
                    row[f"{body.name}.spin"] = num(spin[0])
                else:
                    for axis, x in zip("xyz", spin):
                        row[f"{body.name}.spin.{axis}"] = num(x)
            row[f"{body.name}.deflection_deg"] = num(angle[m][n])
        row["residual.energy"] = num(energy[m])
        row["residual.momentum"] = num(momentum[m])
        row["residual.angular_momentum"] = num(angular[m])
        row["steps"] = text(int(steps[m]))
        row["dt"] = num(dt[m])
        row["sim_time"] = num(sim_time[m])
        row["wall_time_s"] = share
        row["error"] = ""
        rows.append(row)
    return rows


def failure_row(spec: RunSpec, error: str) -> dict[str, str]:
    row = {"run_id": spec.run_id, "scene": spec.scene.name, "error": " ".join(error.split())}  # one line
    row.update({k: _text(v) for k, v in spec.params.items()})
    return row


# ---------------------------------------------------------------------------------------------
# The summary file: rows appended and synced as runs finish; rewritten in run order at the end


def _csv_text(header: list[str], rows: list[dict[str, str]], with_header: bool) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=header, restval="", lineterminator="\n")
    if with_header:
        writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def write_csv_atomic(path: Path, header: list[str], rows: list[dict[str, str]]) -> None:
    """Write a CSV beside `path`, check and sync it, move it into place: readers never see half
    a file, and a failed write (`OutputError`) leaves the old file as it was."""
    write_text_atomic(path, _csv_text(header, rows, True))


class _Journal:
    """The summary file open for appending: each row written, flushed and synced at once."""

    def __init__(self, path: Path, header: list[str]) -> None:
        self.header = header
        self.path = path
        try:
            self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except OSError as exc:
            raise failed(path, exc) from None

    def append(self, rows: list[dict[str, str]]) -> None:
        """Append whole rows or none: a failed write (a full disk) is cut back off the file, so
        no row is left cut short, and raised as an `OutputError`."""
        data = _csv_text(self.header, rows, False).encode("utf-8")
        size = os.fstat(self.fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view):]
            os.fsync(self.fd)
        except OSError as exc:
            try:
                os.ftruncate(self.fd, size)
                os.fsync(self.fd)
            except OSError:
                pass  # cut back as far as the disk lets us; --resume drops a row cut short
            raise failed(self.path, exc) from None

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


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
    load_s: float = 0.0  # of wall_time_s: loading the compiled kernels (once a process)


ProgressCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class ChunkSettings:
    """What every chunk of a batch runs with (sent along with each chunk to a cluster worker)."""

    integrator: str | None = None
    dt: float | str | None = None
    tol: float | None = None
    record_dir: str | None = None  # a folder every worker can reach (a shared file system)
    stride: int = 1


@dataclass
class ChunkResult:
    """A finished chunk: its rows (in the chunk's order) and the recordings it wrote."""

    rows: list[dict[str, str]]
    recordings: list[str]


def run_chunk(specs: list[RunSpec], settings: ChunkSettings) -> ChunkResult:
    """Run one chunk of a batch and write its recordings: the unit of work sent to a cluster.

    A top-level function of picklable arguments, so that a Dask worker imports it by name.
    Runs that fail become rows carrying their error; anything else that goes wrong raises.
    """
    rows: list[dict[str, str]] = []
    recordings: list[str] = []
    record_dir = None if settings.record_dir is None else Path(settings.record_dir)
    for spec, row, run, member in _run_chunk(specs, settings.integrator, settings.dt, settings.tol,
                                             record_dir is not None):
        rows.append(row)
        if run is not None and record_dir is not None:
            from collide.recording import write_recording

            path = record_dir / recording_name(spec)
            recordings.append(str(write_recording(run.member(member), path, stride=settings.stride)))
    return ChunkResult(rows, recordings)


class ChunkExecutor(Protocol):
    """Runs chunks somewhere else (a Dask cluster: `collide.distributed.DaskExecutor`).

    `run` yields each chunk with its result as it finishes, in any order; it turns a chunk that
    could not be run (its task failed twice) into rows carrying the error, and raises BatchError
    when nothing more can run (the scheduler gone). Ctrl-C raises KeyboardInterrupt from it.
    """

    def run(self, chunks: list[list[RunSpec]], settings: ChunkSettings) -> Iterator[tuple[int, ChunkResult]]:
        ...


def plan_chunks(specs: list[RunSpec], integrator: str | None, chunk_size: int) -> list[list[RunSpec]]:
    """Fixed chunks of at most `chunk_size` same-shaped runs, in run order within each shape."""
    return [group[i:i + chunk_size] for group in _groups(specs, integrator)
            for i in range(0, len(group), chunk_size)]


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
              progress: ProgressCallback | None = None, executor: ChunkExecutor | None = None) -> BatchResult:
    """Run every spec of the plan; save each finished run's row (and recording) as it finishes.

    In process (no `executor`), runs go to the stepper in sub-chunks of at most `chunk_size`,
    sized to take about SUBCHUNK_SECONDS each; their rows are appended to `summary` and synced
    to disk right away, each before its recording. With an `executor` (a Dask cluster), chunks
    of `chunk_size` runs are run by `run_chunk` on its workers (which write the recordings) and
    each chunk's rows are appended and synced as it comes back. `progress(done, total)` is called
    after each chunk; raising from it (or Ctrl-C, or a kill) stops the batch with every finished
    run on disk. With `resume`, runs whose complete, well-formed row is already in `summary`
    (same run id, scene and parameter values; with `record_dir`, its recording there too) are
    skipped. Either way the summary ends rewritten in run order.
    """
    if chunk_size < 1:
        raise BatchError(f"chunk size must be at least 1, got {chunk_size}")
    # Where the results go can take them: said before the first run, not after the last.
    if summary is not None:
        check_file(summary, "file name for the summary CSV")
    if record_dir is not None:
        check_folder(record_dir)
    columns = summary_columns(plan)
    header = columns.all
    notes = list(plan.notes)
    done: dict[str, dict[str, str]] = {}
    if resume and summary is not None:
        removed = _remove_stale_temporaries(plan, summary, record_dir)
        if removed:
            notes.append(f"removed {removed} temporary file(s) left by an interrupted run")
        if summary.exists():
            done, dropped = _resumable(summary, header, plan, record_dir)
            if dropped:
                notes.append(f"{dropped} row(s) of {summary} were cut short, malformed or without their "
                             "whole recording (missing, cut or damaged): run again")
    todo = [s for s in plan.specs if s.run_id not in done]
    total = len(plan.specs)
    rows = dict(done)
    recordings: list[Path] = []
    started = time.perf_counter()
    loaded_before = tier.load_seconds()
    failed = 0
    order = {s.run_id: i for i, s in enumerate(plan.specs)}

    def save_in_order(stopping: bool = False) -> None:
        if summary is None:
            return
        try:
            write_csv_atomic(summary, header, sorted(rows.values(), key=lambda r: order[r["run_id"]]))
        except OutputError:
            if not stopping:
                raise
            # Stopping for another error (a full disk): the appended rows, synced, stay as they are.

    save_in_order()  # the header, and the trusted rows of an earlier run (nothing torn)
    journal = _Journal(summary, header) if summary is not None else None
    if progress is not None:
        progress(len(rows), total)
    try:
        if executor is not None:
            # An absolute folder: a worker elsewhere resolves a relative one against its own cwd.
            folder = None if record_dir is None else str(record_dir.resolve())
            settings = ChunkSettings(integrator, dt, tol, folder, stride)
            for _, result in executor.run(plan_chunks(todo, integrator, chunk_size), settings):
                for row in result.rows:
                    failed += bool(row["error"])
                    rows[row["run_id"]] = row
                if journal is not None:
                    journal.append(result.rows)
                recordings += [Path(p) for p in result.recordings]
                if progress is not None:
                    progress(len(rows), total)
        else:
            for group in _groups(todo, integrator):
                start, size = 0, 1
                while start < len(group):
                    chunk = group[start:start + size]
                    began = time.perf_counter()
                    finished = list(_run_chunk(chunk, integrator, dt, tol, record_dir is not None))
                    for spec, row, _, _ in finished:
                        failed += bool(row["error"])
                        rows[spec.run_id] = row
                    if journal is not None:
                        # One append and sync per sub-chunk (a sync costs milliseconds: one per run
                        # would cost more than the runs), before the recordings: a recording always
                        # has its row.
                        journal.append([row for _, row, _, _ in finished])
                    for spec, _, run, member in finished:
                        if run is not None and record_dir is not None:
                            from collide.recording import write_recording

                            path = record_dir / recording_name(spec)
                            recordings.append(write_recording(run.member(member), path, stride=stride))
                    start += len(chunk)
                    per_run = (time.perf_counter() - began) / len(chunk)
                    size = max(1, min(chunk_size, 2 * size, int(SUBCHUNK_SECONDS / max(per_run, 1e-9))))
                    if progress is not None:
                        progress(len(rows), total)
    except (KeyboardInterrupt, BatchError, OutputError):
        if journal is not None:
            journal.close()
        save_in_order(stopping=True)  # the rows so far, in run order (killed, the next resume does it)
        raise
    finally:
        if journal is not None:
            journal.close()
    save_in_order()
    ordered = sorted(rows.values(), key=lambda r: order[r["run_id"]])
    return BatchResult(header, ordered, len(todo), len(done), failed, summary, recordings,
                       time.perf_counter() - started, notes, tier.load_seconds() - loaded_before)


_TEMPORARY = re.compile(r"\.(?P<name>.+)\.[0-9a-f]{8}\.tmp")


def _remove_stale_temporaries(plan: Plan, summary: Path, record_dir: Path | None) -> int:
    """Remove the temporary files (`.<name>.<hex>.tmp`) that killed writes of this batch's
    recordings and summary left behind; files of other names are left alone."""
    targets: list[tuple[Path, set[str]]] = [(summary.parent, {summary.name})]
    if record_dir is not None:
        targets.append((record_dir, {recording_name(s) for s in plan.specs}))
    removed = 0
    for folder, names in targets:
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            match = _TEMPORARY.fullmatch(path.name)
            if match and match.group("name") in names and path.is_file():
                try:
                    path.unlink()
                    removed += 1
                except FileNotFoundError:
                    pass
    return removed


def _complete_lines(path: Path) -> tuple[list[str], bool]:
    """The lines of a file that end in a newline (a kill can cut the last one short), and
    whether there was such a cut line."""
    lines = path.read_bytes().decode("utf-8", errors="replace").split("\n")
    return lines[:-1], lines[-1] != ""


def _well_formed(row: dict[str, str], spec: RunSpec) -> bool:
    """Whether a row holds what a finished run writes: a failed run its error, a successful one
    every outcome of its scene as a finite number, and its steps, step and times."""
    if row["error"]:
        return True

    def number(text: str, empty_ok: bool = False) -> bool:
        if text == "":
            return empty_ok
        try:
            return math.isfinite(float(text))
        except ValueError:
            return False

    for col in outcome_columns(spec.scene):
        if not number(row[col], empty_ok=col.endswith(".deflection_deg")):
            return False
    if not all(number(row[c], empty_ok=True) for c in
               ("residual.energy", "residual.momentum", "residual.angular_momentum")):
        return False
    return re.fullmatch(r"\d+", row["steps"]) is not None and \
        all(number(row[c]) for c in ("dt", "sim_time", "wall_time_s"))


def _resumable(summary: Path, header: list[str], plan: Plan,
               record_dir: Path | None) -> tuple[dict[str, dict[str, str]], int]:
    """Rows of an earlier, interrupted run of the same batch that can be trusted, and how many
    others were dropped (cut short, malformed, or a finished run whose recording is missing).
    Refuses another batch's file: other columns, or a complete row of other parameters."""
    lines, cut = _complete_lines(summary)
    if not lines:
        return {}, 0  # no complete header: nothing of this batch was finished
    old_header = next(csv.reader([lines[0]]), [])
    if old_header != header:
        raise BatchError(f"--resume: {summary} has other columns than this batch; "
                         "use the same arguments, or a new --summary file")
    specs = {s.run_id: s for s in plan.specs}
    wanted = {s.run_id: _identity({"run_id": s.run_id, "scene": s.scene.name,
                                   **{k: _text(v) for k, v in s.params.items()}}, plan.param_keys)
              for s in plan.specs}
    done: dict[str, dict[str, str]] = {}
    dropped = int(cut)
    for line in lines[1:]:
        try:
            fields = next(csv.reader([line]), [])
        except csv.Error:
            fields = []
        if len(fields) != len(header):
            dropped += 1
            continue
        row = dict(zip(header, fields))
        spec = specs.get(row["run_id"])
        if spec is None or _identity(row, plan.param_keys) != wanted[row["run_id"]]:
            raise BatchError(f"--resume: {summary} has run {row['run_id']} with other parameters "
                             "than this batch; use the same arguments, or a new --summary file")
        if not _well_formed(row, spec):
            dropped += 1
            continue
        done[row["run_id"]] = row  # a run appended twice (rerun after a kill): the last row
    if record_dir is not None:
        missing = [i for i, row in done.items()
                   if not row["error"] and not _verified(record_dir / recording_name(specs[i]))]
        for run_id in missing:
            del done[run_id]
        dropped += len(missing)
    return done, dropped


def _verified(path: Path) -> bool:
    """Whether a recording is whole and unchanged (its checksum, read in a child process: a
    damaged file must not crash the batch). One that is not is recorded again."""
    from collide.recording import RecordingError, verify_recording

    if not path.is_file():
        return False
    try:
        verify_recording(path)
    except RecordingError:
        return False
    return True


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
    for i, (spec, row) in enumerate(zip(chunk, outcome_rows(chunk, run, run.result.wall_time_s / len(chunk)))):
        yield spec, row, run, i


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
