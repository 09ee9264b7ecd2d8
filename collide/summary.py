"""The JSON summary (docs/design.md section 4) and the report's CSV columns (section III's printf)."""

from __future__ import annotations

import io
import json
import math
from collections.abc import Iterator
from typing import Any, TextIO

import numpy as np

from collide import diagnostics as dg
from collide.engine import tier
from collide.model import Model, State
from collide.periodic import wrap
from collide.run import SceneRun
from collide.stepper import RunError


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


# Bodies a chunk of the JSON summary's body list (`write_summary_json`): 100 000 bodies as Python
# objects took about 70 MB, more than the run's own arrays.
BODY_CHUNK = 4096


def run_summary(run: SceneRun, member: int = 0, bodies: bool = True) -> dict[str, Any]:
    """The docs/design.md section 4 object for one member of a run. Inapplicable residuals are None.
    `bodies=False` leaves the body list empty (`write_summary_json` writes it a chunk at a time)."""
    r = run.result
    scene = run.scenes[member]
    res = dg.residuals(r)
    # The bodies' values are checked as arrays (100 000 bodies: 7 s walked one number at a time);
    # where one is not finite the walk below names it.
    final = (r.final.s[member], r.final.v[member], r.final.w[member])
    finite = all(np.isfinite(a).all() for a in final)
    listed = _final_bodies(r, scene.dim, member) if bodies or not finite else []
    log = r.contacts
    max_overlap = float(log.max_overlap[member])
    summary = {
        "scene": scene.name,
        "dim": scene.dim,
        "integrator": r.integrator,
        # Which engine ran it and why (collide.alone.engine_choice): the event engine, the DEM
        # kernel or the report's update.
        "engine": r.engine or None,
        "engine_reason": r.engine_reason or None,
        "dt": float(r.dt[member]),
        "dt_auto": bool(run.auto[member]) if run.auto is not None else scene.dt == "auto",
        "tol": run.tol[member] if run.tol is not None else scene.tol,
        # The error model's prediction for the outcome at this step (relative to the fastest
        # initial speed), and the report's own criterion: energy residual below 1%.
        "error_estimate": None if run.error_estimate is None else float(run.error_estimate[member]),
        "error_method": None if run.error_method is None else run.error_method[member],
        "report_criterion_met": None if not math.isfinite(res.energy[member]) else bool(res.energy[member] < 0.01),
        "steps": int(r.steps[member]),
        "jumps": int(r.jumps[member]),
        "sim_time": float(r.final.t[member]),
        "wall_time_s": r.wall_time_s,
        # Which kernels ran (collide.engine.tier): a small run stays interpreted, quicker as a
        # whole process, and its wall_time_s is then the interpreted code's.
        "kernels": "compiled" if tier.COMPILED else "interpreted",
        "threads": r.threads,
        "bodies": listed,
        "residuals": {
            "energy": _finite_or_none(res.energy[member]),
            "momentum": _finite_or_none(res.momentum[member]),
            "angular_momentum": _finite_or_none(res.angular_momentum[member]),
        },
        "contact": {
            "count": int(log.count[member]),
            # Each sphere of a pair takes half the overlap (equal springs in series); a sphere on
            # a wall takes all of it.
            "max_compression": max_overlap / 2 if r.model.n_walls == 0 else max_overlap,
            "max_overlap": max_overlap,
            "max_normal_force": None if log.max_normal_force is None else
            _finite_or_none(log.max_normal_force[member]),
            "duration": float(log.duration[member]),
            "first_start": _finite_or_none(log.first_start[member]),
            "last_end": _finite_or_none(log.last_end[member]),
        },
        "warnings": list(r.warnings),
    }
    if r.dissipation is not None:
        damping, friction, rolling = (float(x) for x in r.dissipation[member])
        stored = 0.0 if r.final.stored is None else float(r.final.stored[member])
        # The kernel's friction account includes what the tangential springs still hold.
        summary["dissipated"] = {"damping": damping, "friction": friction - stored, "rolling": rolling,
                                 "tangential_spring_energy": stored}
    traj = r.trajectories[member] if r.trajectories is not None else None
    if r.frame_steps and traj is not None:
        # A recorded DEM run: its frames, taken at most once each `every_steps` steps (collide.dem).
        summary["frames"] = {"recorded": int(len(traj.knot_times)), "every_steps": int(r.frame_steps)}
    if scene.rest is not None:
        summary["packing_fraction"] = _finite_or_none(dg.packing_fraction(r.model, r.final.s[member], member))
    _refuse_non_finite({k: v for k, v in summary.items() if k != "bodies" or not finite}, scene.name)
    return summary


def write_summary_json(summary: dict[str, Any], run: SceneRun, out: TextIO, member: int = 0) -> None:
    """`summary` (from `run_summary(run, member, bodies=False)`) as the line json.dumps of the whole
    summary makes, its bodies written BODY_CHUNK at a time: never all of them as Python objects."""
    text = json.dumps(summary)
    head, key, tail = text.partition('"bodies": []')  # (in a JSON string a quote is escaped: the key)
    out.write(head + '"bodies": [')
    first = True
    for chunk in _body_chunks(run.result, run.scenes[member].dim, member, BODY_CHUNK):
        if chunk:
            out.write(("" if first else ", ") + json.dumps(chunk)[1:-1])
            first = False
    out.write("]" + tail + "\n")


def _final_bodies(r: Any, dim: int, member: int) -> list[dict[str, Any]]:
    """Each body's name and final position, velocity and spin as the JSON shows them. In a
    periodic box the positions are wrapped into it, with the periods each body crossed
    (docs/design.md section 10): the engines' own are unwrapped."""
    return [body for chunk in _body_chunks(r, dim, member, max(len(r.model.body_names), 1)) for body in chunk]


def _body_chunks(r: Any, dim: int, member: int, size: int) -> Iterator[list[dict[str, Any]]]:
    """`_final_bodies`, `size` bodies at a time."""
    s_all, images_all = wrap(r.final.s[member], np.array(r.model.box_lower), np.array(r.model.period))
    for lo in range(0, len(r.model.body_names), size):
        yield _bodies_of(r, dim, member, s_all, images_all, slice(lo, lo + size))


def _bodies_of(r: Any, dim: int, member: int, s_all: np.ndarray, images_all: np.ndarray,
               part: slice) -> list[dict[str, Any]]:
    s, v, names = s_all[part], r.final.v[member][part], r.model.body_names[part]
    pos, vel = (s[:, 0].tolist(), v[:, 0].tolist()) if dim == 1 else (s.tolist(), v.tolist())
    if dim == 1:
        spin = [None] * len(names)
    elif r.model.spin_dim:
        w = r.final.w[member][part]
        spin = w[:, 0].tolist() if dim == 2 else w.tolist()
    else:
        spin = [0.0 if dim == 2 else [0.0, 0.0, 0.0] for _ in names]
    crossed = images_all[part].tolist() if r.model.periodic else [None] * len(names)
    bodies = []
    for n, p, u, w, c in zip(names, pos, vel, spin, crossed):
        body: dict[str, Any] = {"name": n, "position": p}
        if c is not None:
            body["images"] = c
        body["velocity"] = u
        if dim > 1:
            body["spin"] = w
        bodies.append(body)
    return bodies


def _refuse_non_finite(value: Any, scene: str, where: str = "") -> None:
    """A non-finite number is no result: refuse it (JSON would print `Infinity`, which is not JSON)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _refuse_non_finite(item, scene, f"{where}.{key}" if where else str(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _refuse_non_finite(item, scene, f"{where}[{i}]")
    elif isinstance(value, float) and not math.isfinite(value):
        raise RunError(f"{scene}: the result's {where} is {value} (float64 overflowed); no result to report")


# ---------------------------------------------------------------------------------------------
# CSV in the report's columns


def _vector_names(prefix: str, dim: int) -> list[str]:
    return [f"{prefix}.{c}" for c in "xyz"[:dim]]


def csv_columns(model: Model) -> list[str]:
    """time, s1.x, ..., scom, v1, ..., vcom, p1, ..., p, w1, ..., L1, ..., L, E1, ..., E."""
    n, d = model.n_bodies, model.dim
    cols = ["time"]
    for prefix in ("s", "v"):
        for i in range(n):
            cols += _vector_names(f"{prefix}{i + 1}", d)
        cols += _vector_names(f"{prefix}com", d)
    for i in range(n):
        cols += _vector_names(f"p{i + 1}", d)
    cols += _vector_names("p", d)
    if d == 2:
        cols += [f"w{i + 1}" for i in range(n)] + [f"L{i + 1}" for i in range(n)] + ["L"]
    elif d == 3:
        for i in range(n):
            cols += _vector_names(f"w{i + 1}", 3)
        for i in range(n):
            cols += _vector_names(f"L{i + 1}", 3)
        cols += _vector_names("L", 3)
    cols += [f"E{i + 1}" for i in range(n)] + ["E"]
    return cols


def _per_body_energy(model: Model, st: State) -> np.ndarray:
    """Each body's kinetic, rotational and own spring energy (T, N): the report's E1, E2."""
    energy = 0.5 * model.mass * np.sum(st.v * st.v, -1)
    if st.w.shape[-1]:
        energy = energy + 0.5 * model.inertia * np.sum(st.w * st.w, -1)
    contacts = dg.contacts_near(model, st.s)
    if len(contacts):
        _, overlap, _ = dg.contact_geometry(model, st.s, contacts)
        pressed = np.maximum(overlap, 0.0)
        k = dg.stiffness(model, contacts)
        pair = contacts[:, 1] >= 0
        # Each sphere of a pair is a spring of constant 2 k_eff compressed by half the overlap
        # (half the pair's energy each); on a rigid wall the sphere takes all of it.
        own = np.where(pair, 0.25, 0.5) * k * pressed * pressed
        for c, (i, j) in enumerate(contacts):
            energy[..., i] += own[..., c]
            if j >= 0:
                energy[..., j] += own[..., c]
    return energy


def _rows(model: Model, st: State, diag: State) -> np.ndarray:
    """Columns for states `st` (positions, velocities, spins) and `diag` (the derived sums)."""
    t = diag.t
    m = model.mass[0]
    s, v, w = st.s[:, 0], st.v[:, 0], st.w[:, 0]
    ds, dv, dw = diag.s[:, 0], diag.v[:, 0], diag.w[:, 0]
    total = m.sum()
    parts = [t[:, None], s.reshape(len(t), -1), (m[:, None] * ds).sum(1) / total,
             v.reshape(len(t), -1), (m[:, None] * dv).sum(1) / total]
    p = m[:, None] * dv
    parts += [p.reshape(len(t), -1), p.sum(1)]
    if model.dim > 1:
        k_spin = max(model.spin_dim, 1 if model.dim == 2 else 3)
        wv = w if w.shape[-1] else np.zeros((len(t), model.n_bodies, k_spin))
        dwv = dw if dw.shape[-1] else np.zeros((len(t), model.n_bodies, k_spin))
        lin = dg._cross_z(ds, p)
        ang = lin + model.inertia[0][:, None] * dwv
        parts += [wv.reshape(len(t), -1), ang.reshape(len(t), -1), ang.sum(1)]
    energy = _per_body_energy(model, State(diag.t, diag.s[:, 0][:, None], diag.v[:, 0][:, None],
                                           diag.w[:, 0][:, None], diag.q, diag.work))[:, 0]
    parts += [energy, energy.sum(1, keepdims=True)]
    return np.concatenate(parts, axis=1)


def csv_table(run: SceneRun, times: np.ndarray, layout: str = "aligned") -> tuple[list[str], np.ndarray]:
    """The report's columns at the given times, for member 0 of the run.

    layout "aligned": every column at the row's time. layout "report": as the report's program
    printed them: positions, velocities and spins one step (dt) after the printed time, the
    sums (centre of mass, momenta, angular momenta, energies) at it (docs/design.md section 8).
    """
    r = run.result
    if r.trajectory is None:
        raise ValueError("the run was not recorded; run it with record=True")
    diag = dg.sample(r.model, r.trajectory, times)
    if layout == "report":
        st = dg.sample(r.model, r.trajectory, np.asarray(times) + r.dt[0])
    elif layout == "aligned":
        st = diag
    else:
        raise ValueError(f"unknown CSV layout '{layout}' (aligned or report)")
    return csv_columns(r.model), _rows(r.model, st, diag)


def report_csv(run: SceneRun, every: float, layout: str = "aligned", member: int = 0) -> str:
    """CSV text in the report's columns at times 0, every, 2 every, ... up to the run's end.

    With layout "report" the numbers are printed with %f, as the report's program did.
    """
    if run.result.batch_size > 1:
        run = run.member(member)
    end = float(run.result.final.t[0])
    times = np.arange(0.0, end + 0.5 * every, every)
    times = times[times <= end + 1e-12]
    columns, table = csv_table(run, times, layout)
    out = io.StringIO()
    out.write(",".join(columns) + "\n")
    np.savetxt(out, table, fmt="%f" if layout == "report" else "%.12g", delimiter=",")
    return out.getvalue()
