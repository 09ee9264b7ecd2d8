"""An island over a window (collide/engine/event/island.py): its phase's settings, where a trial
soon after a step's start is one Yoshida step; the restitution's dashpot stepped in islands, with
Coulomb friction too (its F_n through zero located: tests/engine/event/test_modes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import load_scene


def test_an_asymmetric_break_meets_its_tolerance_with_short_trials_as_yoshida_steps():
    """The cue ball 1 cm off the rack's line: every friction mode changes at its own time (143
    steps at tol 1e-6, 83 for the symmetric rack), many soon after a step's start, where a trial
    from the start is one Yoshida step if its error there is at most a tenth of a whole kahan6
    step's. The outcome at tol 1e-6 is within the tolerance of the run at 1e-9 (2.1e-7 of the
    cue ball's speed; with every trial a Yoshida step, 2e-4)."""
    scene = load_scene("billiards-break", ["body.cue.position.y=0.01"])
    speed = 6.0
    runs = {tol: run_scene(scene, tol=tol, record=False, measure=False).result for tol in (1e-6, 1e-9)}
    outcome = {tol: np.concatenate([r.final.v[0].ravel(), r.final.w[0].ravel() * scene.bodies[0].radius])
               for tol, r in runs.items()}
    assert np.abs(outcome[1e-6] - outcome[1e-9]).max() / speed < 1e-6
    assert dg.residuals(runs[1e-6]).energy[0] < 10 * 1e-6


# The restitution's dashpot with the linear spring, in islands (collide/engine/event/contact.py
# `dashpots`, stepped with the friction in substep.py): the DEM kernel's law, unclipped, so each
# separated head-on contact gives the restitution e exactly.

def _chain_scene(seed: int, tol: float, n: int = 3) -> tuple[dict, tuple, float]:
    """n spheres on a line, random masses, radii and e, the first coming in: (scene, (masses,
    radii, positions, velocities), e). Gaps of many contact times: separate collisions."""
    rng = np.random.default_rng(seed)
    # (Down to 0.5: at e = 0.32 five spheres' reference below missed the engine's outcome by 3e-3,
    # where DEM at dt 1e-6 agreed with the engine to 1e-4; that reference is not yet trusted there.)
    e = float(rng.uniform(0.5, 0.95))
    m = rng.uniform(0.1, 1.0, n)
    r = rng.uniform(0.01, 0.03, n)
    v = np.zeros(n)
    v[0] = rng.uniform(0.5, 2.0)
    x = np.concatenate([[0.0], np.cumsum(r[:-1] + r[1:] + rng.uniform(0.01, 0.05, n - 1))])
    bodies = [{"name": f"b{i}", "mass": float(m[i]), "radius": float(r[i]), "position": float(x[i]),
               "velocity": float(v[i])} for i in range(n)]
    return {"dim": 1, "tol": tol, "contact": {"k": 1e6, "restitution": e}, "body": bodies}, (m, r, x, v), e


def _chain_outcome(raw: dict, start: tuple, e: float) -> np.ndarray:
    """The same soft law integrated independently: DOP853 (rtol 1e-12) from contact event to contact
    event (each pair's gap crossing zero, located by scipy), the spring k delta plus the
    dashpot 2 zeta sqrt(m* k) delta' while the gap is closed, unclipped; the velocities once no
    pair touches or closes."""
    from scipy.integrate import solve_ivp

    from collide.model import damping_ratio

    m, r, x, v = start
    n, k = len(m), raw["contact"]["k"]
    reach = r[:-1] + r[1:]
    mstar = m[:-1] * m[1:] / (m[:-1] + m[1:])
    gamma = 2.0 * float(damping_ratio(np.array(e), False)) * np.sqrt(mstar * k)

    def rhs(_, y, on):
        pos, vel = y[:n], y[n:]
        delta = reach - (pos[1:] - pos[:-1])
        f = on * (k * delta + gamma * (vel[:-1] - vel[1:]))  # on i + 1, minus on i
        acc = np.zeros(n)
        acc[1:] += f / m[1:]
        acc[:-1] -= f / m[:-1]
        return np.concatenate([vel, acc])

    y, t = np.concatenate([x, v]), 0.0
    on = np.zeros(n - 1, bool)  # the pairs in contact, switched at their located events
    for _ in range(200 * n):
        if not on.any():
            gaps = (y[1:n] - y[:n - 1]) - reach
            closing = y[n:2 * n - 1] - y[n + 1:]
            times = np.where(closing > 0, gaps / np.where(closing > 0, closing, 1.0), np.inf)
            p = int(np.argmin(times))
            if not np.isfinite(times[p]):
                return y[n:]
            y = np.concatenate([y[:n] + y[n:] * times[p], y[n:]])
            on[p] = True
            continue
        events = []
        for p in range(n - 1):
            def ev(_, z, _on, p=p):
                return reach[p] - (z[p + 1] - z[p])
            ev.terminal, ev.direction = True, (-1.0 if on[p] else 1.0)
            events.append(ev)
        sol = solve_ivp(rhs, (t, t + 10.0), y, method="DOP853", rtol=1e-12, atol=1e-15, args=(on.copy(),),
                        events=events)
        t, y = sol.t[-1], sol.y[:, -1]
        for p in range(n - 1):
            if sol.t_events[p].size:
                on[p] = not on[p]
    raise AssertionError("the reference did not settle")


@pytest.mark.parametrize("seed", range(6))
def test_a_damped_chain_of_collisions_gives_the_restitution_exactly(seed):
    from collide.scene import parse_scene

    raw, start, e = _chain_scene(seed, 1e-9, n=3 + seed % 3)
    m, v = start[0], start[3]
    run = run_scene(parse_scene(raw), record=False)
    got = run.result.final.v[0].ravel()
    assert run.result.engine == "event"
    assert run.error_method[0] == "measured"
    speed = np.abs(v).max()
    # Each collision's e is exact for the unclipped dashpot: the chain's outcome to the tolerance.
    assert np.abs(got - _chain_outcome(raw, start, e)).max() <= 1e-8 * speed
    # Momentum to round-off; the energy lost is the work the dashpots took.
    assert abs((m * got).sum() - (m * v).sum()) <= 1e-13 * (m * speed).sum()
    # (The kicks count the work as kinetic energy changes: velocity errors of tol times the speed
    # move each body's energy by m v dv at most, summed; four times that allowed.)
    lost = 0.5 * (m * v**2).sum() - 0.5 * (m * got**2).sum()
    assert abs(lost - run.result.final.work[0]) <= 4 * 1e-9 * speed * (m * speed).sum()


def _glancing(seed: int, tol: float, dim: int) -> dict:
    """Three spheres with friction, spin and random e, mu, masses, radii and angles, in 2D or 3D."""
    rng = np.random.default_rng(100 + seed)
    bodies = []
    for i in range(3):
        pos = [0.08 * i, rng.uniform(-0.02, 0.02)] + ([rng.uniform(-0.02, 0.02)] if dim == 3 else [])
        vel = ([rng.uniform(-1, 1), rng.uniform(-0.3, 0.3)] + ([rng.uniform(-0.3, 0.3)] if dim == 3 else []))
        if i == 0:
            vel[0] = 1.5
        body = {"name": f"b{i}", "mass": float(rng.uniform(0.1, 1.0)), "radius": float(rng.uniform(0.015, 0.025)),
                "position": pos, "velocity": vel}
        body["spin"] = float(rng.uniform(-20, 20)) if dim == 2 else rng.uniform(-20, 20, 3).tolist()
        bodies.append(body)
    return {"dim": dim, "tol": tol, "duration": 0.3,
            "contact": {"k": 1e5, "restitution": float(rng.uniform(0.2, 0.95)), "mu": float(rng.uniform(0.1, 0.8))},
            "body": bodies}


@pytest.mark.parametrize("seed", range(6))
def test_damped_frictional_islands_conserve_momentum_and_balance_energy(seed):
    from collide.scene import parse_scene

    dim = 2 if seed % 2 else 3
    run = run_scene(parse_scene(_glancing(seed, 1e-7, dim)), record=False)
    r = run.result
    assert r.engine == "event" and run.error_method[0] == "measured"
    m = r.model.mass[0][:, None]
    v0, v1 = r.initial.v[0], r.final.v[0]
    scale = np.abs(v0).max()
    assert np.abs((m * v1).sum(0) - (m * v0).sum(0)).max() <= 1e-12 * (m * scale).sum()
    # Energy: what the dashpots and the friction took is the kinetic and spin energy lost (to the
    # tolerance's share of it: m v dv per body, dv at most tol times the speed; ten times that).
    inertia = r.model.inertia[0][:, None]

    def energy(s):
        return 0.5 * (m * s.v[0] ** 2).sum() + 0.5 * (inertia * s.w[0] ** 2).sum()

    assert abs(energy(r.initial) - energy(r.final) - r.final.work[0]) <= 1e-6 * energy(r.initial)


@pytest.mark.parametrize("seed", range(8))
def test_the_measured_error_of_damped_frictional_islands_holds_against_a_hundredth_of_the_tolerance(seed):
    """A damped contact's F_n passes zero before it ends, while it slides or not: the cap's kink,
    located (collide/engine/event/modes.py). At tol 1e-7, 1e-8 and 1e-9 each run's measured error
    holds against a run at a hundredth of its tolerance (measured at most 10 times the estimate).
    Unlocated, seed 3 (2D) was off by 1.9e-4 at 1e-7 and 3e-5 at 1e-9, at estimates of 1e-7 and
    1e-9."""
    from collide.accuracy import outcome, speed_scale
    from collide.scene import parse_scene

    dim = 2 if seed % 2 else 3
    for tol in (1e-7, 1e-8, 1e-9):
        scene = parse_scene(_glancing(seed, tol, dim))
        run = run_scene(scene, record=False)
        tight = run_scene(scene, tol=tol / 100, record=False, measure=False)
        assert run.result.engine == "event" and run.error_method[0] == "measured"
        off = np.abs(outcome(run.result) - outcome(tight.result)).max() / speed_scale(scene)
        assert off <= 10 * run.error_estimate[0]


def test_the_dem_kernel_converges_at_first_order_towards_the_islands_answer():
    from collide.scene import parse_scene

    raw, _, _ = _chain_scene(3, 1e-10, n=3)
    ref = run_scene(parse_scene(raw), record=False, measure=False).result.final.v[0].ravel()
    dem = []
    for dt in (4e-6, 2e-6, 1e-6):
        raw_dem = dict(raw, integrator="dem", dt=dt)
        dem.append(np.abs(run_scene(parse_scene(raw_dem), record=False, measure=False).result.final.v[0].ravel()
                          - ref).max())
    # First order: halving the step about halves the difference (within a factor 1.5 either way).
    for coarse, fine in zip(dem, dem[1:]):
        assert 1.4 < coarse / fine < 3.0
