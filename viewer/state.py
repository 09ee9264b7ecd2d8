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
from collide.contact_forces import peak_normal_force
from collide.contact_index import SLICE, ContactIndex
from collide.engine import layout
from collide.model import State
from collide.periodic import nearest_image, wrap
from collide.run import SceneRun
from collide.trajectory import Knots
from viewer.geometry import embed3, orientation_wxyz

MAX_PLOT_POINTS = 400
MIN_PLOT_POINTS = 120  # many bodies: the plots' points fall as 1/N to this (each costs N samples)
MAX_PATH_POINTS = 400
ROUND_OFF = 1e-12  # relative: overlaps and spreads below this are float64 round-off, not physics
FLAT = 1e-9  # relative spread below which a conserved line is drawn flat (round-off accumulates)
MAX_COMPRESSION_LINES = 6
CONTACT_LIST_BODIES = 200  # above this, a frame's contacts are arrays only (Frame.links); no paths kept
# A run is prepared a block of plot times at a time, at most this many body states at once:
# 120 times of 100 000 bodies held whole were 1.2 GB, and their contacts as many entries again.
SAMPLE_BODY_TIMES = 1 << 19
# Engaged (time, contact) entries kept for the compression plot's per-contact lines; a run with
# more (a bed of 100 000 spheres: 300 000 contacts at each of 120 times) plots the largest
# compression over all its contacts instead.
COMPRESSION_ENTRIES = 1 << 22


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
class Links:
    """Active contacts as arrays (for many bodies): body i (K,), the other body j (K,; -1 for a
    wall), the contact point (K, 3) m and the normal force's magnitude (K,) N."""

    i: np.ndarray
    j: np.ndarray
    point: np.ndarray
    force: np.ndarray

    @staticmethod
    def empty() -> Links:
        return Links(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)), np.zeros(0))

    def counts(self, n: int) -> np.ndarray:
        """Active contacts per body (n,)."""
        both = np.concatenate((self.i, self.j[self.j >= 0]))
        return np.bincount(both, minlength=n)[:n]


@dataclass
class Frame:
    """The scene at time t: positions (N, 3) m, orientations (N, 4) wxyz, velocities (N, 3)
    m/s, active contacts, and the centre of mass (3,) m."""

    t: float
    positions: np.ndarray
    wxyz: np.ndarray
    contacts: list[ContactFrame]
    velocities: np.ndarray | None = None
    com: np.ndarray | None = None
    links: Links | None = None

    def contact_links(self) -> Links:
        """The contacts as `Links` (built from `contacts` when not given)."""
        if self.links is not None:
            return self.links
        if not self.contacts:
            return Links.empty()
        return Links(np.array([c.i for c in self.contacts]),
                     np.array([-1 if c.j is None else c.j for c in self.contacts]),
                     np.array([c.point for c in self.contacts]),
                     np.array([float(np.linalg.norm(c.normal_force)) for c in self.contacts]))


@dataclass
class Series:
    """A named plot: x = time (s), one y array per line, with units for the axis.

    `scale` is the quantity's natural size in its unit (the run's energy, sum m|v|, sum |s x m
    v| + I|w|): the plot's axis is chosen from it, and `flat` names the lines that are constant
    to round-off against it (drawn flat, not magnified into noise)."""

    title: str
    unit: str
    lines: dict[str, np.ndarray]
    scale: float = 0.0
    flat: tuple[str, ...] = ()


@dataclass
class PlotData:
    times: np.ndarray
    energy: Series
    momentum: Series
    angular_momentum: Series | None
    compression: Series | None
    all: list[Series] = field(default_factory=list)


def plot_times(t: np.ndarray, free: np.ndarray, max_points: int = MAX_PLOT_POINTS) -> np.ndarray:
    """A time grid with half its points spread evenly over the run and half over the contact
    steps, so both the approach and the millisecond-long contact are resolved. t (S,) are the
    knot times, free (S,) whether the segment ending at each was free flight for every body."""
    t0, t1 = float(t[0]), float(t[-1])
    even = np.linspace(t0, t1, max_points // 2) if t1 > t0 else np.array([t0])
    steps = np.flatnonzero(~free[1:]) + 1
    contact_t = np.union1d(t[steps], t[steps - 1]) if len(steps) else np.empty(0)
    if len(contact_t) > max_points // 2:
        contact_t = contact_t[np.linspace(0, len(contact_t) - 1, max_points // 2).round().astype(int)]
    return np.union1d(even, contact_t)


def plot_points(n_bodies: int) -> int:
    """How many times the plots are sampled at: MAX_PLOT_POINTS up to CONTACT_LIST_BODIES bodies,
    then fewer as the bodies grow (the work is bodies x points), down to MIN_PLOT_POINTS."""
    if n_bodies <= CONTACT_LIST_BODIES:
        return MAX_PLOT_POINTS
    return max(MIN_PLOT_POINTS, MAX_PLOT_POINTS * CONTACT_LIST_BODIES // n_bodies)


def _subsample(times: np.ndarray, n: int) -> np.ndarray:
    if len(times) <= n:
        return times
    return times[np.linspace(0, len(times) - 1, n).round().astype(int)]


@dataclass
class _Swept:
    """What one pass over a run's plot times gathers (`ViewRun._sweep`)."""

    conserved: dg.Conserved
    p_scale: np.ndarray  # (T,) sum of m |v|
    arm: np.ndarray | None  # (T,) the angular momentum's natural size
    paths: np.ndarray | None  # (T_p, N, 3) at the path times (a few bodies only)
    com_path: np.ndarray  # (T_p, 3)
    box: tuple[np.ndarray, np.ndarray]  # around every body at the path times, padded by its radius
    max_speed: float
    max_momentum: float
    max_body_energy: float
    max_contacts: int
    max_links: int
    peak: np.ndarray  # (C,) each contact's largest compression, mm
    most: np.ndarray  # (T,) the largest compression of any contact at each time, mm
    entries: tuple[np.ndarray, np.ndarray, np.ndarray] | None  # (tk, ck, compression mm), if few enough
    end_values: dict[float, dict[str, np.ndarray]]


def _joined(parts: list[dg.Conserved]) -> dg.Conserved:
    """Per-time totals computed a block of times at a time, as one."""
    fields = [getattr(parts[0], f) for f in dg.Conserved.__dataclass_fields__]
    return dg.Conserved(*(None if first is None else np.concatenate([getattr(p, f) for p in parts])
                          for f, first in zip(dg.Conserved.__dataclass_fields__, fields)))


# What the status says while a run's error is measured (viewer.live shows the run first).
MEASURING = "pending, being measured (the run again at a tenth of the tolerance)"

class ViewRun:
    """A run prepared for display (member 0 of the run's batch)."""

    def __init__(self, run: SceneRun, *, origin: str = "", preview: bool = False, measuring: bool = False) -> None:
        self.run = run.member(0) if run.result.batch_size > 1 else run
        self.scene = self.run.scene
        self.origin = origin
        self.preview = preview
        self.measuring = measuring  # the run's own, its error being measured (viewer.live)
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
        self.mass = self.model.mass[0].astype(float)
        self.spin_dim = self.model.spin_dim
        self.friction = bool(self.model.friction)
        self.n_walls = self.model.n_walls
        # Sampling and contacts indexed once: nothing below is dense in bodies x knots or in
        # contacts x times (a 1 000-sphere gas: 70 000 knot times, 7 700 contacts).
        self._knots = Knots(self.model, self.traj)
        self._contacts = ContactIndex(self.model, self.traj, self._knots)
        t = self.traj.knot_times
        self.t0, self.t1 = float(t[0]), float(t[-1])
        self._free = ~self._knots.stepped(t)
        self.times = plot_times(t, self._free, plot_points(self.n_bodies))
        path_k = _subsample(np.arange(len(self.times)), MAX_PATH_POINTS)
        self.path_times = self.times[path_k]
        swept = self._sweep(path_k)
        self.plots = self._make_plots(swept)
        # Each body's path (trails: a few bodies); many bodies keep the box they sweep only.
        self.paths = None if swept.paths is None else swept.paths.transpose(1, 0, 2)
        self._box = swept.box
        self.com_path = swept.com_path
        self.walls = [(embed3(np.asarray(w.point, float)), embed3(np.asarray(w.normal, float)))
                      for w in self.scene.walls]
        # The arrows' scales: the fastest on the plot grid or at any knot (free flight's speed
        # is largest at its ends), so that no velocity arrow is longer than the legend says.
        knots = self.traj.knots
        at_knots = np.linalg.norm(knots[:, layout.K_V:layout.K_V + 3], axis=-1)
        body = knots[:, layout.K_BODY].astype(np.int64)
        self.max_speed = float(max(swept.max_speed, np.max(at_knots, initial=0.0)))
        self.max_momentum = float(max(swept.max_momentum, np.max(at_knots * self.mass[body], initial=0.0)))
        self.max_body_energy = swept.max_body_energy
        res = dg.residuals(result)
        self.residuals = {"energy": float(res.energy[0]), "momentum": float(res.momentum[0]),
                          "angular_momentum": float(res.angular_momentum[0])}
        # The run's peak as the engine has it (the JSON summary's max_normal_force): the legend
        # and the arrows' scale; no force drawn exceeds it.
        self.max_normal_force = peak_normal_force(result, self._contacts.forces)
        self.max_contacts, self.max_links = swept.max_contacts, swept.max_links
        records = self.traj.records
        if self.model.friction and len(records):
            force = records[:, layout.R_FX:layout.R_FX + self.dim]
            self.max_friction_force = float(np.max(np.linalg.norm(force, axis=-1), initial=0.0))
        else:
            self.max_friction_force = 0.0
        self.contact_windows = self._contact_windows()
        # Every contact step's start and end: what "one contact step" moves between.
        on = ~self._free[1:] & (t[1:] > t[:-1])
        self.step_times = np.union1d(t[:-1][on], t[1:][on])
        # The values at the run's ends (the table's before and after, asked at every draw): the
        # plot grid's first and last rows.
        self._end_values = swept.end_values

    # ------------------------------------------------------------------------------------------
    # A periodic box (docs/design.md section 10): bodies drawn wrapped into it, with a copy across
    # each side their sphere crosses

    def _wrapped(self, s: np.ndarray) -> np.ndarray:
        """Positions (..., 3) wrapped into the periodic box (unchanged without one)."""
        if not self.model.periodic:
            return s
        return wrap(s, np.array(self.model.box_lower), np.array(self.model.period))[0]

    def images(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The copies to draw of the spheres that cross a periodic side: (body (M,), centre
        (M, 3)), the copy on the other side of each side crossed (at a corner, each combination)."""
        n = len(positions)
        body, points = np.arange(n), np.asarray(positions, float)
        for d, period in enumerate(self.model.period):
            if period <= 0.0:
                continue
            lo, r = self.model.box_lower[d], self.radius[body]
            low, high = points[:, d] - lo < r, lo + period - points[:, d] < r
            shift = np.eye(3)[d] * period
            points = np.concatenate((points, points[low] + shift, points[high] - shift))
            body = np.concatenate((body, body[low], body[high]))
        return body[n:], points[n:]

    def trail_breaks(self, segments: np.ndarray) -> np.ndarray:
        """Trail segments (K, 2, 3) without those that jump across the periodic box (a wrap)."""
        if not self.model.periodic:
            return segments
        half = 0.5 * np.where(np.array(self.model.period) > 0.0, self.model.period, np.inf)
        return segments[~(np.abs(segments[:, 1] - segments[:, 0]) > half).any(axis=1)]

    # ------------------------------------------------------------------------------------------
    # Sampling

    def sample(self, times: np.ndarray) -> State:
        """States at these times (T, 1, N, D): exact in free flight, quintic inside contact steps
        (`collide.trajectory.Knots`: all bodies at once)."""
        return self._knots.sample(np.asarray(times, dtype=float))

    def _chunks(self, times: np.ndarray):  # noqa: ANN202 - a generator of (slice, State)
        """States at `times` a block of times at a time (at most SAMPLE_BODY_TIMES body states)."""
        rows = max(1, SAMPLE_BODY_TIMES // max(self.n_bodies, 1))
        for a in range(0, len(times), rows):
            part = slice(a, min(a + rows, len(times)))
            yield part, self.sample(times[part])

    def _sweep(self, path_k: np.ndarray) -> _Swept:
        """One pass over the plot times, a block at a time: the plots' totals, the paths (a few
        bodies) or the box the bodies sweep, the largest speed, energy and contact counts, and
        the contacts' compression; memory bounded by the block, not by bodies x times."""
        times, n = self.times, self.n_bodies
        n_t, inertia = len(times), self.model.inertia[0]
        is_path = np.zeros(n_t, bool)
        is_path[path_k] = True
        parts, arms, paths, coms = [], [], [], []
        spring, p_scale, most = np.zeros(n_t), np.zeros(n_t), np.zeros(n_t)
        peak = np.zeros(len(self._contacts))
        entries: list | None = []
        kept = 0
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        speed_max = momentum_max = energy_max = 0.0
        contacts_max = links_max = 0
        ends: dict[float, dict[str, np.ndarray]] = {}
        touch = ROUND_OFF * float(self.radius.max())
        for part, st in self._chunks(times):
            s, v, w = st.s[:, 0], st.v[:, 0], st.w[:, 0]
            tk, ck, overlap = self._contacts.overlaps(times[part], s)
            rows = part.stop - part.start
            for a in range(0, len(tk), SLICE):  # in slices: the law's temporaries, a million entries
                cut = slice(a, a + SLICE)
                held = dg.elastic_energy(self.model, self._contacts.pairs[ck[cut]], np.maximum(overlap[cut], 0.0))[0]
                spring[part] += np.bincount(tk[cut], weights=held, minlength=rows)
            parts.append(dg.conserved(self.model, st.t, st.s, st.v, st.w, st.work, np.zeros((0, 2), np.int64),
                                      stored=spring[part][:, None]))
            speed = np.linalg.norm(v, axis=-1)
            p_scale[part] = np.sum(self.mass * speed, axis=-1)
            if self.dim > 1:
                arms.append(dg.angular_scale(self.model, s, v, w))
            speed_max = max(speed_max, float(np.max(speed, initial=0.0)))
            momentum_max = max(momentum_max, float(np.max(speed * self.mass, initial=0.0)))
            energy = 0.5 * self.mass * speed**2
            if w.shape[-1]:
                energy = energy + 0.5 * inertia * np.sum(w**2, axis=-1)
            energy_max = max(energy_max, float(np.max(energy, initial=0.0)))
            here = np.flatnonzero(is_path[part])
            if len(here):
                path_s = embed3(s[here])
                coms.append((self.mass[None, :, None] * path_s).sum(axis=1) / self.mass.sum())
                wrapped = self._wrapped(path_s)
                lo = np.minimum(lo, (wrapped - self.radius[None, :, None]).min(axis=(0, 1)))
                hi = np.maximum(hi, (wrapped + self.radius[None, :, None]).max(axis=(0, 1)))
                if n <= CONTACT_LIST_BODIES:
                    paths.append(wrapped)
            for k in (0, n_t - 1):
                if part.start <= k < part.stop and float(times[k]) in (self.t0, self.t1):
                    ends[float(times[k])] = body_values_arrays(self.mass, inertia, v[k - part.start],
                                                               w[k - part.start])
            touching = overlap > touch
            i, j = self._contacts.pairs[ck[touching], 0], self._contacts.pairs[ck[touching], 1]
            at = tk[touching]
            ends_of = np.concatenate((at * n + i, (at * n + j)[j >= 0]))
            contacts_max = max(contacts_max, int(np.bincount(ends_of, minlength=1).max(initial=0)))
            links_max = max(links_max, int(np.bincount(at, minlength=1).max(initial=0)))  # contacts at once
            comp = self._contacts.compression(ck, overlap) * 1e3
            np.maximum.at(peak, ck, comp)
            np.maximum.at(most, tk + part.start, comp)
            kept += len(tk)
            entries = entries if entries is not None and kept <= COMPRESSION_ENTRIES else None
            if entries is not None:
                entries.append((tk + part.start, ck, comp))
        joined = None if entries is None else tuple(np.concatenate([e[k] for e in entries]) if entries else
                                                    np.zeros(0) for k in range(3))
        if self.dim < 3:
            r = float(self.radius.max())
            lo[2], hi[2] = -r, r
        return _Swept(_joined(parts), p_scale, np.concatenate(arms) if arms else None,
                      np.concatenate(paths) if n <= CONTACT_LIST_BODIES else None, np.concatenate(coms), (lo, hi),
                      speed_max, momentum_max, energy_max, contacts_max, links_max, peak, most, joined, ends)

    def _angular_at(self, times: np.ndarray) -> np.ndarray:
        """The angular momentum (T, L) at sorted `times` (the contact steps' ends), a block of
        times at a time: the knots' own states where every body has a knot there (a DEM
        recording's frames), else sampled."""
        rows = []
        step = max(1, SAMPLE_BODY_TIMES // max(self.n_bodies, 1))
        for a in range(0, len(times), step):
            part = times[a:a + step]
            known = self._knots.at_knots(part)
            if known is None:
                st = self.sample(part)
                s, v, w = st.s, st.v, st.w
            else:
                s, v, w = (x[:, None] for x in known)
            zeros = np.zeros((len(part), 1))
            rows.append(dg.conserved(self.model, part, s, v, w, zeros, np.zeros((0, 2), np.int64))
                        .angular_momentum[:, 0])
        return np.concatenate(rows)

    # ------------------------------------------------------------------------------------------
    # Frames

    def clamp_time(self, t: float) -> float:
        return min(max(float(t), self.t0), self.t1)

    def in_contact(self, t: float) -> bool:
        return any(a <= t <= b for a, b in self.contact_windows)

    def next_step(self, t: float, direction: int) -> float:
        """The next (direction +1) or previous (-1) contact step's time from t: within a contact
        its steps one by one, outside it the nearest step of the next (or previous) contact."""
        times = self.step_times
        if not len(times):
            return self.t1 if direction > 0 else self.t0
        tol = 1e-9 * max(self.duration, 1e-300)
        if direction > 0:
            later = times[times > t + tol]
            return float(later[0]) if len(later) else self.t1
        earlier = times[times < t - tol]
        return float(earlier[-1]) if len(earlier) else self.t0

    def body_values(self, t: float) -> dict[str, np.ndarray]:
        """Per body at time t: velocity (N, D) m/s, speed (N,), momentum (N, D), kinetic energy
        (N,) J (translational), spin (N, K) rad/s and rotational energy (N,) J."""
        t = self.clamp_time(t)
        if t in self._end_values:
            return {key: value.copy() for key, value in self._end_values[t].items()}
        st = self.sample(np.array([t]))
        return body_values_arrays(self.mass, self.model.inertia[0], st.v[0, 0], st.w[0, 0])

    def frame(self, t: float) -> Frame:
        """Bodies and active contacts at time t (clamped to the run). Above CONTACT_LIST_BODIES
        bodies the contacts come as arrays only (`Frame.links`): thousands of them a frame."""
        t = self.clamp_time(t)
        times = np.array([t])
        st = self.sample(times)
        positions = embed3(st.s[0, 0])
        velocities = embed3(st.v[0, 0])
        wxyz = orientation_wxyz(st.q[0, 0])
        e = self._contacts.at(times, st.s[:, 0])
        if self.model.periodic:  # drawn in the box: the bodies wrapped into it, their contacts with them
            placed, _ = wrap(st.s[0, 0], np.array(self.model.box_lower), np.array(self.model.period))
            e.point = e.point + (placed - st.s[0, 0])[e.i]
            positions = embed3(placed)
        # Spheres that touch only to round-off (an overlap of 1e-17 m) are not in contact; those
        # the engine had pressing are, though the motion rebuilt between two DEM frames may
        # have them apart (a collision shorter than a frame).
        force = np.linalg.norm(e.normal_force, axis=-1)
        e = e.select((e.overlap > ROUND_OFF * float(self.radius.max())) | (force > ROUND_OFF * self.max_normal_force))
        links = Links(e.i, np.where(e.j >= 0, e.j, -1), embed3(e.point), np.linalg.norm(e.normal_force, axis=-1))
        contacts = []
        if self.n_bodies <= CONTACT_LIST_BODIES:
            names = self._contacts.names
            for k in range(len(e.ck)):
                i, j = int(e.i[k]), int(e.j[k])
                if j >= 0:
                    d = embed3(nearest_image((positions[j] - positions[i])[:self.dim], self.model.period))
                    normal = d / np.linalg.norm(d)
                else:
                    normal = -embed3(self.model.wall_normal[-1 - j])
                    j = None
                friction = None if e.friction_force is None else embed3(e.friction_force[k])
                comp = e.compression[k]
                contacts.append(ContactFrame(names[int(e.ck[k])], i, j, embed3(e.point[k]), normal,
                                             embed3(e.normal_force[k]), friction, float(e.overlap[k]),
                                             (float(comp[0]), float(comp[1]))))
        com = self.mass @ positions / self.mass.sum()
        return Frame(t, positions, wxyz, contacts, velocities, com, links)

    # ------------------------------------------------------------------------------------------
    # Plots

    def _make_plots(self, swept: _Swept) -> PlotData:
        # The springs' energy is summed over the contacts engaged at each time (no others hold any).
        con = swept.conserved
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
        p_scale = float(np.max(swept.p_scale, initial=0.0))
        angular = None
        if con.angular_momentum is not None:
            # Inside a contact step, straight between the steps' own values: interpolated spins
            # and velocities need not balance there when friction changes within the step.
            # Only the steps' ends around such times are evaluated (not every knot of the run).
            t = self.traj.knot_times
            k = np.clip(np.searchsorted(t, self.times, side="right") - 1, 0, max(len(t) - 2, 0))
            inside = ~self._free[np.minimum(k + 1, len(t) - 1)] & (self.times > t[k])
            values = con.angular_momentum[:, 0].copy()
            if inside.any():
                ends = np.union1d(t[k[inside]], t[np.minimum(k[inside] + 1, len(t) - 1)])
                rows = self._angular_at(ends)
                for c in range(values.shape[-1]):
                    values[inside, c] = np.interp(self.times[inside], ends, rows[:, c])
            comps = ("z",) if values.shape[-1] == 1 else ("x", "y", "z")
            # Its natural size (the residual's scale), largest over the run.
            angular = _conserved_series("angular momentum", "kg m²/s",
                                        {f"L{a}": values[:, c] for c, a in enumerate(comps)},
                                        float(np.max(swept.arm, initial=0.0)))
        compression = self._compression_lines(swept)
        e_scale = float(np.max(np.abs(energy["total"]), initial=0.0))
        energy_series = _conserved_series("energy", "J", energy, e_scale)
        plots = PlotData(self.times, energy_series, _conserved_series("momentum", "kg m/s", momentum, p_scale),
                         angular, Series("compression", "mm", compression,
                                         float(max((v.max() for v in compression.values()), default=0.0)))
                         if compression else None)
        plots.all = [s for s in (plots.energy, plots.momentum, plots.angular_momentum, plots.compression)
                     if s is not None]
        return plots

    def _compression_lines(self, swept: _Swept) -> dict[str, np.ndarray]:
        """Compression (mm) of each contact that was pressed beyond round-off, in the order the
        contacts began; above MAX_COMPRESSION_LINES the largest ones and an 'others (max)' line
        (a pile has thousands of contacts); with more engaged entries than COMPRESSION_ENTRIES,
        the largest of all contacts' at each time."""
        n_t, peak = len(self.times), swept.peak
        pressed = np.flatnonzero(peak > ROUND_OFF * self.radius.max() * 1e3)
        if swept.entries is None:
            return {f"{len(pressed)} contacts (max)": swept.most} if len(pressed) else {}
        tk, ck, comp = swept.entries
        if len(pressed) > MAX_COMPRESSION_LINES:
            top = pressed[np.argsort(-peak[pressed], kind="stable")]
            shown, rest = top[: MAX_COMPRESSION_LINES - 1], top[MAX_COMPRESSION_LINES - 1:]
        else:
            shown, rest = pressed, pressed[:0]
        lines = {}
        names = self._contacts.names
        for k in shown:
            y = np.zeros(n_t)
            mine = ck == k
            y[tk[mine]] = comp[mine]
            lines[names[int(k)]] = y
        if len(rest):
            others = np.zeros(n_t)
            mine = np.isin(ck, rest)
            np.maximum.at(others, tk[mine], comp[mine])
            lines[f"{len(rest)} others (max)"] = others
        return lines

    # ------------------------------------------------------------------------------------------
    # Summary

    def _contact_windows(self) -> list[tuple[float, float]]:
        if self.scene.integrator == "dem":
            # The DEM kernel steps (not free) whenever spheres are within its neighbour skin,
            # touching or not: its contact phases are the windows (overlapping ones merged).
            windows: list[tuple[float, float]] = []
            ivals = self.traj.intervals[:, 2:4]
            ends = np.where(np.isnan(ivals[:, 1]), self.t1, ivals[:, 1])  # still engaged at the end
            for a, b in sorted(zip(ivals[:, 0].tolist(), ends.tolist())):
                if windows and a <= windows[-1][1]:
                    windows[-1] = (windows[-1][0], max(windows[-1][1], b))
                else:
                    windows.append((a, b))
            return windows
        t = self.traj.knot_times
        contact = np.concatenate(([False], ~self._free[1:], [False])).astype(np.int8)
        # Runs of contact segments: segment k (t[k] .. t[k + 1]) is a contact step.
        starts = np.flatnonzero(np.diff(contact) == 1)
        ends = np.flatnonzero(np.diff(contact) == -1)
        return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]

    @property
    def duration(self) -> float:
        return self.t1 - self.t0

    @property
    def name(self) -> str:
        return self.scene.name

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box around every body's path, padded by its radius (m, 3D)."""
        lo, hi = self._box
        return lo.copy(), hi.copy()

    def contact_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box around the bodies while they touch (the first contact), padded by three radii;
        the whole run's box when nothing touches."""
        if not self.contact_windows:
            return self.bounds()
        a, b = self.contact_windows[0]
        pad = 0.25 * (b - a)
        t = np.linspace(max(self.t0, a - pad), min(self.t1, b + pad), 50)
        r = float(self.radius.max())
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for _, st in self._chunks(t):
            s = embed3(st.s[:, 0])
            lo, hi = np.minimum(lo, s.min(axis=(0, 1))), np.maximum(hi, s.max(axis=(0, 1)))
        lo, hi = lo - 2.5 * r, hi + 2.5 * r
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
        lines.append(self.error_line())
        if self.n_bodies > CONTACT_LIST_BODIES:
            # Nothing is held per frame: a frame is sampled from the trajectory when it is shown.
            lines.append(f"{self.n_bodies:,} bodies: each frame rebuilt from the trajectory as the time moves, "
                         f"plots at {len(self.times)} times")
        return lines

    def error_line(self) -> str:
        """The outcome's error estimate and where it comes from: pending while it is measured."""
        if self.measuring:
            return f"error estimate: *{MEASURING}*"
        estimate = self.run.error_estimate
        if estimate is None:
            return "error estimate: n/a"
        method = (self.run.error_method or ["model"])[0]
        how = ("measured: against the run at a tenth of the tolerance" if method == "measured"
               else "the error model's")
        return f"error estimate: {float(estimate[0]):.2g} ({how})"


def body_values_arrays(mass: np.ndarray, inertia: np.ndarray, v: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
    """`ViewRun.body_values` from masses (N,), moments of inertia (N,), velocities (N, D) and
    spins (N, K)."""
    speed = np.linalg.norm(v, axis=-1)
    out = {"velocity": v, "speed": speed, "momentum": mass[:, None] * v, "kinetic": 0.5 * mass * speed**2,
           "spin": w}
    out["rotational"] = 0.5 * inertia * np.sum(w * w, axis=-1) if w.shape[-1] else np.zeros(len(mass))
    return out


def _conserved_series(title: str, unit: str, lines: dict[str, np.ndarray], scale: float) -> Series:
    """A series whose lines that are constant to round-off (spread below FLAT of `scale`) are
    drawn at their mean: a spread of 1e-21 on a quantity of size 1e-3 is not a signal."""
    flat = []
    out = {}
    for name, y in lines.items():
        if scale > 0 and np.all(np.isfinite(y)) and np.ptp(y) <= FLAT * scale:
            level = float(np.mean(y))
            out[name] = np.full_like(y, 0.0 if abs(level) <= ROUND_OFF * scale else level)
            flat.append(name)
        else:
            out[name] = y
    return Series(title, unit, out, scale, tuple(flat))


def format_residual(x: float) -> str:
    """A residual as shown: 'n/a' where it does not apply (NaN)."""
    return "n/a" if not math.isfinite(x) else f"{x:.2e}"
