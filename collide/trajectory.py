"""A run's motion, exactly where it is known (`Trajectory`), and its states at any time
(`sample`): the knots' closed-form free flight or a quintic Hermite across a step."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from collide.engine import layout
from collide.model import Model, State, turned_quaternions


@dataclass
class Trajectory:
    """One run's motion, exactly where it is known, plus its contacts.

    knots (K, layout.NK): a body's state at a time (the ends of its steps, where free flight
    starts and ends), with its acceleration just before and after; between two knots of a body
    the motion is closed-form free flight (the earlier knot's K_FREE) or one integrator step,
    rebuilt by a quintic Hermite (`sample`). records (R, layout.NR): each engaged
    contact at the end of each step (overlap, normal force, friction force on body i, mode).
    intervals (I, 4): (i, j, start, end) of every contact phase; j = -1 - wall for walls.

    `t`, `s`, `v`, `w`, `q`, `work`, `free` are the rows view: every body at every knot time,
    (S, 1, ...), as older code and the recording's exact frames read it.
    """

    knots: np.ndarray
    records: np.ndarray
    intervals: np.ndarray
    model: Model = field(repr=False)
    # DEM runs: (F, 5) per recorded frame: t, work of damping, friction, rolling resistance (J,
    # cumulative), energy held by tangential springs (J).
    energy_parts: np.ndarray | None = field(default=None, repr=False)

    @property
    def knot_times(self) -> np.ndarray:
        return np.unique(self.knots[:, layout.K_T])

    @property
    def n_steps(self) -> int:
        return len(self.knot_times)

    @cached_property
    def _rows(self):
        times = self.knot_times
        return times, sample(self.model, self, times)

    @property
    def t(self) -> np.ndarray:
        # The knot times alone: asking for them must not sample every body at every knot
        # (gas-box: 78 506 knot times x 1 000 bodies, gigabytes).
        return self.knot_times[:, None]

    @property
    def s(self) -> np.ndarray:
        return self._rows[1].s

    @property
    def v(self) -> np.ndarray:
        return self._rows[1].v

    @property
    def w(self) -> np.ndarray:
        return self._rows[1].w

    @property
    def q(self) -> np.ndarray:
        return self._rows[1].q

    @property
    def work(self) -> np.ndarray:
        return self._rows[1].work

    @cached_property
    def index(self) -> Knots:
        """The knots sorted by body and time, once (a sort of every knot: a recording of many
        bodies asks for it several times)."""
        return Knots(self.model, self)

    @cached_property
    def free(self) -> np.ndarray:
        """(S, 1): the segment that ends at row k was free flight for every body."""
        return ~self.index.stepped(self.knot_times)[:, None]

    def contacts_touched(self) -> np.ndarray:
        """(C, 2) every contact that was ever engaged, in the order they began: (i, j) with
        j = -1 - wall."""
        if not len(self.intervals):
            return np.zeros((0, 2), np.int64)
        pairs = self.intervals[:, :2].astype(np.int64)
        _, first = np.unique(pairs, axis=0, return_index=True)
        return pairs[np.sort(first)]


# ---------------------------------------------------------------------------------------------
# Sampling a trajectory at any times (frames for recordings, CSV rows, the viewer's timeline)


def _quintic(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic Hermite basis at x in [0, 1] (for s0, h v0, h^2 a0, h^2 a1, h v1, s1) and its
    derivative."""
    x2, x3, x4, x5 = x * x, x**3, x**4, x**5
    basis = np.stack((1 - 10 * x3 + 15 * x4 - 6 * x5, x - 6 * x3 + 8 * x4 - 3 * x5,
                      0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5, 0.5 * x3 - x4 + 0.5 * x5,
                      -4 * x3 + 7 * x4 - 3 * x5, 10 * x3 - 15 * x4 + 6 * x5))
    deriv = np.stack((-30 * x2 + 60 * x3 - 30 * x4, 1 - 18 * x2 + 32 * x3 - 15 * x4,
                      x - 4.5 * x2 + 6 * x3 - 2.5 * x4, 1.5 * x2 - 4 * x3 + 2.5 * x4,
                      -12 * x2 + 28 * x3 - 15 * x4, 30 * x2 - 60 * x3 + 30 * x4))
    return basis, deriv


def segment_search(values: np.ndarray, lo: np.ndarray, hi: np.ndarray, x: np.ndarray,
                   side: str = "right") -> np.ndarray:
    """np.searchsorted(values[lo:hi], x, side) + lo for many (lo, hi, x) at once (broadcast
    together); values is sorted within each [lo, hi)."""
    lo, hi, x = np.broadcast_arrays(np.asarray(lo, np.int64), np.asarray(hi, np.int64), np.asarray(x, float))
    lo, hi = lo.copy(), hi.copy()
    while True:
        open_ = lo < hi
        if not open_.any():
            return lo
        mid = (lo + hi) // 2
        v = values[np.minimum(mid, len(values) - 1)]
        right = (v <= x) if side == "right" else (v < x)
        lo = np.where(open_ & right, mid + 1, lo)
        hi = np.where(open_ & ~right, mid, hi)


def body_knots(traj: Trajectory) -> list[np.ndarray]:
    """Each body's knots, in time order."""
    knots = traj.knots
    order = np.lexsort((np.arange(len(knots)), knots[:, layout.K_T], knots[:, layout.K_BODY]))
    knots = knots[order]
    cuts = np.searchsorted(knots[:, layout.K_BODY], np.arange(1, traj.model.n_bodies))
    return np.split(knots, cuts)


def settled(traj: Trajectory, times: np.ndarray) -> np.ndarray:
    """Whether at each time (T,), sorted, every body is at one of its knots or in free flight:
    where `sample` is exact. Inside a step of another island a body is rebuilt by interpolation,
    its spin and dissipated work straight across the step, and the energy balance there was off
    by up to 6e-4 (a 27-sphere pile at tol 1e-4, 1e-5 at exact states; two balls sliding on a
    floor, 1.3e-5 against 2e-15)."""
    index = traj.index
    # Each body's steps: a knot followed by one of the same body's, with no free flight between.
    last = np.zeros(len(index.t), bool)
    last[index.end[index.end > 0] - 1] = True
    step = np.flatnonzero(~last & index.steps)
    inside = np.zeros(len(times) + 1, np.int64)
    np.add.at(inside, np.searchsorted(times, index.t[step], side="right"), 1)
    np.add.at(inside, np.searchsorted(times, index.t[step + 1], side="left"), -1)
    return np.cumsum(inside[:-1]) == 0


def sample(model: Model, traj: Trajectory, times: np.ndarray, member: int = 0) -> State:
    """States at the given times (T,), shaped (T, 1, N, D), for a trajectory of one run.

    At a knot the state is exact. Between two knots of a body the motion is closed-form free
    flight, or one integrator step, rebuilt by a quintic Hermite through both ends' positions,
    velocities and accelerations (a high-order step takes about ten steps a contact: a cubic would
    make the energy wobble by per cent between them); spins and dissipated work are linear in
    a step, orientation turns at the spin."""
    return traj.index.with_model(model).sample(times, member)


CHUNK = 1 << 14  # (time, body) pairs evaluated at once: about 6 MB of gathered knot rows


class Knots:
    """A trajectory's knots sorted by (body, time) once, with each body's run [start, end):
    `sample(times)` finds each body's knot at each time with one vectorised binary search over
    all (time, body) pairs and evaluates the closed forms, every body at once, in bounded chunks
    of times (memory O(bodies x times asked) however long the run)."""

    def __init__(self, model: Model, traj: Trajectory) -> None:
        self.model = model
        knots = traj.knots
        self.knots = knots
        # The order body_knots uses: by body, then time, then as recorded (an index,
        # not a sorted copy of the knots).
        self.order = np.lexsort((np.arange(len(knots)), knots[:, layout.K_T], knots[:, layout.K_BODY]))
        self.t = knots[self.order, layout.K_T]
        body = knots[self.order, layout.K_BODY]
        bodies = np.arange(model.n_bodies)
        self.start = np.searchsorted(body, bodies, side="left")
        self.end = np.searchsorted(body, bodies, side="right")
        self.steps = knots[self.order, layout.K_FREE] == 0.0  # the segment after the knot is a step

    def with_model(self, model: Model) -> Knots:
        """The same sorted knots read with another model of the same bodies (a batch's, whose
        member's gravity the trajectory's own model holds as its only one): no second sort."""
        if model is self.model:
            return self
        other = copy.copy(self)
        other.model = model
        return other

    def stepped(self, times: np.ndarray) -> np.ndarray:
        """(S,) for sorted distinct times (the knot times): the segment that ends at times[k]
        was an integrator step for some body (`Trajectory.free`'s complement, without a loop
        over bodies and steps)."""
        last = np.zeros(len(self.t), bool)
        last[self.end[self.end > 0] - 1] = True
        step = ~last[:-1] & self.steps[:-1]
        a = np.searchsorted(times, self.t[:-1][step])
        b = np.searchsorted(times, self.t[1:][step])
        # Rows a + 1 .. b of each step are stepped: +1 at a + 1, -1 at b + 1, summed.
        mark = np.zeros(len(times) + 2, np.int64)
        np.add.at(mark, a + 1, 1)
        np.add.at(mark, b + 1, -1)
        stepped = np.cumsum(mark)[: len(times)] > 0
        if len(stepped):
            stepped[0] = False
        return stepped

    def at_knots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Positions, velocities and spins (T, N, D) and (T, N, K) at times where every body has
        a knot: the knots' own values (the last at that time, the one `sample` starts from),
        with no search for a segment to evaluate. None if some body has no knot at some time."""
        times = np.asarray(times, dtype=float)
        model = self.model
        if not len(times) or (self.end <= self.start).any():
            return None
        at = segment_search(self.t, self.start[None, :], self.end[None, :], times[:, None], "right") - 1
        if (at < self.start[None, :]).any() or (self.t[at] != times[:, None]).any():
            return None
        rows = self.order[at]
        s = self.knots[rows, layout.K_S:layout.K_S + model.dim]
        v = self.knots[rows, layout.K_V:layout.K_V + model.dim]
        w = self.knots[rows, layout.K_W + 3 - model.spin_dim:layout.K_W + 3]
        return s, v, w

    def sample(self, times: np.ndarray, member: int = 0) -> State:
        """States at the given times (T,), shaped (T, 1, N, D) (`sample`)."""
        times = np.asarray(times, dtype=float)
        model = self.model
        n_t, n = len(times), model.n_bodies
        d, k, qd = model.dim, model.spin_dim, model.orient_dim
        s = np.zeros((n_t, n, d))
        v = np.zeros((n_t, n, d))
        w = np.zeros((n_t, n, k))
        q = np.zeros((n_t, n, qd))
        work = np.zeros(n_t)
        g = np.zeros(3) if model.gravity is None else np.pad(model.gravity[member], (0, 3 - d))
        rows = max(1, CHUNK // max(n, 1))
        for a in range(0, n_t, rows):
            part = slice(a, min(a + rows, n_t))
            pos, vel, spin, orient, done = self._evaluate(times[part], g)
            s[part] = pos[..., :d]
            v[part] = vel[..., :d]
            if k == 1:
                w[part, :, 0] = spin[..., 2]
            elif k == 3:
                w[part] = spin
            if qd:
                q[part] = orient[..., :qd]
            # Summed body after body (cumsum adds in order).
            work[part] = np.cumsum(done, axis=1)[:, -1] if n else 0.0
        return State(times, s[:, None], v[:, None], w[:, None], q[:, None], work[:, None])

    def _evaluate(self, times: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, ...]:
        """Positions, velocities, spins (3), orientations (4) (T, N, ...) and work (T, N)."""
        qd = self.model.orient_dim
        start, end = self.start[None, :], self.end[None, :]
        first, last = self.t[start], self.t[end - 1]
        clipped = np.clip(times[:, None], first, last)  # (T, N)
        # The knot a time falls after, never the body's last one (a step needs its end).
        at = segment_search(self.t, start, end, clipped, "right") - 1
        at = np.clip(at, start, np.maximum(end - 2, start))
        shape = at.shape
        at, clipped = at.ravel(), clipped.ravel()
        k0 = self.knots[self.order[at]]
        tau = clipped - k0[:, layout.K_T]
        s0, v0 = k0[:, layout.K_S:layout.K_S + 3], k0[:, layout.K_V:layout.K_V + 3]
        pos = s0 + v0 * tau[:, None] + 0.5 * g * tau[:, None] ** 2
        vel = v0 + g * tau[:, None]
        spin = k0[:, layout.K_W:layout.K_W + 3].copy()
        if qd == 4:
            orient = turned_quaternions(k0[:, layout.K_Q:layout.K_Q + 4], spin, tau)
        else:
            orient = k0[:, layout.K_Q:layout.K_Q + 4].copy()
            orient[:, 0] += spin[:, 2] * tau
        done = k0[:, layout.K_WORK].copy()
        has_next = np.broadcast_to(end - start > 1, shape).ravel()
        k1 = self.knots[self.order[np.where(has_next, at + 1, at)]]
        h = k1[:, layout.K_T] - k0[:, layout.K_T]
        step = has_next & (k0[:, layout.K_FREE] == 0.0) & (h > 0)
        if step.any():
            a0, a1 = k0[step], k1[step]
            hs = h[step][:, None]
            x = tau[step] / h[step]
            basis, deriv = _quintic(x)
            terms = (s0[step], hs * v0[step], hs * hs * a0[:, layout.K_AN:layout.K_AN + 3],
                     hs * hs * a1[:, layout.K_A:layout.K_A + 3], hs * a1[:, layout.K_V:layout.K_V + 3],
                     a1[:, layout.K_S:layout.K_S + 3])
            pos[step] = sum(basis[i][:, None] * term for i, term in enumerate(terms))
            vel[step] = sum(deriv[i][:, None] * term for i, term in enumerate(terms)) / hs
            xb = x[:, None]
            spin[step] = (1 - xb) * spin[step] + xb * a1[:, layout.K_W:layout.K_W + 3]
            q0, q1 = a0[:, layout.K_Q:layout.K_Q + 4], a1[:, layout.K_Q:layout.K_Q + 4]
            if qd == 4:
                q1 = np.where(np.sum(q0 * q1, axis=-1)[:, None] < 0, -q1, q1)
                lerp = (1 - xb) * q0 + xb * q1
                orient[step] = lerp / np.linalg.norm(lerp, axis=1, keepdims=True)
            else:
                orient[step] = (1 - xb) * q0 + xb * q1
            done[step] = (1 - x) * done[step] + x * a1[:, layout.K_WORK]
        return (pos.reshape(*shape, 3), vel.reshape(*shape, 3), spin.reshape(*shape, 3),
                orient.reshape(*shape, 4), done.reshape(shape))
