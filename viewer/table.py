"""The values table: mass, velocity, speed, direction, momentum and energies per ball, before the
collision (start of the run), now (the timeline's time) and after it (end of the run), with each
ball's deflection and the totals. What PhET's Collision Lab shows, as markdown for the GUI.

Pure numpy (no viser). Numbers are given to four significant figures; a value below round-off
of the run's own scale is shown as 0.
"""

from __future__ import annotations

import math

import numpy as np

from viewer.state import ViewRun

MAX_TABLE_BODIES = 6


def _num(x: float, scale: float = 0.0) -> str:
    if not math.isfinite(x):
        return "–"
    if abs(x) <= 1e-12 * scale or x == 0.0:
        return "0"
    return f"{x:.4g}"


def _direction(v: np.ndarray, scale: float) -> float:
    """Angle of a 2D (or 3D, in its xy projection) velocity from +x, degrees; NaN at rest."""
    if len(v) < 2 or np.hypot(v[0], v[1]) <= 1e-12 * scale:
        return math.nan
    return math.degrees(math.atan2(v[1], v[0]))


def deflection_deg(v0: np.ndarray, v1: np.ndarray, scale: float) -> float:
    """Angle between the velocities before and after (degrees, 0-180); NaN if either is at rest."""
    n0, n1 = float(np.linalg.norm(v0)), float(np.linalg.norm(v1))
    if n0 <= 1e-12 * scale or n1 <= 1e-12 * scale:
        return math.nan
    c = float(np.dot(v0, v1)) / (n0 * n1)
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def values_markdown(view: ViewRun, t: float) -> str:
    """The table at time t (seconds): one block per ball (the first MAX_TABLE_BODIES), totals."""
    before = view.body_values(view.t0)
    now = view.body_values(t)
    after = view.body_values(view.t1)
    cols = (before, now, after)
    v_scale = float(max(np.max(c["speed"], initial=0.0) for c in cols)) or 1.0
    p_scale = v_scale * float(view.mass.max())
    e_scale = float(max(np.sum(c["kinetic"] + c["rotational"]) for c in cols)) or 1.0
    spins = view.spin_dim > 0
    head = f"**Values** · now = {t * 1e3:.4g} ms · before = start, after = end of the run"
    blocks = [head]
    n_show = min(view.n_bodies, MAX_TABLE_BODIES)
    for i in range(n_show):
        name = view.names[i]
        rows = [f"| **{name}** · {_num(float(view.mass[i]))} kg | before | now | after |", "|---|--:|--:|--:|"]

        def row(label: str, key: str, scale: float, i: int = i) -> str:
            return f"| {label} | " + " | ".join(_num(float(np.ravel(c[key][i])[0]), scale) for c in cols) + " |"

        def rows_of(label: str, unit: str, key: str, scale: float, i: int = i) -> list[str]:
            """One row per component (a vector in one cell wraps in a narrow panel)."""
            width = np.shape(cols[0][key][i])
            if not width or width[0] == 1:
                return [row(f"{label} ({unit})", key, scale)]
            return [f"| {label} {'xyz'[k]} ({unit}) | " + " | ".join(_num(float(c[key][i][k]), scale) for c in cols)
                    + " |" for k in range(width[0])]

        rows += rows_of("velocity", "m/s", "velocity", v_scale)
        if view.dim > 1:
            rows.append(row("speed (m/s)", "speed", v_scale))
            rows.append("| direction (°) | " + " | ".join(
                _num(_direction(c["velocity"][i], v_scale)) for c in cols) + " |")
        rows += rows_of("momentum", "kg m/s", "momentum", p_scale)
        rows.append(row("kinetic energy (J)", "kinetic", e_scale))
        if spins:
            rows += rows_of("spin", "rad/s", "spin", 1.0)
            rows.append(row("rotational energy (J)", "rotational", e_scale))
        if view.dim > 1:
            angle = deflection_deg(before["velocity"][i], after["velocity"][i], v_scale)
            rows.append(f"| deflected by (°) | | | {_num(angle)} |")
        blocks.append("\n".join(rows))
    if view.n_bodies > n_show:
        blocks.append(f"*(the first {n_show} of {view.n_bodies} bodies; totals below are for all)*")
    total = ["| **all bodies** | before | now | after |", "|---|--:|--:|--:|"]
    for k in range(view.dim):
        axis = f" {'xyz'[k]}" if view.dim > 1 else ""
        total.append(f"| momentum{axis} (kg m/s) | " + " | ".join(
            _num(float(c["momentum"].sum(axis=0)[k]), p_scale) for c in cols) + " |")
    total.append("| kinetic energy (J) | " + " | ".join(_num(float(c["kinetic"].sum()), e_scale) for c in cols) + " |")
    if spins:
        total.append("| rotational energy (J) | " + " | ".join(
            _num(float(c["rotational"].sum()), e_scale) for c in cols) + " |")
    com_v = [(view.mass[:, None] * c["velocity"]).sum(axis=0) / view.mass.sum() for c in cols]
    for k in range(view.dim):
        axis = f" {'xyz'[k]}" if view.dim > 1 else ""
        total.append(f"| centre of mass velocity{axis} (m/s) | " + " | ".join(
            _num(float(v[k]), v_scale) for v in com_v) + " |")
    blocks.append("\n".join(total))
    return "\n\n".join(blocks)
