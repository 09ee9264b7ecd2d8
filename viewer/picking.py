"""A sphere picked with the mouse: which one the click's ray hits, and what it is doing now.

Pure numpy (no viser). The browser sends the click as a ray (origin, direction) in world
coordinates; `pick_sphere` intersects it with every sphere shown (the drawing's own positions),
whatever way they are drawn. `sphere_report` reads the picked sphere's values at a time: its
state from the run's samples, its contacts and their forces from the engine's records
(`collide.contact_index.ContactIndex`, `collide.contact_forces`): nothing here evaluates a law.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from viewer.geometry import embed3
from viewer.state import ROUND_OFF, Frame, ViewRun


def pick_sphere(origin: np.ndarray, direction: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                hidden: np.ndarray | None = None) -> int | None:
    """The index of the nearest sphere (centres (N, 3), radii (N,)) that the ray from `origin`
    along `direction` enters in front of the origin, skipping `hidden` (N,) ones; None if it
    misses them all. A sphere the origin is inside counts, at distance 0."""
    o = np.asarray(origin, float)
    d = np.asarray(direction, float)
    norm = float(np.linalg.norm(d))
    if not norm > 0 or not len(centres):
        return None
    d = d / norm
    rel = np.asarray(centres, float) - o
    along = rel @ d  # distance to the point of the ray nearest each centre
    miss2 = np.sum(rel * rel, axis=-1) - along**2
    r2 = np.asarray(radii, float) ** 2
    hit = miss2 <= r2
    half = np.sqrt(np.maximum(r2 - miss2, 0.0))
    near, far = along - half, along + half
    hit &= far >= 0  # not wholly behind the origin
    if hidden is not None:
        hit &= ~np.asarray(hidden, bool)
    if not hit.any():
        return None
    entry = np.where(near > 0, near, 0.0)
    candidates = np.flatnonzero(hit)
    return int(candidates[np.argmin(entry[candidates])])


@dataclass
class ContactRow:
    """One contact of the picked sphere: the other side's name, overlap (m), the engine's normal
    force (N, positive pushes apart) and friction force's magnitude (N, None without friction)."""

    other: str
    overlap: float
    normal: float
    tangential: float | None


@dataclass
class SphereReport:
    """The picked sphere at time t (SI units)."""

    index: int
    name: str
    t: float
    position: np.ndarray
    velocity: np.ndarray
    spin: np.ndarray
    radius: float
    mass: float
    contacts: list[ContactRow]
    net_contact_force: np.ndarray  # the sum of its contacts' forces on it (3,)
    weight: float  # m |g|


def sphere_report(view: ViewRun, t: float, k: int) -> SphereReport:
    """Body k's values and contacts at time t (clamped to the run)."""
    t = view.clamp_time(t)
    times = np.array([t])
    st = view.sample(times)
    contacts = view._contacts  # the run's contacts indexed for lookups at any time
    e = contacts.at(times, st.s[:, 0])
    force = np.linalg.norm(e.normal_force, axis=-1)
    # As `ViewRun.frame` counts contacts: round-off touches are not contacts.
    e = e.select(((e.overlap > ROUND_OFF * float(view.radius.max())) | (force > ROUND_OFF * view.max_normal_force))
                 & ((e.i == k) | (e.j == k)))
    rows = []
    net = np.zeros(3)
    normal_values = contacts.forces.normal(e.ck, times[e.tk])
    for m in range(len(e.ck)):
        i, j = int(e.i[m]), int(e.j[m])
        sign = 1.0 if i == k else -1.0  # the records' forces act on body i; on j, the reaction
        other = i if j == k else j
        name = view.names[other] if other >= 0 else f"wall {-1 - other}"
        fn = embed3(e.normal_force[m]) * sign
        ft = None if e.friction_force is None else embed3(e.friction_force[m]) * sign
        net += fn + (ft if ft is not None else 0.0)
        rows.append(ContactRow(name, float(e.overlap[m]), float(normal_values[m]),
                               None if ft is None else float(np.linalg.norm(ft))))
    rows.sort(key=lambda r: -r.normal)
    spin = st.w[0, 0, k] if st.w.shape[-1] else np.zeros(0)
    gravity = np.asarray(view.scene.gravity, float) if view.scene.gravity is not None else np.zeros(1)
    return SphereReport(k, view.names[k], t, embed3(st.s[0, 0, k]), embed3(st.v[0, 0, k]), np.asarray(spin, float),
                        float(view.radius[k]), float(view.mass[k]), rows, net,
                        float(view.mass[k] * np.linalg.norm(gravity)))


def frame_report(view: Any, frame: Frame, k: int) -> SphereReport:
    """Body k's values from a replayed frame alone (a run given as frames: no engine records
    behind it, so its contacts' normal forces as the frames give them, no friction or spin)."""
    links = frame.contact_links()
    mine = (links.i == k) | (links.j == k)
    rows = []
    for i, j, force in zip(links.i[mine], links.j[mine], links.force[mine]):
        other = int(j if i == k else i)
        rows.append(ContactRow(view.names[other] if other >= 0 else "wall", float("nan"), float(force), None))
    rows.sort(key=lambda r: -r.normal)
    velocity = frame.velocities[k] if frame.velocities is not None else np.zeros(3)
    return SphereReport(k, view.names[k], frame.t, frame.positions[k], velocity, np.zeros(0), float(view.radius[k]),
                        float(view.mass[k]), rows, np.full(3, np.nan), 0.0)


def _vec(x: np.ndarray, scale: float = 1.0, digits: int = 4) -> str:
    return "(" + ", ".join(f"{v * scale:.{digits}g}" for v in np.ravel(x)) + ")"


def report_markdown(r: SphereReport, max_rows: int = 12) -> str:
    """The report as markdown for the panel."""
    speed = float(np.linalg.norm(r.velocity))
    lines = [f"**{r.name}** (body {r.index}) at {r.t * 1e3:.4g} ms", "",
             "| | |", "|---|--:|",
             f"| position (mm) | {_vec(r.position, 1e3)} |",
             f"| velocity (m/s) | {_vec(r.velocity)} |",
             f"| speed (m/s) | {speed:.4g} |"]
    if len(r.spin):
        lines.append(f"| spin (rad/s) | {_vec(r.spin)} |")
    lines += [f"| radius (mm) | {r.radius * 1e3:.4g} |",
              f"| mass (g) | {r.mass * 1e3:.4g} |",
              f"| contacts | {len(r.contacts)} |"]
    if np.all(np.isfinite(r.net_contact_force)):
        lines.append(f"| sum of contact forces (N) | {_vec(r.net_contact_force)} |")
    if r.weight > 0:
        lines.append(f"| its weight m g (N) | {r.weight:.4g} |")
    if r.contacts:
        tangential = r.contacts[0].tangential is not None
        lines += ["", "| contact with | overlap (µm) | F_n (N) |" + (" abs F_t (N) |" if tangential else ""),
                  "|---|--:|--:|" + ("--:|" if tangential else "")]
        for c in r.contacts[:max_rows]:
            overlap = f"{c.overlap * 1e6:.3g}" if np.isfinite(c.overlap) else "–"
            row = f"| {c.other} | {overlap} | {c.normal:.4g} |"
            if tangential:
                row += f" {c.tangential:.4g} |"
            lines.append(row)
        if len(r.contacts) > max_rows:
            lines.append(f"*(the {max_rows} strongest of {len(r.contacts)})*")
    return "\n".join(lines)
