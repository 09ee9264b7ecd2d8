"""A run's contacts at given times, only those engaged there: the viewer's frames and plots, and
a recording's frames of many contacts.

`diagnostics.contact_series` evaluates every contact the run ever had at every time asked:
(times x contacts), and a scan of every record per contact for friction. A gas of 1 000
spheres has 7 700 contacts over the run, a settling pile 3 700 engaged at once, so the plots'
400 times cost gigabytes and one frame seconds (issue 12). `ContactIndex` reads the run's contact
intervals (when each contact was engaged) and records once, and `at(times, s)` evaluates the
same quantities (overlap, compression, point, normal and friction force) only for the (time,
contact) pairs whose interval holds the time: memory O(contacts engaged at those times). The
forces are the engine's own, from its records (`collide.contact_forces`); the geometry (overlap,
normal, point) is the drawn bodies'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide.contact_forces import RecordedForces
from collide.engine import layout
from collide.model import Model
from collide.periodic import nearest_image
from collide.trajectory import Knots, Trajectory, segment_search

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
        self._names: list[str] | None = None
        # The forces as the engine recorded them (never a law evaluated here).
        self.forces = RecordedForces(traj, self.pairs, model.n_bodies, model.n_walls, model.dim,
                                     bool(model.friction))
        iv = traj.intervals
        self.iv_contact = self.forces.contact_of(iv[:, 0], iv[:, 1])
        start = iv[:, layout.V_START].astype(float) if len(iv) else np.zeros(0)
        # A contact still engaged when the run ended has no end: it lasts to the end.
        end = np.where(np.isnan(iv[:, layout.V_END]), np.inf, iv[:, layout.V_END]) if len(iv) else np.zeros(0)
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
        self.radius_i = model.radius[0, self.pairs[:, 0]] if len(self.pairs) else np.zeros(0)

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
        # A contact whose phases touch (one ends where the next begins) is listed once. Sorted
        # and compared with its neighbour: np.unique hashes, seconds for a pile's million entries.
        key = np.sort(tk * max(len(self), 1) + ck)
        if len(key) > 1:
            key = key[np.concatenate(([True], key[1:] != key[:-1]))]
        return key // max(len(self), 1), key % max(len(self), 1)

    def _geometry(self, tk: np.ndarray, ck: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Normal (E, D), overlap (E,), and whether each is a pair of spheres (E,)."""
        model = self.model
        i, j = self.pairs[ck, 0], self.pairs[ck, 1]
        pair = j >= 0
        si = s[tk, i]
        jj = np.where(pair, j, 0)
        delta = nearest_image(s[tk, jj] - si, model.period)
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

    def at(self, times: np.ndarray, s: np.ndarray) -> Engaged:
        """The contacts engaged at sorted `times` (T,), the bodies being at s (T, N, D) there."""
        tk, ck = self.engaged_pairs(times)
        model = self.model
        i, j = self.pairs[ck, 0], self.pairs[ck, 1]
        n, overlap, pair = self._geometry(tk, ck, s)
        si = s[tk, i]
        pressed = np.maximum(overlap, 0.0)
        # Equal springs in series share the overlap; a sphere on a rigid wall takes all of it.
        first = np.where(pair, 0.5 * pressed, pressed)
        compression = np.stack((first, np.where(pair, 0.5 * pressed, 0.0)), axis=-1)
        point = si + (self.radius_i[ck] - first)[:, None] * n
        # The engine's normal force along the drawn normal, on body i.
        normal_force = -self.forces.normal(ck, times[tk])[:, None] * n
        friction = None
        if model.friction:
            friction, found = self.forces.friction(ck, times[tk])
            # Not once the spheres have parted (the record after a contact's end is another phase's).
            friction[~(found & (overlap >= -1e-9 * self.radius_i[ck]))] = 0.0
        return Engaged(tk, ck, i, j, overlap, n, compression, point, normal_force, friction)
