"""The DEM run on several threads (collide/dem_threads.py, collide/engine/dem/threads.py) against
the one-thread kernel (`loop.dem_run`): every output equal bit for bit, at 2 and 3 threads."""

from __future__ import annotations

import numpy as np
import pytest

from collide.dem import contact_time, kernel_args
from collide.model import compile_scenes
from collide.scene import parse_scene
from tests.dem_scenes import open_box_walls


def _box(n: int, shuffled: bool, rolling: float, seed: int) -> dict:
    """n spheres of two sizes and materials dropped in a box of five walls, shaken: many
    contacts open and close; `shuffled` numbers them at random (most pairs then join two
    threads' bodies)."""
    rng = np.random.default_rng(seed)
    per = int(np.ceil(n ** (1 / 3)))
    cells = np.array([(i, j, k) for k in range(per) for j in range(per) for i in range(per)][:n], float)
    if shuffled:
        cells = cells[rng.permutation(n)]
    side = per * 0.024
    bodies = [{"name": f"b{a}", "material": "glass" if a % 3 else "steel", "radius": 0.01 if a % 2 else 0.009,
               "position": (cells[a] * 0.024 + 0.012 + rng.uniform(-1e-3, 1e-3, 3)).tolist(),
               "velocity": rng.uniform(-1.5, 1.5, 3).tolist(), "spin": rng.uniform(-5, 5, 3).tolist()}
              for a in range(n)]
    walls = open_box_walls(side)
    return {"dim": 3, "integrator": "dem", "dt": 2e-5, "duration": 0.006, "gravity": [0.0, 0.0, -9.81],
            "contact": {"model": "hertz", "restitution": 0.5, "tangential": "spring", "mu": 0.4,
                        "rolling_friction": rolling},
            "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6, "poisson_ratio": 0.25},
                         {"name": "steel", "density": 7800.0, "youngs_modulus": 2e7, "poisson_ratio": 0.3}],
            "body": bodies, "wall": walls}


def _args(raw: dict, record: bool, rest: float):
    model, state = compile_scenes([parse_scene(raw)])
    t_c, _, _ = contact_time(model, state)
    duration = np.array([np.nan if rest else raw["duration"]])
    args, _ = kernel_args(model, state, 0, dt=np.array([raw["dt"]]), duration=duration, rest=np.array([rest or np.nan]),
                          record=record, max_steps=100_000, t_c=t_c)
    return args


def _copy(args):
    return tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args)


@pytest.mark.parametrize(("shuffled", "record", "rest", "rolling"),
                         [(False, False, 0.0, 0.0), (True, False, 0.0, 0.02), (True, True, 0.0, 0.0),
                          (False, True, 0.0, 0.02), (True, False, 0.05, 0.0)])
def test_threads_give_the_one_thread_run_bit_for_bit(shuffled, record, rest, rolling):
    """1, 2 and 3 threads: the final state (positions, velocities, spins, orientations), the work
    of each force part per body, the frames, records, intervals, energy parts, counts and
    figures all the same bits (recorded or not, stopped at rest or at a duration, with rolling
    resistance, bodies numbered along the box or at random)."""
    from collide.dem_threads import dem_run_threaded
    from collide.engine.dem.loop import dem_run

    args = _args(_box(64, shuffled, rolling, seed=3), record, rest)
    one = _copy(args)
    expected = dem_run(*one)
    assert expected[6][2] > 20  # contacts opened: not vacuous
    for threads in (2, 3):
        mine = _copy(args)
        got = dem_run_threaded(*mine, threads)
        for a, b in zip(one[:4] + expected, mine[:4] + got):
            assert np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
            assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


def test_a_run_takes_the_threads_asked_and_says_so(monkeypatch):
    """COLLIDE_THREADS (what `collide run --threads` sets) is the number of threads one compiled
    DEM run steps on, reported in its result (the summary's `threads`), its outcome the same as on
    one thread; unset, a run takes every core from THREADS_FROM bodies and one below."""
    from collide.dem import run_threads
    from collide.dem_threads import THREADS_FROM
    from collide.engine import tier
    from collide.run import run_scene
    from collide.stepper import cores

    scene = parse_scene(_box(27, True, 0.0, seed=5))
    results = {}
    for count in ("1", "2"):
        monkeypatch.setenv("COLLIDE_THREADS", count)
        results[count] = run_scene(scene, record=False).result
    assert results["1"].threads == 1
    assert results["2"].threads == (2 if tier.COMPILED else 1)  # interpreted kernels hold the GIL: one
    for field in ("s", "v", "w", "q", "work"):
        assert np.array_equal(getattr(results["1"].final, field), getattr(results["2"].final, field))
    monkeypatch.delenv("COLLIDE_THREADS")
    assert run_threads(THREADS_FROM - 1) == 1
    assert run_threads(THREADS_FROM) == cores()


@pytest.mark.parametrize("record", [False, True])
def test_threads_give_the_one_thread_run_bit_for_bit_in_a_periodic_box(record):
    """The same in a box periodic in x and y with a floor (docs/design.md section 10): pairs
    across the sides meet at their nearest images on every thread count alike."""
    from collide.dem_threads import dem_run_threaded
    from collide.engine.dem.loop import dem_run

    raw = _box(64, True, 0.0, seed=5)
    side = 4 * 0.024
    raw["wall"] = [w for w in raw["wall"] if w["normal"][2] != 0.0]
    raw["domain"] = {"lower": [0.0, 0.0, 0.0], "upper": [side, side, side], "periodic": ["x", "y"]}
    raw["duration"] = 0.02  # long enough for bodies to cross
    args = _args(raw, record, 0.0)
    one = _copy(args)
    expected = dem_run(*one)
    assert expected[6][2] > 20
    crossed = np.floor(one[0][:, :2] / side) != 0  # bodies that went across a side
    assert crossed.any()
    for threads in (2, 3):
        mine = _copy(args)
        got = dem_run_threaded(*mine, threads)
        for a, b in zip(one[:4] + expected, mine[:4] + got):
            assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


def test_a_run_that_changes_its_threads_between_stretches_gives_the_one_thread_run(monkeypatch):
    """Where the threads mostly wait for each other (other work holds the cores), the driver goes
    on on one thread for a while (`dem_threads._Pace`). Made to judge every stretch on two threads
    as waiting too long, a run alternates between two threads and one, rebuilding its lists on
    both kinds of stretch, and ends with the one-thread run's bits; the run reports its stretches
    on one thread and the barrier's meetings."""
    from collide.dem_threads import LAST_RUN, _Pace, dem_run_threaded
    from collide.engine.dem.layout import S_BUILDS
    from collide.engine.dem.loop import dem_run

    monkeypatch.setattr(_Pace, "WAITED", -1.0)
    monkeypatch.setattr(_Pace, "MEETS", 0)
    args = _args(_box(64, True, 0.0, seed=3), True, 0.0)
    one = _copy(args)
    expected = dem_run(*one)
    mine = _copy(args)
    got = dem_run_threaded(*mine, 2)
    for a, b in zip(one[:4] + expected, mine[:4] + got):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
    assert expected[6][S_BUILDS] > 4  # neighbour lists built: several stretches
    assert LAST_RUN["alone"] > 0 and LAST_RUN["meets"][0] > 0


def test_the_cuts_follow_the_threads_speeds():
    """`dem_threads._Balance`: a thread that took twice the cycles for the same work is given a
    third of the next, once learned (the speeds' ratio tends to 2 as the same stretch repeats);
    a stretch with a thread that did nothing teaches nothing."""
    from collide.dem_threads import _Balance

    balance = _Balance(2)
    assert np.allclose(balance.cut(2), [0.0, 0.5, 1.0])
    balance.learn(np.array([0, 100]), np.array([1.0, 2.0]))
    assert np.allclose(balance.cut(2), [0.0, 0.5, 1.0])
    for _ in range(40):
        balance.learn(np.array([100, 100]), np.array([1.0, 2.0]))
    assert np.allclose(balance.cut(2), [0.0, 2.0 / 3.0, 1.0])
    assert np.allclose(balance.cut(3), [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0])  # (another count: even)


def test_uneven_cuts_give_the_one_thread_run_bit_for_bit(monkeypatch):
    """Wherever the bodies are cut among the threads (here most to one thread, then most to the
    other, list after list), the run is the one-thread run bit for bit."""
    from collide.dem_threads import _Balance, dem_run_threaded
    from collide.engine.dem.loop import dem_run

    lists = []

    def cut(self, threads):
        lists.append(threads)
        heavy = np.full(threads, 1.0)
        heavy[len(lists) % threads] = 8.0
        return np.concatenate(([0.0], np.cumsum(heavy))) / heavy.sum()

    monkeypatch.setattr(_Balance, "cut", cut)
    args = _args(_box(64, False, 0.0, seed=4), True, 0.0)
    one = _copy(args)
    expected = dem_run(*one)
    mine = _copy(args)
    got = dem_run_threaded(*mine, 2)
    assert len(lists) > 4  # several lists, cut both ways
    for a, b in zip(one[:4] + expected, mine[:4] + got):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


@pytest.mark.parametrize("threads", [2, 3])
def test_a_rebuild_on_threads_makes_the_one_thread_lists(threads):
    """`dem_threads._rebuild` (the pair search, the keys' split, the history carried over and the
    body-wall list, each by ranges of bodies written from the counts before them) against the
    one-thread `neighbours.rebuild`, from lists holding contacts engaged, closed and never
    engaged: the same pairs, slots, carried history rows, wall list and wall history, bit for
    bit."""
    from collide.dem_threads import _rebuild
    from collide.engine.broad import NO_BOX
    from collide.engine.dem.layout import H_ON, NH, S_BUILDS
    from collide.engine.dem.neighbours import rebuild

    X, _, _, _, Bd, _, _, WP, _, _, _ = _args(_box(300, True, 0.0, seed=5), False, 0.0)
    rng = np.random.default_rng(6)
    n, skin = len(X), 0.008
    none = np.zeros(0, np.int64)
    ST = np.zeros(int(S_BUILDS) + 1, np.int64)
    PI, PJ, PS, HS, _, _, WL, WH = rebuild(X, X.copy(), Bd, WP, np.zeros((0, 4), np.int64), np.zeros((0, int(NH))),
                                           n, 3, skin, none, none, none, np.zeros((0, int(NH))), ST, NO_BOX)
    taken = rng.random(len(PI)) < 0.6  # slots taken: engaged, or closed since
    PS[taken] = rng.permutation(len(PI))[:taken.sum()]
    HS[:] = rng.normal(size=HS.shape)
    HS[:, H_ON] = rng.random(len(HS)) < 0.7
    WH[:] = rng.normal(size=WH.shape)
    WH[:, H_ON] = rng.random(len(WH)) < 0.7
    assert len(WL) > 20 and taken.sum() > 100  # not vacuous
    X = X + rng.uniform(-0.003, 0.003, X.shape)  # moved: pairs and wall pairs come and go
    X0, mine = X.copy(), X.copy()
    NI, NJ, NS, table, _, _, NWL, NWH = rebuild(X, X0, Bd, WP, WL, WH, n, 3, skin, PI, PJ, PS, HS, ST.copy(), NO_BOX)
    got = _rebuild(X, mine, Bd, WP, WL, WH, n, 3, skin, PI, PJ, PS, HS, ST.copy(), NO_BOX, threads)
    carried = len(table) - len(NS)
    assert carried > 50 and (got[3].shape == table.shape)
    for a, b in zip((NI, NJ, NS, table[:carried], NWL, NWH, X0), got[:3] + (got[3][:carried],) + got[4:] + (mine,)):
        assert a.tobytes() == b.tobytes()
