"""Runs given as frames: what the viewer draws for many bodies without the engine's model.

`FramesRun` holds positions, velocities and orientations of N bodies at F times, and the
contacts as a fixed list of links with a force per frame. It answers the same questions as
`ViewRun` (frames at any time, plots, values, bounds), so the session and the drawer treat both
alike. It serves two purposes: replaying runs the engine cannot produce yet (1 000 spheres: the
benchmark and the many-body drawing tests use `settling_pile`), and, once the compiled engine
lands, a run that is too large to sample exactly at every frame.

Between frames, positions and velocities are interpolated linearly and contacts taken from
the nearest frame: a display approximation, stated in the status line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from collide.model import compile_scenes
from collide.scene import Scene
from viewer.geometry import embed3, orientation_wxyz
from viewer.state import Frame, Links, PlotData, Series, _conserved_series, body_values_arrays


@dataclass
class FramesRun:
    """N bodies at F frames. times (F,) s; positions, velocities (F, N, 3) m, m/s; wxyz (F, N, 4)
    or None; link_i, link_j (K,) body indices (j = -1: a wall) and link_force (F, K) N (0: not
    touching); walls as (point, unit normal) pairs; gravity (3,) m/s² or None."""

    name: str
    dim: int
    names: list[str]
    radius: np.ndarray
    mass: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    wxyz: np.ndarray | None = None
    link_i: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    link_j: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    link_force: np.ndarray | None = None
    walls: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    gravity: np.ndarray | None = None
    origin: str = "frames"

    # What ViewRun has and a frames run does not.
    scene = None
    run = None
    preview = False
    friction = False
    spin_dim = 0
    residuals = {"energy": float("nan"), "momentum": float("nan"), "angular_momentum": float("nan")}
    contact_windows = ()
    paths = None
    path_times = np.zeros(0)

    def __post_init__(self) -> None:
        self.n_bodies = len(self.names)
        self.t0, self.t1 = float(self.times[0]), float(self.times[-1])
        if self.link_force is None:
            self.link_force = np.zeros((len(self.times), len(self.link_i)))
        self.n_walls = len(self.walls)
        self.step_times = self.times
        speed = np.linalg.norm(self.velocities, axis=-1)
        self.max_speed = float(speed.max(initial=0.0))
        self.max_momentum = float((speed * self.mass).max(initial=0.0))
        self.max_body_energy = float((0.5 * self.mass * speed**2).max(initial=0.0))
        self.max_normal_force = float(self.link_force.max(initial=0.0))
        self.max_friction_force = 0.0
        self.max_links = len(self.link_i)
        counts = [self._links(k).counts(self.n_bodies).max(initial=0) for k in range(0, len(self.times),
                                                                                  max(1, len(self.times) // 20))]
        self.max_contacts = int(max(counts, default=0))
        total = self.mass.sum()
        self.com_path = np.einsum("n,fnd->fd", self.mass, self.positions) / total
        self.plots = self._make_plots()

    @property
    def duration(self) -> float:
        return self.t1 - self.t0

    def clamp_time(self, t: float) -> float:
        return min(max(float(t), self.t0), self.t1)

    def in_contact(self, t: float) -> bool:
        return False  # a pile touches all the time: no slow motion

    def next_step(self, t: float, direction: int) -> float:
        """The next or previous stored frame."""
        times = self.times
        tol = 1e-9 * max(self.duration, 1e-300)
        if direction > 0:
            later = times[times > t + tol]
            return float(later[0]) if len(later) else self.t1
        earlier = times[times < t - tol]
        return float(earlier[-1]) if len(earlier) else self.t0

    def _links(self, k: int) -> Links:
        on = self.link_force[k] > 0
        i, j = self.link_i[on], self.link_j[on]
        pos = self.positions[k]
        # The contact point: on the line of centres at body i's radius (at the wall for j = -1).
        other = np.where((j >= 0)[:, None], pos[np.maximum(j, 0)], pos[i])
        d = other - pos[i]
        dist = np.linalg.norm(d, axis=-1, keepdims=True)
        unit = np.divide(d, dist, out=np.zeros_like(d), where=dist > 0)
        point = pos[i] + self.radius[i][:, None] * unit
        if self.walls and np.any(j < 0):
            wall_point, wall_normal = self.walls[0]
            below = j < 0
            height = (pos[i[below]] - wall_point) @ wall_normal
            point[below] = pos[i[below]] - height[:, None] * wall_normal
        return Links(i, j, point, self.link_force[k, on])

    def frame(self, t: float) -> Frame:
        """Bodies at time t: linear between the stored frames; contacts of the nearest frame."""
        t = self.clamp_time(t)
        times = self.times
        k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
        if k + 1 < len(times) and times[k + 1] > times[k]:
            x = (t - times[k]) / (times[k + 1] - times[k])
            pos = (1 - x) * self.positions[k] + x * self.positions[k + 1]
            vel = (1 - x) * self.velocities[k] + x * self.velocities[k + 1]
            nearest = k + 1 if x > 0.5 else k
        else:
            pos, vel, nearest = self.positions[k], self.velocities[k], k
        wxyz = self.wxyz[nearest] if self.wxyz is not None else np.tile([1.0, 0.0, 0.0, 0.0], (self.n_bodies, 1))
        com = self.mass @ pos / self.mass.sum()
        return Frame(t, pos, wxyz, [], vel, com, self._links(nearest))

    def body_values(self, t: float) -> dict[str, np.ndarray]:
        frame = self.frame(t)
        return body_values_arrays(self.mass, np.zeros(self.n_bodies), frame.velocities[:, : self.dim],
                                  np.zeros((self.n_bodies, 0)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box around every body over the run, padded by its radius."""
        r = self.radius[None, :, None]
        lo = (self.positions - r).min(axis=(0, 1))
        hi = (self.positions + r).max(axis=(0, 1))
        return lo, hi

    def contact_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.bounds()

    def status_lines(self) -> list[str]:
        return [f"{self.n_bodies} bodies, {len(self.times)} frames over {self.duration:.4g} s "
                "(drawn between frames by linear interpolation)",
                f"contacts: up to {self.max_contacts} per body, {int((self.link_force > 0).sum(axis=1).max())} "
                "at once"]

    def _make_plots(self) -> PlotData:
        v2 = np.sum(self.velocities**2, axis=-1)
        energy = {"kinetic": 0.5 * v2 @ self.mass}
        if self.gravity is not None:
            energy["gravitational"] = -np.einsum("n,fnd,d->f", self.mass, self.positions, self.gravity)
        energy["total"] = sum(energy.values())
        momentum = {f"p{a}": np.einsum("n,fn->f", self.mass, self.velocities[:, :, c])
                    for c, a in enumerate("xyz"[: self.dim])}
        p_scale = float(np.max(np.linalg.norm(self.velocities, axis=-1) @ self.mass, initial=0.0))
        touching = (self.link_force > 0).sum(axis=1).astype(float)
        e = _conserved_series("energy", "J", energy, float(np.max(np.abs(energy["total"]), initial=0.0)))
        p = _conserved_series("momentum", "kg m/s", momentum, p_scale)
        contacts = Series("contacts", "count", {"touching pairs": touching}, float(touching.max(initial=0.0)))
        plots = PlotData(self.times, e, p, None, None)
        plots.all = [e, p, contacts]
        return plots


class StartFrames(FramesRun):
    """A scene at its start, one frame: what a scene of many bodies shows while its run goes (a
    preview: `scene` is the scene, `run` None until the run is in)."""

    preview = True
    preview_note = "its start: the run follows"

    def status_lines(self) -> list[str]:
        return [f"{self.n_bodies} bodies at the start (t = {self.t0:.4g} s): the run goes in the background "
                "and replaces this when done"]


def start_frames(scene: Scene, kind: type[StartFrames] = StartFrames) -> StartFrames:
    """The scene's bodies where they start, as a one-frame run (O(N): its model and initial
    state, no stepping). A run of a thousand spheres takes seconds to minutes; this is drawn at
    once, so the page shows the scene (and a moved slider its new start) while the run goes."""
    model, state = compile_scenes([scene])
    walls = [(embed3(np.asarray(w.point, float)), embed3(np.asarray(w.normal, float))) for w in scene.walls]
    gravity = None if model.gravity is None else embed3(model.gravity[0])
    wxyz = orientation_wxyz(state.q[0])[None] if model.orient_dim else None
    start = kind(scene.name, model.dim, list(model.body_names), model.radius[0].astype(float),
                 model.mass[0].astype(float), np.array([float(state.t[0])]), embed3(state.s[0])[None],
                 embed3(state.v[0])[None], wxyz, walls=walls, gravity=gravity, origin="the start of the run")
    start.scene = scene
    return start


def _lattice_pairs(rest: np.ndarray, radii: np.ndarray, layer: np.ndarray, row: np.ndarray, col: np.ndarray,
                   side: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j, in row-major order) of the pile's rest lattice closer than 1.1 times their
    radii's sum: only lattice neighbours can be (one row, column or layer apart), so O(n), where
    all pairs' distances took n² memory (80 GB for a hundred thousand spheres)."""
    n = len(rest)
    idx = np.arange(n)
    found_i, found_j = [], []
    for dl in (0, 1):
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dl == 0 and (dr, dc) <= (0, 0):
                    continue  # a pair in one layer once
                r2, c2 = row + dr, col + dc
                j = (layer + dl) * side * side + r2 * side + c2
                ok = (r2 >= 0) & (r2 < side) & (c2 >= 0) & (c2 < side) & (j < n)
                a, b = idx[ok], j[ok]
                close = np.linalg.norm(rest[a] - rest[b], axis=-1) < 1.1 * (radii[a] + radii[b])
                found_i.append(np.minimum(a, b)[close])
                found_j.append(np.maximum(a, b)[close])
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    order = np.lexsort((j, i))
    return i[order], j[order]


def settling_pile(n: int = 1000, *, seed: int = 0, duration: float = 2.0, fps: float = 60.0,
                  radius: float = 0.01) -> FramesRun:
    """A synthetic pile of n spheres settling on a floor (z = 0): a loose lattice of layers in a
    square footprint, each sphere bouncing down to rest with a damped oscillation and a little
    sway, its contacts those of the rest lattice with forces that grow with the weight above.
    Not a simulation: frames for drawing, of the size the compiled engine will produce."""
    rng = np.random.default_rng(seed)
    radii = radius * rng.uniform(0.85, 1.15, n)
    side = int(np.ceil(np.sqrt(n / 4)))
    pitch = 2.04 * radius
    idx = np.arange(n)
    layer, cell = divmod(idx, side * side)
    row, col = divmod(cell, side)
    rest = np.stack(((col - side / 2 + 0.5 * (layer % 2)) * pitch, (row - side / 2 + 0.5 * (layer % 2)) * pitch,
                     radius + layer * 1.45 * radius), axis=-1)
    rest[:, :2] += rng.normal(0, 0.03 * radius, (n, 2))
    rest[layer == 0, 2] = radii[layer == 0]  # the bottom layer rests on the floor
    times = np.arange(0.0, duration + 0.5 / fps, 1.0 / fps)
    t = times[:, None]
    drop = rng.uniform(2, 6, n) * radius
    omega = rng.uniform(12, 20, n)
    tau = rng.uniform(0.15, 0.35, n)
    phase = rng.uniform(0, 0.5, n)
    decay = np.exp(-t / tau)
    wave = np.cos(omega * t + phase)
    z = rest[:, 2] + drop * decay * np.abs(wave)
    dz = drop * decay * np.sign(wave) * (-omega * np.sin(omega * t + phase)) - drop * np.abs(wave) * decay / tau
    sway = 0.4 * radius * decay
    ax, ay = rng.uniform(0, 2 * np.pi, (2, n))
    x = rest[:, 0] + sway * np.cos(ax + 3 * t)
    y = rest[:, 1] + sway * np.sin(ay + 3 * t)
    positions = np.stack((x, y, z), axis=-1)
    velocities = np.stack((-sway * (3 * np.sin(ax + 3 * t) + np.cos(ax + 3 * t) / tau),
                           sway * (3 * np.cos(ay + 3 * t) - np.sin(ay + 3 * t) / tau), dz), axis=-1)
    # Contacts of the rest lattice: pairs within 5 % of touching, and the bottom layer on the floor.
    i, j = _lattice_pairs(rest, radii, layer, row, col, side)
    bottom = np.flatnonzero(layer == 0)
    link_i = np.concatenate((i, bottom))
    link_j = np.concatenate((j, -np.ones(len(bottom), int)))
    mass = 1000.0 * 4 / 3 * np.pi * radii**3
    layers = layer.max() + 1
    weight = mass * 9.81 * (layers - layer)  # roughly what a sphere carries
    base = np.concatenate((0.5 * (weight[i] + weight[j]), weight[bottom] * 1.5))
    # Contact forces in a pile are far from even: a few strong chains carry most of the weight
    # (roughly exponentially distributed).
    base = base * rng.exponential(1.0, len(base))
    settle = 1 - np.exp(-times / 0.25)[:, None]
    flicker = 1 + 0.25 * np.sin(7 * times[:, None] + rng.uniform(0, 2 * np.pi, len(link_i)))
    active = rng.uniform(0, 1, len(link_i)) < 0.8
    link_force = np.where(active, base * settle * flicker, 0.0)
    link_force[times < 0.05] = 0.0
    angle = 20 * t * decay
    wxyz = np.zeros((len(times), n, 4))
    wxyz[..., 0] = np.cos(angle / 2)
    wxyz[..., 1] = np.sin(angle / 2)
    floor = (np.zeros(3), np.array([0.0, 0.0, 1.0]))
    return FramesRun(f"synthetic pile of {n}", 3, [f"s{k + 1}" for k in range(n)], radii, mass, times,
                     positions, velocities, wxyz, link_i, link_j, link_force, [floor], np.array([0.0, 0.0, -9.81]),
                     origin="synthetic frames")
