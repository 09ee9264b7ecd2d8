"""A work-precision study (`collide.accuracy`) as a recording."""

from __future__ import annotations

import math
import uuid
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from collide.output import OutputError, write_atomic
from collide.recording.integrity import _file_messages
from collide.recording.spec import APP_ID
from collide.recording.stream import rrd_file


def write_accuracy_recording(wp: Any, path: Path) -> Path:
    """A work-precision study (`collide.accuracy.WorkPrecision`) as a recording: for each
    integrator, log10 of the error on a `run_time` timeline (seconds of wall time), and the
    table as a text document; the blueprint shows one plot with a line per integrator."""
    def produce(tmp: Path) -> None:
        _write_accuracy(wp, tmp)

    def check(tmp: Path) -> None:
        if _file_messages(tmp) is None:
            raise OutputError(f"could not write {tmp}: the file is incomplete (cut short); is the disk full?")

    return write_atomic(Path(path), produce, check)


def _write_accuracy(wp: Any, tmp: Path) -> None:
    rec = rr.RecordingStream(f"{APP_ID}-accuracy", recording_id=uuid.uuid4(), send_properties=False)
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.TimeSeriesView(origin="/accuracy", name="log10 error against run time"),
        rrb.TextDocumentView(origin="/table", name="table")))
    with rrd_file(rec, tmp, blueprint):
        lines = ["| integrator | omega dt | dt (s) | steps | run time (s) | error |", "|---|---|---|---|---|---|"]
        for p in wp.points:
            err = "refused" if p.error is None else f"{p.error:.3e}"
            lines.append(f"| {p.integrator} | {p.omega_dt:g} | {p.dt:.3g} | {p.steps} | {p.wall_time_s:.4g} | {err} |")
        orders = ", ".join(f"{k}: {'-' if v is None else f'{v:.2f}'}" for k, v in wp.orders().items())
        lines += ["", f"observed orders: {orders}"]
        rec.log("/table", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)
        for name in dict.fromkeys(p.integrator for p in wp.points):
            pts = sorted((p for p in wp.points if p.integrator == name and p.error and p.wall_time_s > 0),
                         key=lambda p: p.wall_time_s)
            if not pts:
                continue
            rec.send_columns(f"/accuracy/{name}",
                             indexes=[rr.TimeColumn("run_time", duration=[p.wall_time_s for p in pts])],
                             columns=rr.Scalars.columns(scalars=[math.log10(p.error) for p in pts]))
