"""Oblique impacts with friction and a tangential spring in the event engine
(collide/engine/event/oblique.py; issue 51): over 100 seeded random cases of angle, spin,
stiffness ratio, friction and normal law, runs at tol 1e-6 and 1e-9 agree to 1e-6 and the 1e-6
run's reported error holds against the 1e-9 run (measured at most 10 times the estimate); a
handful against scipy's DOP853 (rtol 1e-12) integrating the same law, written here from
docs/design.md and collide/engine/dem/tangential.py's docstring, its stick and slip switches
located by scipy's events."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from collide.dem import damping_ratio
from collide.errors import RunError
from collide.run import run_scene
from collide.scene import parse_scene

R, DENSITY, E, NU, SPEED = 0.01, 7800.0, 2e11, 0.3, 1.0
MASS = DENSITY * 4.0 / 3.0 * math.pi * R**3
INERTIA = 0.4 * MASS * R * R


def _scene(case: dict, tol: float) -> dict:
    theta, spin, ratio, mu, model, e = (case[k] for k in ("theta", "spin", "ratio", "mu", "model", "e"))
    contact = {"model": model, "restitution": e, "tangential": "spring", "mu": mu,
               "tangential_stiffness_ratio": ratio, "rolling_friction": case.get("mu_r", 0.0)}
    if model == "linear":
        contact["k"] = 1e7
    return {"name": "oblique", "dim": 2, "tol": tol, "duration": 1e-3, "contact": contact,
            "material": [{"name": "steel", "density": DENSITY, "youngs_modulus": E, "poisson_ratio": NU}],
            "body": [{"name": "ball", "material": "steel", "radius": R, "position": [0.0, R + 1e-5],
                      "velocity": [SPEED * math.sin(theta), -SPEED * math.cos(theta)], "spin": spin}],
            "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}


def _run(case: dict, tol: float):
    run = run_scene(parse_scene(copy.deepcopy(_scene(case, tol))), record=False)
    res = run.result
    assert res.engine == "event", res.engine_reason
    assert "stick and slip located" in res.engine_reason
    return res.final.v[0, 0, :2].copy(), float(np.ravel(res.final.w[0])[-1]), float(np.max(run.error_estimate)), res


def _cases(n: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    return [{"theta": math.radians(rng.uniform(3.0, 87.0)), "spin": rng.uniform(-2.0, 2.0) * SPEED / R,
             "ratio": rng.uniform(0.1, 1.5), "mu": rng.uniform(0.02, 0.9),
             "model": ("hertz", "linear")[int(rng.integers(2))], "e": rng.choice([1.0, rng.uniform(0.3, 1.0)])}
            for _ in range(n)]


# What the event engine says when it hands a contact on (to DEM, which refuses tolerances this
# fine for a stiff steel contact): modes alternating without end, a measurement that does not
# confirm the run (mostly a saw whose phase the law leaves open), or steps that do not converge.
HANDED_ON = ("alternates between stick and slip", "could not be confirmed", "could not be integrated")


def _outcome(case: dict, tol: float):
    """(velocity, spin, estimate, result, run) of the case at tol, or None where it was refused or
    went to DEM, with one of the event engine's causes."""
    try:
        run = run_scene(parse_scene(copy.deepcopy(_scene(case, tol))), record=False)
    except RunError as exc:
        assert any(cause in str(exc) for cause in HANDED_ON), str(exc)
        return None
    res = run.result
    if res.engine != "event":
        assert any(cause in res.engine_reason for cause in HANDED_ON), res.engine_reason
        return None
    assert "stick and slip located" in res.engine_reason
    # Every oblique contact is confirmed by a run at a tenth of its tolerance.
    assert run.error_method[0] == "measured", res.warnings
    v, w = res.final.v[0, 0, :2].copy(), float(np.ravel(res.final.w[0])[-1])
    return v, w, float(np.max(run.error_estimate)), res, run


def test_random_oblique_impacts_agree_across_tolerances_and_their_error_holds():
    """130 cases, of which at least 100 run in the event engine at both tolerances: their outcomes
    (rebound velocity, spin times the radius) at tol 1e-6 and 1e-9 within 1e-6 of the speed, and
    the 1e-6 run's difference from the 1e-9 run at most 10 times its reported estimate. The rest
    are handed on with their cause (mostly a damped slip ending into a saw of sticks whose phase the
    law leaves open: collide/engine/event/oblique.py), never answered unconfirmed."""
    worst, worst_ratio, counted, handed_on = 0.0, 0.0, 0, 0
    for case in _cases(130, seed=51):
        coarse, fine = _outcome(case, 1e-6), _outcome(case, 1e-9)
        if coarse is None or fine is None:
            handed_on += 1
            continue
        (v6, w6, est6, _, _), (v9, w9, _, _, _) = coarse, fine
        counted += 1
        diff = max(np.abs(v6 - v9).max(), abs(w6 - w9) * R) / SPEED
        worst, worst_ratio = max(worst, diff), max(worst_ratio, diff / est6)
        assert diff <= 1e-6, (case, diff)
        assert diff <= 10.0 * est6, (case, diff, est6)
    print(f"{counted} cases in the event engine, {handed_on} handed on; worst difference {worst:.2e} of "
          f"the speed, {worst_ratio:.2f} times the estimate")
    assert counted >= 100


def reference(case: dict, hold: float = 1e-7) -> tuple[float, float]:
    """The same contact by DOP853 at rtol 1e-12: normal overlap and rate, the stretch, the
    centre's velocity along the wall and the spin, in stick or slip; each switch (the spring's
    force reaching mu F_n; slip stopping) located by scipy's events and the integration restarted
    there; a hold (`after_event`) until the point moves along the force at hold of the speed.
    With rolling resistance (case["mu_r"]) the spin rolls (the torque mu_r R max(F_n, 0) against
    its sign) or is held (locked, while the torque holding it, -(R - delta) F, is within that cap),
    each switch an event too. Returns (velocity along the wall, spin times R) after it."""
    hertz = case["model"] == "hertz"
    mu_r = case.get("mu_r", 0.0)
    roll = [0.0]  # the spin's sign while rolling, 0 held
    estar = E / (1.0 - NU * NU)
    zeta = float(damping_ratio(np.array(case["e"]), hertz))
    mu, ratio = case["mu"], case["ratio"]

    def law(delta, u):
        if hertz:
            kn = 2.0 * estar * math.sqrt(R * max(delta, 0.0))
            elastic = 4.0 / 3.0 * estar * math.sqrt(R * max(delta, 0.0)) * delta
        else:
            kn, elastic = 1e7, 1e7 * delta
        gamma = 2.0 * zeta * math.sqrt(MASS * kn)
        fn = elastic + gamma * u
        kt, gt = ratio * kn, math.sqrt(ratio) * gamma
        return fn, kn, kt, gt, mu * max(fn, 0.0)

    def parts(y, mode, s):
        delta, u, xi, v, w = y
        fn, kn, kt, gt, cap = law(delta, u)
        slip = v + (R - delta) * w
        f = -kt * xi - gt * slip if mode == "stick" else s * cap
        return fn, kn, kt, gt, cap, slip, f

    def rhs(_, y, mode, s):
        fn, kn, kt, gt, cap, slip, f = parts(y, mode, s)
        torque = (R - y[0]) * f - roll[0] * mu_r * R * max(fn, 0.0)
        return [y[1], -fn / MASS, slip if mode == "stick" else 0.0, f / MASS,
                torque / INERTIA if roll[0] != 0.0 or mu_r == 0.0 else 0.0]

    def turns(_, y, mode, s):
        if mu_r == 0.0:
            return 1.0
        fn, kn, kt, gt, cap, slip, f = parts(y, mode, s)
        return roll[0] * y[4] if roll[0] != 0.0 else mu_r * R * max(fn, 0.0) - abs((R - y[0]) * f)

    def leaves(_, y, mode, s):
        fn, kn, kt, gt, cap, slip, f = parts(y, mode, s)
        if mode == "stick":
            return cap - abs(f)
        if mode == "hold":
            return hold * SPEED - s * slip
        if gt > 0.0:
            return -s * slip
        # c = mu F_n / k_t: (2/3) (mu / ratio) delta for Hertz, (mu / ratio) delta for the spring
        return -s * slip - (2.0 / 3.0 if hertz else 1.0) * mu / ratio * y[1]

    def apart(_, y, mode, s):
        return y[0] if y[1] < 0 else 1.0

    for ev in (leaves, apart, turns):
        ev.terminal, ev.direction = True, -1
    theta = case["theta"]
    v0, w0 = SPEED * math.sin(theta), case["spin"]
    # Touching: the mode the ratio of spring to cap settles at (both vanish under Hertz)
    d = 1e-10 * R
    u0 = SPEED * math.cos(theta)
    fn, kn, kt, gt, cap = law(d, u0)
    slip0 = v0 + R * w0
    mode = "stick" if abs(kt * slip0 * d / u0 + gt * slip0) <= cap else "slip"
    s = -math.copysign(1.0, slip0)
    y, t = [0.0, u0, 0.0, v0, w0], 0.0
    roll[0] = math.copysign(1.0, w0)
    fresh = False  # rolling from a hold: the spin leaves zero at a rate that starts from zero
    # (a held spin is 0: its error absolute, at 1e-14 of the speed over R, or the steps collapse)
    atol = [1e-30, 1e-30, 1e-30, 1e-30, 1e-14 * SPEED / R] if mu_r > 0.0 else 1e-30
    for _ in range(20000):
        # (a spin just let go leaves zero as t^2: its zero at the start is not looked for again
        # over the first 1e-10 s, 1e-6 of the contact)
        sol = solve_ivp(rhs, (t, t + (1e-10 if fresh else 1.0)), y, method="DOP853", rtol=1e-12, atol=atol,
                        args=(mode, s), events=(leaves, apart) if fresh else (leaves, apart, turns), max_step=1e-6)
        fresh = False
        t, y = sol.t[-1], list(sol.y[:, -1])
        if sol.status == 1 and len(sol.t_events[1]):
            return y[3], y[4] * R
        fn, kn, kt, gt, cap, slip, f = parts(y, mode, s)
        if sol.status == 1 and len(sol.t_events) > 2 and len(sol.t_events[2]):
            need = -(R - y[0]) * f
            if roll[0] != 0.0:  # the spin reached zero: held where the cap holds it
                y[4] = 0.0
                roll[0] = 0.0 if abs(need) <= mu_r * R * max(fn, 0.0) else (-1.0 if need > 0.0 else 1.0)
            else:  # the torque holding it reached the cap: rolling the way the rest turns it
                roll[0], fresh = (-1.0 if need > 0.0 else 1.0), True
        elif sol.status == 1 and len(sol.t_events[0]):
            mode, s, y[2] = after_event(mode, s, (slip, f, cap, kt, gt), leaves, rhs, t, np.array(y), 2)
        t += 1e-15 * max(t, 1e-9)  # past the located switch
    raise AssertionError("the reference contact did not end")


# The references' hold (`after_event`) lasts from a slip's end, where the stick cannot hold
# either, until the point moves along the force at `hold` of the speed (1e-7 by default; the
# engine's is about 1e-14 n_mid; scipy's events are located to 1e-15 s, longer than the first
# sticks from a smaller one). While it lasts the DEM law's force lies between the cap and the cap
# less gamma_t times that slip, so the hold itself moves the outcome by at most gamma_t hold^2 /
# (mu F_n) of the speed (the hold lasts hold over the slip's acceleration, about 3.5 mu F_n / m):
# below 1e-13 here. Where the saw of sticks begins sets its phase, which the law does not fix
# (collide/engine/event/oblique.py): the tests measure that spread with a second hold.


def after_event(mode: str, s: float, at: tuple, leaves, rhs, t: float, y: np.ndarray,
                stretch: int) -> tuple[str, float, float]:
    """The references' mode after a located event (`switched`, at = (slip, f, cap, k_t,
    gamma_t) there), with the hold: where a slip ends (damped) and the stick, its stretch holding
    the cap, would leave the cap at once (`leaves` in stick below zero a short Euler step of its
    `rhs` on), the force is held at the cap (as in slip) until the point moves along it at the
    hold's speed (`leaves` in "hold"); the stretch then holds the cap and the contact sticks (the
    DEM law's limit: its dashpot's share is dropped at each return to the cap, so from there the
    force runs between the cap and the cap less gamma_t v_t, the sticks growing from zero
    length). A stick that cannot hold even after the hold (the cap zero where the damped normal
    force pulls: its event, looking for a crossing, would miss a stick over the cap from its start)
    slips instead."""
    slip, f, cap, kt, gt = at
    after, s_after, xi = ("stick", s, -s * cap / kt) if mode == "hold" else switched(mode, s, slip, f, cap, kt, gt)
    if mode != "stick" and gt > 0.0:
        probe = y.copy()
        probe[stretch] = xi
        probe = probe + 1e-12 * np.asarray(rhs(t, probe, "stick", s))
        if leaves(t, probe, "stick", s) < 0.0:
            # neither lasts: a slip's end is held; after a hold (the cap zero, F_n pulling) it slips
            return ("hold", s, xi) if mode == "slip" else ("slip", -math.copysign(1.0, slip), xi)
    return after, s_after, xi


def switched(mode: str, s: float, slip: float, f: float, cap: float, kt: float, gt: float) -> tuple[str, float, float]:
    """The references' switch at a located stick or slip event: (mode, slip's sign, stretch).
    Slip ends: stick, the stretch holding the cap. The spring reaches the cap: the stretch set to
    hold it alone (the DEM kernel's rule); it sticks on where the point moves along the force and
    the dashpot's share keeps it within the cap, else slips."""
    if mode == "slip":
        return "stick", s, -s * cap / kt
    s = math.copysign(1.0, f)
    held = s * cap - gt * slip  # the spring held at the cap, its dashpot's share dropped
    mode = "stick" if gt > 0.0 and s * slip >= 0.0 and abs(held) <= cap else "slip"
    stretch = -s * cap / kt
    return mode, s if mode == "stick" or s * slip < 0.0 else math.copysign(1.0, held), stretch


@pytest.mark.parametrize("case", _cases(6, seed=7) + [dict(c, mu_r=0.1) for c in _cases(6, seed=7)])
def test_oblique_impacts_match_dop853(case):
    """A handful of cases (both laws, damped and not, sticking and sliding) against DOP853:
    velocity along the wall and spin times R within 1e-8 of the speed at tol 1e-10."""
    v, w, _, _ = _run(case, 1e-10)
    ref_v, ref_w = reference(case)
    assert v[0] == pytest.approx(ref_v, abs=1e-8 * SPEED)
    assert w * R == pytest.approx(ref_w, abs=1e-8 * SPEED)


SAWS = _cases(130, seed=51)  # 110: a hold whose saw's phase barely matters; 94: one whose phase moves it 6e-3


def test_a_damped_slip_ending_where_the_stick_cannot_hold_is_held_then_sawn():
    """A case the event engine could not take before the hold (a damped slip ending late in the
    contact, where the stick cannot hold either; its steps did not converge there) against
    DOP853 taking the same hold by hand (`after_event`): within 1e-8 of the speed at tol 1e-10,
    plus the spread of the saw's phase, which the law leaves open and the reference measures by
    starting its hold's end at twice the speed (2.4e-11 here)."""
    case = SAWS[110]
    v, w, _, _ = _run(case, 1e-10)
    (ref_v, ref_w), (other_v, other_w) = reference(case), reference(case, 2e-7)
    spread = max(abs(ref_v - other_v), abs(ref_w - other_w))
    assert spread <= 1e-9 * SPEED  # the saw's phase matters little here (else the case proves nothing)
    assert v[0] == pytest.approx(ref_v, abs=1e-8 * SPEED + spread)
    assert w * R == pytest.approx(ref_w, abs=1e-8 * SPEED + spread)


def test_a_saw_whose_phase_moves_the_outcome_is_refused_with_its_cause():
    """A case whose saw's phase, which the law does not fix, moves the outcome by 6e-3 of the
    speed between DOP853 references starting it at 1e-7 and 2e-7 of the speed: the event
    engine's measurement (its run at a tenth of --tol starts the saw elsewhere) does not confirm
    a run at tol 1e-6, which is handed on with that cause, not answered."""
    case = SAWS[94]
    (ref_v, ref_w), (other_v, other_w) = reference(case), reference(case, 2e-7)
    assert max(abs(ref_v - other_v), abs(ref_w - other_w)) > 1e-4 * SPEED
    try:
        run = run_scene(parse_scene(copy.deepcopy(_scene(case, 1e-6))), record=False)
    except RunError as exc:
        assert "could not be confirmed" in str(exc), str(exc)
        return
    assert run.result.engine == "dem" and "could not be confirmed" in run.result.engine_reason


def test_a_slip_off_one_line_goes_to_dem_with_its_cause():
    """In 3D a ball spinning about the line it slides along (its contact point slips across it)
    is not the one-line contact the event engine takes: chosen by itself the run goes to DEM and
    says why; with the event engine asked for it is refused with that cause."""
    raw = _scene({"theta": 0.5, "spin": 0.0, "ratio": 0.5, "mu": 0.3, "model": "hertz", "e": 0.8}, 1e-3)
    raw["dim"] = 3
    body = raw["body"][0]
    body["position"], body["velocity"], body["spin"] = [0.0, 0.0, R + 1e-5], [0.5, 0.0, -0.8], [50.0, 0.0, 0.0]
    raw["wall"] = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    run = run_scene(parse_scene(copy.deepcopy(raw)), record=False)
    assert run.result.engine == "dem" and "not along one line" in run.result.engine_reason
    with pytest.raises(RunError, match="not along one line"):
        run_scene(parse_scene({**copy.deepcopy(raw), "integrator": "kahan6"}), record=False)


def _roll_on(P, T, y, stop, steps_per_period):
    """`oblique.middle` from the state y (over time, delta in Y0) to the stop, as `rub` steps a
    contact that gravity holds: the trail of `keep`'s rows."""
    from numba.typed import List

    from collide.engine.event import impact as im
    from collide.engine.event import oblique as ob

    P = P.copy()
    P[im.P_STOP] = stop
    P[im.P_SPEED] = 1e-17
    ws = np.zeros((9, ob.NY))
    floors = np.full(ob.NY, 1e-300)
    trail = List([(0.0,) * 13])
    trail.pop()
    count = np.zeros(2, np.int64)
    period = 2.0 * math.pi / math.sqrt(P[1] / P[4])
    t, mode, how = ob.middle(P, T, ob.STICK, 0.0, 0.0, period / steps_per_period, 10**7, y, ws, floors, trail,
                             count)
    assert how == 2 and t == stop
    return np.array(list(trail))


def test_a_ball_rolling_under_rolling_resistance_stops_where_the_closed_form_says_and_stays_held():
    """A solid ball rolling without slip on a floor (linear spring at its rest overlap, so F_n = m g;
    the tangential spring stretched to the steady force) under rolling resistance mu_r r F_n
    decelerates at a = mu_r r l m g / (I + m l^2) (l = r - delta the lever: 5/7 mu_r g for l = r)
    and stops at v0 / a after v0^2 / (2 a); then held: the spin locked at 0 (the torque that holds
    it, at most 5/7 of the cap). Both to 1e-9 relative: the motion is polynomial in time between
    the two located events, so the steps are exact to round-off (of 1e4 steps: 1e-12 a step)."""
    from collide.engine.event import impact as im
    from collide.engine.event import oblique as ob

    m, r, k, g, mu, mu_r, v0 = 0.1, 0.03, 1e6, 9.81, 0.5, 0.05, 0.5
    inertia = 0.4 * m * r * r
    P = im.impact_params(hertz=False, mstar=m, k=k, accel=g)
    deq = m * g / k
    lever = r - deq
    a = mu_r * r * lever * m * g / (inertia + m * lever**2)
    ratio = 2.0 / 7.0
    T = np.array([mu, ratio, math.sqrt(ratio), m, inertia, r, 0.0, 1.0, 1.0, math.inf, 0.0, 0.0, 0.0, mu_r, -1.0])
    y = np.zeros(ob.NY)
    y[ob.Y0], y[ob.YVT], y[ob.YWB] = deq, v0, -v0 / lever
    y[ob.YXI] = m * a / (ratio * k)  # the spring's force -k_t xi = m v' = -m a
    t_stop = v0 / a
    rows = _roll_on(P, T, y, 1.5 * t_stop, 8)
    spin = rows[:, 7]
    held = np.flatnonzero(spin == 0.0)
    assert held.size and (spin[held[0]:] == 0.0).all(), "held from the spin's zero on"
    assert rows[held[0], 0] == pytest.approx(t_stop, rel=1e-9)
    assert rows[held[0], 4] == pytest.approx(v0**2 / (2 * a), rel=1e-9)
    assert a == pytest.approx(5.0 / 7.0 * mu_r * g, rel=1e-4)  # (l = r less 3e-4)
    # Held: the tangential spring's release moves the centre by at most its stretch's share.
    assert np.abs(rows[held[0]:, 5]).max() <= 1.01 * a / math.sqrt(ratio * k / m)
