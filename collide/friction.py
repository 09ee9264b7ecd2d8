"""Coulomb friction with the dead band, as a piecewise-smooth system with located mode changes.

The report's law (friction mu F_n against the slip when the slip exceeds eps, none inside the
band) converges, as dt -> 0, to a system with three modes per contact (DESIGN section 8):

* slide: the slip is outside the band and friction is mu F_n against it;
* stick: the slip sits on the band's edge (|slip| = eps), held there by exactly the friction
  that keeps it there (the Filippov sliding mode, F = G / K below), while that is below mu F_n;
* band: the slip is inside the band and there is no friction.

Within a mode the equations are smooth, so a high-order step keeps its order if every mode
change lands on a step. This module decides modes, applies friction impulses per mode inside
the integrators' kicks, and gives the event functions the stepper locates: each is positive
while its contact stays in its mode.

Notation per contact: u is the tangential slip (surface of i relative to surface of j, or of the
sphere relative to the wall), d its direction, K the slip change per unit tangential impulse,
G = du/dt . d with no friction (the "hold rate"); holding the slip needs friction G / K.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collide import physics as ph
from collide.model import Model, State

BAND, SLIDE, STICK = 0, 1, 2
EDGE_TOL = 1e-9  # relative to the speed scale: how close to the band's edge counts as on it
STICK_SCALE = 1e-3  # s: turns a friction force into a slip change, to compare with EDGE_TOL


@dataclass
class Modes:
    """Friction mode of every pair (B, P) and sphere-wall contact (B, W, N), and for 2D the side
    of the band (+1/-1) the slip is on, which fixes the friction direction within a mode."""

    pair: np.ndarray
    pair_side: np.ndarray
    wall: np.ndarray
    wall_side: np.ndarray
    pair_dir: np.ndarray  # (B, P, D) slip direction when the mode was chosen
    wall_dir: np.ndarray  # (B, W*N, D)


@dataclass
class SlipTerms:
    """Slip kinematics of one contact set (pairs, or walls flattened to (B, W*N))."""

    u: np.ndarray  # (B, C, D) slip vector, measured with the slip lever
    sliding: np.ndarray  # (B, C, D) its part from the centres' velocities
    t: np.ndarray  # (B, C, D) unit tangent (2D: perp(n)); direction of u in 3D
    n: np.ndarray  # (B, C, D) contact normal
    slip: np.ndarray  # (B, C) slip along t (2D signed; 3D = |u|)
    k_slip: np.ndarray  # (B, C)
    fn: np.ndarray  # (B, C) normal force


def _pair_terms(model: Model, c: ph.Contacts, fn: np.ndarray, state: State) -> SlipTerms:
    li, lj = ph._slip_arms(model, c)
    sliding = ph._sliding(model, c, state.v)
    u = sliding + ph._rolling(model, c, state.w, li, lj) if state.w.shape[-1] else sliding
    k_slip = model.pair_inv_mass + li * c.arm_i * model.pair_inv_inertia_i + lj * c.arm_j * model.pair_inv_inertia_j
    t, slip = _tangent(model, u, c.n)
    return SlipTerms(u=u, sliding=sliding, t=t, n=c.n, slip=slip, k_slip=k_slip, fn=fn)


def _wall_terms(model: Model, c: ph.Contacts, fw: np.ndarray, state: State) -> SlipTerms:
    b = state.v.shape[0]
    arm = ph._wall_slip_arm(model, c)
    u = ph.wall_slip(model, c, state.v, state.w, arm).reshape(b, -1, model.dim)
    nw = np.broadcast_to(model.wall_normal[None, :, None, :], (b, model.n_walls, model.n_bodies, model.dim))
    k_slip = (model.inv_mass[:, None, :] + arm * c.wall_arm * model.inv_inertia[:, None, :]).reshape(b, -1)
    t, slip = _tangent(model, u, nw.reshape(b, -1, model.dim))
    return SlipTerms(u=u, sliding=u, t=t, n=nw.reshape(b, -1, model.dim), slip=slip, k_slip=k_slip,
                     fn=fw.reshape(b, -1))


def _tangent(model: Model, u: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if model.dim == 2:
        t = ph.perp2(n)
        return t, ph.dot(u, t)
    mag = ph.norm(u)
    return u / np.where(mag > 0, mag, 1.0)[..., None], mag


def _hold_rate_pairs(model: Model, c: ph.Contacts, state: State, acc: np.ndarray, terms: SlipTerms) -> np.ndarray:
    """G = d(slip)/dt . t with no friction, for pairs (B, P)."""
    n = c.n
    v_rel = -(model.pair_diff @ state.v)
    a_rel = -(model.pair_diff @ acc)
    dist = model.pair_reach - c.overlap
    vn = ph.dot(v_rel, n)
    n_dot = -(v_rel - vn[..., None] * n) / dist[..., None]
    du = -(n_dot * vn[..., None] + n * ph.dot(n_dot, v_rel)[..., None]) + a_rel - ph.dot(a_rel, n)[..., None] * n
    if state.w.shape[-1]:
        li, lj = ph._slip_arms(model, c)
        wi, wj = model.select_i @ state.w, model.select_j @ state.w
        spin = wi * li[..., None] + wj * lj[..., None]
        du = du + ph.spin_cross(spin, n_dot)
        if not model.seed_lever:
            # The contact point moves in as the overlap grows: arm rate = -overlap rate / 2.
            arm_rate = -0.5 * vn
            du = du + ph.spin_cross((wi + wj) * arm_rate[..., None], n)
    return ph.dot(du, terms.t)


def _hold_rate_walls(model: Model, c: ph.Contacts, state: State, acc: np.ndarray, terms: SlipTerms) -> np.ndarray:
    b = state.v.shape[0]
    nw = model.wall_normal[None, :, None, :]
    a = acc[:, None]
    du = a - ph.dot(a, nw)[..., None] * nw
    if state.w.shape[-1] and not model.seed_lever:
        arm_rate = ph.dot(state.v[:, None], nw)  # the arm grows as the sphere leaves the wall
        du = du - ph.spin_cross(state.w[:, None] * arm_rate[..., None], nw)
    return ph.dot(du.reshape(b, -1, model.dim), terms.t)


def _all_terms(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
               ) -> tuple[SlipTerms, SlipTerms | None]:
    pairs = _pair_terms(model, c, fn, state)
    walls = _wall_terms(model, c, fw, state) if model.n_walls else None
    return pairs, walls


def hold_force(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
               acc: np.ndarray | None = None, terms: tuple[SlipTerms, SlipTerms | None] | None = None,
               ) -> tuple[tuple[SlipTerms, np.ndarray], tuple[SlipTerms, np.ndarray] | None]:
    """Friction each contact needs to hold its slip constant, signed along the slip's side:
    positive means against the slip (what Coulomb friction can give). `acc` (the springs' and
    gravity's accelerations) and `terms` may be passed in when the caller has them."""
    acc = ph.normal_accel(model, c, fn, fw) if acc is None else acc
    pairs, walls = _all_terms(model, c, fn, fw, state) if terms is None else terms
    side = np.sign(pairs.slip) if model.dim == 2 else 1.0
    need = side * _hold_rate_pairs(model, c, state, acc, pairs) / pairs.k_slip
    out_walls = None
    if walls is not None:
        wside = np.sign(walls.slip) if model.dim == 2 else 1.0
        out_walls = (walls, wside * _hold_rate_walls(model, c, state, acc, walls) / walls.k_slip)
    return (pairs, need), out_walls


def _decide(terms: SlipTerms, need: np.ndarray, mu: np.ndarray, eps: np.ndarray, tol: np.ndarray,
            engaged: np.ndarray) -> np.ndarray:
    """Mode from the state: outside the band slide, inside band; on its edge, stick if the
    friction that holds the slip is available (0 < need < mu F_n), else slide or band.

    The margins are the event tolerance in the units of the stick events (`_mode_values`), so a
    step that landed on a mode change always switches."""
    slip = terms.slip
    mag = np.abs(slip)
    at_edge = np.abs(mag - eps) <= tol
    force_tol = tol / (terms.k_slip * STICK_SCALE)
    edge_mode = np.where(need <= force_tol, BAND, np.where(need < mu * terms.fn - force_tol, STICK, SLIDE))
    mode = np.where(at_edge, edge_mode, np.where(mag > eps, SLIDE, BAND))
    return np.where(engaged > 0, mode, BAND).astype(np.int8)


def decide_modes(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
                 engaged: ph.Engaged, scale: np.ndarray) -> tuple[Modes, np.ndarray]:
    """Modes of every contact at this state (at a phase start or after a located event), and
    their event values here (`mode_events`), from one evaluation of the hold force."""
    held = hold_force(model, c, fn, fw, state)
    (pairs, need), walls = held
    tol = (EDGE_TOL * scale)[:, None]
    mu, eps = model.mu[:, None], model.eps[:, None]
    pair_mode = _decide(pairs, need, mu, eps, tol, engaged.pair)
    pair_side = np.where(pairs.slip >= 0, 1.0, -1.0)
    b = state.v.shape[0]
    shape = (b, model.n_walls, model.n_bodies)
    if walls is None:
        wall_mode, wall_side = np.zeros(shape, np.int8), np.ones(shape)
        wall_dir = np.zeros((b, 0, model.dim))
    else:
        wterms, wneed = walls
        wall_mode = _decide(wterms, wneed, mu, eps, tol, engaged.wall.reshape(b, -1)).reshape(shape)
        wall_side = np.where(wterms.slip >= 0, 1.0, -1.0).reshape(shape)
        wall_dir = wterms.t * wall_side.reshape(b, -1)[..., None]
    modes = Modes(pair_mode, pair_side, wall_mode, wall_side, pairs.t * pair_side[..., None], wall_dir)
    return modes, mode_events(model, c, fn, fw, state, modes, scale, held=held)


def _impulse(terms: SlipTerms, mode: np.ndarray, side: np.ndarray, entry: np.ndarray, mu: np.ndarray,
             eps: np.ndarray, hk: np.ndarray, dim: int, need: np.ndarray | None) -> np.ndarray:
    """Tangential impulse on the first body over hk seconds, by mode (B, C, D).

    The friction direction is the slip's side of the tangent in 2D; in 3D it is the slip's
    direction at the start of the step carried over the step (exact for planar motion, first
    order in how fast a non-planar slip turns)."""
    if dim == 2:
        direction = terms.t * side[..., None]
        along = terms.slip * side
    else:
        # Slide and stick keep the direction the slip had when the mode was chosen, carried onto
        # the current tangent plane: the slip may pass near zero inside a (backward) substep.
        direction = _transport(entry, terms.n)
        along = ph.dot(terms.u, direction)
    # slide: mu F_n against the slip, for the signed time hk (substeps may run backwards).
    # stick: in a step's first half-kick the force that holds the slip at this state (explicit);
    # in its second, whatever puts the slip back on the band's edge (implicit: the hold force at
    # the end). Both ends use their own state, so the step is symmetric and compositions of it
    # keep their order.
    slide = mu * terms.fn * hk
    stick = (along - eps) / terms.k_slip if need is None else need * hk
    magnitude = np.where(mode == SLIDE, slide, np.where(mode == STICK, stick, 0.0))
    return -magnitude[..., None] * direction


def mode_kick(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
              hk: np.ndarray, modes: Modes, first: bool, acc: np.ndarray | None = None,
              ) -> tuple[np.ndarray, np.ndarray]:
    """Apply the friction impulses of the current modes over hk seconds; returns forces.
    `first` marks a step's first half-kick (explicit hold force in stick mode); `acc` is the
    springs' and gravity's acceleration the kick already computed."""
    pairs, walls = _all_terms(model, c, fn, fw, state)
    need = wneed = None
    if first and (np.any(modes.pair == STICK) or np.any(modes.wall == STICK)):
        (_, need), walls_need = hold_force(model, c, fn, fw, state, acc, (pairs, walls))
        wneed = None if walls_need is None else walls_need[1]
    hkc = hk[:, None]
    mu, eps = model.mu[:, None], model.eps[:, None]
    ji = _impulse(pairs, modes.pair, modes.pair_side, modes.pair_dir, mu, eps, hkc, model.dim, need)
    b = state.v.shape[0]
    jw = np.zeros((b, model.n_walls, model.n_bodies, model.dim))
    work = _work(model, c, state, ji, pairs, None)
    if walls is not None:
        jwf = _impulse(walls, modes.wall.reshape(b, -1), modes.wall_side.reshape(b, -1), modes.wall_dir, mu, eps,
                       hkc, model.dim, wneed)
        work = work + _work(model, c, state, jwf, walls, True)
        jw = jwf.reshape(jw.shape)
    dp, dl = ph.friction_response(model, c, ji, jw)
    state.v += dp * model.inv_mass[..., None]
    state.w += dl * model.inv_inertia[..., None]
    state.work += work
    safe = np.where(hk != 0, hk, 1.0)
    return ji / safe[:, None, None], jw / safe[:, None, None, None]


def _work(model: Model, c: ph.Contacts, state: State, j: np.ndarray, terms: SlipTerms, walls: bool | None,
          ) -> np.ndarray:
    """Kinetic energy an impulse j removes: -j . (mean slip at the contact point over the kick)."""
    b = state.v.shape[0]
    if walls:
        arm = c.wall_arm
        up = ph.wall_slip(model, c, state.v, state.w, arm).reshape(b, -1, model.dim)
        k_power = (model.inv_mass[:, None, :] + arm * arm * model.inv_inertia[:, None, :]).reshape(b, -1)
    else:
        up = terms.sliding + ph._rolling(model, c, state.w, c.arm_i, c.arm_j) \
            if model.seed_lever and state.w.shape[-1] else terms.u
        k_power = (model.pair_inv_mass + c.arm_i ** 2 * model.pair_inv_inertia_i
                   + c.arm_j ** 2 * model.pair_inv_inertia_j)
    return np.add.reduce(-ph.dot(j, up) - 0.5 * k_power * ph.dot(j, j), -1)


def mode_events(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, state: State,
                modes: Modes, scale: np.ndarray, rates: bool = False, held: tuple | None = None):
    """Event functions (B, 2C), positive while each contact stays in its mode, scaled to speeds:
    slide: slip beyond the band's edge; band: room left inside the band; stick: the margin to
    mu F_n and the need itself (both as the slip rate they correspond to over the step).
    With `rates`, also their time derivatives (NaN for stick, whose rate is not known in closed
    form), so a crossing can be located with a cubic Hermite through both ends of a step.
    `held`: `hold_force`'s result at this state, when the caller has it."""
    (pairs, need), walls = hold_force(model, c, fn, fw, state) if held is None else held
    mu, eps = model.mu[:, None], model.eps[:, None]
    values = [_mode_values(pairs, need, modes.pair, modes.pair_side, modes.pair_dir, mu, eps, model.dim)]
    slopes = [_mode_rates(pairs, need, modes.pair, modes.pair_side, modes.pair_dir, mu, model.dim)] if rates else []
    if walls is not None:
        b = state.v.shape[0]
        wterms, wneed = walls
        wmode, wside = modes.wall.reshape(b, -1), modes.wall_side.reshape(b, -1)
        values.append(_mode_values(wterms, wneed, wmode, wside, modes.wall_dir, mu, eps, model.dim))
        if rates:
            slopes.append(_mode_rates(wterms, wneed, wmode, wside, modes.wall_dir, mu, model.dim))
    out = np.concatenate(values, axis=1) / scale[:, None]
    if not rates:
        return out
    return out, np.concatenate(slopes, axis=1) / scale[:, None]


def _mode_rates(terms: SlipTerms, need: np.ndarray, mode: np.ndarray, side: np.ndarray, entry: np.ndarray,
                mu: np.ndarray, dim: int) -> np.ndarray:
    """Time derivatives of `_mode_values`' columns (B, 2C); NaN where not known."""
    # G, the slip's rate along t without friction, from need = sign(slip) G / K (2D; 3D: need = G / K).
    g = need * terms.k_slip * (np.sign(terms.slip) if dim == 2 else 1.0)
    slide = (side * g if dim == 2 else g) - terms.k_slip * mu * terms.fn
    if dim == 2:
        band_a, band_b = -g, g
    else:
        band_a, band_b = -g, g * ph.dot(terms.t, _transport(entry, terms.n))
    nan = np.full_like(g, np.nan)
    first = np.where(mode == SLIDE, slide, np.where(mode == STICK, nan, band_a))
    second = np.where(mode == SLIDE, 0.0, np.where(mode == STICK, nan, band_b))
    return np.concatenate((first, second), axis=1)


def _transport(entry: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The step's sliding direction carried onto the current tangent plane (unit)."""
    d = entry - ph.dot(entry, n)[..., None] * n
    mag = ph.norm(d)
    return d / np.where(mag > 0, mag, 1.0)[..., None]


def _mode_values(terms: SlipTerms, need: np.ndarray, mode: np.ndarray, side: np.ndarray, entry: np.ndarray,
                 mu: np.ndarray, eps: np.ndarray, dim: int) -> np.ndarray:
    """Two event columns per contact (B, 2C), so that a mode entered on one of its boundaries
    still sees the other: band has both edges, stick both limits of the friction it needs."""
    along = terms.slip * side if dim == 2 else ph.dot(terms.u, _transport(entry, terms.n))
    slide = along - eps
    if dim == 2:
        band_a, band_b = eps - terms.slip, eps + terms.slip
    else:
        # 3D: the far edge as seen along the slip's direction when the band was entered.
        band_a, band_b = eps - terms.slip, eps + ph.dot(terms.u, _transport(entry, terms.n))
    # Stick: forces turned into the slip change they would make over STICK_SCALE seconds.
    cap = (mu * terms.fn - need) * terms.k_slip * STICK_SCALE
    hold = need * terms.k_slip * STICK_SCALE
    first = np.where(mode == SLIDE, slide, np.where(mode == STICK, cap, band_a))
    second = np.where(mode == SLIDE, 1.0, np.where(mode == STICK, hold, band_b))
    return np.concatenate((first, second), axis=1)
