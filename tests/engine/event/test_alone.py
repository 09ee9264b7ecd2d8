"""A sphere alone among walls (collide/engine/event/alone.py) and the contact it takes whole
(`impact.contact`): stopped at any time inside a contact, the state against DOP853 and the
linear spring-dashpot's closed form; a contact gravity holds goes on over time; a second wall in
reach stops the run with its status."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba.typed import List
from scipy.integrate import solve_ivp

from collide.dem import damping_ratio
from collide.engine import layout
from collide.engine.event import alone
from collide.engine.event import impact as im
from collide.engine.event.oblique import rub_steps
from tests.test_event_laws import rubber_ball


def _stopped(params, v, stop, tol=1e-10):
    P = params.copy()
    P[im.P_STOP] = stop
    out = np.zeros(im.NOUT)
    trail = List([(0.0, 0.0, 0.0, 0.0)])  # (emptied by `contact`: numba cannot type an empty list)
    n_end, n_mid = im.steps_for(tol, P)
    im.contact(P, v, n_end, n_mid, 10**6, out, trail)
    return out, trail


@pytest.mark.parametrize("share", [0.02, 0.1, 0.5, 0.9, 0.99])
def test_a_contact_stopped_anywhere_matches_dop853(share):
    """Stopped at a share of the contact time (in the rise over sigma, the middle over time, the
    fall over sigma), the overlap and its rate match DOP853 at rtol 1e-13 integrating to then."""
    params = rubber_ball(True, 0.8)
    v = math.sqrt(2 * 9.81)
    full = im.normal_impact(params, v, 1e-10)
    stop = share * full[im.O_TIME]
    out, trail = _stopped(params, v, stop)
    assert out[im.O_END] == im.STOPPED and out[im.O_TIME] == stop
    _, estar, rstar, mstar, zeta, accel = params[1:7]

    def rhs(_, y):
        delta, u = max(y[0], 0.0), y[1]
        kn = 2.0 * estar * math.sqrt(rstar * delta)
        force = 4.0 / 3.0 * estar * math.sqrt(rstar * delta) * delta + 2.0 * zeta * math.sqrt(mstar * kn) * u
        return [u, accel - force / mstar]

    sol = solve_ivp(rhs, (0.0, stop), [0.0, v], method="DOP853", rtol=1e-13, atol=1e-30, max_step=stop / 50)
    assert out[im.O_DELTA] == pytest.approx(sol.y[0, -1], rel=1e-8, abs=1e-8 * full[im.O_DMAX])
    assert out[im.O_U] == pytest.approx(sol.y[1, -1], rel=1e-8, abs=1e-8 * v)
    assert trail[-1][0] == stop and [row[0] for row in trail] == sorted(row[0] for row in trail)


def test_a_contact_gravity_holds_goes_on_over_time():
    """A slow, heavily damped ball does not separate (`impact` answers ok 0); `contact` steps it
    on to the stop, where it matches the linear spring-dashpot's closed form under gravity."""
    e, mstar, k, v, g = 0.1, 0.1, 1e5, 0.05, 9.81
    zeta = float(damping_ratio(np.array(e), False))
    params = im.impact_params(hertz=False, mstar=mstar, k=k, zeta=zeta, accel=g)
    stop = 0.07
    out, _ = _stopped(params, v, stop)
    assert out[im.O_END] == im.STOPPED
    omega = math.sqrt(k / mstar)
    omega_d = omega * math.sqrt(1 - zeta * zeta)
    d_eq = mstar * g / k
    a = -d_eq
    b = (v + zeta * omega * a) / omega_d
    decay = math.exp(-zeta * omega * stop)
    c, s = math.cos(omega_d * stop), math.sin(omega_d * stop)
    delta = d_eq + decay * (a * c + b * s)
    rate = decay * ((-zeta * omega) * (a * c + b * s) + omega_d * (b * c - a * s))
    assert out[im.O_DELTA] == pytest.approx(delta, rel=1e-9)
    assert out[im.O_U] == pytest.approx(rate, abs=1e-9 * v)


def _run(walls, position, velocity, t_end):
    params = rubber_ball(True, 0.8)
    G = np.zeros((1, layout.NG))
    G[0, layout.G_S:layout.G_S + 2] = position
    G[0, layout.G_V:layout.G_V + 2] = velocity
    G[0, layout.G_R], G[0, layout.G_M] = params[3], params[4]
    G[0, layout.G_IM] = 1.0 / params[4]
    WP = np.array(walls, dtype=float)
    laws = np.array(np.broadcast_to(params, (len(walls), params.size)), order="C")
    laws.setflags(write=False)  # as collide.alone.law_rows gives them (the compiled signature)
    fl = np.zeros(layout.NFL, np.int64)
    fl[layout.FL_RECORD], fl[layout.FL_MAXSTEPS], fl[layout.FL_PLANAR] = 1, 10**6, 1
    fp = np.zeros(layout.NFP)
    fp[layout.FP_TEND], fp[layout.FP_TAIL] = t_end, math.nan
    rubs = np.zeros((len(walls), 4))  # no tangential spring nor rolling resistance (collide.alone.rub_rows)
    rubs.setflags(write=False)
    return alone.alone_run(G, WP, laws, rubs, np.array([0.0, -9.81, 0.0]), fl, fp,
                           np.array(im.steps_for(1e-8, laws) + rub_steps(1e-8)))


def test_a_second_wall_within_reach_stops_the_run():
    """A ball landing on the floor 10 um from a side wall it moves toward at 0.5 m/s would touch
    both at once within the contact: the run stops there with ALONE_WALLS, naming the wall and
    the time."""
    floor, side = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0], [-0.03 - 1e-5, 0.0, 0.0, 1.0, 0.0, 0.0]
    landing = math.sqrt(2 * 0.17 / 9.81)
    _, _, _, _, st, fg = _run([floor, side], [0.5 * landing, 0.2], [-0.5, 0.0], 1.0)
    assert st[layout.S_STATUS] == alone.ALONE_WALLS and fg[layout.F_STATUS_A] == 0
    assert fg[layout.F_STATUS_T] == pytest.approx(landing)
    # Far from the side wall the same drop bounces on.
    t, knots, records, ivals, st, _ = _run([floor, side], [0.2, 0.2], [0.0, 0.0], 1.0)
    assert st[layout.S_STATUS] == layout.OK and len(ivals) >= 2 and t == 1.0
    assert (np.diff(knots[:, layout.K_T]) >= 0).all() and (records[:, layout.R_DELTA] >= 0).all()


# Rolling resistance (event/oblique.py's rolling and held modes) for a sphere alone among walls


def _rolling(**keys) -> dict:
    """A rubber ball dropped 1 mm onto a floor with backspin under rolling resistance (Hertz, e =
    0.5, a tangential spring capped by Coulomb): it bounces, slides, rolls from about 0.03 s and
    stops (held) at about 0.2 s."""
    r = 0.03
    raw = {"name": "rolling", "dim": 2, "duration": 0.4, "gravity": [0.0, -9.81],
           "contact": {"model": "hertz", "restitution": 0.5, "mu": 0.3, "tangential": "spring",
                       "rolling_friction": 0.2},
           "material": [{"name": "rubber", "density": 1100.0, "youngs_modulus": 5e6, "poisson_ratio": 0.45}],
           "body": [{"name": "ball", "material": "rubber", "radius": r, "position": [0.0, r + 1e-3],
                     "velocity": [0.4, 0.0], "spin": 5.0}],
           "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}
    return {**raw, **keys}


def _state(run) -> np.ndarray:
    res = run.result
    return np.r_[res.final.v[0, 0, :2], 0.03 * np.ravel(res.final.w[0])]


@pytest.mark.parametrize("duration", [0.05, 0.12, 0.4])
def test_a_ball_sliding_rolling_and_held_under_rolling_resistance_holds_its_measured_error(duration):
    """Stopped while it slides (0.05 s), while it rolls (0.12 s) and once held (0.4 s): in the event
    engine, its error measured, and the run at tol 1e-6 within 10 times its estimate of the run at
    1e-9 (velocities and spin times r, over the 0.4 m/s thrown); held at the end, the spin exactly 0."""
    from collide.run import run_scene
    from collide.scene import parse_scene

    runs = {tol: run_scene(parse_scene(_rolling(tol=tol, duration=duration)), record=False) for tol in (1e-6, 1e-9)}
    for run in runs.values():
        assert run.result.engine == "event", run.result.engine_reason
        assert "between rolling and held located" in run.result.engine_reason
        assert run.error_method[0] == "measured"
    error = np.abs(_state(runs[1e-6]) - _state(runs[1e-9])).max() / 0.4
    assert error <= 10 * float(np.max(runs[1e-6].error_estimate)), error
    if duration == 0.4:
        assert float(np.ravel(runs[1e-9].result.final.w[0])[-1]) == 0.0


def test_a_bouncing_ball_with_rolling_resistance_runs_at_full_order():
    """The built-in bounce (Hertz, e = 0.8) thrown along the floor with friction (a tangential
    spring) and rolling resistance: its bounces, and the contact that gravity then holds, in the
    event engine; tol 1e-6 within 10 times its estimate of tol 1e-9."""
    from collide.run import run_scene
    from collide.scene import load_scene

    changes = ["contact.mu=0.5", "contact.tangential=spring", "contact.rolling_friction=0.05"]
    runs = {tol: run_scene(load_scene("bounce", changes), tol=tol, record=False) for tol in (1e-6, 1e-9)}
    res = runs[1e-6].result
    assert res.engine == "event" and "between rolling and held located" in res.engine_reason
    assert runs[1e-6].error_method[0] == "measured" and res.contacts.count[0] >= 5
    error = np.abs(_state(runs[1e-6]) - _state(runs[1e-9])).max() / float(np.abs(res.initial.v).max() + 1e-300)
    assert error <= 10 * float(np.max(runs[1e-6].error_estimate)), error


def test_rolling_resistance_beyond_a_sphere_alone_goes_to_dem_with_its_cause():
    """With the dead band's Coulomb friction, or between two spheres with a wall: DEM, the JSON's reason naming
    why (and an event integrator asked for is refused with it)."""
    from collide.alone import engine_choice
    from collide.scene import SceneError, parse_scene

    dead_band = _rolling(contact={"model": "hertz", "restitution": 0.5, "mu": 0.3, "rolling_friction": 0.2})
    scene = parse_scene(dead_band)
    assert scene.integrator == "dem"
    assert "rolling resistance with Coulomb friction's dead band is DEM's so far" in engine_choice(scene, "dem",
                                                                                                    False)[1]
    two = _rolling()
    two["body"] = two["body"] + [{"name": "b", "material": "rubber", "radius": 0.03, "position": [0.2, 0.031]}]
    assert "between two with walls, is DEM's so far" in engine_choice(parse_scene(two), "dem", False)[1]
    with pytest.raises(SceneError, match="rolling resistance with Coulomb friction's dead band"):
        parse_scene({**dead_band, "integrator": "kahan6"})


def test_collide_run_answers_a_rolling_ball_at_the_default_tol_and_refuses_bad_values(tmp_path):
    """`collide run` of a ball rolling on a floor under rolling resistance at the default --tol
    (1e-6): exit 0, the event engine, the error measured; a negative rolling_friction: one line,
    exit 2."""
    import json
    import subprocess
    import sys

    from collide.scene import dump_toml

    def collide(path):
        return subprocess.run([sys.executable, "-m", "cli.main", "run", str(path), "--json"], capture_output=True,
                              text=True, timeout=600)

    path = tmp_path / "rolling.toml"
    raw = _rolling()
    path.write_text(dump_toml(raw))
    done = collide(path)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["engine"] == "event" and summary["tol"] == 1e-6 and summary["error_method"] == "measured"
    raw["contact"]["rolling_friction"] = -0.1
    path.write_text(dump_toml(raw))
    bad = collide(path)
    assert bad.returncode == 2 and "rolling_friction" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
