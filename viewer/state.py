"""What the viewer shows for one run: frames at any time, plot series, residuals, paths.

`ViewRun` wraps a `SceneRun` (fresh from the stepper or read back from a recording) and
answers everything the drawing layer asks, without viser: `frame(t)` gives body positions,
orientations and active contacts (point, normal and friction force, compression); `plots`
gives the energy, momentum, angular momentum and compression series on a time grid that
resolves the contacts; `residuals` and `status_lines()` give the numbers shown beside them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from collide import diagnostics as dg
from collide.engine import kernels as kn
from collide.model import State
from collide.run import SceneRun
from collide.stepper import Trajectory
from viewer.geometry import embed3, orientation_wxyz

MAX_PLOT_POINTS = 400
MAX_PATH_POINTS = 400


@dataclass
class ContactFrame:
    """One active contact at one instant. Forces act on body `i` (the first body); body `j` is
    None for a wall. `normal` is the unit vector from body i towards the other side."""

    name: str
    i: int
    j: int | None
    point: np.ndarray
    normal: np.ndarray
    normal_force: np.ndarray
    friction_force: np.ndarray | None
    overlap: float
    compression: tuple[float, float]


@dataclass
class Frame:
    """The scene at time t: positions (N, 3) m, orientations (N, 4) wxyz, active contacts."""

    t: float
    positions: np.ndarray
    wxyz: np.ndarray
    contacts: list[ContactFrame]


@dataclass
class Series:
    """A named plot: x = time (s), one y array per line, with units for the axis."""

    title: str
    unit: str
    lines: dict[str, np.ndarray]


@dataclass
class PlotData:
    times: np.ndarray
    energy: Series
    momentum: Series
    angular_momentum: Series | None
    compression: Series | None
    all: list[Series] = field(default_factory=list)


def plot_times(traj: Trajectory, max_points: int = MAX_PLOT_POINTS) -> np.ndarray:
    """A time grid with half its points spread evenly over the run and half over the contact
    steps, so both the approach and the millisecond-long contact are resolved."""
    t = traj.t[:, 0]
    t0, t1 = float(t[0]), float(t[-1])
    even = np.linspace(t0, t1, max_points // 2) if t1 > t0 else np.array([t0])
    steps = np.flatnonzero(~traj.free[1:, 0]) + 1
    contact_t = np.union1d(t[steps], t[steps - 1]) if len(steps) else np.empty(0)
    if len(contact_t) > max_points // 2:
        contact_t = contact_t[np.linspace(0, len(contact_t) - 1, max_points // 2).round().astype(int)]
    return np.union1d(even, contact_t)


def _subsample(times: np.ndarray, n: int) -> np.ndarray:
    if len(times) <= n:
        return times
    return times[np.linspace(0, len(times) - 1, n).round().astype(int)]


class ViewRun:
    """A run prepared for display (member 0 of the run's batch)."""

    def __init__(self, run: SceneRun, *, origin: str = "", preview: bool = False) -> None:
        self.run = run.member(0) if run.result.batch_size > 1 else run
        self.scene = self.run.scene
        self.origin = origin
        self.preview = preview
        result = self.run.result
        if result.trajectory is None:
            raise ValueError("the run has no trajectory (run it with record=True)")
        self.result = result
        self.model = result.model
        self.traj = result.trajectory
        self.dim = self.model.dim
        self.n_bodies = self.model.n_bodies
        self.names = list(self.model.body_names)
        self.radius = self.model.radius[0].astype(float)
        t = self.traj.t[:, 0]
        self.t0, self.t1 = float(t[0]), float(t[-1])
        self.times = plot_times(self.traj)
        states = self.sample(self.times)
        self._plot_states = states
        self.plots = self._make_plots(states)
        path_t = _subsample(self.times, MAX_PATH_POINTS)
        self.path_times = path_t
        self.paths = embed3(self.sample(path_t).s[:, 0]).transpose(1, 0, 2)
        res = dg.residuals(result)
        self.residuals = {"energy": float(res.energy[0]), "momentum": float(res.momentum[0]),
                          "angular_momentum": float(res.angular_momentum[0])}
        series = dg.contact_series(self.model, self.traj, self.times, states)
        self.max_normal_force = float(np.max(np.linalg.norm(series.normal_force, axis=-1), initial=0.0))
        records = self.traj.records
        if self.model.friction and len(records):
            force = records[:, kn.R_FX:kn.R_FX + 3]
            self.max_friction_force = float(np.max(np.linalg.norm(force, axis=-1), initial=0.0))
        else:
            self.max_friction_force = 0.0
        self.contact_windows = self._contact_windows()

    # ------------------------------------------------------------------------------------------
    # Sampling

    def sample(self, times: np.ndarray) -> State:
        """States at these times (T, 1, N, D): exact in free flight, quintic inside contact steps
        (`diagnostics.sample`)."""
        return dg.sample(self.model, self.traj, np.asarray(times, dtype=float))

    # ------------------------------------------------------------------------------------------
    # Frames

    def clamp_time(self, t: float) -> float:
        return min(max(float(t), self.t0), self.t1)

    def in_contact(self, t: float) -> bool:
        return any(a <= t <= b for a, b in self.contact_windows)

    def frame(self, t: float) -> Frame:
        """Bodies and active contacts at time t (clamped to the run)."""
        t = self.clamp_time(t)
        times = np.array([t])
        st = self.sample(times)
        positions = embed3(st.s[0, 0])
        wxyz = orientation_wxyz(st.q[0, 0])
        series = dg.contact_series(self.model, self.traj, times, st)
        contacts = []
        for c, name in enumerate(series.names):
            overlap = float(series.overlap[0, 0, c])
            if overlap <= 0.0:
                continue
            i, j = (int(x) for x in series.pairs[c])
            if j >= 0:
                d = positions[j] - positions[i]
                normal = d / np.linalg.norm(d)
            else:
                normal = -embed3(self.model.wall_normal[-1 - j])
                j = None
            friction = None
            if series.friction_force is not None:
                friction = embed3(series.friction_force[0, 0, c])
            comp = series.compression[0, 0, c]
            contacts.append(ContactFrame(name, i, j, embed3(series.point[0, 0, c]), normal,
                                         embed3(series.normal_force[0, 0, c]), friction, overlap,
                                         (float(comp[0]), float(comp[1]))))
        return Frame(t, positions, wxyz, contacts)

    # ------------------------------------------------------------------------------------------
    # Plots

    def _make_plots(self, states: State) -> PlotData:
        series = dg.contact_series(self.model, self.traj, self.times, states)
        con = dg.conserved(self.model, states.t, states.s, states.v, states.w, states.work, series.pairs)
        energy = {"kinetic": con.kinetic[:, 0]}
        if con.rotational is not None:
            energy["rotational"] = con.rotational[:, 0]
        energy["spring"] = con.spring[:, 0]
        if con.gravitational is not None:
            energy["gravitational"] = con.gravitational[:, 0]
        energy["total"] = con.total[:, 0]
        if con.dissipated is not None:
            energy["dissipated"] = con.dissipated[:, 0]
            energy["total + dissipated"] = con.balance[:, 0]
        axes = "xyz"[: self.dim]
        momentum = {f"p{a}": con.momentum[:, 0, k] for k, a in enumerate(axes)}
        angular = None
        if con.angular_momentum is not None:
            # Inside a contact step, straight between the steps' own values: interpolated spins
            # and velocities need not balance there when friction changes within the step.
            rows = dg.trajectory_conserved(self.model, self.traj).angular_momentum[:, 0]
            t = self.traj.t[:, 0]
            k = np.clip(np.searchsorted(t, self.times, side="right") - 1, 0, max(len(t) - 2, 0))
            inside = ~self.traj.free[np.minimum(k + 1, len(t) - 1), 0] & (self.times > t[k])
            values = con.angular_momentum[:, 0].copy()
            for c in range(values.shape[-1]):
                values[inside, c] = np.interp(self.times[inside], t, rows[:, c])
            comps = ("z",) if values.shape[-1] == 1 else ("x", "y", "z")
            angular = Series("angular momentum", "kg m^2/s", {f"L{a}": values[:, c] for c, a in enumerate(comps)})
        compression = {}
        for c, name in enumerate(series.names):
            comp = series.compression[:, 0, c, 0]
            if np.any(comp > 0):
                compression[name] = comp * 1e3
        plots = PlotData(self.times, Series("energy", "J", energy), Series("momentum", "kg m/s", momentum),
                         angular, Series("compression", "mm", compression) if compression else None)
        plots.all = [s for s in (plots.energy, plots.momentum, plots.angular_momentum, plots.compression)
                     if s is not None]
        return plots

    # ------------------------------------------------------------------------------------------
    # Summary

    def _contact_windows(self) -> list[tuple[float, float]]:
        t = self.traj.t[:, 0]
        contact = ~self.traj.free[1:, 0]
        windows = []
        start = None
        for k, on in enumerate(contact):
            if on and start is None:
                start = float(t[k])
            if not on and start is not None:
                windows.append((start, float(t[k])))
                start = None
        if start is not None:
            windows.append((start, float(t[-1])))
        return windows

    @property
    def duration(self) -> float:
        return self.t1 - self.t0

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box around every body's path, padded by its radius (m, 3D)."""
        r = self.radius[:, None, None]
        lo = (self.paths - r).min(axis=(0, 1))
        hi = (self.paths + r).max(axis=(0, 1))
        if self.dim < 3:
            lo[2], hi[2] = -float(self.radius.max()), float(self.radius.max())
        return lo, hi

    def contact_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box around the bodies while they touch (the first contact), padded by three radii;
        the whole run's box when nothing touches."""
        if not self.contact_windows:
            return self.bounds()
        a, b = self.contact_windows[0]
        pad = 0.25 * (b - a)
        t = np.linspace(max(self.t0, a - pad), min(self.t1, b + pad), 50)
        s = embed3(self.sample(t).s[:, 0])
        r = float(self.radius.max())
        lo, hi = s.min(axis=(0, 1)) - 2.5 * r, s.max(axis=(0, 1)) + 2.5 * r
        if self.dim < 3:
            lo[2], hi[2] = -r, r
        return lo, hi

    def status_lines(self) -> list[str]:
        """The run in three lines: settings and cost, residuals, contact."""
        r = self.result
        dt = float(r.dt[0])
        auto = " (auto)" if (self.run.dt_request == "auto" or
                             (self.run.dt_request is None and self.scene.dt == "auto")) else ""
        lines = [f"{r.integrator}, dt {dt:.3g} s{auto}, {int(r.steps[0])} steps, "
                 f"{self.duration:.4g} s simulated in {r.wall_time_s * 1e3:.4g} ms wall"]
        lines.append("residuals: " + ", ".join(f"{label} {format_residual(self.residuals[key])}"
                                               for key, label in (("energy", "energy"), ("momentum", "momentum"),
                                                                  ("angular_momentum", "angular momentum"))))
        log = r.contacts
        if int(log.count[0]):
            lines.append(f"contact: {int(log.count[0])}, {float(log.duration[0]) * 1e3:.4g} ms, "
                         f"max overlap {float(log.max_overlap[0]) * 1e3:.4g} mm")
        else:
            lines.append("contact: none")
        return lines


def format_residual(x: float) -> str:
    """A residual as shown: 'n/a' where it does not apply (NaN)."""
    return "n/a" if not math.isfinite(x) else f"{x:.2e}"
