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

Notation per contact: s is the tangential slip (surface of i relative to surface of j, or of the
sphere relative to the wall), d the direction friction acts against (2D: the slip's side of the
tangent; 3D: the slip's direction when the mode began, carried onto the tangent plane, which is
exact while the slip keeps its plane), K the slip change per unit tangential impulse, and
G = d(s . d)/dt with no friction (the "hold rate"); holding the slip needs friction G / K.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from collide import physics as ph
from collide.model import Model, State

BAND, SLIDE, STICK = 0, 1, 2
EDGE_TOL = 1e-9  # relative to the speed scale: how close to the band's edge counts as on it
STICK_SCALE = 1e-3  # s: turns a friction force into a slip change, to compare with EDGE_TOL


@dataclass
class Modes:
    """Friction mode of every contact (B, C), pairs then sphere-wall contacts (C = P + W N),
    and the direction friction acts against within it: 2D the side (+1/-1) of the tangent
    perp(n) the slip is on; 3D the slip's direction when the mode began (B, C, D)."""

    mode: np.ndarray
    side: np.ndarray
    entry: np.ndarray
    turn: np.ndarray | None = None  # 3D (B, C, D): how fast a sliding slip's direction turns

    def midway(self, h: np.ndarray) -> Modes:
        """The modes for a step of h: in 3D a sliding contact's direction is the one its slip
        will have half-way through, so that its turning is followed to second order."""
        if self.turn is None:
            return self
        return Modes(self.mode, self.side, self.entry + 0.5 * h[:, None, None] * self.turn)

    def __post_init__(self) -> None:
        # Fixed for the whole step: what every kick of it uses.
        self.sliding = (self.mode == SLIDE).astype(float)
        self.stuck = (self.mode == STICK).astype(float)
        self.any_stick = bool(self.stuck.any())


@dataclass
class ContactRows:
    """What a friction kick needs that depends on positions only, built once per geometry.

    Each contact has T = D - 1 tangent directions (`basis`; 2D: perp(n), 3D: an orthonormal
    pair). Its slip in that basis is `slip_rows[:, c*T:(c+1)*T] . V`, V = (v, w) flattened (B, F);
    a friction impulse with coordinates j changes V by -model.inv_mass_gen * (j . impulse_rows). A
    sphere's slip responds to a tangential impulse the same in every tangent direction
    (`response`, the K of the module notes), so an impulse along the slip never turns it.
    """

    slip_rows: np.ndarray  # (B, C T, F)
    impulse_rows: np.ndarray  # (B, C T, F)
    basis: np.ndarray  # (B, C, T, D)
    normals: np.ndarray  # (B, C, D): contact normals (pairs from i to j, walls outward)
    response: np.ndarray  # (B, C)
    normal: np.ndarray  # (B, C): normal force
    dist: np.ndarray  # (B, P) distance between the pairs' centres
    slip_spin: np.ndarray  # (B, P, N): lever of each body's spin in the pair's slip (l_i, l_j)
    turn_response: np.ndarray | None  # 3D (B, P): l_i a_i / I_i + l_j a_j / I_j
    lever_response: np.ndarray | None  # contact lever (B, C): pairs a_i / I_i + a_j / I_j, walls -a / I


@dataclass
class KickFrame:
    """Contact rows with the modes in effect: the friction direction of every contact, and
    which contacts slide or stick. Friction depends on positions only within a mode, so the
    force law is smooth there, as the springs' is within a contact."""

    rows: ContactRows
    modes: Modes
    unit: np.ndarray  # (B, C, T): d in tangent coordinates
    direction: np.ndarray  # (B, C, D): d in space
    slide: np.ndarray  # (B, C): mu F_n where the contact slides, else 0

    @property
    def stick(self) -> np.ndarray:
        """(B, C): 1.0 where the contact sticks, else 0."""
        return self.modes.stuck

    @property
    def any_stick(self) -> bool:
        return self.modes.any_stick


_EX, _EY = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def _tangent_basis(n: np.ndarray) -> np.ndarray:
    """(..., T, D) unit tangents of normals n (..., D): 2D perp(n); 3D two orthonormal ones."""
    if n.shape[-1] == 2:
        return ph.perp2(n)[..., None, :]
    helper = np.where((np.abs(n[..., :1]) < 0.9), _EX, _EY)
    e1 = ph.torque(n, helper)
    e1 = e1 / ph.norm(e1)[..., None]
    return np.stack((e1, ph.torque(n, e1)), axis=-2)


def _turned(basis: np.ndarray) -> np.ndarray:
    """n x e for a 3D tangent basis (e1, e2 = n x e1): (e2, -e1)."""
    return np.stack((basis[..., 1, :], -basis[..., 0, :]), axis=-2)


def _transport(entry: np.ndarray, n: np.ndarray) -> np.ndarray:
    """A direction carried onto the tangent plane of n (unit)."""
    d = entry - ph.dot(entry, n)[..., None] * n
    mag = ph.norm(d)
    return d / np.where(mag > 0, mag, 1.0)[..., None]


def contact_rows(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray) -> ContactRows:
    """The slip and impulse rows of every contact at this geometry (see `ContactRows`)."""
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
        force_spin = si * c.arm_i[..., None] + sj * c.arm_j[..., None]
        if dim == 2:  # n x perp(n) = 1
            slip_w.append(slip_spin)
            imp_w.append(force_spin)
        else:
            nxe = _turned(basis)[:, :, :, None, :]  # (B, P, T, 1, K): n x e
            slip_w.append((slip_spin[:, :, None, :, None] * nxe).reshape(b, pair_rows, n_bodies * k))
            imp_w.append((force_spin[:, :, None, :, None] * nxe).reshape(b, pair_rows, n_bodies * k))
    bases, normals = [basis], [c.n]
    lever = None if model.seed_lever or not k else \
        [c.arm_i * model.pair_inv_inertia_i + c.arm_j * model.pair_inv_inertia_j]
    normal = fn
    if model.n_walls:
        wall_normal = np.broadcast_to(model.wall_normal[None, :, None, :],
                                      (b, model.n_walls, n_bodies, dim)).reshape(b, -1, dim)
        wbasis = np.broadcast_to(_wall_basis(model.wall_normal.tobytes(), dim, n_bodies),
                                 (b, model.n_walls * n_bodies, tangents, dim))  # (B, W N, T, D)
        # Sphere n on wall w: slip = v_n . e - arm w_n . (n_w x e); the impulse -j acts at -arm n_w.
        own = _owners(model.n_walls, n_bodies)  # (1, W N, 1, N, 1)
        wall_rows = model.n_walls * n_bodies * tangents
        wv = (own * wbasis[:, :, :, None, :]).reshape(b, wall_rows, n_bodies * dim)
        slip_v.append(wv)
        imp_v.append(wv)
        if k:
            nxe = 1.0 if dim == 2 else _turned(wbasis)[:, :, :, None, :]
            slip_arm = ph._wall_slip_arm(model, c).reshape(b, -1)[:, :, None, None, None]
            force_arm = c.wall_arm.reshape(b, -1)[:, :, None, None, None]
            slip_w.append(-(own * slip_arm * nxe).reshape(b, wall_rows, n_bodies * k))
            imp_w.append(-(own * force_arm * nxe).reshape(b, wall_rows, n_bodies * k))
        bases.append(wbasis)
        normals.append(wall_normal)
        if lever is not None:
            lever.append(-(c.wall_arm * model.inv_inertia[:, None, :]).reshape(b, -1))
        normal = np.concatenate((fn, fw.reshape(b, -1)), axis=1)
    slip_rows, impulse_rows = _join(slip_v), _join(imp_v)
    if k:
        slip_rows = np.concatenate((slip_rows, _join(slip_w)), axis=2)
        impulse_rows = np.concatenate((impulse_rows, _join(imp_w)), axis=2)
    inv_mass_gen = model.inv_mass_gen
    # The response along the first tangent is the response along any.
    if tangents == 1:
        first, first_imp = slip_rows, impulse_rows
    else:
        width = slip_rows.shape[-1]
        first = slip_rows.reshape(b, -1, tangents, width)[:, :, 0]
        first_imp = impulse_rows.reshape(b, -1, tangents, width)[:, :, 0]
    turn = li * c.arm_i * model.pair_inv_inertia_i + lj * c.arm_j * model.pair_inv_inertia_j if dim == 3 else None
    return ContactRows(
        slip_rows=slip_rows, impulse_rows=impulse_rows, basis=_join(bases), normals=_join(normals),
        response=np.add.reduce(first * inv_mass_gen[:, None, :] * first_imp, -1),
        normal=normal, dist=model.pair_reach - c.overlap, slip_spin=slip_spin, turn_response=turn,
        lever_response=None if lever is None else _join(lever))


@functools.cache
def _wall_basis(normals: bytes, dim: int, n_bodies: int) -> np.ndarray:
    """(1, W N, T, D): the tangent basis of every sphere-wall contact (walls do not move)."""
    wall_normal = np.frombuffer(normals).reshape(-1, dim)
    return _tangent_basis(np.repeat(wall_normal, n_bodies, axis=0))[None]


@functools.cache
def _owners(n_walls: int, n_bodies: int) -> np.ndarray:
    """(1, W N, 1, N, 1): contact (w, n) belongs to body n."""
    return np.tile(np.eye(n_bodies), (n_walls, 1))[None, :, None, :, None]


def _join(parts: list[np.ndarray], axis: int = 1) -> np.ndarray:
    return np.concatenate(parts, axis=axis) if len(parts) > 1 else parts[0]


def kick_frame(model: Model, rows: ContactRows, modes: Modes) -> KickFrame:
    """The rows with these modes in effect (see `KickFrame`)."""
    if model.dim == 2:
        direction = rows.basis[:, :, 0] * modes.side[..., None]
        unit = modes.side[..., None]
    else:
        direction = _transport(modes.entry, rows.normals)
        unit = np.add.reduce(rows.basis * direction[:, :, None, :], -1)
    return KickFrame(rows=rows, modes=modes, unit=unit, direction=direction,
                     slide=modes.sliding * model.mu[:, None] * rows.normal)


def geometry_frame(model: Model, c: ph.Contacts, fn: np.ndarray, fw: np.ndarray, modes: Modes) -> KickFrame:
    """`kick_frame` of a geometry's contacts."""
    return kick_frame(model, contact_rows(model, c, fn, fw), modes)


def slip(model: Model, rows: ContactRows, vel: np.ndarray) -> np.ndarray:
    """Slip coordinates (B, C, T) at generalised velocity vel (B, F)."""
    return (rows.slip_rows @ vel[..., None]).reshape(vel.shape[0], -1, model.dim - 1)


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
    rows = frame.rows
    b, p = vel.shape[0], model.n_pairs
    nv = model.n_bodies * model.dim
    v = vel[:, :nv].reshape(b, model.n_bodies, model.dim)
    w = vel[:, nv:].reshape(b, model.n_bodies, -1)
    tangents = model.dim - 1
    along_acc = (rows.slip_rows[..., :nv] @ acc.reshape(b, nv, 1)).reshape(b, -1, tangents)
    rate = np.add.reduce(along_acc * frame.unit, -1)
    u = model.pair_diff @ v
    d, n = frame.direction[:, :p], rows.normals[:, :p]
    un = ph.dot(u, n)
    turn = un * ph.dot(u, d) / rows.dist
    slope = un * model.pair_inv_mass / rows.dist
    k = w.shape[-1]
    if model.dim == 3:
        n_rate = (u - un[..., None] * n) / rows.dist[..., None]
        # d = (e - (e . n) n) / |...| turns with n; its rate, and that rate's change per unit
        # impulse (which turns n at kappa d / dist).
        e = frame.modes.entry[:, :p]
        en = ph.dot(e, n)
        length = ph.norm(e - en[..., None] * n)[..., None]
        length = np.where(length > 0, length, 1.0)  # no direction yet (no slip): no turning

        def d_rate_of(nr: np.ndarray) -> np.ndarray:
            pr = -ph.dot(e, nr)[..., None] * n - en[..., None] * nr
            return (pr - ph.dot(pr, d)[..., None] * d) / length

        d_rate = d_rate_of(n_rate)
        d_rate_slope = d_rate_of(d * (model.pair_inv_mass / rows.dist)[..., None])
        s_vec = np.add.reduce((rows.slip_rows[:, :p * tangents] @ vel[..., None]).reshape(b, p, tangents, 1)
                              * rows.basis[:, :p], -2)
        turn = turn + ph.dot(s_vec, d_rate)
        slope = slope + ph.dot(s_vec, d_rate_slope)
        if k:
            # s . d' above already holds the rolling part's (L x n) . d'.
            n_rate_x_d = ph.torque(n_rate, d)
            turn = turn + ph.dot(rows.slip_spin @ w, n_rate_x_d)
            # The impulse turns the spins (along -n x d) and n' (along d, so n' x d stays).
            slope = slope - rows.turn_response * ph.dot(ph.torque(n, d), n_rate_x_d)
    lever_speed = None
    if k and not model.seed_lever:
        lever_speed = 0.5 * un
        turn = turn + ph.dot((model.select_i + model.select_j) @ w, ph.torque(n, d)) * lever_speed
    if model.n_walls:
        wall = np.zeros((b, rate.shape[1] - p))
        if lever_speed is not None:
            vw = np.broadcast_to(v[:, None], (b, model.n_walls) + v.shape[1:]).reshape(b, -1, model.dim)
            ww = np.broadcast_to(w[:, None], (b, model.n_walls) + w.shape[1:]).reshape(b, -1, k)
            speed = -ph.dot(vw, rows.normals[:, p:])
            wall = speed * ph.dot(ww, ph.torque(rows.normals[:, p:], frame.direction[:, p:]))
            lever_speed = np.concatenate((lever_speed, speed), axis=1)
        turn = np.concatenate((turn, wall), axis=1)
        slope = np.concatenate((slope, np.zeros_like(wall)), axis=1)
    if lever_speed is not None:
        slope = slope - lever_speed * rows.lever_response
    return rate + turn, slope


def frame_kick(model: Model, frame: KickFrame, vel: np.ndarray, acc: np.ndarray, end: np.ndarray | None,
               start: np.ndarray | None) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """The kicks at one geometry between two Verlet substeps, on the generalised velocity vel
    (B, F) in place: the end of one (springs and gravity `acc` over `end` seconds, then friction)
    and the start of the next (friction, then springs over `start`). Either may be None.
    Returns the work done against friction (B,) and, when nothing follows, the friction forces
    at the end of the step (pairs (B, P, D), walls (B, W, N, D)).

    slide: mu F_n against the slip for the signed time (substeps may run backwards). stick: the
    force that holds the slip on the band's edge, at the start state of a substep (explicit) and
    at its end state (implicit: lam = h G(v + dv(lam)) / K), so the substep's two halves mirror
    each other and compositions of it keep their order. The work is the kinetic energy the
    impulses remove, exactly.
    """
    b = vel.shape[0]
    nv = acc[0].size
    response = frame.rows.response
    kick = acc.reshape(b, nv)
    work = 0.0
    rate = None
    forces = None
    if end is not None:
        span = end[:, None]
        vel[:, :nv] += kick * span
        lam = frame.slide * span
        if frame.any_stick:
            rate, slope = hold_rate(model, frame, vel, acc)
            held = span * rate / (response - span * slope)
            lam = lam + frame.stick * held
            # G is affine in the contact's own impulse: its value after this one, for the next kick.
            rate = rate + slope * held if response.shape[1] == 1 else None
        work = _impulse(model, frame, vel, lam)
        if start is None:
            forces = -(lam / np.where(span != 0, span, 1.0))[..., None] * frame.direction
    if start is not None:
        span = start[:, None]
        lam = frame.slide * span
        if frame.any_stick:
            if rate is None:
                rate = hold_rate(model, frame, vel, acc)[0]
            lam = lam + frame.stick * span * rate / response
        vel[:, :nv] += kick * span
        work = work + _impulse(model, frame, vel, lam)
    if forces is None:
        return work, None
    return work, (forces[:, :model.n_pairs],
                  forces[:, model.n_pairs:].reshape(b, model.n_walls, model.n_bodies, model.dim))


def _impulse(model: Model, frame: KickFrame, vel: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Apply friction impulses lam (B, C) against the slip to vel in place; returns the kinetic
    energy they remove, -(dv . M . (vel + dv / 2)) = impulse . (vel + dv / 2)."""
    rows = frame.rows
    impulse = ((lam[..., None] * frame.unit).reshape(vel.shape[0], 1, -1) @ rows.impulse_rows)[:, 0]
    change = -model.inv_mass_gen * impulse
    work = np.add.reduce(impulse * (vel + 0.5 * change), -1)
    vel += change
    return work


def settle(model: Model, frame: KickFrame, vel: np.ndarray) -> np.ndarray:
    """Put stuck slips back on the band's edge (vel in place); returns the work done."""
    along = np.add.reduce(slip(model, frame.rows, vel) * frame.unit, -1)
    return _impulse(model, frame, vel, frame.stick * (along - model.eps[:, None]) / frame.rows.response)


def decide_modes(model: Model, rows: ContactRows, state: State, acc: np.ndarray, engaged: ph.Engaged,
                 scale: np.ndarray) -> tuple[KickFrame, np.ndarray]:
    """Modes of every contact at this state (at a phase start or after a located event), as a
    frame, and their event values here (`frame_events`).

    Outside the band: slide; inside: band; on its edge (within the event tolerance, in the units
    of `frame_events`, so a step that landed on a mode change always switches): stick if the
    friction that holds the slip there is available (0 < G / K < mu F_n), else slide or band."""
    b = state.v.shape[0]
    vel = ph.generalised_velocity(state)
    coords = slip(model, rows, vel)
    if model.dim == 2:
        side = np.where(coords[..., 0] >= 0, 1.0, -1.0)
        entry = np.zeros(side.shape + (2,))
    else:
        mag = ph.norm(coords)
        side = np.ones(mag.shape)
        unit = coords / np.where(mag > 0, mag, 1.0)[..., None]
        entry = np.add.reduce(unit[..., None] * rows.basis, -2)
    candidate = kick_frame(model, rows, Modes(np.full(side.shape, STICK, np.int8), side, entry))
    along = np.add.reduce(coords * candidate.unit, -1)  # |slip| (2D: along the side it is on)
    need = hold_rate(model, candidate, vel, acc)[0] / rows.response
    tol = (EDGE_TOL * scale)[:, None]
    eps = model.eps[:, None]
    force_tol = tol / (rows.response * STICK_SCALE)
    at_edge = np.abs(along - eps) <= tol
    edge_mode = np.where(need <= force_tol, BAND,
                         np.where(need < model.mu[:, None] * rows.normal - force_tol, STICK, SLIDE))
    mode = np.where(at_edge, edge_mode, np.where(along > eps, SLIDE, BAND))
    active = np.concatenate((engaged.pair, engaged.wall.reshape(b, -1)), axis=1) if model.n_walls else engaged.pair
    mode = np.where(active > 0, mode, BAND).astype(np.int8)
    turn = None
    if model.dim == 3 and (mode == SLIDE).any():
        # The slip turns at (ds/dt . e) / |s| towards e = n x d (friction only shortens it).
        across = ph.torque(rows.normals, candidate.direction)
        sideways = kick_frame(model, rows, Modes(mode, side, across))
        rate = hold_rate(model, sideways, vel, acc)[0]
        turn = np.where((mode == SLIDE) & (along > 0), rate / np.where(along > 0, along, 1.0), 0.0)[..., None] * across
    frame = kick_frame(model, rows, Modes(mode, side, entry, turn))
    return frame, frame_events(model, frame, state, acc, scale)


def frame_events(model: Model, frame: KickFrame, state: State, acc: np.ndarray, scale: np.ndarray,
                 rates: bool = False, engaged: ph.Engaged | None = None):
    """Event functions (B, 2C) of the frame's modes at this state, positive while each contact
    stays in its mode, scaled to speeds; with `rates` also their time derivatives, so a crossing
    can be located with a cubic Hermite through both ends of a step. A stuck contact's rates have
    no closed form: given the contact phase's `engaged` contacts they come from a central
    difference along the motion (`_stick_rates`), else they are NaN (and bracketed); in 3D the
    band's near edge is NaN.

    Two columns per contact, so that a mode entered on one of its boundaries still sees the
    other: slide: slip beyond the band's edge (and a constant); band: room left to either edge
    (3D: the far edge as seen along the slip's direction when the band was entered); stick: the
    margin to mu F_n and the need itself, as the slip change they would make over STICK_SCALE."""
    rows = frame.rows
    vel = ph.generalised_velocity(state)
    coords = slip(model, rows, vel)
    along = np.add.reduce(coords * frame.unit, -1)
    rate, _ = hold_rate(model, frame, vel, acc)
    k, mode = rows.response, frame.modes.mode
    eps, mu_fn = model.eps[:, None], model.mu[:, None] * rows.normal
    if model.dim == 2:
        signed = coords[..., 0]
        band_a, band_b = eps - signed, eps + signed
    else:
        band_a, band_b = eps - ph.norm(coords), eps + along
    first = np.where(mode == SLIDE, along - eps, np.where(mode == STICK, (mu_fn * k - rate) * STICK_SCALE, band_a))
    second = np.where(mode == SLIDE, 1.0, np.where(mode == STICK, rate * STICK_SCALE, band_b))
    values = np.concatenate((first, second), axis=1) / scale[:, None]
    if not rates:
        return values
    # The slip along d grows at G - K mu F_n when sliding, at G in the band (2D: d = side t).
    nan = np.full_like(rate, np.nan)
    rate_t = rate * frame.modes.side if model.dim == 2 else nan
    stick_first = stick_second = nan
    if engaged is not None and frame.any_stick:
        stick_first, stick_second = _stick_rates(model, frame, state, acc, engaged, rate)
    first_rate = np.where(mode == SLIDE, rate - k * mu_fn, np.where(mode == STICK, stick_first, -rate_t))
    band_b_rate = rate_t if model.dim == 2 else rate
    second_rate = np.where(mode == SLIDE, 0.0, np.where(mode == STICK, stick_second, band_b_rate))
    return values, np.concatenate((first_rate, second_rate), axis=1) / scale[:, None]


def _stick_rates(model: Model, frame: KickFrame, state: State, acc: np.ndarray, engaged: ph.Engaged,
                 rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time derivatives (B, C) of the stick event values (mu F_n K - G and G, times STICK_SCALE):
    central differences over +-delta along the motion (springs, gravity and every contact's
    friction), delta = 1e-4 / omega, so the truncation error is about 1e-9 and rounding about
    1e-12, relative. `rate`: G here."""
    rows = frame.rows
    b, nv = state.v.shape[0], state.v[0].size
    vel = ph.generalised_velocity(state)
    force = frame.slide + frame.stick * rate / rows.response
    impulse = ((force[..., None] * frame.unit).reshape(b, 1, -1) @ rows.impulse_rows)[:, 0]
    motion = np.concatenate((acc.reshape(b, nv), np.zeros((b, vel.shape[1] - nv))), axis=1) - \
        model.inv_mass_gen * impulse
    stiffest = np.concatenate((model.k_pair * model.pair_inv_mass, model.k_wall * model.inv_mass), axis=1) \
        if model.n_walls else model.k_pair * model.pair_inv_mass
    delta = 1e-4 / np.sqrt(stiffest.max(axis=1))
    ends = []
    for sign in (1.0, -1.0):
        d = sign * delta
        c = ph.contact_geometry(model, state.s + d[:, None, None] * state.v, engaged)
        fn, fw = ph.normal_forces(model, c)
        moved = kick_frame(model, contact_rows(model, c, fn, fw), frame.modes)
        g = hold_rate(model, moved, vel + d[:, None] * motion, ph.normal_accel(model, c, fn, fw))[0]
        ends.append((model.mu[:, None] * moved.rows.normal * moved.rows.response - g, g))
    per = (STICK_SCALE / (2.0 * delta))[:, None]
    return (ends[0][0] - ends[1][0]) * per, (ends[0][1] - ends[1][1]) * per
