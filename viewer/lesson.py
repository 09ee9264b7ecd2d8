"""A lesson's pictures (PhET's Collision Lab): the momentum diagram, the energy bars, their values
as CSV, and the scene switches of the Set up folder (motion on a line or in a plane, perfectly
inelastic).

Pure numpy (no viser). Every number comes from the run's own states: momenta and kinetic
energies from the sampled velocities and spins (`ViewRun.body_values`), the springs' energy from
the contacts engaged at that time (`collide.diagnostics.elastic_energy`, as the energy plot),
the dissipated energy from the run's work record; nothing is re-derived from a collision law.
"""

from __future__ import annotations

import copy
import html
import io
import math
from dataclasses import dataclass

import numpy as np

from collide import diagnostics as dg
from collide.scene import Scene, parse_scene
from viewer.colours import body_colour, hex_colour
from viewer.state import ViewRun

SVG_W, SVG_H = 300, 190
MAX_CHAIN = 12  # bodies whose momenta are drawn tip to tail; beyond, the total only


@dataclass
class Moment:
    """The bodies' momenta (N, D) kg m/s and energies (J) at one time."""

    t: float
    momentum: np.ndarray
    kinetic: np.ndarray  # (N,) translational
    rotational: np.ndarray  # (N,)
    elastic: float  # held by the contacts' springs
    dissipated: float  # by dashpots and friction since the start
    gravitational: float | None = None  # potential energy, under gravity

    @property
    def total_momentum(self) -> np.ndarray:
        return self.momentum.sum(axis=0)

    @property
    def total_energy(self) -> float:
        """Kinetic, rotational, elastic and gravitational (what the bodies and springs hold now)."""
        return float(self.kinetic.sum() + self.rotational.sum() + self.elastic + (self.gravitational or 0.0))


def moment(view: ViewRun, t: float) -> Moment:
    """Momenta and energies at time t (clamped to the run)."""
    t = view.clamp_time(t)
    values = view.body_values(t)
    st = view.sample(np.array([t]))
    # collide's own balance at that state: the springs of the contacts engaged, the work done.
    con = dg.conserved(view.model, st.t, st.s, st.v, st.w, st.work)
    dissipated = float(con.dissipated[0, 0]) if con.dissipated is not None else 0.0
    gravitational = float(con.gravitational[0, 0]) if con.gravitational is not None else None
    return Moment(t, values["momentum"], values["kinetic"], values["rotational"], float(con.spring[0, 0]),
                  dissipated, gravitational)


def momentum_scale(view: ViewRun, moments: list[Moment]) -> float:
    """The run's momentum size (the residual's: sum m|v|, largest at the moments)."""
    return float(max(np.sum(np.linalg.norm(m.momentum, axis=-1)) for m in moments)) or 1.0


# ---------------------------------------------------------------------------------------------
# The pictures (SVG in the page)


def _hex(i: int) -> str:
    return hex_colour(body_colour(i))


def _arrow(x0: float, y0: float, x1: float, y1: float, colour: str, width: float = 2.5) -> str:
    length = math.hypot(x1 - x0, y1 - y0)
    if length < 1e-9:
        return f"<circle cx='{x0:.1f}' cy='{y0:.1f}' r='2' fill='{colour}'/>"
    ux, uy = (x1 - x0) / length, (y1 - y0) / length
    head = min(8.0, 0.4 * length)
    hx, hy = x1 - ux * head, y1 - uy * head
    px, py = -uy * head * 0.45, ux * head * 0.45
    return (f"<line x1='{x0:.1f}' y1='{y0:.1f}' x2='{hx:.1f}' y2='{hy:.1f}' stroke='{colour}' "
            f"stroke-width='{width}'/><polygon points='{x1:.1f},{y1:.1f} {hx + px:.1f},{hy + py:.1f} "
            f"{hx - px:.1f},{hy - py:.1f}' fill='{colour}'/>")


def _chain(m: Moment, names: list[str], origin: tuple[float, float], scale: float, dim: int) -> list[str]:
    """Each body's momentum tip to tail from `origin`, then the total from the first tail to
    the last tip (dashed black). 1D: stacked a little below one another to stay apart. Above
    MAX_CHAIN bodies, the total only."""
    out = []
    x, y = origin
    for i, p in enumerate(m.momentum if len(names) <= MAX_CHAIN else []):
        dx = float(p[0]) * scale
        dy = -float(p[1]) * scale if dim > 1 else 0.0
        out.append(_arrow(x, y, x + dx, y + dy, _hex(i)))
        x, y = x + dx, y + dy
        if dim == 1:
            y += 6.0
    tx, ty = m.total_momentum[0] * scale, (-m.total_momentum[1] * scale if dim > 1 else 0.0)
    y_total = origin[1] + (6.0 * len(names) + 4.0 if dim == 1 else 0.0)
    out.append(f"<g stroke-dasharray='5,3'>{_arrow(origin[0], y_total, origin[0] + tx, y_total + ty, '#222', 2)}</g>")
    return out


def momentum_svg(view: ViewRun, before: Moment, now: Moment) -> str:
    """Two panels: before (the start) and now, each body's momentum tip to tail and the total."""
    dim = view.dim
    p_scale = momentum_scale(view, [before, now])
    half = SVG_W / 2
    scale = 0.8 * half / p_scale  # a chain is at most sum |p| long: it fits its panel
    parts = [f"<svg xmlns='http://www.w3.org/2000/svg' width='{SVG_W}' height='{SVG_H}' "
             f"style='background:#fff;font:11px sans-serif'>"]
    for k, (label, m) in enumerate((("before (t = 0)", before), (f"now ({m_ms(now.t)} ms)", now))):
        cx, cy = half * k + half / 2, SVG_H / 2 + (-10 if dim == 1 else 5)
        # Every arrow ends inside its panel: the chain starts left of centre by half the total.
        x0 = cx - 0.5 * float(m.total_momentum[0]) * scale
        y0 = cy + (0.5 * float(m.total_momentum[1]) * scale if dim > 1 else 0.0)
        parts.append(f"<text x='{half * k + 6}' y='14'>{html.escape(label)}</text>")
        parts += _chain(m, view.names, (x0, y0), scale, dim)
        total = " ".join(f"{c:.4g}" for c in m.total_momentum)
        parts.append(f"<text x='{half * k + 6}' y='{SVG_H - 22}'>total (dashed), kg m/s:</text>"
                     f"<text x='{half * k + 6}' y='{SVG_H - 8}'>({total})</text>")
    parts.append(f"<line x1='{half}' y1='4' x2='{half}' y2='{SVG_H - 4}' stroke='#ccc'/></svg>")
    return "".join(parts)


def m_ms(t: float) -> str:
    return f"{t * 1e3:.4g}"


def energy_svg(view: ViewRun, now: Moment) -> str:
    """Bars at the time shown: each body's kinetic (translational + rotational), the springs'
    elastic energy, what damping and friction took, and the total they hold now."""
    rows: list[tuple[str, float, str]] = []
    for i, name in enumerate(view.names[:8]):
        rows.append((f"{name} kinetic", float(now.kinetic[i] + now.rotational[i]), _hex(i)))
    if len(view.names) > 8:
        rows.append((f"{len(view.names) - 8} more kinetic", float(now.kinetic[8:].sum() + now.rotational[8:].sum()),
                     "#888"))
    rows.append(("elastic (springs)", now.elastic, "#2a9d8f"))
    if now.gravitational is not None:
        rows.append(("gravitational", now.gravitational, "#6a4c93"))
    if now.dissipated > 0:
        rows.append(("dissipated", now.dissipated, "#999"))
    rows.append(("total held", now.total_energy, "#222"))
    top = max([v for _, v, _ in rows] + [now.total_energy + now.dissipated, 1e-300])
    bar_h, gap, left = 14, 6, 130
    height = len(rows) * (bar_h + gap) + 26
    parts = [f"<svg xmlns='http://www.w3.org/2000/svg' width='{SVG_W}' height='{height}' "
             f"style='background:#fff;font:11px sans-serif'>",
             f"<text x='4' y='13'>energy at {m_ms(now.t)} ms (J)</text>"]
    for k, (label, value, colour) in enumerate(rows):
        y = 20 + k * (bar_h + gap)
        w = max(0.0, value) / top * (SVG_W - left - 50)
        parts.append(f"<text x='4' y='{y + 11}'>{html.escape(label)}</text>"
                     f"<rect x='{left}' y='{y}' width='{w:.1f}' height='{bar_h}' fill='{colour}'/>"
                     f"<text x='{left + w + 3:.1f}' y='{y + 11}'>{value:.3g}</text>")
    parts.append("</svg>")
    return "".join(parts)


# ---------------------------------------------------------------------------------------------
# The values export


def lesson_csv(view: ViewRun, t: float) -> bytes:
    """The diagram's and the bars' numbers: one row per quantity, body and component, with its
    value before (the start), now (t) and after (the end of the run)."""
    at = [moment(view, view.t0), moment(view, t), moment(view, view.t1)]
    out = io.StringIO()
    out.write(f"# {view.name}: momentum (kg m/s) and energy (J); now = {t!r} s\n")
    out.write("quantity,body,component,before,now,after\n")

    def row(quantity: str, body: str, component: str, values: list[float]) -> None:
        out.write(f"{quantity},{body},{component}," + ",".join(repr(float(v)) for v in values) + "\n")

    axes = "xyz"[: view.dim]
    for i, name in enumerate(view.names):
        for c, a in enumerate(axes):
            row("momentum", name, a, [m.momentum[i, c] for m in at])
        row("kinetic", name, "", [m.kinetic[i] for m in at])
        row("rotational", name, "", [m.rotational[i] for m in at])
    for c, a in enumerate(axes):
        row("momentum", "total", a, [m.total_momentum[c] for m in at])
    row("elastic", "total", "", [m.elastic for m in at])
    if at[0].gravitational is not None:
        row("gravitational", "total", "", [m.gravitational for m in at])
    row("dissipated", "total", "", [m.dissipated for m in at])
    row("energy", "total", "", [m.total_energy for m in at])
    return out.getvalue().encode()


# ---------------------------------------------------------------------------------------------
# Scene switches


def with_dimensions(scene: Scene, dim: int) -> Scene:
    """The same scene with its motion confined to a line (dim 1: the x components, no spin) or
    a plane (dim 2: x and y, spin about z), or opened to space (dim 3). Raises SceneError when
    the result cannot run (e.g. two balls that overlap once their y offsets are dropped)."""
    if dim not in (1, 2, 3):
        raise ValueError(f"dimensions: 1, 2 or 3, not {dim}")
    raw = copy.deepcopy(scene.source)
    old = scene.dim
    raw["dim"] = dim

    def fit(value: object) -> object:
        vec = [float(x) for x in (value if isinstance(value, list) else [value])]
        vec = (vec + [0.0] * 3)[:dim]
        return vec[0] if dim == 1 else vec

    for body in raw.get("body", []):
        for key in ("position", "velocity"):
            if key in body:
                body[key] = fit(body[key])
        spin = body.pop("spin", None)
        if dim == 2 and spin is not None:
            body["spin"] = float(spin[-1]) if isinstance(spin, list) else float(spin)
        elif dim == 3 and spin is not None:
            body["spin"] = [0.0, 0.0, float(spin)] if old == 2 and not isinstance(spin, list) else spin
    for wall in raw.get("wall", []):
        for key in ("point", "normal"):
            wall[key] = fit(wall[key])
    if "gravity" in raw:
        raw["gravity"] = list(fit(raw["gravity"])) if dim > 1 else [fit(raw["gravity"])]
    if dim == 1:
        raw.pop("domain", None)
    return parse_scene(raw, scene.name)


def with_restitution(scene: Scene, e: float) -> Scene:
    """The scene with every restitution (the contact's, the materials' and the pairs') set to e;
    e = 0 is perfectly inelastic (a critically damped dashpot: a head-on pair ends moving
    together, docs/viewer.md)."""
    raw = copy.deepcopy(scene.source)
    raw.setdefault("contact", {})["restitution"] = e
    for table in raw.get("material", []) + raw.get("pair", []):
        if "restitution" in table:
            table["restitution"] = e
    if e < 1.0 and raw.get("integrator") not in (None, "dem"):
        raw["integrator"] = "dem"
        raw["dt"] = "auto"
        raw["tol"] = max(float(raw.get("tol", 1e-3)), 1e-3)
    if e == 0.0 and scene.duration is None and scene.rest is None:
        raw["duration"] = sticky_duration(scene)  # the contact never ends by itself
    return parse_scene(raw, scene.name)


STICKY_CONTACT_TIMES = 15  # after the first contact: the relative velocity is down by (1 + 47) e^-47


def sticky_duration(scene: Scene) -> float:
    """How long to run a perfectly inelastic scene: until STICKY_CONTACT_TIMES contact times
    after the first meeting (the critically damped relative velocity then below 1e-18 of its
    start), then as long again as the approach took, to see the bodies move on together."""
    from collide.dem import contact_time
    from collide.model import compile_scenes
    from viewer.params import approach_time

    model, state = compile_scenes([scene])
    t_c = float(contact_time(model, state)[0][0])
    approach = approach_time(scene) or 0.0
    return 2.0 * approach + STICKY_CONTACT_TIMES * t_c


def common_velocity(masses: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """(sum m v) / (sum m): where perfectly inelastic bodies end, together."""
    m = np.asarray(masses, float)
    return (m[:, None] * np.asarray(velocities, float)).sum(axis=0) / m.sum()
