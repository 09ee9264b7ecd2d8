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
    n_end, n_mid = im.steps_for(tol)
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
                           np.array(im.steps_for(1e-8) + rub_steps(1e-8)))


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
