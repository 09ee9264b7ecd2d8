"""A run's contact forces as its engine computed them, at any time: the one place the viewer,
the Rerun recording and the diagnostics take them from.

Every engine records each engaged contact's normal force (R_FN) and friction force (R_FX..) as
its own law gave them: the event engine and the seed at the end of every step (linear k delta),
the DEM kernel at every frame it records (linear or Hertz, with the dashpot of the restitution:
docs/design.md sections 2, 3 and 9, its tangential spring or Coulomb slip for friction). Nothing
here evaluates a law again: between two records of a contact the normal force is taken straight
across, from zero where a contact phase begins or ends (the elastic force's value there); the
friction force is the record of the step that ends at or after the time (the force that step
applied). A DEM contact that began and ended between two frames has no record: it is drawn
without force, and the run's peak (`peak_normal_force`) still counts it.
"""

from __future__ import annotations

import numpy as np

from collide.engine import layout
from collide.results import RunResult
from collide.trajectory import Trajectory, segment_search


class RecordedForces:
    """The recorded forces of a run's contacts `pairs` (C, 2) (i, j; j = -1 - wall), grouped by
    contact and in time order within each, for lookups at any (contact, time)."""

    def __init__(self, traj: Trajectory, pairs: np.ndarray, n_bodies: int, n_walls: int, dim: int,
                 friction: bool) -> None:
        self.pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        self._width = n_bodies + n_walls + 1
        self._walls = n_walls
        self.dim = dim
        keys = self._key(self.pairs[:, 0], self.pairs[:, 1])
        self._key_order = np.argsort(keys)
        self._sorted_keys = keys[self._key_order]
        c = len(self.pairs)
        rec, iv = traj.records, traj.intervals
        # The normal force: each contact's records and a zero at each of its phases' ends.
        rows_c = self.contact_of(rec[:, layout.R_I], rec[:, layout.R_J]) if len(rec) else np.zeros(0, np.int64)
        iv_c = self.contact_of(iv[:, layout.V_I], iv[:, layout.V_J]) if len(iv) else np.zeros(0, np.int64)
        ends = np.isfinite(iv[:, layout.V_END]) if len(iv) else np.zeros(0, bool)
        contact = np.concatenate((rows_c, iv_c, iv_c[ends]))
        t = np.concatenate((rec[:, layout.R_T] if len(rec) else np.zeros(0),
                            iv[:, layout.V_START] if len(iv) else np.zeros(0),
                            iv[ends, layout.V_END] if len(iv) else np.zeros(0)))
        # At one time: a phase's start before that time's record, its end after it.
        kind = np.concatenate((np.ones(len(rows_c)), np.zeros(len(iv_c)), np.full(int(ends.sum()), 2.0)))
        value = np.concatenate((rec[:, layout.R_FN] if len(rec) else np.zeros(0),
                                np.zeros(len(iv_c) + int(ends.sum()))))
        order = np.lexsort((kind, t, contact))
        order = order[contact[order] >= 0]
        grouped = contact[order]
        self._n_t = np.ascontiguousarray(t[order])
        self._n_value = value[order]
        cs = np.arange(c)
        self._n_start = np.searchsorted(grouped, cs, side="left")
        self._n_end = np.searchsorted(grouped, cs, side="right")
        # Whether each contact's last phase is still open at the run's end (its last entry is not
        # a phase's end): its last records hold from there on.
        kinds = kind[order]
        self._open = np.zeros(c, bool)
        has = self._n_end > self._n_start
        self._open[has] = kinds[self._n_end[has] - 1] != 2.0
        self.record_peak = float(np.max(np.abs(rec[:, layout.R_FN]), initial=0.0)) if len(rec) else 0.0
        # Friction: the records alone, in the same order (by contact, then time, then as recorded).
        self._f_t = None
        if friction and len(rec) and c:
            rows = order[order < len(rows_c)]
            f_contact = rows_c[rows]
            self._f_t = np.ascontiguousarray(rec[rows, layout.R_T])
            self._f_force = rec[rows, layout.R_FX:layout.R_FX + dim]
            self._f_start = np.searchsorted(f_contact, cs, side="left")
            self._f_end = np.searchsorted(f_contact, cs, side="right")

    def _key(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        return np.asarray(i, np.int64) * self._width + np.asarray(j, np.int64) + self._walls

    def contact_of(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Index into `pairs` of each contact (i, j); -1 for one not in `pairs`."""
        keys = self._key(i, j)
        if not len(self._sorted_keys):
            return np.full(len(keys), -1, np.int64)
        at = np.minimum(np.searchsorted(self._sorted_keys, keys), len(self._sorted_keys) - 1)
        return np.where(self._sorted_keys[at] == keys, self._key_order[at], -1)

    def normal(self, ck: np.ndarray, times: np.ndarray) -> np.ndarray:
        """The normal force (E,) N of contacts ck (E,) at times (E,): positive pushes the bodies
        apart (a damped contact may pull as it ends). Zero outside the contact's phases."""
        ck = np.asarray(ck, np.int64)
        times = np.asarray(times, float)
        out = np.zeros(len(ck))
        if not len(ck) or not len(self._n_t):
            return out
        lo, hi = self._n_start[ck], self._n_end[ck]
        after = segment_search(self._n_t, lo, hi, times, "right")
        inside = (after > lo) & (after < hi)
        a = np.where(inside, after - 1, 0)
        b = np.where(inside, after, 0)
        ta, tb = self._n_t[a], self._n_t[b]
        span = tb - ta
        with np.errstate(invalid="ignore", divide="ignore"):
            x = np.where(span > 0, (times - ta) / span, 1.0)
        value = (1.0 - x) * self._n_value[a] + x * self._n_value[b]
        out[inside] = value[inside]
        # Past a phase that never ended (the run's end): its last record holds.
        last = (after == hi) & (hi > lo)
        out[last] = self._n_value[hi[last] - 1]
        return out

    def friction(self, ck: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The friction force (E, D) N on body i of contacts ck at times (E,): the record of the
        step that ends at or after each time (past the last, in a phase still open at the run's
        end, the last); and whether there is one (E,)."""
        ck = np.asarray(ck, np.int64)
        force = np.zeros((len(ck), self.dim))
        if self._f_t is None or not len(ck):
            return force, np.zeros(len(ck), bool)
        lo, hi = self._f_start[ck], self._f_end[ck]
        at = segment_search(self._f_t, lo, hi, np.asarray(times, float), side="left")
        # Past the last record of a phase that never ended (the run's end), that record holds.
        found = (at < hi) | ((at == hi) & (hi > lo) & self._open[ck])
        rows = np.minimum(at, np.maximum(hi - 1, 0))
        force[found] = self._f_force[rows[found]]
        return force, found


def peak_normal_force(result: RunResult, forces: RecordedForces | None = None, member: int = 0) -> float:
    """The run's largest normal force (N): the engine's own figure over every step, as the JSON
    summary's `max_normal_force` gives it (collide.summary), or, where the engine keeps none (the
    seed's runs with walls), the largest it recorded. Never below a recorded one, so that an
    arrow scaled by it is never longer than the legend says."""
    log = result.contacts
    figure = float("nan") if log is None or log.max_normal_force is None else float(log.max_normal_force[member])
    recorded = forces.record_peak if forces is not None else 0.0
    if not np.isfinite(figure):
        return recorded
    return max(figure, recorded)
