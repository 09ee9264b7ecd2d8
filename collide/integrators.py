"""Time integrators for the contact phase. Each maps (model, state, h) to a new state.

`h` is a (B,) array of step sizes; a member with h = 0 is left unchanged, which lets one call
serve a batch whose members are in different phases. Every integrator applies forces as equal
and opposite impulses at one contact point, so linear and angular momentum are conserved to
round-off whatever the step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from collide import friction as fr
from collide import pairstep
from collide import physics as ph
from collide.model import Model, State


@dataclass
class Geometry:
    """Contact geometry and spring forces at one configuration, reused by the next step."""

    c: ph.Contacts
    fn: np.ndarray
    fw: np.ndarray
    engaged: ph.Engaged | None = None
    modes: fr.Modes | None = None
    events: np.ndarray | None = None  # the modes' event values at this state
    frame: fr.KickFrame | None = None  # the friction kick's rows here (built on first use)
    speeds: tuple | None = None  # the modes' event values and rates here, unscaled, when known


def geometry(model: Model, s: np.ndarray, engaged: ph.Engaged | None = None,
             modes: fr.Modes | None = None) -> Geometry:
    c = ph.contact_geometry(model, s, engaged)
    fn, fw = ph.normal_forces(model, c)
    return Geometry(c, fn, fw, engaged, modes)


@dataclass
class StepForces:
    """Friction forces in effect at the end of a step, for display (pairs, walls)."""

    pair: np.ndarray
    wall: np.ndarray


def no_friction(model: Model) -> StepForces:
    """No friction forces on any contact (display arrays of the right shapes)."""
    return StepForces(np.zeros((model.batch, model.n_pairs, model.dim)),
                      np.zeros((model.batch, model.n_walls, model.n_bodies, model.dim)))


def seed_step(model: Model, state: State, h: np.ndarray,
              start: Geometry | None = None) -> tuple[State, StepForces, Geometry]:
    """The report's update (section III): forces from the current state, then
    w += alpha h, s += v h + a h^2 / 2, v += a h. First order; kept to reproduce its tables."""
    out = state.copy()
    start = start or geometry(model, state.s)
    c, fn, fw = start.c, start.fn, start.fw
    acc = ph.normal_accel(model, c, fn, fw)
    forces = no_friction(model)
    hb = h[:, None, None]
    if model.friction:
        ft, fwt = ph.coulomb_explicit(model, c, fn, fw, state.v, state.w)
        facc, alpha = ph.apply_friction(model, c, ft, fwt)
        acc = acc + facc
        out.w = state.w + alpha * hb
        forces = StepForces(ft, fwt)
        # Work against friction: force times the power slip at the start of the step.
        before = ph.kinetic_energy(model, state.v, state.w)
        v_mid = state.v + facc * hb
        out.work = state.work + before - ph.kinetic_energy(model, v_mid, out.w)
    out.s = state.s + state.v * hb + 0.5 * acc * hb * hb
    out.v = state.v + acc * hb
    out.q = ph.advance_orientation(state.q, 0.5 * (state.w + out.w), h)
    out.t = state.t + h
    return out, forces, geometry(model, out.s)


def _kick(model: Model, vel: np.ndarray, g: Geometry, end: np.ndarray | None, start: np.ndarray | None,
          ) -> tuple[np.ndarray, StepForces | None]:
    """The velocity kicks at geometry g between two Verlet substeps: the end of one (over `end`
    seconds) and the start of the next (over `start`); either may be None. `vel` (B, F) holds
    the velocities and then the spins, flattened, and is updated in place. Springs and gravity
    are explicit; friction goes by the contacts' modes (`friction.frame_kick`; the stepper
    decides modes before it steps). Returns the work done against friction and, after a step's
    last kick, the friction forces."""
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    if not model.friction:
        nv = acc[0].size
        kick = acc.reshape(acc.shape[0], nv)
        # Two adds, as with friction: a sweep mixing mu = 0 with mu > 0 matches single runs.
        for part in (end, start):
            if part is not None:
                vel[:, :nv] += kick * part[:, None]
        return 0.0, (no_friction(model) if start is None else None)
    work, forces = fr.frame_kick(model, friction_frame(model, g), vel, acc, end, start)
    return work, (None if forces is None else StepForces(*forces))


def friction_frame(model: Model, g: Geometry) -> fr.KickFrame:
    """The friction rows of this geometry with its modes, built on first use."""
    if g.frame is None:
        g.frame = fr.geometry_frame(model, g.c, g.fn, g.fw, g.modes)
    return g.frame


SCALAR_PAIRS = True  # one run of two spheres in 1D/2D without walls: `pairstep` (plain floats)


def _composition(weights: tuple[float, ...]) -> Callable:
    """A symmetric composition of Verlet (kick-drift-kick) substeps of gamma h each: second order
    and symplectic for one, higher order for more, always momentum-exact. The kicks between two
    substeps share a geometry and are applied together; the geometry at the end is returned so
    the next step starts from it (one geometry a substep).

    After the whole step, stuck slips are put back on the band's edge: the symmetric step holds
    them there to its order, and this projection keeps the drift from piling up (and the order).
    """

    def step(model: Model, state: State, h: np.ndarray,
             start: Geometry | None = None) -> tuple[State, StepForces, Geometry]:
        if SCALAR_PAIRS and pairstep.applies(model):
            g = start or geometry(model, state.s)
            engaged = g.engaged is not None and bool(g.engaged.pair[0, 0] > 0)
            new, force, speeds = pairstep.composite(model, state, float(h[0]), weights, engaged, g.modes)
            forces = no_friction(model)
            if model.friction:
                forces.pair = force
            end = geometry(model, new.s, g.engaged, g.modes)
            end.speeds = speeds
            return new, forces, end
        b, n, dim = state.s.shape
        nv = n * dim
        vel = ph.generalised_velocity(state)
        g = start or geometry(model, state.s)
        if g.modes is not None and g.modes.turn is not None:
            g = Geometry(g.c, g.fn, g.fw, g.engaged, g.modes.midway(h))
        s, q = state.s, state.q
        steps = [gamma * h for gamma in weights]
        work, _ = _kick(model, vel, g, None, 0.5 * steps[0])
        forces = None
        for k, hk in enumerate(steps):
            s = s + vel[:, :nv].reshape(b, n, dim) * hk[:, None, None]
            q = ph.advance_orientation(q, vel[:, nv:].reshape(state.w.shape), hk)
            g = geometry(model, s, g.engaged, g.modes)
            done, forces = _kick(model, vel, g, 0.5 * hk, 0.5 * steps[k + 1] if k + 1 < len(steps) else None)
            work = work + done
        if model.friction and g.modes is not None and g.modes.any_stick:
            work = work + fr.settle(model, friction_frame(model, g), vel)
        return State(state.t + h, s, vel[:, :nv].reshape(state.v.shape), vel[:, nv:].reshape(state.w.shape), q,
                     state.work + work), forces, g

    return step


_CBRT2 = 2.0 ** (1.0 / 3.0)
_Y1 = 1.0 / (2.0 - _CBRT2)
# Yoshida (1990) fourth order; Kahan & Li (1997) s9odr6a sixth order.
YOSHIDA4 = (_Y1, -_CBRT2 * _Y1, _Y1)
_KL6_HALF = (0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
             0.08221359629355080023)
KAHAN6 = _KL6_HALF + (0.79854399093482996340,) + _KL6_HALF[::-1]


@dataclass(frozen=True)
class Integrator:
    """An integrator, its order without friction, and its linear stability limit (omega h)."""

    name: str
    step: Callable
    order: int
    stability: float
    events: bool  # locates contact starts and ends and friction mode changes exactly


INTEGRATORS: dict[str, Integrator] = {
    "seed": Integrator("seed", seed_step, 1, 2.0, events=False),
    "verlet": Integrator("verlet", _composition((1.0,)), 2, 2.0, events=True),  # velocity Verlet
    "yoshida4": Integrator("yoshida4", _composition(YOSHIDA4), 4, 2.0 / (_CBRT2 * _Y1),
                           events=True),
    "kahan6": Integrator("kahan6", _composition(KAHAN6), 6, 2.0 / max(abs(x) for x in KAHAN6),
                         events=True),
}
