"""The contacts of a run for the viewer: only those engaged at the times asked.

`diagnostics.contact_series` evaluates every contact the run ever had at every time asked:
(times x contacts), and a scan of every record per contact for friction. A gas of 1 000
spheres has 7 700 contacts over the run, a settling pile 3 700 engaged at once, so the plots'
400 times cost gigabytes and one frame seconds (issue 12). `ContactIndex` reads the run's contact
intervals (when each contact was engaged) and records once, and `at(times, s)` evaluates the
same quantities (overlap, compression, point, normal and friction force) only for the (time,
contact) pairs whose interval holds the time: memory O(contacts engaged at those times).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide import diagnostics as dg
from collide.engine import layout as kn
from collide.model import Model
from collide.trajectory import Trajectory
from viewer.sampling import Knots, segment_search

SLICE = 1 << 16  # contact entries evaluated at once by `ContactIndex.overlaps`


@dataclass
class Engaged:
    """Engaged contacts at some times, one entry per (time, contact) pair, E entries.

    tk (E,) index into the times asked; ck (E,) index into `ContactIndex.pairs`; i, j (E,)
    the bodies (j = -1 - wall); overlap (E,) m; normal (E, D) unit vector from i towards j (into
    the wall); compression (E, 2) m of body i and j; point (E, D) m; normal_force (E, D) N and
    friction_force (E, D) N (or None without friction), both on body i."""

    tk: np.ndarray
    ck: np.ndarray
    i: np.ndarray
    j: np.ndarray
    overlap: np.ndarray
    normal: np.ndarray
    compression: np.ndarray
    point: np.ndarray
    normal_force: np.ndarray
    friction_force: np.ndarray | None

    def select(self, keep: np.ndarray) -> Engaged:
        """The entries where `keep` (E,) is true."""
        friction = None if self.friction_force is None else self.friction_force[keep]
        return Engaged(self.tk[keep], self.ck[keep], self.i[keep], self.j[keep], self.overlap[keep],
                       self.normal[keep], self.compression[keep], self.point[keep], self.normal_force[keep],
                       friction)


class ContactIndex:
    """A run's contacts in the order they began (`pairs`, `names` as `contact_series`), with
    their engaged intervals and records indexed for lookups at any times."""

    def __init__(self, model: Model, traj: Trajectory, knots: Knots) -> None:
        self.model = model
        self.pairs = traj.contacts_touched()
        c = len(self.pairs)
        self._names: list[str] | None = None
        iv = traj.intervals
        self._width = model.n_bodies + model.n_walls + 1
        keys = self._key(self.pairs[:, 0], self.pairs[:, 1])
        self._key_order = np.argsort(keys)
        self._sorted_keys = keys[self._key_order]
        self.iv_contact = self._contact_of(iv[:, 0], iv[:, 1])
        start = iv[:, kn.V_START].astype(float) if len(iv) else np.zeros(0)
        # A contact still engaged when the run ended has no end: it lasts to the end.
        end = np.where(np.isnan(iv[:, kn.V_END]), np.inf, iv[:, kn.V_END]) if len(iv) else np.zeros(0)
        # Widened to body i's knots around them: between two knots the motion is rebuilt, and
        # the rebuilt spheres may touch a little before the engine saw them touch (DEM frames
        # are far apart). Whether they touch is then the overlap's to say. The event engine's
        # contacts start and end on knots: unchanged.
        body = iv[:, 0].astype(np.int64) if len(iv) else np.zeros(0, np.int64)
        lo, hi = knots.start[body], knots.end[body]
        before = np.clip(segment_search(knots.t, lo, hi, start, "right") - 1, lo, hi - 1)
        after = np.clip(segment_search(knots.t, lo, hi, end, "left"), lo, hi - 1)
        self.iv_start = np.minimum(start, knots.t[before]) if len(iv) else start
        self.iv_end = np.maximum(np.minimum(end, knots.t[hi - 1]), knots.t[after]) if len(iv) else end
        self.stiffness = dg.stiffness(model, self.pairs)[0] if c else np.zeros(0)
        self.radius_i = model.radius[0, self.pairs[:, 0]] if c else np.zeros(0)
        # Records grouped by contact, in time order within each: friction at any time is a search.
        rec = traj.records
        if model.friction and len(rec) and c:
            rk = self._contact_of(rec[:, kn.R_I], rec[:, kn.R_J])
            order = np.lexsort((np.arange(len(rec)), rec[:, kn.R_T], rk))
            order = order[rk[order] >= 0]
            self.rec_contact = rk[order]
            self.rec_t = np.ascontiguousarray(rec[order, kn.R_T])
            self.rec_force = rec[order, kn.R_FX:kn.R_FX + model.dim]
            cs = np.arange(c)
            self.rec_start = np.searchsorted(self.rec_contact, cs, side="left")
            self.rec_end = np.searchsorted(self.rec_contact, cs, side="right")
        else:
            self.rec_t = None

    def _key(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        return np.asarray(i, np.int64) * self._width + np.asarray(j, np.int64) + self.model.n_walls

    def _contact_of(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Index into `pairs` of each contact (i, j); -1 for one that never engaged."""
        keys = self._key(i, j)
        if not len(self._sorted_keys):
            return np.full(len(keys), -1, np.int64)
        at = np.minimum(np.searchsorted(self._sorted_keys, keys), len(self._sorted_keys) - 1)
        return np.where(self._sorted_keys[at] == keys, self._key_order[at], -1)

    @property
    def names(self) -> list[str]:
        if self._names is None:
            self._names = [self.model.contact_name(int(i), int(j)) for i, j in self.pairs]
        return self._names

    def __len__(self) -> int:
        return len(self.pairs)

    def engaged_pairs(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tk, ck): every (time, contact) pair whose contact was engaged at that time (sorted
        times), ordered by time then contact."""
        lo = np.searchsorted(times, self.iv_start, side="left")
        hi = np.searchsorted(times, self.iv_end, side="right")
        count = np.maximum(hi - lo, 0)
        total = int(count.sum())
        if not total:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        # Each interval's run of time indices lo .. hi - 1, all runs concatenated.
        first = np.repeat(lo - np.cumsum(count) + count, count)
        tk = first + np.arange(total)
        ck = np.repeat(self.iv_contact, count)
        # A contact whose phases touch (one ends where the next begins) is listed once.
        key = np.unique(tk * max(len(self), 1) + ck)
        return key // max(len(self), 1), key % max(len(self), 1)

    def _geometry(self, tk: np.ndarray, ck: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Normal (E, D), overlap (E,), and whether each is a pair of spheres (E,)."""
        model = self.model
        i, j = self.pairs[ck, 0], self.pairs[ck, 1]
        pair = j >= 0
        si = s[tk, i]
        jj = np.where(pair, j, 0)
        delta = s[tk, jj] - si
        dist = np.sqrt(np.sum(delta * delta, axis=-1))
        with np.errstate(invalid="ignore", divide="ignore"):
            n = delta / dist[:, None]
        reach = model.radius[0, i] + np.where(pair, model.radius[0, jj], 0.0)
        if model.n_walls:
            w = np.where(pair, 0, -1 - j)
            wall_normal = model.wall_normal[w]
            height = np.sum((si - model.wall_point[w]) * wall_normal, axis=-1)
            n = np.where(pair[:, None], n, -wall_normal)
            dist = np.where(pair, dist, height)
        return n, reach - dist, pair

    def overlaps(self, times: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tk, ck, overlap (m)) of the contacts engaged at sorted `times` (T,), the bodies
        being at s (T, N, D) there: the plots' light version of `at`."""
        tk, ck = self.engaged_pairs(times)
        overlap = np.empty(len(tk))
        # In slices: the geometry's temporaries are some 20 numbers an entry (a pile: a million).
        for a in range(0, len(tk), SLICE):
            part = slice(a, a + SLICE)
            overlap[part] = self._geometry(tk[part], ck[part], s)[1]
        return tk, ck, overlap

    def compression(self, ck: np.ndarray, overlap: np.ndarray) -> np.ndarray:
        """How much body i of each contact is compressed (m): half the overlap between spheres
        (equal springs in series), all of it on a rigid wall."""
        pressed = np.maximum(overlap, 0.0)
        return np.where(self.pairs[ck, 1] >= 0, 0.5 * pressed, pressed)

    def normal_force(self, ck: np.ndarray, overlap: np.ndarray) -> np.ndarray:
        """The normal force's size (N) at these overlaps."""
        return self.stiffness[ck] * np.maximum(overlap, 0.0)

    def at(self, times: np.ndarray, s: np.ndarray) -> Engaged:
        """The contacts engaged at sorted `times` (T,), the bodies being at s (T, N, D) there."""
        tk, ck = self.engaged_pairs(times)
        model = self.model
        d = model.dim
        i, j = self.pairs[ck, 0], self.pairs[ck, 1]
        n, overlap, pair = self._geometry(tk, ck, s)
        si = s[tk, i]
        pressed = np.maximum(overlap, 0.0)
        # Equal springs in series share the overlap; a sphere on a rigid wall takes all of it.
        first = np.where(pair, 0.5 * pressed, pressed)
        compression = np.stack((first, np.where(pair, 0.5 * pressed, 0.0)), axis=-1)
        point = si + (self.radius_i[ck] - first)[:, None] * n
        normal_force = -(self.stiffness[ck] * pressed)[:, None] * n
        friction = None
        if model.friction:
            friction = np.zeros((len(ck), d))
            if self.rec_t is not None and len(ck):
                # The record of the step that ends at or after t (as contact_series).
                lo, hi = self.rec_start[ck], self.rec_end[ck]
                at = segment_search(self.rec_t, lo, hi, times[tk], side="left")
                valid = (at < hi) & (overlap >= -1e-9 * self.radius_i[ck])
                rows = np.minimum(at, np.maximum(hi - 1, 0))
                friction[valid] = self.rec_force[rows[valid]]
        return Engaged(tk, ck, i, j, overlap, n, compression, point, normal_force, friction)
