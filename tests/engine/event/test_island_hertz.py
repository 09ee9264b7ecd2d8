"""Hertz between spheres in the islands (collide/engine/event/island.py, substep.py `mapped_step`):
the DEM kernel's force (and its dashpot) with each contact's start and end stepped over s, against
an independent DOP853 integration of the same law."""

from __future__ import annotations

import numpy as np
import pytest

from collide.model import damping_ratio
from collide.run import run_scene
from collide.scene import parse_scene
from tests.engine.event.test_island import _glancing

YOUNG, POISSON = 1e8, 0.3


def _chain(seed: int, n: int, e: float, tol: float, cradle: bool = False) -> tuple[dict, tuple]:
    """n spheres on a line under Hertz (E 1e8 Pa), random masses and radii, the first coming in:
    apart by random gaps (separate collisions), or a Newton's cradle (the others touching at
    rest). Returns (scene, (masses, radii, positions, velocities))."""
    rng = np.random.default_rng(seed)
    m = rng.uniform(0.1, 1.0, n)
    r = rng.uniform(0.01, 0.03, n)
    v = np.zeros(n)
    v[0] = rng.uniform(0.5, 2.0)
    gaps = rng.uniform(0.01, 0.05, n - 1)
    if cradle:
        m[:], r[:] = m[0], r[0]
        gaps[1:] = 0.0
    x = np.concatenate([[0.0], np.cumsum(r[:-1] + r[1:] + gaps)])
    bodies = [{"name": f"b{i}", "mass": float(m[i]), "radius": float(r[i]), "position": float(x[i]),
               "velocity": float(v[i]), "material": "ball"} for i in range(n)]
    raw = {"dim": 1, "tol": tol, "contact": {"model": "hertz", "restitution": e},
           "material": [{"name": "ball", "youngs_modulus": YOUNG, "poisson_ratio": POISSON}], "body": bodies}
    return raw, (m, r, x, v)


def _reference(start: tuple, e: float) -> np.ndarray:
    """The same law integrated independently: DOP853 (rtol 1e-13) of every pair's force,
    4/3 E* sqrt(R*) delta^1.5 plus Hertz's dashpot 2 zeta sqrt(m* 2 E* sqrt(R* delta)) delta'
    (LIGGGHTS', unclipped) while it overlaps, restarted at each pair's start and end (located by
    scipy) so no step spans one; the velocities once no pair touches or closes."""
    from scipy.integrate import solve_ivp

    m, r, x, v = start
    n = len(m)
    estar = YOUNG / (2.0 * (1.0 - POISSON**2))
    reach = r[:-1] + r[1:]
    rstar = r[:-1] * r[1:] / reach
    mstar = m[:-1] * m[1:] / (m[:-1] + m[1:])
    zeta = float(damping_ratio(np.array(e), True))

    def rhs(_, y):
        delta = np.maximum(reach - (y[1:n] - y[:n - 1]), 0.0)
        closing = y[n:2 * n - 1] - y[n + 1:]
        f = 4.0 / 3.0 * estar * np.sqrt(rstar) * delta**1.5 + \
            2.0 * zeta * np.sqrt(mstar * 2.0 * estar * np.sqrt(rstar * delta)) * closing
        f = np.where(delta > 0.0, f, 0.0)  # on i + 1, minus on i
        acc = np.zeros(n)
        acc[1:] += f / m[1:]
        acc[:-1] -= f / m[:-1]
        return np.concatenate([y[n:], acc])

    y = np.concatenate([x, v])
    for _ in range(500):
        gaps = (y[1:n] - y[:n - 1]) - reach
        closing = y[n:2 * n - 1] - y[n + 1:]
        pressed = (gaps < -1e-14 * reach) | ((np.abs(gaps) <= 1e-14 * reach) & (closing >= 0.0))
        if not pressed.any():
            times = np.where(closing > 0.0, gaps / np.where(closing > 0.0, closing, 1.0), np.inf)
            p = int(np.argmin(times))
            if not np.isfinite(times[p]):
                return y[n:]
            y = np.concatenate([y[:n] + y[n:] * times[p], y[n:]])
            continue
        events = []
        for p in range(n - 1):
            if abs(gaps[p]) <= 1e-14 * reach[p] and abs(closing[p]) <= 1e-12 * np.abs(v).max():
                continue  # touching at rest (a cradle): the pair's overlap starts as t^3.5, no event
            def ev(_, z, p=p):
                return reach[p] - (z[p + 1] - z[p])
            ev.terminal, ev.direction = True, (-1.0 if pressed[p] else 1.0)
            events.append(ev)
        y = solve_ivp(rhs, (0.0, 1.0), y, method="DOP853", rtol=1e-13, atol=1e-18, events=events).y[:, -1]
    raise AssertionError("the reference did not settle")


def _check(raw: dict, start: tuple, e: float) -> None:
    m, v = start[0], start[3]
    run = run_scene(parse_scene(raw), record=False)
    r = run.result
    got = r.final.v[0].ravel()
    assert r.engine == "event", r.engine_reason
    assert "Hertz's force" in r.engine_reason
    assert run.error_method[0] == "measured"
    speed = np.abs(v).max()
    error = np.abs(got - _reference(start, e)).max() / speed
    # The speeds within 1e-8 at tol 1e-9, and the measured estimate holds (the error at most 10
    # times it).
    assert error <= 1e-8
    assert error <= 10.0 * run.error_estimate[0]
    # Momentum to round-off.
    assert abs((m * got).sum() - (m * v).sum()) <= 1e-13 * (m * speed).sum()
    # Energy: kept undamped; damped, what is lost is the dashpots' work. (Velocity errors of tol
    # times the speed move each body's energy by m v dv at most, summed; four times that allowed.)
    lost = 0.5 * (m * v**2).sum() - 0.5 * (m * got**2).sum()
    assert abs(lost - r.final.work[0]) <= 4e-9 * speed * (m * speed).sum()
    if e == 1.0:
        assert r.final.work[0] == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_hertz_chains_match_an_independent_integration(seed):
    """Chains of 3 to 5 spheres, undamped (even seeds) and with Hertz's dashpot (odd, e 0.5 to
    0.95), at tol 1e-9: separate collisions passing the impulse along."""
    e = 1.0 if seed % 2 == 0 else float(np.random.default_rng(50 + seed).uniform(0.5, 0.95))
    raw, start = _chain(seed, 3 + seed % 3, e, 1e-9)
    _check(raw, start, e)


@pytest.mark.parametrize("e", [1.0, 0.8])
def test_a_hertz_newtons_cradle_matches_an_independent_integration(e):
    """Five equal spheres, four touching at rest: under Hertz the impulse spreads through the
    touching contacts together (not the linear chain's one at a time)."""
    raw, start = _chain(7, 5, e, 1e-9, cradle=True)
    _check(raw, start, e)


def test_the_start_and_end_regions_keep_the_order():
    """Undamped Hertz chain: without the start and end regions over s a contact's error goes as
    (dt / t_c)^2.5; with them the outcome at tol 1e-8 is within the tolerance of the run at 1e-11,
    and a hundred times closer at 1e-10 (at least order 4 over dt, which shrinks 2.2 times)."""
    raw, start = _chain(1, 4, 1.0, 1e-11)
    speed = np.abs(start[3]).max()
    out = {}
    for tol in (1e-8, 1e-10, 1e-11):
        raw["tol"] = tol
        out[tol] = run_scene(parse_scene(raw), record=False, measure=False).result.final.v[0].ravel()
    coarse = np.abs(out[1e-8] - out[1e-11]).max() / speed
    fine = np.abs(out[1e-10] - out[1e-11]).max() / speed
    assert coarse <= 1e-8
    assert fine <= coarse / 25.0


def test_the_viewers_restitution_slider_keeps_a_hertz_chain_in_the_event_engine():
    """A slider moving a Hertz chain's restitution (viewer.params.build_scene) keeps the event
    engine, whose run is measured: no first-order DEM run for a law the islands step."""
    from viewer.params import build_scene, scene_controls

    raw, _ = _chain(1, 4, 1.0, 1e-6)
    controls = scene_controls(parse_scene(raw))
    scene = build_scene(controls, controls.defaults() | {"contact.restitution": 0.7}, controls.settings)
    assert scene.integrator == "kahan6" and scene.contact.restitution == 0.7
    run = run_scene(scene, record=False)
    assert run.result.engine == "event" and run.error_method[0] == "measured"
    assert run.error_estimate[0] <= 1e-6


def _rubbing(seed: int, dim: int) -> dict:
    """The damped islands' glancing trios (2D or 3D, spin, random mu, masses, radii and angles)
    under undamped Hertz with Coulomb friction."""
    raw = _glancing(seed, 1e-6, dim)
    raw["contact"] = {"model": "hertz", "youngs_modulus": 1e8, "mu": raw["contact"]["mu"]}
    return raw


@pytest.mark.parametrize("seed", range(8))
def test_hertz_with_coulomb_friction_between_spheres_meets_its_tolerance(seed):
    """Undamped Hertz with Coulomb friction in the islands (2D and 3D glancing trios, spin): the
    outcome at tol 1e-6 within the tolerance of the run at 1e-9, and within 10 times its
    measured estimate; its energy only falls (friction's work)."""
    dim = 2 if seed % 2 else 3
    raw = _rubbing(seed, dim)
    radii = np.array([b["radius"] for b in raw["body"]])[:, None]
    out = {}
    for tol in (1e-6, 1e-9):
        run = run_scene(parse_scene(dict(raw, tol=tol)), record=False)
        assert run.result.engine == "event" and "friction mode change" in run.result.engine_reason
        out[tol] = run, np.concatenate([run.result.final.v[0].ravel(), (run.result.final.w[0] * radii).ravel()])
    run = out[1e-6][0]
    off = np.abs(out[1e-6][1] - out[1e-9][1]).max() / 1.5
    assert run.error_method[0] == "measured"
    assert off <= 1e-6
    assert off <= 10.0 * run.error_estimate[0]
    # Energy: what the spheres lose is friction's work (a velocity error of tol times the speed
    # moves each body's energy by m v dv at most; four times that allowed).
    m = np.array([b["mass"] for b in raw["body"]])

    def energy(v, w):
        return 0.5 * (m * (v**2).sum(-1)).sum() + 0.2 * (m * radii[:, 0] ** 2 * (w**2).sum(-1)).sum()

    final = run.result.final
    w0 = np.array([np.atleast_1d(b["spin"]) for b in raw["body"]])
    lost = energy(np.array([b["velocity"] for b in raw["body"]]), w0) - energy(final.v[0], final.w[0])
    assert final.work[0] >= 0.0
    assert abs(lost - final.work[0]) <= 4e-6 * 1.5 * (m * 1.5).sum()
