"""The force pass of a step: every listed contact's forces (`contact.contact_force`), each
contact's start and end (its history and interval), and the run's contact figures."""

from __future__ import annotations

import math

import numpy as np

from collide.engine.broad import BOX_ANY, nearest
from collide.engine.dem.contact import contact_force
from collide.engine.dem.geometry import wall_height
from collide.engine.dem.layout import (
    B_M,
    B_R,
    F_RECORD,
    G_FIRST,
    G_FORCE,
    G_LAST,
    G_OVERLAP,
    H_IV,
    H_KT,
    H_ON,
    H_PEAK,
    H_XI,
    S_CONTACTS,
)
from collide.engine.dem.neighbours import take_slot
from collide.engine.jit import jit, jit_inline


@jit
def forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wtabs, grav, fl, dt, t, n, FG, ST,
           IV, niv, REC, nrec, record_now, out, box):
    """Forces and torques of every engaged contact (F, T, and by part PT) and the run's contact
    figures, over the listed pairs (PI, PJ; their history in HS at slots PS, new contacts' slots
    taken from the regions BB, BUMP: `neighbours.take_slot`) and body-wall pairs (WL: rows
    k = i * walls + w, i, w); wtabs is
    the wall table as (materials, 1, columns). IV and REC have room for every listed contact
    (the caller grows them); out is scratch (4,). Returns (engaged, niv, nrec): no array is made
    or returned here, which at a few bodies costs a step as much as its contacts. In a periodic
    box (`box`) a pair meets at its nearest images."""
    record = fl[F_RECORD]
    g0, g1, g2 = grav[0], grav[1], grav[2]
    # Whole-array fills: stored element by element with F's, they took twice as long.
    T[:, :] = 0.0
    PT[:, :] = 0.0
    for a in range(n):
        m = Bd[a, B_M]
        F[a, 0], F[a, 1], F[a, 2] = m * g0, m * g1, m * g2
    # The pair pass in two copies, the nearest-image test folded away in the one without: a scene
    # with no periodic axis runs the pass it ran before periodic boundaries.
    if box[BOX_ANY] != 0.0:
        engaged, niv, nrec, deepest, strongest = _pairs(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB,
                                                        BUMP, tabs, fl, dt, t, FG, ST, IV, niv, REC, nrec, record,
                                                        record_now, out, box,
                                                        True)
    else:
        engaged, niv, nrec, deepest, strongest = _pairs(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB,
                                                        BUMP, tabs, fl, dt, t, FG, ST, IV, niv, REC, nrec, record,
                                                        record_now, out, box,
                                                        False)
    for m in range(WL.shape[0]):
        k, i, w = WL[m, 0], WL[m, 1], WL[m, 2]
        delta = Bd[i, B_R] - wall_height(X, WP, i, w)
        if delta <= 0.0:
            if WH[k, H_ON] != 0.0:
                nrec = _close(WH, k, IV, t, FG, REC, nrec, i, -1 - w)
            continue
        if WH[k, H_ON] == 0.0:
            niv = _open(WH, k, IV, niv, i, -1 - w, t, FG, ST, record)
        engaged += 1
        fn = contact_force(X, V, W, F, T, PT, Bd, i, -1 - w, -WP[w, 3], -WP[w, 4], -WP[w, 5], delta, wtabs, MAT[i], 0,
                           WH, k, fl, dt, out)
        deepest = max(deepest, delta)
        strongest = max(strongest, fn)
        if record:
            _peak(WH, k, t, delta, fn, out)
        if record_now:
            _record(REC, nrec, t, i, -1 - w, delta, fn, out)
            nrec += 1
    FG[G_OVERLAP], FG[G_FORCE] = deepest, strongest
    return engaged, niv, nrec


@jit_inline
def _pairs(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, tabs, fl, dt, t, FG, ST, IV, niv, REC, nrec, record,
           record_now, out, box, periodic):
    """The listed pairs' part of `forces` (at the nearest images if `periodic`). Returns (engaged,
    niv, nrec, deepest overlap, strongest force)."""
    engaged = 0
    deepest, strongest = FG[G_OVERLAP], FG[G_FORCE]
    for k in range(PI.shape[0]):
        i, j = PI[k], PJ[k]
        apart, dx, dy, dz, d2, reach = pair_gap(X, Bd, i, j, box, periodic)
        s = PS[k]
        if apart:
            if s >= 0 and HS[s, H_ON] != 0.0:
                nrec = _close(HS, s, IV, t, FG, REC, nrec, i, j)
            continue
        dist = math.sqrt(d2)
        inv = 1.0 / dist
        delta = reach - dist
        if s < 0 or HS[s, H_ON] == 0.0:
            s = take_slot(PS, BUMP, BB, k, j)
            niv = _open(HS, s, IV, niv, i, j, t, FG, ST, record)
        engaged += 1
        fn = contact_force(X, V, W, F, T, PT, Bd, i, j, dx * inv, dy * inv, dz * inv, delta, tabs, MAT[i], MAT[j],
                           HS, s, fl, dt, out)
        deepest = max(deepest, delta)
        strongest = max(strongest, fn)
        if record:
            _peak(HS, s, t, delta, fn, out)
        if record_now:
            _record(REC, nrec, t, i, j, delta, fn, out)
            nrec += 1
    return engaged, niv, nrec, deepest, strongest


@jit_inline
def pair_gap(X, Bd, i, j, box, periodic):
    """Whether spheres i and j are apart (not where a position is not a number: the contact's
    numbers then show it); the vector from i to j (at the nearest images if `periodic`), its
    squared length and their radii's sum."""
    dx = X[j, 0] - X[i, 0]
    dy = X[j, 1] - X[i, 1]
    dz = X[j, 2] - X[i, 2]
    if periodic:
        dx, dy, dz = nearest(dx, dy, dz, box)
    reach = Bd[i, B_R] + Bd[j, B_R]
    d2 = dx * dx + dy * dy + dz * dz
    return d2 >= reach * reach, dx, dy, dz, d2, reach


@jit_inline
def _open(hist, k, IV, niv, i, j, t, FG, ST, record):
    """Start contact k's history (and its interval row, IV having room). Returns niv."""
    hist[k, H_ON] = 1.0
    for c in range(3):
        hist[k, H_XI + c] = 0.0
    hist[k, H_KT] = 0.0
    hist[k, H_PEAK + 1] = -math.inf  # no force yet this phase
    ST[S_CONTACTS] += 1
    if not FG[G_FIRST] <= t:
        FG[G_FIRST] = t
    hist[k, H_IV] = -1.0
    if record:
        IV[niv, 0], IV[niv, 1], IV[niv, 2], IV[niv, 3] = i, j, t, np.nan
        hist[k, H_IV] = niv
        niv += 1
    return niv


@jit_inline
def _close(hist, k, IV, t, FG, REC, nrec, i, j):
    """End contact k's phase (its interval row, and its peak as a record: REC has room).
    Returns nrec."""
    if hist[k, H_IV] >= 0.0:
        nrec = peak_record(hist, k, REC, nrec, i, j)
    hist[k, H_ON] = 0.0
    # A spring released stores nothing; what it held was given back as it unloaded.
    for c in range(4):
        hist[k, H_XI + c] = 0.0
    FG[G_LAST] = t
    row = np.int64(hist[k, H_IV])
    if row >= 0:
        IV[row, 3] = t
    hist[k, H_IV] = -1.0
    return nrec


@jit_inline
def _peak(hist, k, t, delta, fn, out):
    """Keep the step's forces as contact k's peak if its normal force is the phase's largest."""
    if fn > hist[k, H_PEAK + 1]:
        hist[k, H_PEAK], hist[k, H_PEAK + 1], hist[k, H_PEAK + 2] = t, fn, delta
        for c in range(4):
            hist[k, H_PEAK + 3 + c] = out[c]


@jit_inline
def peak_record(hist, k, REC, nrec, i, j):
    """Contact k's peak so far as record row nrec (REC has room), if it had a force. Returns nrec."""
    if hist[k, H_PEAK + 1] == -math.inf:
        return nrec
    REC[nrec, 0], REC[nrec, 1], REC[nrec, 2] = hist[k, H_PEAK], i, j
    REC[nrec, 3], REC[nrec, 4] = hist[k, H_PEAK + 2], hist[k, H_PEAK + 1]
    for c in range(4):
        REC[nrec, 5 + c] = hist[k, H_PEAK + 3 + c]
    return nrec + 1


@jit_inline
def _record(REC, row, t, i, j, delta, fn, out):
    REC[row, 0], REC[row, 1], REC[row, 2], REC[row, 3], REC[row, 4] = t, i, j, delta, fn
    REC[row, 5], REC[row, 6], REC[row, 7], REC[row, 8] = out[0], out[1], out[2], out[3]
