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


@dataclass
class KickFrame:
    """What the friction kick needs that depends only on positions and modes, built once per
    geometry (each serves the kicks on both sides of it).

    Contacts are pairs then sphere-wall contacts (C = P + W N), each with T = D - 1 tangent
    directions (2D: t = perp(n); 3D: an orthonormal pair). The slip of contact c in those
    coordinates is `slip_rows[:, c*T:(c+1)*T] . V`, V = (v, w) flattened (B, F); a friction impulse
    with coordinates j changes V by -inv_mass_gen * (j . impulse_rows). Friction acts along a
    direction d that depends on positions only, so the force law is smooth within a mode (as the
    springs' is within a contact): in 2D the slip's side of the tangent; in 3D the slip's
    direction when the mode began, carried onto the tangent plane (exact for planar motion;
    a slip that turns out of its plane is followed from step to step).
    """

    slip_rows: np.ndarray  # (B, C T, F)
    impulse_rows: np.ndarray  # (B, C T, F)
    basis: np.ndarray  # (B, C, T, D)
    inv_mass_gen: np.ndarray  # (B, F)
    response: np.ndarray  # (B, C): slip change per unit impulse (the K of the module notes)
    unit: np.ndarray  # (B, C, T): d in tangent coordinates
    direction: np.ndarray  # (B, C, D): d in space
    slide: np.ndarray  # (B, C): mu F_n where the contact slides, else 0
    stick: np.ndarray  # (B, C): 1.0 where it sticks, else 0
    any_stick: bool
    hold: HoldTerms


@dataclass
class HoldTerms:
    """Position-only terms of the hold rate (`hold_rate`) and of its slope in the impulse."""

    n: np.ndarray  # (B, P, D) pair normals
    dist: np.ndarray  # (B, P) distance between centres
    wall_normal: np.ndarray  # (B, W N, D)
    slip_spin: np.ndarray  # (B, P, N): lever of each body's spin in the pair's slip (l_i, l_j)
    entry: np.ndarray | None  # 3D: (B, P, D) the pairs' slip directions when their modes began
    turn_response: np.ndarray  # (B, P): l_i a_i / I_i + l_j a_j / I_j
    lever_response: np.ndarray  # (B, C): contact lever, pairs a_i / I_i + a_j / I_j, walls -a / I


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b with K components (np.cross is slow on small arrays)."""
    if a.shape[-1] == 2:
        return (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])[..., None]
    return a[..., _ROLL1] * b[..., _ROLL2] - a[..., _ROLL2] * b[..., _ROLL1]


_ROLL1, _ROLL2 = [1, 2, 0], [2, 0, 1]


def _tangent_basis(n: np.ndarray) -> np.ndarray:
    """(..., T, D) unit tangents of normals n (..., D): 2D perp(n); 3D two orthonormal ones."""
    if n.shape[-1] == 2:
        return ph.perp2(n)[..., None, :]
    helper = np.where((np.abs(n[..., :1]) < 0.9), _EX, _EY)
    e1 = _cross(n, helper)
    e1 = e1 / ph.norm(e1)[..., None]
    return np.stack((e1, _cross(n, e1)), axis=-2)


_EX, _EY = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def kick_frame(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, modes: Modes) -> KickFrame:
    """The friction kick's rows at this geometry for these modes (see `KickFrame`)."""
    b, n_bodies, dim, k = model.batch, model.n_bodies, model.dim, model.spin_dim
    tangents = dim - 1
    basis = _tangent_basis(c.n)  # (B, P, T, D)
    # Pairs: slip = (v_i - v_j) . e + (l_i w_i + l_j w_j) . (n x e) along each tangent e; the
    # impulse -j acts on i (and +j on j) at the contact arms a_i n and -a_j n.
    pair_rows = model.n_pairs * tangents
    v_rows = (-model.pair_diff[None, :, None, :, None] * basis[:, :, :, None, :]).reshape(b, pair_rows, n_bodies * dim)
    slip_v, imp_v, slip_w, imp_w = [v_rows], [v_rows], [], []
    li, lj = ph._slip_arms(model, c)
    si, sj = model.select_i[None], model.select_j[None]
    slip_spin = si * li[..., None] + sj * lj[..., None]  # (B, P, N)
    if k:
        nxe = _cross(c.n[:, :, None, :], basis)[:, :, :, None, :]  # (B, P, T, 1, K)
        force_spin = si * c.arm_i[..., None] + sj * c.arm_j[..., None]
        slip_w.append((slip_spin[:, :, None, :, None] * nxe).reshape(b, pair_rows, n_bodies * k))
        imp_w.append((force_spin[:, :, None, :, None] * nxe).reshape(b, pair_rows, n_bodies * k))
    if dim == 2:
        d_pair = ph.perp2(c.n) * modes.pair_side[..., None]
    else:
        d_pair = _transport(modes.pair_dir, c.n)
    mode, directions, bases = [modes.pair], [d_pair], [basis]
    lever = [c.arm_i * model.pair_inv_inertia_i + c.arm_j * model.pair_inv_inertia_j]
    wall_normal = np.zeros((b, 0, dim))
    if model.n_walls:
        wall_normal = np.broadcast_to(model.wall_normal[None, :, None, :],
                                      (b, model.n_walls, n_bodies, dim)).reshape(b, -1, dim)
        wbasis = _tangent_basis(wall_normal)  # (B, W N, T, D)
        # Sphere n on wall w: slip = v_n . e - arm w_n . (n_w x e); the impulse -j acts at -arm n_w.
        own = np.tile(np.eye(n_bodies), (model.n_walls, 1))[None, :, None, :, None]  # (1, W N, 1, N, 1)
        wall_rows = model.n_walls * n_bodies * tangents
        wv = (own * wbasis[:, :, :, None, :]).reshape(b, wall_rows, n_bodies * dim)
        slip_v.append(wv)
        imp_v.append(wv)
        if k:
            nxe = _cross(wall_normal[:, :, None, :], wbasis)[:, :, :, None, :]
            slip_arm = ph._wall_slip_arm(model, c).reshape(b, -1)[:, :, None, None, None]
            force_arm = c.wall_arm.reshape(b, -1)[:, :, None, None, None]
            slip_w.append(-(own * slip_arm * nxe).reshape(b, wall_rows, n_bodies * k))
            imp_w.append(-(own * force_arm * nxe).reshape(b, wall_rows, n_bodies * k))
        mode.append(modes.wall.reshape(b, -1))
        if dim == 2:
            directions.append(ph.perp2(wall_normal) * modes.wall_side.reshape(b, -1)[..., None])
        else:
            directions.append(_transport(modes.wall_dir, wall_normal))
        bases.append(wbasis)
        lever.append(-(c.wall_arm * model.inv_inertia[:, None, :]).reshape(b, -1))

    def join(parts: list[np.ndarray], axis: int = 1) -> np.ndarray:
        return np.concatenate(parts, axis=axis) if len(parts) > 1 else parts[0]

    slip_rows, impulse_rows = join(slip_v), join(imp_v)
    if k:
        slip_rows = np.concatenate((slip_rows, join(slip_w)), axis=2)
        impulse_rows = np.concatenate((impulse_rows, join(imp_w)), axis=2)
    inv_mass_gen = np.concatenate((np.repeat(model.inv_mass, dim, axis=1), np.repeat(model.inv_inertia, k, axis=1)),
                                  axis=1)
    mode = join(mode)
    normal = np.concatenate((fn, fw.reshape(b, -1)), axis=1) if model.n_walls else fn
    # The response along the first tangent is the response along any.
    first = slip_rows.reshape(b, -1, tangents, slip_rows.shape[-1])[:, :, 0]
    first_imp = impulse_rows.reshape(b, -1, tangents, slip_rows.shape[-1])[:, :, 0]
    turn_response = li * c.arm_i * model.pair_inv_inertia_i + lj * c.arm_j * model.pair_inv_inertia_j
    hold = HoldTerms(c.n, model.pair_reach - c.overlap, wall_normal, slip_spin,
                     modes.pair_dir if dim == 3 else None, turn_response, join(lever))
    basis, direction = join(bases), join(directions)
    return KickFrame(
        slip_rows=slip_rows, impulse_rows=impulse_rows, basis=basis, inv_mass_gen=inv_mass_gen,
        response=np.add.reduce(first * inv_mass_gen[:, None, :] * first_imp, -1),
        unit=np.add.reduce(basis * direction[:, :, None, :], -1), direction=direction,
        slide=np.where(mode == SLIDE, model.mu[:, None] * normal, 0.0),
        stick=(mode == STICK).astype(float), any_stick=bool((mode == STICK).any()), hold=hold)


def slip(model: Model, frame: KickFrame, vel: np.ndarray) -> np.ndarray:
    """Slip coordinates (B, C, T) at generalised velocity vel (B, F)."""
    return (frame.slip_rows @ vel[..., None]).reshape(vel.shape[0], -1, model.dim - 1)


def _velocity(state: State) -> np.ndarray:
    b = state.v.shape[0]
    return np.concatenate((state.v.reshape(b, -1), state.w.reshape(b, -1)), axis=1)


def hold_rate(model: Model, frame: KickFrame, vel: np.ndarray, acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hold rate G (B, C): how fast each contact's slip along its friction direction d would
    grow with no friction, at generalised velocity vel (B, F) and accelerations `acc` (springs and
    gravity); and dG/dlam, its change per unit impulse of the contact's own friction.

    Pairs, with u = v_j - v_i, L = l_i w_i + l_j w_j and s the slip vector (-u + L x n, tangential):
    G = (a_i - a_j) . d + (u . n)(u . d) / dist + L . (n' x d) + L' . (n x d) + s . d', where the
    line of centres turns at n' = (u - (u . n) n) / dist, with the contact lever the arms shorten
    as the overlap grows (L' = (w_i + w_j)(u . n) / 2), and in 3D d, carried along with n, turns
    at d' (in 2D s . d' = 0). Walls: G = a . d - (v . n_w) w . (n_w x d) with the contact lever.
    An impulse along d changes u . d, s and the spins but not the normal speeds, and s only along
    d (d . d' = 0): G is affine in it, so the implicit hold force is one division.
    """
    terms = frame.hold
    b, p = vel.shape[0], model.n_pairs
    nv = model.n_bodies * model.dim
    v = vel[:, :nv].reshape(b, model.n_bodies, model.dim)
    w = vel[:, nv:].reshape(b, model.n_bodies, -1)
    tangents = model.dim - 1
    along_acc = (frame.slip_rows[..., :nv] @ acc.reshape(b, nv, 1)).reshape(b, -1, tangents)
    rate = np.add.reduce(along_acc * frame.unit, -1)
    u = model.pair_diff @ v
    un = ph.dot(u, terms.n)
    d = frame.direction[:, :p]
    turn = un * ph.dot(u, d) / terms.dist
    slope = un * model.pair_inv_mass / terms.dist
    k = w.shape[-1]
    if model.dim == 3:
        n_rate = (u - un[..., None] * terms.n) / terms.dist[..., None]
        # d = (e - (e . n) n) / |...| turns with n; its rate, and that rate's change per unit
        # impulse (which turns n at kappa d / dist).
        e = terms.entry
        en = ph.dot(e, terms.n)
        length = ph.norm(e - en[..., None] * terms.n)[..., None]

        def d_rate_of(nr: np.ndarray) -> np.ndarray:
            pr = -ph.dot(e, nr)[..., None] * terms.n - en[..., None] * nr
            return (pr - ph.dot(pr, d)[..., None] * d) / length

        d_rate = d_rate_of(n_rate)
        d_rate_slope = d_rate_of(d * (model.pair_inv_mass / terms.dist)[..., None])
        s_vec = np.add.reduce((frame.slip_rows[:, :p * tangents] @ vel[..., None]).reshape(b, p, tangents, 1)
                              * frame.basis[:, :p], -2)
        turn = turn + ph.dot(s_vec, d_rate)
        slope = slope + ph.dot(s_vec, d_rate_slope)
        if k:
            # s . d' above already holds the rolling part's (L x n) . d'.
            n_rate_x_d = _cross(n_rate, d)
            turn = turn + ph.dot(terms.slip_spin @ w, n_rate_x_d)
            # The impulse turns the spins (along -n x d) and n' (along d, so n' x d stays).
            slope = slope - terms.turn_response * ph.dot(_cross(terms.n, d), n_rate_x_d)
    lever_speed = None
    if k and not model.seed_lever:
        lever_speed = 0.5 * un
        turn = turn + ph.dot((model.select_i + model.select_j) @ w, _cross(terms.n, d)) * lever_speed
    if model.n_walls:
        wall = np.zeros((b, rate.shape[1] - p))
        if lever_speed is not None:
            vw = np.broadcast_to(v[:, None], (b, model.n_walls) + v.shape[1:]).reshape(b, -1, model.dim)
            ww = np.broadcast_to(w[:, None], (b, model.n_walls) + w.shape[1:]).reshape(b, -1, k)
            speed = -ph.dot(vw, terms.wall_normal)
            wall = speed * ph.dot(ww, _cross(terms.wall_normal, frame.direction[:, p:]))
            lever_speed = np.concatenate((lever_speed, speed), axis=1)
        turn = np.concatenate((turn, wall), axis=1)
        slope = np.concatenate((slope, np.zeros_like(wall)), axis=1)
    if lever_speed is not None:
        slope = slope - lever_speed * terms.lever_response
    return rate + turn, slope


def _velocity(state: State) -> np.ndarray:
    b = state.v.shape[0]
    return np.concatenate((state.v.reshape(b, -1), state.w.reshape(b, -1)), axis=1)


def frame_kick(model: Model, frame: KickFrame, state: State, hk: np.ndarray, acc: np.ndarray,
               first: bool) -> tuple[np.ndarray, np.ndarray]:
    """Springs and gravity (`acc`) and friction by mode over hk seconds; returns the friction
    forces on pairs (B, P, D) and walls (B, W, N, D).

    slide: mu F_n against the slip for the signed time hk (substeps may run backwards). stick:
    the force that holds the slip on the band's edge, at the start state in a step's first
    half-kick (explicit) and at the end state in its second (implicit: lam = hk G(v + dv(lam)) / K),
    so the step's two halves mirror each other and compositions of it keep their order. The
    work done is the kinetic energy the impulses remove, exactly.
    """
    hkc = hk[:, None]
    lam = frame.slide * hkc
    if first and frame.any_stick:
        lam = lam + frame.stick * hkc * hold_rate(model, frame, _velocity(state), acc)[0] / frame.response
    state.v = state.v + acc * hk[:, None, None]
    vel = _velocity(state)
    if not first and frame.any_stick:
        rate, slope = hold_rate(model, frame, vel, acc)
        lam = lam + frame.stick * hkc * rate / (frame.response - hkc * slope)
    return _apply(model, frame, state, vel, lam, hk)


def _apply(model: Model, frame: KickFrame, state: State, vel: np.ndarray, lam: np.ndarray,
           hk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply friction impulses lam (B, C) against the slip; add their work; return forces."""
    b = vel.shape[0]
    nv = state.v[0].size
    coords = (lam[..., None] * frame.unit).reshape(b, 1, -1)
    impulse = (coords @ frame.impulse_rows)[:, 0]
    change = -frame.inv_mass_gen * impulse
    # Kinetic energy removed: -(change . M . (vel + change / 2)) = impulse . (vel + change / 2).
    state.work = state.work + np.add.reduce(impulse * (vel + 0.5 * change), -1)
    vel = vel + change
    state.v = vel[:, :nv].reshape(state.v.shape)
    state.w = vel[:, nv:].reshape(state.w.shape)
    safe = np.where(hk != 0, hk, 1.0)[:, None]
    forces = -(lam / safe)[..., None] * frame.direction
    pair = forces[:, :model.n_pairs]
    wall = forces[:, model.n_pairs:].reshape(b, model.n_walls, model.n_bodies, model.dim)
    return pair, wall


def settle(model: Model, frame: KickFrame, state: State) -> None:
    """Put stuck slips back on the band's edge: a projection after a whole step (the symmetric
    step holds them there to its order; this keeps the drift from piling up, and keeps it)."""
    vel = _velocity(state)
    along = np.add.reduce(slip(model, frame, vel) * frame.unit, -1)
    lam = frame.stick * (along - model.eps[:, None]) / frame.response
    _apply(model, frame, state, vel, lam, np.zeros(state.t.shape))


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
