"""The fixed-step DEM kernel: the contact laws of docs/design.md section 9, stepped as DEM codes step them.

Velocity Verlet at a fixed dt (half kick, drift, forces, half kick: LIGGGHTS' `nve/sphere`),
with forces from the positions after the drift and the half-step velocities; contacts switch on
and off at steps; a Verlet neighbour list (a hashed cell grid, rebuilt when a body has moved
half the skin) keeps the cost per step proportional to the bodies. Each contact composes:

- normal: linear (k delta, springs in series) or Hertz (4/3 E* sqrt(R*) delta^1.5);
- damping for a restitution e: gamma = 2 zeta sqrt(m* k_n), zeta = -ln e / sqrt(ln^2 e + pi^2),
  with k_n = dF/d delta (linear: the spring-dashpot formula; Hertz: LIGGGHTS' and LAMMPS'
  2 sqrt(5/6) beta sqrt(S_n m*), the same number). The force is not clipped at zero, so a
  contact may pull as it ends; with that choice e_out = e exactly for both laws;
- tangential: the report's Coulomb slip (mu F_n against any slip faster than eps) or a history
  spring (Cundall-Strack; Mindlin's stiffness for Hertz) with LIGGGHTS' tangential damping,
  capping spring plus dashpot at mu F_n (as LAMMPS' pair granular; LIGGGHTS 3.8 compares the
  spring alone and drops the dashpot while sliding). After a slip the spring alone holds the
  capped force (as LIGGGHTS); LAMMPS folds the dashpot's share into the stretch
  (-(F + gamma_t v_t) / k_t), which with Hertz and damping made the outcome drift as dt shrank
  (2 % between 400 and 102 400 steps per contact, measured, and growing) instead of converging;
- rolling resistance: a torque mu_r R* F_n against the relative rotation (rolling and
  twisting), capped by a viscous
  torque that would stop it in ROLL_STEPS steps (so that a ball at rest does not chatter, and a
  sphere with many contacts does not overshoot).

Work taken out by each part (damping, friction, rolling) is summed per body, so the energy
balance (kinetic + potential + elastic + dissipated) stays a check on the stepping.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.flight import turn
from collide.engine.jit import jit, jit_inline
from collide.engine.numerics import grow

# Bodies: B (N, NB).
B_IM, B_II, B_R, B_M, B_I, B_MAT = range(6)
NB = 6
# Contact tables (as collide.model, with the restitution column turned into the damping ratio
# zeta and sqrt(k_t / k_n) added by `collide.dem.kernel_tables`): k, mu, eps, E*, zeta, rolling
# friction, k_t / k_n, sqrt(k_t / k_n) (the tangential dashpot's factor: taken once a table, not
# once a contact a step).
T_K, T_MU, T_EPS, T_ESTAR, T_ZETA, T_ROLL, T_KTR, T_KTR_ROOT = range(8)
# History per contact: tangential spring (3), its stiffness (for the energy it stores: read
# only when recorded), open interval row, engaged.
H_XI, H_KT, H_IV, H_ON = 0, 3, 4, 5
NH = 6
# The contact forces' parts, per body (N, NPT): damping force, friction force, rolling torque.
# (Friction's torque is the rest of the torque: no other part has one.)
PT_DAMP, PT_FRIC, PT_ROLL = 0, 3, 6
NPT = 9
# Flags and figures.
F_DIM, F_SPIN, F_HERTZ, F_TSPRING, F_RECORD, F_MAXSTEPS = range(6)
NFLAG = 6
P_DT, P_TEND, P_REST, P_TAIL, P_FRAME, P_SKIN, P_NOW, P_NOW_STEPS = range(8)
NPAR = 8  # the last two are written by the run: time reached and steps, read by a progress display
# Outputs: stats (int) and figures (float).
S_STEPS, S_STATUS, S_CONTACTS, S_BUILDS, S_PAIRS, S_JUMPS = range(6)
NSTAT = 6
G_FIRST, G_LAST, G_TOUCH, G_OVERLAP, G_FORCE, G_DAMP, G_FRIC, G_ROLL, G_STORED, G_STATUS_T = range(10)
NFIG = 10
OK, NONFINITE, MAXSTEPS = 0, 1, 4
# Record layouts shared with the event engine (collide.engine.kernels): knots, records, intervals.
NK, NR = 23, 9
EP_T, EP_DAMP, EP_FRIC, EP_ROLL, EP_STORED = range(5)
NEP = 5
HASH_PRIMES = (73856093, 19349663, 83492791)
# The neighbour search's grid is dense (not hashed) where it has at most this many cells a body:
# 128 bytes a body at most, less than its state takes (a settling box has about 4).
DENSE_CELLS = 16
# Below mu_r R* F_n, rolling resistance is a viscous torque that would stop the relative rolling
# in this many steps: more than the 12 contacts a sphere can have, so that together they never
# overshoot (a cap of one step each made a sphere in a pile spin up, measured).
ROLL_STEPS = 16
for _name, _value in list(globals().items()):
    if _name.isupper() and type(_value) is int:
        globals()[_name] = np.int64(_value)


@jit_inline
def _cell(x, size):
    return np.int64(math.floor(x / size))


@jit
def build_pairs(P, Bd, n, dim, reach_pad):
    """Pairs (i < j) whose gap is under reach_pad: (keys i * n + j in ascending order, i, j). A
    cell grid whose cells hold their bodies contiguously (a counting sort), searched by
    `_gather_pairs`: a dense grid over the bodies' bounding box where it has at most
    DENSE_CELLS cells a body (a body's 3 x 3 x 3 cells are then 9 runs of consecutive cells:
    the search takes about half the time of a hashed grid's 27 cells, 1 000 spheres settling in
    a box), else the grid hashed into 8 n buckets (bodies spread far apart)."""
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, Bd[i, B_R])
    size = 2.0 * rmax + reach_pad
    lo = np.zeros(3)
    hi = np.zeros(3)
    span = np.ones(3, np.int64)
    total = 1.0
    for d in range(dim):
        lo[d], hi[d] = math.inf, -math.inf
        for i in range(n):
            lo[d], hi[d] = min(lo[d], P[i, d]), max(hi[d], P[i, d])
        total *= (hi[d] - lo[d]) / size + 1.0
    dense = total <= DENSE_CELLS * n  # (false for non-finite positions too)
    if dense:
        for d in range(dim):
            span[d] = _cell(hi[d] - lo[d], size) + 1
        table = span[0] * span[1] * span[2]
    else:
        table = 1
        while table < 8 * n:  # (few hash collisions: a collision's bodies are visited for nothing)
            table *= 2
    cells = np.zeros((n, 3), np.int64)
    bucket = np.empty(n, np.int64)
    start = np.zeros(table + 1, np.int64)
    for i in range(n):
        h = 0
        for d in range(dim):
            c = _cell(P[i, d] - lo[d], size)
            cells[i, d] = c
            h ^= c * HASH_PRIMES[d]
        bucket[i] = (cells[i, 0] * span[1] + cells[i, 1]) * span[2] + cells[i, 2] if dense else h & (table - 1)
        start[bucket[i] + 1] += 1
    for b in range(table):
        start[b + 1] += start[b]
    order = np.empty(n, np.int64)
    fill = start[:table].copy()
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    keys = np.empty(8 * n + 16, np.int64)
    while True:
        count = _gather_pairs(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, keys)
        if count >= 0:
            found = keys[:count]
            rows = np.empty(count, np.int64)
            partners = np.empty(count, np.int64)
            i = 0
            for k in range(count):  # (keys ascend: no division)
                while found[k] >= (i + 1) * n:
                    i += 1
                rows[k] = i
                partners[k] = found[k] - i * n
            return found, rows, partners
        # Out of room: start again with twice as much (rare; growing in the search loop would
        # count references to `keys` at every cell visited, which cost more than the search).
        keys = np.empty(2 * keys.shape[0], np.int64)


@jit_inline
def _partners(P, Bd, i, n, reach_pad, order, first, last, cells, cx, cy, cz, hashed, keys, count):
    """The bodies order[first:last] that are i's partners (j > i, within reach; `hashed`: from the
    cell (cx, cy, cz) itself, as a hashed bucket also holds other cells') into keys from count.
    Returns the new count."""
    for m in range(first, last):
        j = order[m]
        dx = P[j, 0] - P[i, 0]
        dy = P[j, 1] - P[i, 1]
        dz = P[j, 2] - P[i, 2]
        lim = Bd[i, B_R] + Bd[j, B_R] + reach_pad
        # Written always, kept if j is a partner: a branch here is a coin toss (j > i) that the
        # processor mispredicts half the time.
        keys[count] = i * n + j
        kept = (j > i) & (dx * dx + dy * dy + dz * dz < lim * lim)
        if hashed:
            kept &= (cells[j, 0] == cx) & (cells[j, 1] == cy) & (cells[j, 2] == cz)
        count += kept
    return count


@jit
def _gather_pairs(P, Bd, n, dim, reach_pad, cells, start, order, table, span, dense, keys):
    """The pairs of `build_pairs` into keys, each body's partners gathered from the 3^dim cells
    around it and sorted among themselves. Returns their number, or -1 if keys is too short."""
    count = 0
    reach = 1 if dim >= 1 else 0
    ry = 1 if dim >= 2 else 0
    rz = 1 if dim >= 3 else 0
    for i in range(n):
        first = count
        for ox in range(-reach, reach + 1):
            for oy in range(-ry, ry + 1):
                cx, cy = cells[i, 0] + ox, cells[i, 1] + oy
                if dense:
                    # The cells (cx, cy, cz - 1 .. cz + 1) are consecutive: one run.
                    if cx < 0 or cx >= span[0] or cy < 0 or cy >= span[1]:
                        continue
                    row = (cx * span[1] + cy) * span[2]
                    low = row + max(cells[i, 2] - rz, 0)
                    high = row + min(cells[i, 2] + rz, span[2] - 1)
                    if count + start[high + 1] - start[low] > keys.shape[0]:
                        return -1
                    count = _partners(P, Bd, i, n, reach_pad, order, start[low], start[high + 1], cells, cx, cy, 0,
                                      False, keys, count)
                    continue
                for oz in range(-rz, rz + 1):
                    cz = cells[i, 2] + oz
                    h = ((cx * HASH_PRIMES[0]) ^ (cy * HASH_PRIMES[1]) ^ (cz * HASH_PRIMES[2])) & (table - 1)
                    if count + start[h + 1] - start[h] > keys.shape[0]:
                        return -1
                    count = _partners(P, Bd, i, n, reach_pad, order, start[h], start[h + 1], cells, cx, cy, cz, True,
                                      keys, count)
        # i's row ascending (a handful of partners: insertion sort).
        for a in range(first + 1, count):
            key = keys[a]
            at = a
            while at > first and keys[at - 1] > key:
                keys[at] = keys[at - 1]
                at -= 1
            keys[at] = key
    return count


@jit
def carry_history(old_keys, old_hist, new_keys):
    """History rows of the new pair list: the old pair's where it was listed, else zero."""
    hist = np.zeros((new_keys.shape[0], NH))
    for k in range(new_keys.shape[0]):
        hist[k, H_IV] = -1.0
    a = 0
    for k in range(new_keys.shape[0]):
        while a < old_keys.shape[0] and old_keys[a] < new_keys[k]:
            a += 1
        if a < old_keys.shape[0] and old_keys[a] == new_keys[k]:
            for c in range(NH):
                hist[k, c] = old_hist[a, c]
    return hist


# One function per piece of a contact law; `contact_force` composes the ones a scene uses
# (flags fixed when the scene is compiled), as LAMMPS' pair_style granular composes sub-models.


@jit_inline
def normal_elastic(hertz, k, estar, rstar, delta):
    """Elastic normal force and stiffness dF/d delta: linear k delta, or Hertz 4/3 E* sqrt(R*) delta^1.5."""
    if hertz:
        root = math.sqrt(rstar * delta)
        return 4.0 / 3.0 * estar * root * delta, 2.0 * estar * root
    return k * delta, k


@jit_inline
def dashpot(zeta, mstar, k):
    """The dashpot for the restitution with a spring of stiffness k: 2 zeta sqrt(m* k)."""
    return 2.0 * zeta * math.sqrt(mstar * k)


@jit_inline
def tangential_spring(hist, k, nx, ny, nz, tx, ty, tz, kt, gt, cap, dt):
    """History spring with dashpot, capped at `cap`: the friction force on i and its mode (2
    stick, 1 slip). The stretch is turned into the current tangent plane at its length; after a
    slip the spring alone holds the capped force (module docstring)."""
    hx, hy, hz = hist[k, H_XI], hist[k, H_XI + 1], hist[k, H_XI + 2]
    hn = hx * nx + hy * ny + hz * nz
    if hn != 0.0:
        before = hx * hx + hy * hy + hz * hz
        hx, hy, hz = hx - hn * nx, hy - hn * ny, hz - hn * nz
        after = hx * hx + hy * hy + hz * hz
        if after > 0.0:
            scale = math.sqrt(before / after)
            hx, hy, hz = hx * scale, hy * scale, hz * scale
    hx, hy, hz = hx + tx * dt, hy + ty * dt, hz + tz * dt
    sx, sy, sz = -kt * hx - gt * tx, -kt * hy - gt * ty, -kt * hz - gt * tz
    mag2 = sx * sx + sy * sy + sz * sz
    mode = 2.0
    if mag2 > cap * cap:
        mode = 1.0
        ratio = cap / math.sqrt(mag2)
        sx, sy, sz = sx * ratio, sy * ratio, sz * ratio
        inv = 1.0 / kt
        hx, hy, hz = -sx * inv, -sy * inv, -sz * inv
    hist[k, H_XI], hist[k, H_XI + 1], hist[k, H_XI + 2] = hx, hy, hz
    hist[k, H_KT] = kt
    return sx, sy, sz, mode


@jit_inline
def coulomb_slip(tx, ty, tz, cap, eps):
    """The report's law: cap against any slip faster than the dead band eps, else nothing."""
    slip = math.sqrt(tx * tx + ty * ty + tz * tz)
    if slip > eps and slip > 0.0:
        f = cap / slip
        return -f * tx, -f * ty, -f * tz, 1.0
    return 0.0, 0.0, 0.0, 0.0


@jit_inline
def rolling_resistance(W, T, PT, Bd, i, j, cap, dt):
    """Torque up to `cap` against the relative rotation (rolling and twisting alike: LAMMPS
    composes a twisting model, here it shares mu_r, since a sphere left spinning about its
    contact normal would never stop), below it a viscous torque that would stop the rotation
    in ROLL_STEPS steps."""
    wx, wy, wz = W[i, 0], W[i, 1], W[i, 2]
    ieff = Bd[i, B_I]
    if j >= 0:
        wx, wy, wz = wx - W[j, 0], wy - W[j, 1], wz - W[j, 2]
        ieff = Bd[i, B_I] * Bd[j, B_I] / (Bd[i, B_I] + Bd[j, B_I])
    rate = math.sqrt(wx * wx + wy * wy + wz * wz)
    if rate == 0.0:
        return
    g = min(cap, ieff * rate / (ROLL_STEPS * dt)) / rate
    for d, wd in ((0, wx), (1, wy), (2, wz)):
        T[i, d] -= g * wd
        PT[i, PT_ROLL + d] -= g * wd
        if j >= 0:
            T[j, d] += g * wd
            PT[j, PT_ROLL + d] += g * wd


@jit_inline
def contact_force(X, V, W, F, T, PT, Bd, i, j, nx, ny, nz, delta, tabs, mi, mj, hist, k, fl, dt, out):
    """Add contact (i, j)'s forces and torques (j < 0: a rigid wall along -n) to F, T, and by
    part to PT. n points from i into j; the law's coefficients are tabs[mi, mj]. Returns the normal
    force; `out` gets the friction force on i (3) and the mode."""
    tspring, spin = fl[F_TSPRING], fl[F_SPIN]
    ri = Bd[i, B_R]
    if j >= 0:
        rj = Bd[j, B_R]
        ai, aj = ri - 0.5 * delta, rj - 0.5 * delta
        mstar = Bd[i, B_M] * Bd[j, B_M] / (Bd[i, B_M] + Bd[j, B_M])
        rstar = ri * rj / (ri + rj)
    else:
        ai, aj = ri - delta, 0.0
        mstar = Bd[i, B_M]
        rstar = ri
    # Surface velocities at the contact point: i's minus j's.
    vx, vy, vz = V[i, 0], V[i, 1], V[i, 2]
    if spin:
        vx += W[i, 1] * nz * ai - W[i, 2] * ny * ai
        vy += W[i, 2] * nx * ai - W[i, 0] * nz * ai
        vz += W[i, 0] * ny * ai - W[i, 1] * nx * ai
    if j >= 0:
        vx -= V[j, 0]
        vy -= V[j, 1]
        vz -= V[j, 2]
        if spin:
            vx += W[j, 1] * nz * aj - W[j, 2] * ny * aj
            vy += W[j, 2] * nx * aj - W[j, 0] * nz * aj
            vz += W[j, 0] * ny * aj - W[j, 1] * nx * aj
    vn = vx * nx + vy * ny + vz * nz  # the overlap's rate: > 0 while approaching
    tx, ty, tz = vx - vn * nx, vy - vn * ny, vz - vn * nz
    elastic, kn = normal_elastic(fl[F_HERTZ], tabs[mi, mj, T_K], tabs[mi, mj, T_ESTAR], rstar, delta)
    zeta = tabs[mi, mj, T_ZETA]
    gn = dashpot(zeta, mstar, kn) if zeta > 0.0 else 0.0
    damp = gn * vn
    fn = elastic + damp
    press = max(fn, 0.0)
    fx, fy, fz = -fn * nx, -fn * ny, -fn * nz  # on i
    mode = 0.0
    sx, sy, sz = 0.0, 0.0, 0.0  # friction on i
    mu = tabs[mi, mj, T_MU]
    if spin and (mu > 0.0 or tspring):
        if tspring:
            sx, sy, sz, mode = tangential_spring(hist, k, nx, ny, nz, tx, ty, tz, tabs[mi, mj, T_KTR] * kn,
                                                 gn * tabs[mi, mj, T_KTR_ROOT],
                                                 mu * press, dt)
        else:
            sx, sy, sz, mode = coulomb_slip(tx, ty, tz, mu * press, tabs[mi, mj, T_EPS])
        fx += sx
        fy += sy
        fz += sz
        # Torque a x F with a = ai n on i, -aj n on j (which takes -F).
        cx, cy, cz = ny * sz - nz * sy, nz * sx - nx * sz, nx * sy - ny * sx
        for d, c in ((0, cx), (1, cy), (2, cz)):
            T[i, d] += ai * c
            if j >= 0:
                T[j, d] += aj * c
        PT[i, PT_FRIC] += sx
        PT[i, PT_FRIC + 1] += sy
        PT[i, PT_FRIC + 2] += sz
        if j >= 0:
            PT[j, PT_FRIC] -= sx
            PT[j, PT_FRIC + 1] -= sy
            PT[j, PT_FRIC + 2] -= sz
    roll = tabs[mi, mj, T_ROLL]
    if spin and roll > 0.0 and press > 0.0:
        rolling_resistance(W, T, PT, Bd, i, j, roll * rstar * press, dt)
    F[i, 0] += fx
    F[i, 1] += fy
    F[i, 2] += fz
    dx, dy, dz = -damp * nx, -damp * ny, -damp * nz
    PT[i, PT_DAMP] += dx
    PT[i, PT_DAMP + 1] += dy
    PT[i, PT_DAMP + 2] += dz
    if j >= 0:
        F[j, 0] -= fx
        F[j, 1] -= fy
        F[j, 2] -= fz
        PT[j, PT_DAMP] -= dx
        PT[j, PT_DAMP + 1] -= dy
        PT[j, PT_DAMP + 2] -= dz
    out[0], out[1], out[2], out[3] = sx, sy, sz, mode
    return fn


@jit
def forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, hist, WL, WH, WP, tabs, wtabs, grav, fl, dt, t, n, FG, ST, IV, niv,
           REC, nrec, record_now, out):
    """Forces and torques of every engaged contact (F, T, and by part PT) and the run's contact
    figures, over the listed pairs (PI, PJ) and body-wall pairs (WL: rows k = i * walls + w, i, w); wtabs is
    the wall table as (materials, 1, columns). IV and REC have room for every listed contact
    (the caller grows them); out is scratch (4,). Returns (engaged, niv, nrec): no array is made
    or returned here, which at a few bodies costs a step as much as its contacts."""
    record = fl[F_RECORD]
    g0, g1, g2 = grav[0], grav[1], grav[2]
    # Whole-array fills: stored element by element with F's, they took twice as long.
    T[:, :] = 0.0
    PT[:, :] = 0.0
    for a in range(n):
        m = Bd[a, B_M]
        F[a, 0], F[a, 1], F[a, 2] = m * g0, m * g1, m * g2
    engaged = 0
    deepest, strongest = FG[G_OVERLAP], FG[G_FORCE]
    for k in range(PI.shape[0]):
        i, j = PI[k], PJ[k]
        dx = X[j, 0] - X[i, 0]
        dy = X[j, 1] - X[i, 1]
        dz = X[j, 2] - X[i, 2]
        reach = Bd[i, B_R] + Bd[j, B_R]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 >= reach * reach:
            if hist[k, H_ON] != 0.0:
                _close(hist, k, IV, t, FG)
            continue
        dist = math.sqrt(d2)
        inv = 1.0 / dist
        delta = reach - dist
        if hist[k, H_ON] == 0.0:
            niv = _open(hist, k, IV, niv, i, j, t, FG, ST, record)
        engaged += 1
        fn = contact_force(X, V, W, F, T, PT, Bd, i, j, dx * inv, dy * inv, dz * inv, delta, tabs, MAT[i], MAT[j],
                           hist, k, fl, dt, out)
        deepest = max(deepest, delta)
        strongest = max(strongest, fn)
        if record_now:
            _record(REC, nrec, t, i, j, delta, fn, out)
            nrec += 1
    for m in range(WL.shape[0]):
        k, i, w = WL[m, 0], WL[m, 1], WL[m, 2]
        h = ((X[i, 0] - WP[w, 0]) * WP[w, 3] + (X[i, 1] - WP[w, 1]) * WP[w, 4]
             + (X[i, 2] - WP[w, 2]) * WP[w, 5])
        delta = Bd[i, B_R] - h
        if delta <= 0.0:
            if WH[k, H_ON] != 0.0:
                _close(WH, k, IV, t, FG)
            continue
        if WH[k, H_ON] == 0.0:
            niv = _open(WH, k, IV, niv, i, -1 - w, t, FG, ST, record)
        engaged += 1
        fn = contact_force(X, V, W, F, T, PT, Bd, i, -1 - w, -WP[w, 3], -WP[w, 4], -WP[w, 5], delta, wtabs, MAT[i], 0,
                           WH, k, fl, dt, out)
        deepest = max(deepest, delta)
        strongest = max(strongest, fn)
        if record_now:
            _record(REC, nrec, t, i, -1 - w, delta, fn, out)
            nrec += 1
    FG[G_OVERLAP], FG[G_FORCE] = deepest, strongest
    return engaged, niv, nrec


@jit_inline
def _open(hist, k, IV, niv, i, j, t, FG, ST, record):
    """Start contact k's history (and its interval row, IV having room). Returns niv."""
    hist[k, H_ON] = 1.0
    for c in range(3):
        hist[k, H_XI + c] = 0.0
    hist[k, H_KT] = 0.0
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
def _close(hist, k, IV, t, FG):
    hist[k, H_ON] = 0.0
    # A spring released stores nothing; what it held was given back as it unloaded.
    for c in range(4):
        hist[k, H_XI + c] = 0.0
    FG[G_LAST] = t
    row = np.int64(hist[k, H_IV])
    if row >= 0:
        IV[row, 3] = t
    hist[k, H_IV] = -1.0


@jit_inline
def _record(REC, row, t, i, j, delta, fn, out):
    REC[row, 0], REC[row, 1], REC[row, 2], REC[row, 3], REC[row, 4] = t, i, j, delta, fn
    REC[row, 5], REC[row, 6], REC[row, 7], REC[row, 8] = out[0], out[1], out[2], out[3]


@jit_inline
def _half_kick(WK, a, h2, im, ii, spins, F, T, PT, rolling, vb0, vb1, vb2, wb0, wb1, wb2):
    """Body a's half kick as `kick` makes it (the same operations in the same order), its work
    booked in WK; returns the velocity and spin after it."""
    tx, ty, tz = T[a, 0], T[a, 1], T[a, 2]
    rx, ry, rz = 0.0, 0.0, 0.0
    if rolling:
        rx, ry, rz = PT[a, PT_ROLL], PT[a, PT_ROLL + 1], PT[a, PT_ROLL + 2]
    va0, va1, va2 = vb0 + h2 * F[a, 0] * im, vb1 + h2 * F[a, 1] * im, vb2 + h2 * F[a, 2] * im
    wa0, wa1, wa2 = wb0 + h2 * tx * ii, wb1 + h2 * ty * ii, wb2 + h2 * tz * ii
    v0, v1, v2 = 0.5 * (vb0 + va0), 0.5 * (vb1 + va1), 0.5 * (vb2 + va2)
    w0, w1, w2 = 0.5 * (wb0 + wa0), 0.5 * (wb1 + wa1), 0.5 * (wb2 + wa2)
    WK[a, 0] -= h2 * (PT[a, PT_DAMP] * v0 + PT[a, PT_DAMP + 1] * v1 + PT[a, PT_DAMP + 2] * v2)
    WK[a, 1] -= h2 * (PT[a, PT_FRIC] * v0 + PT[a, PT_FRIC + 1] * v1 + PT[a, PT_FRIC + 2] * v2
                      + ((tx - rx) * w0 + (ty - ry) * w1 + (tz - rz) * w2) * spins)
    if rolling:
        WK[a, 2] -= h2 * (rx * w0 + ry * w1 + rz * w2) * spins
    return va0, va1, va2, wa0, wa1, wa2


@jit
def kick(V, W, F, T, PT, Bd, h2, n, WK, rolling, energy):
    """A half kick of h2, and the work each part of the contact forces did in it, from the
    kinetic energy it changed: F . (v_before + v_after) / 2 h2 per body (exact for a kick, and
    additive over the parts). WK (N, 3) gathers minus that: damping, friction (with what the
    tangential springs hold), rolling resistance (if the scene has it). Returns the kinetic
    energy after the kick if asked (`energy`), else 0."""
    e = 0.0
    for a in range(n):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h2, im, ii, spins, F, T, PT, rolling,
                                            V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        if energy:
            e += 0.5 * Bd[a, B_M] * (v0 ** 2 + v1 ** 2 + v2 ** 2)
            e += 0.5 * Bd[a, B_I] * (w0 ** 2 + w1 ** 2 + w2 ** 2)
    return e


@jit
def drift(X, X0, V, W, Qo, h, n, spin, planar):
    """Move and turn every body for h at its velocity and spin. Returns the largest squared
    distance a body is from where the neighbour lists were built (X0)."""
    moved = 0.0
    for a in range(n):
        for d in range(3):
            X[a, d] += h * V[a, d]
        if spin:
            turn(Qo[a], W[a, 0], W[a, 1], W[a, 2], h, planar)
        ddx, ddy, ddz = X[a, 0] - X0[a, 0], X[a, 1] - X0[a, 1], X[a, 2] - X0[a, 2]
        moved = max(moved, ddx * ddx + ddy * ddy + ddz * ddz)
    return moved


@jit
def kick_kick_drift(X, X0, V, W, Qo, F, T, PT, Bd, WK, h_close, h_open, h, n, rolling, spin, planar):
    """One step's closing half kick (h_close), the next step's opening half kick (h_open) and its
    drift (h) in one pass over the bodies, each body's numbers as `kick`, `kick` and `drift` make
    them (bit for bit): as three passes they took 1.2-1.3 times as long (1 000 bodies). Returns (the
    kinetic energy between the kicks, as `kick` returns it; `drift`'s moved)."""
    e = 0.0
    moved = 0.0
    for a in range(n):
        im, ii, spins = Bd[a, B_IM], Bd[a, B_II], Bd[a, B_II] > 0.0
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_close, im, ii, spins, F, T, PT, rolling,
                                            V[a, 0], V[a, 1], V[a, 2], W[a, 0], W[a, 1], W[a, 2])
        e += 0.5 * Bd[a, B_M] * (v0 ** 2 + v1 ** 2 + v2 ** 2)
        e += 0.5 * Bd[a, B_I] * (w0 ** 2 + w1 ** 2 + w2 ** 2)
        v0, v1, v2, w0, w1, w2 = _half_kick(WK, a, h_open, im, ii, spins, F, T, PT, rolling, v0, v1, v2, w0, w1, w2)
        V[a, 0], V[a, 1], V[a, 2] = v0, v1, v2
        W[a, 0], W[a, 1], W[a, 2] = w0, w1, w2
        X[a, 0] += h * v0
        X[a, 1] += h * v1
        X[a, 2] += h * v2
        if spin:
            turn(Qo[a], w0, w1, w2, h, planar)
        ddx, ddy, ddz = X[a, 0] - X0[a, 0], X[a, 1] - X0[a, 1], X[a, 2] - X0[a, 2]
        moved = max(moved, ddx * ddx + ddy * ddy + ddz * ddz)
    return e, moved


@jit
def _stored(hist, WH):
    """The energy the tangential springs hold: 1/2 k_t |xi|^2 each."""
    total = 0.0
    for H in (hist, WH):
        for k in range(H.shape[0]):
            hx, hy, hz = H[k, H_XI], H[k, H_XI + 1], H[k, H_XI + 2]
            total += 0.5 * H[k, H_KT] * (hx * hx + hy * hy + hz * hz)
    return total


@jit
def _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, free):
    """Every body's state at t (knots); `free`: free flight follows, in closed form."""
    KN = grow(KN, nkn + n)
    for a in range(n):
        r = nkn + a
        KN[r, 0], KN[r, 1], KN[r, 2] = t, a, free
        for d in range(3):
            KN[r, 3 + d] = X[a, d]
            KN[r, 6 + d] = V[a, d]
            KN[r, 9 + d] = W[a, d]
            acc = F[a, d] * Bd[a, B_IM]
            KN[r, 16 + d] = acc
            KN[r, 19 + d] = acc
        for d in range(4):
            KN[r, 12 + d] = Qo[a, d]
        KN[r, 22] = WK[a, 0] + WK[a, 1] + WK[a, 2]
    return KN, nkn + n


@jit
def wall_list(X, Bd, WP, WH, n, skin):
    """Body-wall pairs within the skin of touching, and those still engaged (with the list rebuilt
    when a body has moved half the skin, no other can touch), in order: rows (i * walls + w, i, w)."""
    nw = WP.shape[0]
    out = np.empty((n * nw, 3), np.int64)
    count = 0
    for i in range(n):
        for w in range(nw):
            h = ((X[i, 0] - WP[w, 0]) * WP[w, 3] + (X[i, 1] - WP[w, 1]) * WP[w, 4]
                 + (X[i, 2] - WP[w, 2]) * WP[w, 5])
            if h - Bd[i, B_R] < skin or WH[i * nw + w, H_ON] != 0.0:
                out[count, 0], out[count, 1], out[count, 2] = i * nw + w, i, w
                count += 1
    return out[:count].copy()


@jit
def _rebuild(X, X0, Bd, WP, WH, n, dim, skin, keys, hist, ST):
    """Fresh neighbour lists (pairs as keys i * n + j and as (i, j); body-wall pairs), the
    listed pairs' history carried over."""
    fresh, PI, PJ = build_pairs(X, Bd, n, dim, skin)
    hist = carry_history(keys, hist, fresh)
    X0[:, :] = X
    ST[S_BUILDS] += 1
    return fresh, PI, PJ, hist, wall_list(X, Bd, WP, WH, n, skin)


@jit
def _free_time(X, V, Bd, PI, PJ, WL, WP, grav, n, skin):
    """How long every body can fly freely with no contact able to begin: until the fastest could
    have covered half the smallest gap (listed pairs, walls; an unlisted pair's gap is at least
    the skin, the lists being fresh), gravity included."""
    gap = skin
    for k in range(PI.shape[0]):
        i, j = PI[k], PJ[k]
        dx, dy, dz = X[j, 0] - X[i, 0], X[j, 1] - X[i, 1], X[j, 2] - X[i, 2]
        gap = min(gap, math.sqrt(dx * dx + dy * dy + dz * dz) - Bd[i, B_R] - Bd[j, B_R])
    for m in range(WL.shape[0]):
        i, w = WL[m, 1], WL[m, 2]
        h = ((X[i, 0] - WP[w, 0]) * WP[w, 3] + (X[i, 1] - WP[w, 1]) * WP[w, 4]
             + (X[i, 2] - WP[w, 2]) * WP[w, 5])
        gap = min(gap, h - Bd[i, B_R])
    if gap <= 0.0:
        return 0.0
    speed = 0.0
    for a in range(n):
        speed = max(speed, math.sqrt(V[a, 0] ** 2 + V[a, 1] ** 2 + V[a, 2] ** 2))
    g = math.sqrt(grav[0] ** 2 + grav[1] ** 2 + grav[2] ** 2)
    reach = 0.5 * gap  # each of two bodies may close it by half
    if g > 0.0:
        return (-speed + math.sqrt(speed * speed + 2.0 * g * reach)) / g
    return reach / speed if speed > 0.0 else math.inf


@jit
def _kinetic(V, W, Bd, n):
    e = 0.0
    for a in range(n):
        e += 0.5 * Bd[a, B_M] * (V[a, 0] ** 2 + V[a, 1] ** 2 + V[a, 2] ** 2)
        e += 0.5 * Bd[a, B_I] * (W[a, 0] ** 2 + W[a, 1] ** 2 + W[a, 2] ** 2)
    return e


@jit
def _will_meet(X, V, Bd, WP, grav, n):
    """Whether any two spheres, or a sphere and a wall, may touch in free flight: a pair on
    straight lines (a uniform gravity cancels in their relative motion), a wall when a sphere
    heads for it or gravity pulls it back (conservative: any component)."""
    for i in range(n):
        for j in range(i + 1, n):
            dx, dy, dz = X[j, 0] - X[i, 0], X[j, 1] - X[i, 1], X[j, 2] - X[i, 2]
            ux, uy, uz = V[j, 0] - V[i, 0], V[j, 1] - V[i, 1], V[j, 2] - V[i, 2]
            closing = dx * ux + dy * uy + dz * uz
            if closing >= 0.0:
                continue
            speed2 = ux * ux + uy * uy + uz * uz
            # Nearest approach of two straight lines.
            tau = -closing / speed2
            cx, cy, cz = dx + ux * tau, dy + uy * tau, dz + uz * tau
            reach = Bd[i, B_R] + Bd[j, B_R]
            if cx * cx + cy * cy + cz * cz < reach * reach:
                return True
        for w in range(WP.shape[0]):
            if V[i, 0] * WP[w, 3] + V[i, 1] * WP[w, 4] + V[i, 2] * WP[w, 5] < 0.0:
                return True
            if grav[0] * WP[w, 3] + grav[1] * WP[w, 4] + grav[2] * WP[w, 5] < 0.0:
                return True
    return False


@jit
def dem_run(X, V, W, Qo, Bd, tabs, wtabs, WP, grav, fl, fp):
    """Run to the end (duration, rest, or every contact over and none to come) at the fixed
    step fp[P_DT]. X, V, W (N, 3) and Qo (N, 4) are updated in place; WK (N, 3) returns each
    body's share of the work of damping, friction and rolling resistance. Returns (t, WK,
    knots, records, intervals, energy parts, stats, figures)."""
    n = X.shape[0]
    dim, planar = fl[F_DIM], fl[F_DIM] < 3
    dt, t_end, rest, skin = fp[P_DT], fp[P_TEND], fp[P_REST], fp[P_SKIN]
    record = fl[F_RECORD]
    ST = np.zeros(NSTAT, np.int64)
    FG = np.zeros(NFIG)
    FG[G_FIRST] = np.nan
    FG[G_LAST] = np.nan
    FG[G_STATUS_T] = np.nan
    F = np.zeros((n, 3))
    T = np.zeros((n, 3))
    PT = np.zeros((n, NPT))
    WK = np.zeros((n, 3))
    KN = np.zeros((0, NK))
    REC = np.zeros((0, NR))
    IV = np.zeros((0, 4))
    EP = np.zeros((0, NEP))
    nkn, nrec, niv, nep = 0, 0, 0, 0
    MAT = np.empty(n, np.int64)
    for a in range(n):
        MAT[a] = np.int64(Bd[a, B_MAT])
    wt = wtabs.reshape((wtabs.shape[0], 1, wtabs.shape[1]))
    rolling = False  # whether any contact has rolling resistance (the kick books it only then)
    if fl[F_SPIN]:
        for table in (tabs.reshape((-1, tabs.shape[-1])), wtabs):
            for r in range(table.shape[0]):
                rolling |= table[r, T_ROLL] > 0.0
    WH = np.zeros((n * WP.shape[0], NH))
    for k in range(WH.shape[0]):
        WH[k, H_IV] = -1.0
    X0 = X.copy()
    keys, PI, PJ, hist, WL = _rebuild(X, X0, Bd, WP, WH, n, dim, skin, np.zeros(0, np.int64), np.zeros((0, NH)), ST)
    t = 0.0
    scratch = np.zeros(4)
    # IV and REC get room for every listed contact to open and be recorded before forces runs,
    # so that no array is replaced inside its loops (that costs reference counting per contact);
    # checked here, as a call returning the arrays costs as much at a few bodies.
    most = PI.shape[0] + WL.shape[0]
    if record:
        IV = grow(IV, niv + most)
        REC = grow(REC, nrec + most)
    engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, hist, WL, WH, WP, tabs, wt, grav, fl,
                                0.0, t, n, FG, ST, IV, niv, REC, nrec, record != 0, scratch)
    if record:
        KN, nkn = _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
        EP = grow(EP, nep)
        EP[nep, :] = 0.0  # nothing done yet (grow leaves new rows unset)
        nep += 1
    next_frame = fp[P_FRAME]
    peak = _kinetic(V, W, Bd, n)
    ever = engaged > 0
    steps = 0
    last = False
    fused = False  # this step's opening kick and drift done by the last step's `kick_kick_drift`
    moved = 0.0
    while not last:
        if engaged == 0:
            # Nothing touches and nothing ever can (with no end set): the run is over, whether
            # or not anything touched before (bodies moving apart from the start, with nothing
            # ahead, stepped on until the step limit).
            if not math.isfinite(t_end) and not _will_meet(X, V, Bd, WP, grav, n):
                break
            # Nothing touches: fly in closed form as far as no contact can begin (free flight is
            # not stepped, as in the event engine), then step again.
            keys, PI, PJ, hist, WL = _rebuild(X, X0, Bd, WP, WH, n, dim, skin, keys, hist, ST)
            tau = _free_time(X, V, Bd, PI, PJ, WL, WP, grav, n, skin)
            if t + tau >= t_end * (1.0 - 1e-12):
                tau = t_end - t
            if tau > 2.0 * dt:
                if record:
                    if nkn >= n and KN[nkn - 1, 0] == t:
                        for r in range(nkn - n, nkn):
                            KN[r, 2] = 1.0
                    else:
                        KN, nkn = _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 1.0)
                for a in range(n):
                    for d in range(3):
                        X[a, d] += V[a, d] * tau + 0.5 * grav[d] * tau * tau
                        V[a, d] += grav[d] * tau
                    if fl[F_SPIN]:
                        turn(Qo[a], W[a, 0], W[a, 1], W[a, 2], tau, planar)
                t += tau
                ST[S_JUMPS] += 1
                if record:
                    KN, nkn = _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
                if t >= t_end * (1.0 - 1e-12):
                    break
                if not math.isfinite(t_end) and ever and not _will_meet(X, V, Bd, WP, grav, n):
                    break
        h = dt
        if t + h >= t_end * (1.0 - 1e-12):
            h = t_end - t
            last = True
        if h <= 0.0:
            break
        if not fused:
            kick(V, W, F, T, PT, Bd, 0.5 * h, n, WK, rolling, False)
            moved = drift(X, X0, V, W, Qo, h, n, fl[F_SPIN], planar)
        if 4.0 * moved > skin * skin:
            keys, PI, PJ, hist, WL = _rebuild(X, X0, Bd, WP, WH, n, dim, skin, keys, hist, ST)
        t = t + h
        steps += 1
        record_now = record != 0 and (t >= next_frame or last)
        most = PI.shape[0] + WL.shape[0]  # the lists may have been rebuilt
        if record and niv + most >= IV.shape[0]:
            IV = grow(IV, niv + most)
        if record_now and nrec + most >= REC.shape[0]:
            REC = grow(REC, nrec + most)
        engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, hist, WL, WH, WP, tabs, wt, grav,
                                    fl, h, t, n, FG, ST, IV, niv, REC, nrec, record_now, scratch)
        # The closing kick and, where nothing before the next step reads the velocities at this
        # step's end (no frame to record, no free flight, no end or rest to test), the next
        # step's opening kick and drift with it, in one pass over the bodies.
        h_next = dt
        if t + h_next >= t_end * (1.0 - 1e-12):
            h_next = t_end - t  # as the next step will take it
        fused = engaged != 0 and not last and not record_now and h_next > 0.0 and rest <= 0.0 and steps < fl[F_MAXSTEPS]
        if fused:
            kinetic, moved = kick_kick_drift(X, X0, V, W, Qo, F, T, PT, Bd, WK, 0.5 * h, 0.5 * h_next, h_next,
                                             n, rolling, fl[F_SPIN], planar)
        else:
            kinetic = kick(V, W, F, T, PT, Bd, 0.5 * h, n, WK, rolling, True)
        if engaged:
            FG[G_TOUCH] += h
            ever = True
        if not math.isfinite(kinetic):
            ST[S_STATUS] = NONFINITE
            FG[G_STATUS_T] = t
            break
        peak = max(peak, kinetic)
        if record_now:
            KN, nkn = _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
            EP = grow(EP, nep)
            EP[nep, EP_T] = t
            for c in range(3):
                s = 0.0
                for a in range(n):
                    s += WK[a, c]
                EP[nep, EP_DAMP + c] = s
            EP[nep, EP_STORED] = _stored(hist, WH)
            nep += 1
            while next_frame <= t:
                next_frame += fp[P_FRAME]
        if steps & 255 == 0:
            fp[P_NOW] = t
            fp[P_NOW_STEPS] = steps
        if steps >= fl[F_MAXSTEPS]:
            ST[S_STATUS] = MAXSTEPS
            FG[G_STATUS_T] = t
            break
        if rest > 0.0 and ever and kinetic < rest * peak:
            break
        if not math.isfinite(t_end) and ever and engaged == 0 and not _will_meet(X, V, Bd, WP, grav, n):
            break
    ST[S_STEPS] = steps
    ST[S_PAIRS] = keys.shape[0]
    FG[G_STORED] = _stored(hist, WH)
    for c in range(3):
        s = 0.0
        for a in range(n):
            s += WK[a, c]
        FG[G_DAMP + c] = s
    if record and (nkn == 0 or KN[nkn - 1, 0] < t):
        KN, nkn = _frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
    return t, WK, KN[:nkn], REC[:nrec], IV[:niv], EP[:nep], ST, FG
