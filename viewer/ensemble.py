"""Ensembles: a small batch of scenes around the current one, run together with `run_scenes`.

The spread stands for what is uncertain in an experiment: the spring constant (the report
measured k = 1500 +- 30 N/m, i.e. 2 %), the impact parameter (the first body's offset across
the line of approach), or the first body's speed.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from collide.run import run_scenes
from collide.scene import Scene, parse_scene, set_path
from viewer.geometry import embed3


@dataclass(frozen=True)
class EnsembleKind:
    """One way to spread a batch: `default` spread in the kind's unit."""

    label: str
    unit: str
    default: float
    lo: float
    hi: float
    step: float
    needs_plane: bool = False


KINDS = {
    "k": EnsembleKind("contact.k +- % (report: 1500 +- 30 N/m)", "%", 2.0, 0.1, 20.0, 0.1),
    "offset": EnsembleKind("impact offset of the first body +- mm", "mm", 1.0, 0.01, 20.0, 0.01, needs_plane=True),
    "speed": EnsembleKind("speed of the first body +- %", "%", 5.0, 0.1, 50.0, 0.1),
}


def kinds_for(scene: Scene) -> list[str]:
    return [k for k, kind in KINDS.items() if scene.dim > 1 or not kind.needs_plane]


def _across(scene: Scene) -> int:
    """The position component across the line of approach of the first two bodies (2D, 3D)."""
    if len(scene.bodies) < 2:
        return 1
    d = np.abs(np.subtract(scene.bodies[1].position, scene.bodies[0].position))
    order = np.argsort(d)
    return int(order[0]) if order[0] != int(np.argmax(d)) else 1


def ensemble_scenes(scene: Scene, kind: str, spread: float, members: int) -> list[Scene]:
    """`members` copies of `scene` with one quantity spread evenly over +- `spread`."""
    members = max(2, int(members))
    offsets = np.linspace(-spread, spread, members)
    body = scene.bodies[0]
    out = []
    for x in offsets:
        raw = copy.deepcopy(scene.source)
        raw["integrator"], raw["dt"], raw["tol"] = scene.integrator, scene.dt, scene.tol
        if kind == "k":
            set_path(raw, "contact.k", scene.contact.k * (1 + x / 100))
        elif kind == "offset":
            pos = list(body.position)
            pos[_across(scene)] += x / 1000
            set_path(raw, f"body.{body.name}.position", pos)
        elif kind == "speed":
            vel = [c * (1 + x / 100) for c in body.velocity]
            set_path(raw, f"body.{body.name}.velocity", vel if scene.dim > 1 else vel[0])
        else:
            raise ValueError(f"unknown ensemble kind '{kind}' (choose from {', '.join(KINDS)})")
        out.append(parse_scene(raw, scene.name))
    return out


def ensemble_paths(scenes: list[Scene], *, dt: float | str | None = None, tol: float | None = None,
                   points: int = 200) -> tuple[list[np.ndarray], float]:
    """Run the batch; each member's body paths as (N, T, 3), and the batch's wall time."""
    run = run_scenes(scenes, dt=dt, tol=tol, record=True)
    from collide import diagnostics as dg

    paths = []
    for m in range(len(scenes)):
        member = run.result.member(m)
        traj = member.trajectory
        t = np.linspace(float(traj.t[0, 0]), float(traj.t[-1, 0]), points)
        s = dg.sample(member.model, traj, t).s[:, 0]
        paths.append(embed3(s).transpose(1, 0, 2))
    return paths, run.result.wall_time_s
