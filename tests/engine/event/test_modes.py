"""Friction modes and their events (collide/engine/event/modes.py): a 3D slide's event value as its
slip turns, a stuck slip flipped across the band in one decision (`flips`), contacts that change
modes at once re-judged into consistent modes, a damped slide's F_n through zero against DOP853."""

from __future__ import annotations

import numpy as np
import pytest

from collide.engine import layout
from collide.engine.event import contact, modes
from collide.run import run_scene
from collide.scene import load_scene
from tests.engine.event.off_centre import _flip_runs, _off_centre_scales
from tests.engine.event.tables import pressed_island
from tests.tolerance_ladders import _tolerance_ladder


def test_a_3d_slides_event_value_is_continuous_as_its_slip_turns():
    """Out of the plane a slip near the band can turn half round without slowing to it (its way
    slaved to the other forces). The slide's event value must not jump as it turns, or the root
    search bisects the jump to the clock and gives up (40 trials: a pile of 27 spheres warned of
    dozens of such steps). It is |slip| cos^2(turn / 2) - eps: |slip| - eps while the slip keeps
    its way, and -eps reversed, so a slip that reverses through the band still changes sign."""
    X, C, CI, WP, nc, grav = pressed_island(3, 0, False)
    seed = np.int64(0)
    contact.geometry(X, C, CI, nc, WP, seed, layout.YES)
    contact.springs(X, C, CI, 2, nc, grav)
    contact.set_basis(C, 0, False)
    e1, e2 = C[0, layout.C_B:layout.C_B + 3], C[0, layout.C_B + 3:layout.C_B + 6]  # the tangent plane
    X[:, layout.X_W:layout.X_W + 3] = 0.0
    X[0, layout.X_V:layout.X_V + 3] = 0.0
    eps, size, mu = 1e-6, 37e-6, 0.3  # a slip of 37 eps, as in the pile
    CI[0, layout.CI_MODE] = layout.SLIDE
    C[0, layout.C_MU], C[0, layout.C_EPS] = mu, eps
    fl = np.zeros(int(layout.NFL), np.int64)
    fl[layout.FL_SPIN], fl[layout.FL_FRICTION], fl[layout.FL_PLANAR] = 1, 1, layout.NO
    E = np.zeros((2 * nc, 4))
    turns = np.linspace(0.0, np.pi, 721)
    values, held = [], None
    for turn in turns:
        X[1, layout.X_V:layout.X_V + 3] = -size * (np.cos(turn) * e1 + np.sin(turn) * e2)
        contact.geometry(X, C, CI, nc, WP, seed, layout.YES)
        slip = np.array(contact.slip(X, C, CI, 0, layout.X_V, layout.X_W, 1, False))
        if held is None:
            held = slip / np.linalg.norm(slip)
        C[0, layout.C_HELD:layout.C_HELD + 3] = held
        assert modes.mode_events(X, C, CI, E, 2, nc, layout.E_V0, layout.E_R0, np.zeros(3, np.int64), np.zeros((6, 6)),
                              np.zeros(6), fl, 1.0, layout.YES, layout.NO)
        values.append(E[0, layout.E_V0])
    values = np.array(values)
    expected = np.linalg.norm(slip) * np.cos(turns / 2) ** 2 - eps
    assert values == pytest.approx(expected, rel=1e-9, abs=1e-9 * size)
    # Continuous: between neighbouring turns it moves by at most |slip| / 2 per radian.
    assert np.abs(np.diff(values)).max() <= 0.5 * size * (turns[1] - turns[0]) * (1 + 1e-6)
    assert values[0] > 0 > values[-1]  # and a reversal is below the band's edge


def test_a_hold_force_through_zero_flips_the_slip_to_the_bands_other_edge():
    """A stuck contact whose hold force comes to zero crosses the band (no friction there) to its
    other edge, where it sticks again: two mode changes a fraction of a microsecond apart, each
    ending the whole group's step. Where the crossing is that short (`flips`), it is taken as
    the impulse that moves the slip across, in one decision. The off-centre break at tol 1e-6
    flips 20 times, each within FLIP_SHARE / FLIP_SAFETY (1/8) of the event tolerance (8.3e-8 of
    the cue ball's speed here: half the band): together at most 2.1e-7 (measured 4e-9) from
    the run with both changes landed, in fewer steps (113 against 131). The interpreted kernels,
    so that the gate can be switched off."""
    runs = _flip_runs("on", "no-flips")
    speed, event_tol = _off_centre_scales()
    per_flip = layout.FLIP_SHARE / layout.FLIP_SAFETY * event_tol
    flips = runs["on"][1]
    assert flips > 0 and runs["no-flips"][1] == 0
    assert runs["on"][0] < runs["no-flips"][0]
    assert np.abs(runs["on"][4] - runs["no-flips"][4]).max() / speed <= flips * per_flip


@pytest.mark.parametrize("offset", ["0", "0.01"])
@pytest.mark.parametrize("eps", ["1e-5", "1e-4"])
def test_flips_across_a_wide_band_keep_the_break_within_its_tolerance(eps, offset):
    """A wider band takes longer to cross (T grows as sqrt(eps)), and in that time the contact
    may end, another contact change its mode, or the hold force at the far edge pass mu F_n: a
    flip then stands for friction that never acts. Taken wherever the crossing's own model
    (the hold force's rate and curvature) said it was accurate (tried 2026-12-05), the break at
    eps = 1e-4 missed its run at tol 1e-9 by up to 1.2e-5 of the cue ball's speed at tol 1e-6.
    `flips`' bound grows as eps^1.5 and refuses them there; whatever gate comes next must keep
    the break within its tolerance at band widths 10 and 100 times the scene's."""
    from collide.accuracy import outcome, speed_scale

    scene = load_scene("billiards-break", [f"contact.eps={eps}", f"body.cue.position.y={offset}"])
    final = {tol: outcome(run_scene(scene, tol=tol, record=False, measure=False).result) for tol in (1e-6, 1e-9)}
    assert np.abs(final[1e-6] - final[1e-9]).max() / speed_scale(scene) < 1e-6


def test_contacts_changing_modes_at_once_reach_consistent_modes():
    """A ball against another and the floor: both contacts change at once, and the first left
    sliding with its slip heading back into the band (value zero at the step's start, so the
    crossing went unseen). The outcome moved by 6e-3 between tolerances down to 1e-9; with the
    contact held again and re-judged, it converges."""
    loose, tight = _tolerance_ladder("coupled-edge-change", (1e-8, 1e-9))
    assert tight < 1e-4
    assert loose > 3 * tight


def _oblique_damped(dim: int, floor: str = "", hertz: bool = False) -> dict:
    """Two spheres meeting obliquely with spin, a dashpot (e = 0.6) and Coulomb friction (mu =
    0.1), or the first alone onto a floor under gravity (`floor` "bounce"): the slip stays far
    from the dead band, so the contact slides throughout, and its F_n passes zero before the
    overlap does (the dashpot pulls at the end). `floor` "settle": it comes down slowly (4.9e-2
    m/s, five times its resting overlap's speed over a period) at e = 0.3 and stays, F_n pulling
    for a while as it rebounds: F_n passes zero and comes back. `hertz`: the same under Hertz
    (E 1e8 Pa, nu 0.3) with its dashpot."""
    spins = ([30.0, -60.0, 80.0], [-20.0, 15.0, 5.0]) if dim == 3 else (150.0, -20.0)
    bodies = [{"name": "a", "mass": 0.3, "radius": 0.02, "position": [0.0, 0.0, 0.0][:dim],
               "velocity": [1.2, 0.1, -0.2][:dim], "spin": spins[0]},
              {"name": "b", "mass": 0.5, "radius": 0.025, "position": [0.06, 0.02, -0.01][:dim],
               "velocity": [-0.3, 0.0, 0.1][:dim], "spin": spins[1]}]
    raw = {"dim": dim, "tol": 1e-9, "duration": 0.1, "contact": {"k": 1e5, "restitution": 0.6, "mu": 0.1},
           "body": bodies}
    if floor:
        bodies[0].update(position=[0.0, 0.03, 0.0][:dim], velocity=[0.4, -1.0, 0.2][:dim])
        raw.update(body=bodies[:1], duration=0.05, gravity=[0.0, -9.81, 0.0][:dim],
                   wall=[{"point": [0.0, 0.0, 0.0][:dim], "normal": [0.0, 1.0, 0.0][:dim]}])
    if floor == "settle":
        bodies[0].update(mass=0.1, position=[0.0, 0.02 + 1e-5, 0.0][:dim], velocity=[0.5, -0.04696, 0.2][:dim])
        raw.update(duration=0.01)
        raw["contact"]["restitution"] = 0.3
    if hertz:
        raw["contact"].pop("k")
        raw["contact"].update(model="hertz", youngs_modulus=1e8, poisson_ratio=0.3)
    return raw


def _oblique_reference(raw: dict, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The same law integrated independently: DOP853 (rtol 1e-13) from the touch (in closed form)
    to the overlap's end (if it ends), then in flight to the run's end. A pair: the spring k / 2 (two in
    series), the dashpot 2 zeta sqrt(m* k / 2), levers l = r - delta / 2; a sphere on the floor:
    k, 2 zeta sqrt(m k), l = r - delta; unclipped. Hertz: 4/3 E* sqrt(R*) delta^1.5 and its
    dashpot 2 zeta sqrt(m* 2 E* sqrt(R* delta)) (LIGGGHTS'), E* = E / (2 (1 - nu^2)) for a pair,
    E / (1 - nu^2) on the rigid floor. Friction mu max(F_n, 0) against the slip P_t(v_i
    - v_j) + (l_i w_i + l_j w_j) x n, its torques l (n x f). The cap's kink (F_n through zero) is
    an event the integration stops at and restarts from. Returns (velocities, spins, how many
    times F_n crossed zero)."""
    from scipy.integrate import solve_ivp

    from collide.model import damping_ratio

    def full(v):
        return np.array((list(v) + [0.0, 0.0])[:3]) if isinstance(v, list) else np.array([0.0, 0.0, v])

    floor = "wall" in raw
    a, b = raw["body"][0], raw["body"][-1]  # on the floor b is a, unmoved and unused
    mi, mj, ri, rj = a["mass"], b["mass"], a["radius"], b["radius"]
    c = raw["contact"]
    g = full(raw.get("gravity", [0.0, 0.0]))
    hertz = c.get("model") == "hertz"
    mu, reach = c["mu"], (ri if floor else ri + rj)
    mstar = mi if floor else mi * mj / (mi + mj)
    zeta = float(damping_ratio(np.array(c["restitution"]), hertz))
    if hertz:
        estar = c["youngs_modulus"] / ((1.0 if floor else 2.0) * (1.0 - c["poisson_ratio"] ** 2))
        root = np.sqrt(ri if floor else ri * rj / (ri + rj))

        def normal(delta, rate):
            return 4.0 / 3.0 * estar * root * max(delta, 0.0) ** 1.5 + 2.0 * zeta * np.sqrt(
                mstar * 2.0 * estar * root * np.sqrt(max(delta, 0.0))) * rate
    else:
        k = c["k"] if floor else 0.5 * c["k"]

        def normal(delta, rate):
            return k * delta + 2.0 * zeta * np.sqrt(mstar * k) * rate
    y = np.concatenate([full(b_[key]) for key in ("position", "velocity", "spin") for b_ in (a, b)])
    if floor:  # the touch: y + v t - g t^2 / 2 = r, falling
        touch = (y[7] + np.sqrt(y[7] ** 2 + 2.0 * -g[1] * (y[1] - reach))) / -g[1]
    else:
        d, u = y[3:6] - y[0:3], y[9:12] - y[6:9]
        qa, qb, qc = u @ u, 2.0 * d @ u, d @ d - reach**2
        touch = (-qb - np.sqrt(qb * qb - 4.0 * qa * qc)) / (2.0 * qa)
    y[0:6] += touch * y[6:12] + 0.5 * touch**2 * np.concatenate([g, g])
    y[6:12] += touch * np.concatenate([g, g])

    def parts(y):
        if floor:
            n, delta, rel, lj = np.array([0.0, -1.0, 0.0]), reach - y[1], y[6:9], 0.0
            li = ri - delta
        else:
            n = (y[3:6] - y[0:3]) / np.linalg.norm(y[3:6] - y[0:3])
            delta = reach - np.linalg.norm(y[3:6] - y[0:3])
            rel = y[6:9] - y[9:12]
            li, lj = ri - 0.5 * delta, rj - 0.5 * delta
        slip = rel - (rel @ n) * n + np.cross(li * y[12:15] + lj * y[15:18], n)
        return n, delta, normal(delta, rel @ n), li, lj, slip

    def rhs(_, y, side):
        n, _, fn, li, lj, s = parts(y)
        f = -(mu * fn if side > 0 else 0.0) * s / np.linalg.norm(s)
        on_i = -fn * n + f
        on_j = np.zeros(3) if floor else -on_i / mj
        return np.concatenate([y[6:12], on_i / mi + g, on_j + g, li * np.cross(n, f) / inertia[0],
                               lj * np.cross(n, f) / inertia[-1]])

    def pressing(_, y, side):
        return parts(y)[2] * side

    def ended(_, y, side):
        return parts(y)[1]

    def banded(_, y, side):
        return np.linalg.norm(parts(y)[5]) - 10.0 * c.get("eps", 1e-6)

    for event in (pressing, ended, banded):
        event.terminal, event.direction = True, -1.0
    t, side, crossings = touch, 1.0, 0
    while t < raw["duration"]:
        sol = solve_ivp(rhs, (t, raw["duration"]), y, method="DOP853", rtol=1e-13, atol=1e-16, args=(side,),
                        events=(pressing, ended, banded))
        t, y = sol.t[-1], sol.y[:, -1]
        assert sol.t_events[2].size == 0, "the slip came to the dead band: the case must slide throughout"
        if sol.t_events[1].size:
            y[6:12] += (raw["duration"] - t) * np.concatenate([g, g])  # in flight to the run's end
            break
        if sol.t_events[0].size:
            side, crossings = -side, crossings + 1
    n = len(raw["body"])
    return y[6:12].reshape(2, 3)[:n], y[12:18].reshape(2, 3)[:n], crossings


@pytest.mark.parametrize("hertz", [False, True])
@pytest.mark.parametrize(("dim", "floor", "crossings"), [(2, "", 1), (3, "", 1), (2, "bounce", 1), (3, "bounce", 1),
                                                        (2, "settle", 2), (3, "settle", 2)])
def test_a_damped_sliding_contacts_normal_force_through_zero_is_an_event_as_dop853_sees_it(dim, floor, crossings,
                                                                                           hertz):
    """The cap mu max(F_n, 0) has a kink where a damped F_n passes zero, before the contact ends:
    the slide's second mode value, located as an event, and each step keeps the cap's branch it
    started on (`cap`, CI_PRESS), so a kahan6 substep reaching back past the kink keeps the order.
    A slide whose F_n pulls, and then presses again, goes on without friction between. At tol
    1e-9 the outcome agrees with DOP853's to 1e-8 of the speed (measured, in 3D and 2D: two
    spheres 1.7e-10 and 1.8e-10; a sphere onto a floor under gravity 1.8e-10 and 2.0e-10; settling
    there, F_n through zero and back, 6.7e-11 and 8.7e-11). Under Hertz with its dashpot, F_n
    through zero is located on `contact.press`'s value (F_n over gamma(delta)), each contact's
    start and end stepped over s (measured: two spheres 6.7e-11 and 4.5e-11, onto a floor
    8.6e-11 and 2.1e-11, settling 1.5e-12 and 1.2e-11)."""
    from collide.scene import parse_scene

    raw = _oblique_damped(dim, floor, hertz)
    run = run_scene(parse_scene(raw), record=False)
    r = run.result
    assert r.engine == "event" and run.error_method[0] == "measured"
    v, w, seen = _oblique_reference(raw, r.model.inertia[0])
    assert seen == crossings
    n = len(raw["body"])
    got_v = np.zeros((n, 3))
    got_v[:, :dim] = r.final.v[0]
    got_w = r.final.w[0] if dim == 3 else np.column_stack([np.zeros((n, 2)), r.final.w[0]])
    radius = r.model.radius[0][:, None]
    speed = max(np.linalg.norm(b["velocity"]) for b in raw["body"])
    off = max(np.abs(got_v - v).max(), np.abs((got_w - w) * radius).max()) / speed
    assert off <= 1e-8
