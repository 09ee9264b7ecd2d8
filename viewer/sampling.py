"""Sampling a trajectory for the viewer: every body at once, without a Python loop per body.

`diagnostics.sample` walks the bodies one by one and sorts every knot on each call: fine for a
few bodies, 30-90 ms a frame for 1 000 (issue 12: replay at 30 frames a second). `Knots`
sorts the knots by body and time once; `sample(times)` then finds each body's knot at each
time with one vectorised binary search over all (time, body) pairs and evaluates the same
closed forms (free flight, the quintic Hermite inside a step, the spin's turn). It returns the
same `State` as `diagnostics.sample`, in bounded chunks of times, so memory stays O(bodies x
times asked) however long the run.

`segment_search` (collide.trajectory) is the binary search: sorted runs of values (one run per
body, or per contact's records), many queries at once.
"""

from __future__ import annotations

import numpy as np

from collide import diagnostics as dg
from collide.engine import layout
from collide.model import Model, State, turned_quaternions
from collide.trajectory import Trajectory, _quintic, segment_search

CHUNK = 1 << 14  # (time, body) pairs evaluated at once: about 6 MB of gathered knot rows


class Knots:
    """A trajectory's knots sorted by (body, time), with each body's run [start, end)."""

    def __init__(self, model: Model, traj: Trajectory) -> None:
        self.model = model
        knots = traj.knots
        self.knots = knots
        # The order diagnostics.body_knots uses: by body, then time, then as recorded (an index,
        # not a sorted copy of the knots).
        self.order = np.lexsort((np.arange(len(knots)), knots[:, layout.K_T], knots[:, layout.K_BODY]))
        self.t = knots[self.order, layout.K_T]
        body = knots[self.order, layout.K_BODY]
        bodies = np.arange(model.n_bodies)
        self.start = np.searchsorted(body, bodies, side="left")
        self.end = np.searchsorted(body, bodies, side="right")
        self.steps = knots[self.order, layout.K_FREE] == 0.0  # the segment after the knot is a step

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

    def sample(self, times: np.ndarray, member: int = 0) -> State:
        """States at the given times (T,), shaped (T, 1, N, D): `diagnostics.sample`'s values."""
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
            # Summed body after body, as diagnostics.sample does (cumsum adds in order).
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
                q1 = np.where(dg._dot(q0, q1)[:, None] < 0, -q1, q1)
                lerp = (1 - xb) * q0 + xb * q1
                orient[step] = lerp / np.linalg.norm(lerp, axis=1, keepdims=True)
            else:
                orient[step] = (1 - xb) * q0 + xb * q1
            done[step] = (1 - x) * done[step] + x * a1[:, layout.K_WORK]
        return (pos.reshape(*shape, 3), vel.reshape(*shape, 3), spin.reshape(*shape, 3),
                orient.reshape(*shape, 4), done.reshape(shape))
