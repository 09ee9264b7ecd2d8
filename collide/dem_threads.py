"""One DEM run on several threads: `dem_run` of `collide.engine.dem.loop` step for step, its
force pass and kicks split among the threads (`collide.engine.dem.threads`: every body's sums in
the one-thread order, so the run is the same bit for bit whatever the number of threads).

Every thread runs `threads.run_share` at once; they meet at a spinning barrier once a step (a
thread that needs another's part of a step waits for its flag: `collide.engine.dem.barrier`),
and come back here only for what one thread does: coasting where nothing touches, the steps
that record a frame, growing the record tables, and rebuilding the neighbour lists and the
threads' shares of them, whose passes over the bodies and pairs are split among the threads
again (`_rebuild`, `_Shares`). Where other work holds the
cores and the threads mostly wait for each other, the run goes on on one thread for a while
(`_Pace`). Below THREADS_FROM bodies a run takes one thread by default: the meetings cost more
than the split saves.
"""

from __future__ import annotations

import functools
import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from collide.engine.broad import BOX_ANY, NBOX
from collide.engine.dem import barrier
from collide.engine.dem import layout as dk
from collide.engine.dem import threads as par
from collide.engine.dem.flight import may_meet
from collide.engine.dem.forces import forces
from collide.engine.dem.loop import _any_rolling, _finish, _materials, _outputs, _step_length, flight, never_again
from collide.engine.dem.neighbours import (
    carry_rows,
    grid,
    keys_range,
    periodic_pairs,
    slot_regions,
    split_keys,
    wall_rows,
)
from collide.engine.dem.records import energy_row, frame
from collide.engine.dem.verlet import kick, kinetic
from collide.engine.numerics import grow

# Bodies from which a run takes every core by default (below, one thread: the hand-offs cost
# more than the split saves), measured with benchmarks/bench_dem.py --threads.
THREADS_FROM = 4000
# The last threaded run's figures (benchmarks/bench_dem.py shows them; of one of them if several
# run at once): threads, seconds, seconds in the threads' shares (the rest is this driver's, on
# one thread), stretches of steps it took on one thread (`_Pace`), and per thread the barrier's
# meetings, the flags it waited for, its sleeps and cycles spent waiting (`barrier`).
LAST_RUN: dict = {}


_POOL: list = []
_POOL_LOCK = threading.Lock()


def _pool(workers: int) -> ThreadPoolExecutor:
    with _POOL_LOCK:
        if not _POOL or _POOL[0][0] != os.getpid() or _POOL[0][1] < workers:
            _POOL[:] = [(os.getpid(), workers, ThreadPoolExecutor(workers, thread_name_prefix="collide-dem"))]
        return _POOL[0][2]


def _each(task, threads: int) -> None:
    """task(r) for every thread r, share 0 on this thread."""
    start = time.perf_counter()
    futures = [_pool(threads - 1).submit(task, r) for r in range(1, threads)] if threads > 1 else []
    task(0)
    for future in futures:
        future.result()
    LAST_RUN["parallel"] = LAST_RUN.get("parallel", 0.0) + time.perf_counter() - start


class _Shares:
    """The threads' shares of the current pair list and their buffers (`threads.plan`, then the
    passes over the pairs on the threads: `plan_count`, `plan_cross`); made as the list is
    built, before any force pass on it. New contacts take their slots from the regions
    (SBB, BUMP: `neighbours.slot_regions`) of the list's shares among all threads, whatever
    threads a stretch of steps takes (`_Pace`): one set of regions a list, so no slot is taken
    twice (`slots`: the all-threads shares, whose regions these share; None for those)."""

    def __init__(self, PI, PJ, PS, HS, WL, n: int, cut: np.ndarray, record: bool, rest: bool, slots=None):
        self.PI = PI
        threads = len(cut) - 1
        bounds, kb, wb, self.work = par.plan(PI, WL, n, cut)
        CNT = np.zeros((threads, threads), np.int64)
        _each(lambda r: par.plan_count(PJ, bounds, kb, r, CNT), threads)
        sb, ib, AT, starts = par.plan_slots(CNT)
        self.cross, self.inbound = np.empty(sb[threads], np.int64), np.empty(sb[threads], np.int64)
        _each(lambda r: par.plan_cross(PJ, bounds, kb, r, sb, AT, self.cross, self.inbound), threads)
        self.kb, self.wb = kb, wb
        self.SBB, self.BUMP = (bounds, slot_regions(PS, HS, starts)) if slots is None else (slots.SBB, slots.BUMP)
        self.RB = np.array([[bounds[r], bounds[r + 1], kb[r], kb[r + 1], wb[r], wb[r + 1], sb[r], sb[r + 1], ib[r],
                             ib[r + 1]] for r in range(threads)], np.int64)
        self.XB = np.zeros((len(self.cross), par.NX))
        self.SF = np.zeros(len(self.cross), np.int64)
        self.EVP = np.zeros(len(PI) if record else 0, np.int64)
        self.EVW = np.zeros(len(WL) if record else 0, np.int64)
        self.EB = np.zeros((n if rest else 0, 2))


def dem_run_threaded(X, V, W, Qo, Bd, tabs, wtabs, WP, grav, fl, fp, threads: int):
    """`loop.dem_run` on `threads` threads: the same arguments and outputs, bit for bit."""
    LAST_RUN.clear()
    start = time.perf_counter()
    out = _run(X, V, W, Qo, Bd, tabs, wtabs, WP, grav, fl, fp, threads)
    LAST_RUN.update(threads=threads, seconds=time.perf_counter() - start)
    return out


class _Crew:
    """What the threads of one count share apart from the pair list's plan: the barrier, and
    each thread's rows of figures (STT, PM) and scratch, padded (no two threads' rows in a cache
    line)."""

    def __init__(self, threads: int):
        self.barrier = barrier.rows(threads)  # (kept alive here while the threads wait at it)
        self.rows = (self.barrier, np.zeros((2, threads, par.NST_ROW)), np.zeros((2, threads)), np.zeros((threads, 16)))


class _Balance:
    """Where the bodies are cut among the threads (`threads.plan`): each thread's share of the
    work in proportion to its speed, work done a cycle busy (not waiting), learned from the
    stretches on all threads: a thread slowed by its share's contacts (the plan counts listed
    pairs, not engaged ones), or by its core, is given less. The result is the same bit for bit
    wherever the cuts fall."""

    KEEP, LEAST = 0.5, 0.5  # the weight of what was learned before; the least speed against the mean

    def __init__(self, threads: int):
        self.speed = np.ones(threads)

    def cut(self, threads: int) -> np.ndarray:
        speed = self.speed if threads == len(self.speed) else np.ones(threads)
        return np.concatenate(([0.0], np.cumsum(speed))) / speed.sum()

    def learn(self, work: np.ndarray, busy: np.ndarray) -> None:
        """A stretch's work (the plan's) and cycles busy, thread by thread."""
        if len(work) != len(self.speed) or (work <= 0).any() or (busy <= 0).any():
            return
        speed = work / busy
        speed = np.clip(speed / speed.mean(), self.LEAST, 1.0 / self.LEAST)
        self.speed = self.KEEP * self.speed + (1.0 - self.KEEP) * speed / speed.mean()


class _Pace:
    """How many threads each stretch of steps between the driver's turns takes: all of them, or
    one while all would be slower. Where other work holds the cores, the threads are seldom on
    them at once and wait for each other at every barrier: a stretch at which they waited more
    than half the time (more than WAITED of it, judged over at least MEETS meetings) is followed
    by stretches on one thread, 1, then 2, 4... up to LONGEST while it lasts, then all threads
    are tried again. The result is the same bit for bit whatever the threads."""

    WAITED, MEETS, LONGEST = 0.5, 50, 64

    def __init__(self, threads: int):
        self.all, self.alone, self.backoff = threads, 0, 1
        self.crews = {count: _Crew(count) for count in {1, threads}}

    def next(self) -> int:
        if self.alone > 0:
            self.alone -= 1
            return 1
        return self.all

    def run(self, task, use: int, work: np.ndarray, balance: _Balance) -> None:
        """task(r) on `use` threads, and whether the next stretches take one; the threads' busy
        cycles (for `work`, their shares of it) to `balance`."""
        rows = self.crews[use].barrier[:use]
        meets, each, start = rows[:, barrier.W_MEETS].sum(), rows[:, barrier.W_CYCLES].copy(), barrier.cycles()
        waited = each.mean()
        _each(task, use)
        span = barrier.cycles() - start
        if use > 1 and rows[:, barrier.W_MEETS].sum() - meets >= self.MEETS * use:
            balance.learn(work, span - (rows[:, barrier.W_CYCLES] - each))
            LAST_RUN["speeds"] = balance.speed.copy()
            if rows[:, barrier.W_CYCLES].mean() - waited > self.WAITED * span:
                self.alone, self.backoff = self.backoff, min(2 * self.backoff, self.LONGEST)
                LAST_RUN["alone"] = LAST_RUN.get("alone", 0) + self.alone
            else:
                self.backoff = 1
        crew = self.crews[self.all].barrier[:self.all]
        LAST_RUN.update(meets=crew[:, barrier.W_MEETS].copy(), flags=crew[:, barrier.W_FLAGWAITS].copy(),
                        sleeps=crew[:, barrier.W_SLEEPS].copy(), waited=crew[:, barrier.W_CYCLES].copy())


def _run(X, V, W, Qo, Bd, tabs, wtabs, WP, grav, fl, fp, threads):
    n = X.shape[0]
    dim, spin, rest, skin = fl[dk.F_DIM], fl[dk.F_SPIN], fp[dk.P_REST], fp[dk.P_SKIN]
    box = fp[dk.P_BOX:dk.P_BOX + NBOX]
    record = fl[dk.F_RECORD]
    ST, FG, F, T, PT, WK, WH = _outputs(n, WP.shape[0])
    KN, REC, IV, EP = np.zeros((0, dk.NK)), np.zeros((0, dk.NR)), np.zeros((0, 4)), np.zeros((0, dk.NEP))
    nkn, nep = 0, 0
    MAT = _materials(Bd, n)
    wt = wtabs.reshape((wtabs.shape[0], 1, wtabs.shape[1]))
    rolling = _any_rolling(tabs, wtabs, spin)
    X0 = X.copy()
    none = np.zeros(0, np.int64)
    PI, PJ, PS, HS, WL, WH = _rebuild(X, X0, Bd, WP, np.zeros((0, 4), np.int64), WH, n, dim, skin, none, none, none,
                                      np.zeros((0, dk.NH)), ST, box, threads)
    kept = (bool(record), rest > 0.0)  # (whether the shares keep events, bodies' energies)
    balance = _Balance(threads)
    shares = {threads: _Shares(PI, PJ, PS, HS, WL, n, balance.cut(threads), *kept)}
    scratch = np.zeros(4)
    pace = _Pace(threads)
    most = PI.shape[0] + WL.shape[0]
    if record:
        IV, REC = grow(IV, most), grow(REC, most)
    slots = shares[threads]
    engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, slots.SBB, slots.BUMP, WL, WH, WP, tabs, wt,
                                grav, fl, 0.0, 0.0, n, FG, ST, IV, 0, REC, 0, record != 0, scratch, box)
    if record:
        KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, 0.0, n, 0.0)
        EP = grow(EP, nep)
        EP[nep, :] = 0.0
        nep += 1
    C = np.zeros(par.NCTL)
    C[par.C_NEXT], C[par.C_PEAK], C[par.C_EVER] = fp[dk.P_FRAME], kinetic(V, W, Bd, n), engaged > 0
    C[par.C_ENGAGED], C[par.C_NIV], C[par.C_NREC] = engaged, niv, nrec
    while True:
        if shares[threads].PI is not PI:  # (the lists were rebuilt)
            shares = {threads: _Shares(PI, PJ, PS, HS, WL, n, balance.cut(threads), *kept)}
        use = pace.next()
        if use not in shares:
            shares[use] = _Shares(PI, PJ, PS, HS, WL, n, balance.cut(use), *kept, slots=shares[threads])
        s = shares[use]
        meet, STT, PM, outs = pace.crews[use].rows
        args = (meet, X, X0, V, W, Qo, F, T, PT, Bd, MAT, WK, PI, PJ, PS, HS, s.SBB, s.BUMP, WL, WH, WP, tabs, wt,
                grav, fl, fp, rolling, ST, FG, IV, REC, s.RB, s.kb, s.wb, s.cross, s.inbound, s.XB, s.SF, s.EVP, s.EVW,
                s.EB, STT, PM, outs, C)
        pace.run(functools.partial(_share, args), use, s.work, balance)
        reason, t = int(C[par.C_REASON]), C[par.C_T]
        C[par.C_STAY] = 0.0
        if reason == par.R_COAST:
            over, t, (PI, PJ, PS, HS, WL, WH), KN, nkn = _coast(X, X0, V, W, Qo, F, Bd, WK, WP, grav, fl, fp, t,
                                                                 C[par.C_EVER] != 0.0, (PI, PJ, PS, HS, WL, WH), ST,
                                                                 KN, nkn, threads)
            C[par.C_T], C[par.C_STAY] = t, 1.0
            if over:
                break
        elif reason == par.R_REBUILD:
            PI, PJ, PS, HS, WL, WH = _rebuild(X, X0, Bd, WP, WL, WH, n, dim, skin, PI, PJ, PS, HS, ST, box, threads)
        elif reason == par.R_GROW:
            most = PI.shape[0] + WL.shape[0]
            IV, REC = grow(IV, int(C[par.C_NIV]) + most), grow(REC, int(C[par.C_NREC]) + most)
        elif reason == par.R_RECORD:
            state = (X, V, W, Qo, F, T, PT, Bd, MAT, PI, PJ, PS, HS, s.SBB, s.BUMP, WL, WH, WP, tabs, wt, grav, fl, fp,
                     WK, rolling, ST, FG, scratch)
            over, IV, REC, KN, nkn, EP, nep = _recorded_step(state, C, IV, REC, KN, nkn, EP, nep)
            if over:
                break
        elif reason == par.R_MEET:
            if not may_meet(X, V, Bd, WP, grav, n, box):
                break
        else:
            if reason == par.R_NONFINITE:
                ST[dk.S_STATUS], FG[dk.G_STATUS_T] = dk.NONFINITE, t
            elif reason == par.R_MAXSTEPS:
                ST[dk.S_STATUS], FG[dk.G_STATUS_T] = dk.MAXSTEPS, t
            break
    t = C[par.C_T]
    ST[dk.S_STEPS] = int(C[par.C_STEPS])
    ST[dk.S_PAIRS] = PI.shape[0]
    niv, nrec = int(C[par.C_NIV]), int(C[par.C_NREC])
    KN, nkn, REC, nrec = _finish(X, V, W, Qo, F, Bd, WK, PS, HS, WH, PI, PJ, WL, t, record, ST, FG, KN, nkn, REC,
                                 nrec)
    return t, WK, KN[:nkn], REC[:nrec], IV[:niv], EP[:nep], ST, FG


def _rebuild(X, X0, Bd, WP, WL, WH, n, dim, skin, PI, PJ, PS, HS, ST, box, threads):
    """`neighbours.rebuild` with its work split among the threads by equal ranges of bodies (and
    of the new pairs, each range's bodies' pairs): the search for pairs (`keys_range`), the keys
    turned into pairs (`split_keys`), the engaged contacts' history carried over (`carry_rows`)
    and the body-wall pairs listed (`wall_rows`), each range written from the counts of those
    before it, so that the lists are `rebuild`'s, bit for bit, whatever the threads. The cell
    grid (`grid`, a counting sort) and a periodic box's search are made on this thread. Returns
    (PI, PJ, PS, HS, WL, WH)."""
    bounds = [n * r // threads for r in range(threads + 1)]
    if box[BOX_ANY] != 0.0:
        NI, NJ = periodic_pairs(X, Bd, n, dim, skin, box)
        firsts, parts = np.searchsorted(NI, bounds), None
    else:
        cells, start, order, table, span, dense = grid(X, Bd, n, dim, skin)
        parts = [None] * threads

        def search(r: int) -> None:
            parts[r] = keys_range(X, Bd, n, dim, skin, cells, start, order, table, span, dense, bounds[r],
                                  bounds[r + 1])

        _each(search, threads)
        del cells, start, order  # (the grid goes before the tables are made, as in `rebuild`)
        firsts = np.cumsum([0] + [count for _, count in parts])
        NI, NJ = np.empty(firsts[-1], np.int64), np.empty(firsts[-1], np.int64)
    NS = np.empty(len(NI), np.int64)
    carried, walls = np.zeros(threads + 1, np.int64), np.zeros(threads + 1, np.int64)
    none = (np.empty((0, 4), np.int64), np.empty((0, dk.NH)))

    def count(r: int) -> None:
        if parts is not None:
            split_keys(*parts[r], bounds[r], n, NI, NJ, firsts[r])
            parts[r] = None
        carried[r + 1] = carry_rows(PI, PJ, PS, HS, NI, NJ, n, firsts[r], firsts[r + 1], 0, NS, none[1])
        walls[r + 1] = wall_rows(X, Bd, WP, WL, WH, skin, bounds[r], bounds[r + 1], 0, *none)

    _each(count, threads)
    carried, walls = np.cumsum(carried), np.cumsum(walls)
    table = np.empty((carried[-1] + len(NI), dk.NH))
    NWL, NWH = np.empty((walls[-1], 4), np.int64), np.empty((walls[-1], dk.NH))

    def fill(r: int) -> None:
        carry_rows(PI, PJ, PS, HS, NI, NJ, n, firsts[r], firsts[r + 1], carried[r], NS, table)
        wall_rows(X, Bd, WP, WL, WH, skin, bounds[r], bounds[r + 1], walls[r], NWL, NWH)

    _each(fill, threads)
    X0[:, :] = X
    ST[dk.S_BUILDS] += 1
    return NI, NJ, NS, table, NWL, NWH


def _coast(X, X0, V, W, Qo, F, Bd, WK, WP, grav, fl, fp, t, ever, lists, ST, KN, nkn, threads):
    """`loop._coast` with its neighbour lists made by `_rebuild` (the pair search split among
    the threads), then the same flight (`loop.flight`). Returns (whether the run is over, t, the
    lists (PI, PJ, PS, HS, WL, WH), KN, nkn)."""
    if never_again(X, V, Bd, WP, grav, fp):
        return True, t, lists, KN, nkn
    box = fp[dk.P_BOX:dk.P_BOX + NBOX]
    lists = _rebuild(X, X0, Bd, WP, lists[4], lists[5], X.shape[0], fl[dk.F_DIM], fp[dk.P_SKIN], *lists[:4], ST, box,
                     threads)
    over, t, KN, nkn = flight(X, V, W, Qo, F, Bd, WK, WP, grav, fl, fp, t, ever, lists[0], lists[1], lists[4], ST, KN,
                             nkn)
    return over, t, lists, KN, nkn


def _share(args: tuple, r: int) -> None:
    par.run_share(r, args[0][r], *args[1:])  # (thread r's row of the barrier)


def _recorded_step(state, C, IV, REC, KN, nkn, EP, nep):
    """The rest of a step that records a frame, on this thread as `loop.dem_run` takes it (its
    opening kick and drift done). Returns (whether the run is over, IV, REC, KN, nkn, EP, nep)."""
    (X, V, W, Qo, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wt, grav, fl, fp, WK, rolling, ST,
     FG, scratch) = state
    n = X.shape[0]
    h, last = _step_length(C[par.C_T], fp[dk.P_DT], fp[dk.P_TEND])
    t = C[par.C_T] + h
    steps = int(C[par.C_STEPS]) + 1
    niv, nrec = int(C[par.C_NIV]), int(C[par.C_NREC])
    most = PI.shape[0] + WL.shape[0]
    if niv + most >= IV.shape[0]:
        IV = grow(IV, niv + most)
    if nrec + most >= REC.shape[0]:
        REC = grow(REC, nrec + most)
    engaged, niv, nrec = forces(X, V, W, F, T, PT, Bd, MAT, PI, PJ, PS, HS, BB, BUMP, WL, WH, WP, tabs, wt, grav, fl,
                                h, t, n, FG, ST, IV, niv, REC, nrec, True, scratch, fp[dk.P_BOX:dk.P_BOX + NBOX])
    kinetic_now = kick(V, W, F, T, PT, Bd, 0.5 * h, n, WK, rolling, True)
    ever = C[par.C_EVER] != 0.0 or engaged > 0
    if engaged:
        FG[dk.G_TOUCH] += h
    C[par.C_T], C[par.C_STEPS], C[par.C_FUSED], C[par.C_OPENED] = t, steps, 0.0, 0.0
    C[par.C_ENGAGED], C[par.C_NIV], C[par.C_NREC], C[par.C_EVER] = engaged, niv, nrec, ever
    if not math.isfinite(kinetic_now):
        ST[dk.S_STATUS], FG[dk.G_STATUS_T] = dk.NONFINITE, t
        return True, IV, REC, KN, nkn, EP, nep
    C[par.C_PEAK] = peak = max(C[par.C_PEAK], kinetic_now)
    KN, nkn = frame(KN, nkn, X, V, W, Qo, F, Bd, WK, t, n, 0.0)
    EP, nep = energy_row(EP, nep, t, WK, PS, HS, WH, n)
    while C[par.C_NEXT] <= t:
        C[par.C_NEXT] += fp[dk.P_FRAME]
    if steps & 255 == 0:
        fp[dk.P_NOW], fp[dk.P_NOW_STEPS], fp[dk.P_NOW_KINETIC], fp[dk.P_NOW_PEAK] = t, steps, kinetic_now, peak
    if steps >= fl[dk.F_MAXSTEPS]:
        ST[dk.S_STATUS], FG[dk.G_STATUS_T] = dk.MAXSTEPS, t
        return True, IV, REC, KN, nkn, EP, nep
    rest, t_end = fp[dk.P_REST], fp[dk.P_TEND]
    over = (rest > 0.0 and ever and kinetic_now < rest * peak) or last or (
        not math.isfinite(t_end) and ever and engaged == 0 and not may_meet(X, V, Bd, WP, grav, n,
                                                                             fp[dk.P_BOX:dk.P_BOX + NBOX]))
    return over, IV, REC, KN, nkn, EP, nep
