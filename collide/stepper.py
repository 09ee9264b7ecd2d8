"""The run loop: closed-form free flight between contacts, integrator steps during contact.

`simulate` advances B runs in lock step. In each pass a run either jumps in closed form to
its next contact (or to its end), or takes one integrator step; so the step count follows the
contact time, not the run time. Integrators with `events` shorten the step that would cross the
start or end of a contact so that both land exactly on a step; the `seed` integrator keeps the
report's fixed grid instead (its jumps land on grid points), which is what reproduces its tables.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from collide import friction as fr
from collide import integrators, pairstep
from collide import physics as ph
from collide.integrators import INTEGRATORS, Geometry, Integrator, StepForces, friction_frame, geometry, no_friction
from collide.model import Model, State, select_model, select_state

MAX_STEPS_DEFAULT = 20_000_000
NO_CONTACT_TAIL = 1.0  # s: how long a run with no contact at all lasts


class RunError(RuntimeError):
    """A run that cannot be trusted: unstable step, blow-up, non-finite numbers, runaway length."""


@dataclass
class Trajectory:
    """Every step of B runs. Segment k-1 -> k was closed-form free flight where `free[k]`.

    t (S, B); s, v (S, B, N, D); w (S, B, N, K); q (S, B, N, Q); work (S, B);
    friction_pair (S, B, P, D) and friction_wall (S, B, W, N, D) in N, or None without friction.
    """

    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    w: np.ndarray
    q: np.ndarray
    work: np.ndarray
    free: np.ndarray
    friction_pair: np.ndarray | None = None
    friction_wall: np.ndarray | None = None

    @property
    def n_steps(self) -> int:
        return self.t.shape[0]

    def member(self, b: int) -> Trajectory:
        """Run b alone, without the repeated rows that lock-step added after it ended."""
        t = self.t[:, b]
        keep = np.ones(len(t), bool)
        keep[1:] = t[1:] > t[:-1]

        def pick(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[keep, b][:, None]

        return Trajectory(t[keep][:, None], pick(self.s), pick(self.v), pick(self.w), pick(self.q),
                          pick(self.work), pick(self.free), pick(self.friction_pair),
                          pick(self.friction_wall))


@dataclass
class ContactLog:
    """Per run (B,): first contact start, last contact end, total contact time, max overlap."""

    first_start: np.ndarray
    last_end: np.ndarray
    duration: np.ndarray
    max_overlap: np.ndarray
    count: np.ndarray


@dataclass
class RunResult:
    """What a run produced: the seam between the physics and everything that shows it."""

    model: Model
    initial: State
    final: State
    integrator: str
    dt: np.ndarray
    steps: np.ndarray
    jumps: np.ndarray
    wall_time_s: float
    contacts: ContactLog
    trajectory: Trajectory | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def batch_size(self) -> int:
        return self.model.batch

    def member(self, index: int) -> RunResult:
        """Batch member `index` as a run of batch 1 (its trajectory without lock-step padding)."""
        def pick(x: np.ndarray) -> np.ndarray:
            return x[index:index + 1]

        log = ContactLog(*(pick(getattr(self.contacts, f)) for f in
                           ("first_start", "last_end", "duration", "max_overlap", "count")))
        return RunResult(select_model(self.model, index), select_state(self.initial, index),
                         select_state(self.final, index), self.integrator, pick(self.dt),
                         pick(self.steps), pick(self.jumps), self.wall_time_s, log,
                         None if self.trajectory is None else self.trajectory.member(index),
                         list(self.warnings))


# ---------------------------------------------------------------------------------------------
# Stability


def contact_frequencies(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Angular frequency of each pair spring (B, P) and each sphere-wall spring (B, N)."""
    inv_reduced = model.inv_mass[:, model.pair_i] + model.inv_mass[:, model.pair_j]
    pair = np.sqrt(model.k_pair * inv_reduced)
    wall = np.sqrt(model.k_wall * model.inv_mass) if model.n_walls else np.zeros((model.batch, 0))
    return pair, wall


def max_frequency(model: Model) -> np.ndarray:
    """The stiffest frequency (B,) the contacts can produce, all engaged at once.

    One pair alone: exactly sqrt(k_eff (1/m_i + 1/m_j)). Otherwise (chains, walls) a
    Gershgorin bound on the mass-symmetrised stiffness matrix M^-1/2 K M^-1/2, whose rows hold
    k/m_i on the diagonal and k/sqrt(m_i m_j) off it: exact for a uniform chain's fastest mode.
    """
    pair, wall = contact_frequencies(model)
    if model.n_bodies == 2 and not model.n_walls:
        return pair.max(axis=1, initial=0.0)
    mi = model.mass[:, model.pair_i]
    mj = model.mass[:, model.pair_j]
    cross = model.k_pair / np.sqrt(mi * mj)
    rows = (model.select_i.T @ (model.k_pair / mi + cross)[..., None])[..., 0] + \
        (model.select_j.T @ (model.k_pair / mj + cross)[..., None])[..., 0]
    if model.n_walls:
        rows = rows + model.n_walls * model.k_wall / model.mass
    return np.sqrt(rows.max(axis=1))


def energy_bounds(model: Model, state: State) -> tuple[np.ndarray, np.ndarray]:
    """Upper bounds on the overlap each pair (B, P) and wall contact (B, N) can reach.

    All the energy in the centre-of-mass frame could end up in one pair's spring; against a
    wall, all the energy could. Gravity adds what a fall over the run could release (ignored
    here without a fixed duration).
    """
    ke = ph.kinetic_energy(model, state.v, state.w)
    total_mass = model.mass.sum(axis=1)
    p = np.einsum("bn,bnd->bd", model.mass, state.v)
    ke_com = ke - 0.5 * np.sum(p * p, -1) / total_mass
    pair = np.sqrt(2 * np.maximum(ke_com, 0.0)[:, None] / model.k_pair)
    wall = np.sqrt(2 * ke[:, None] / model.k_wall) if model.n_walls else np.zeros((model.batch, 0))
    return pair, wall


def check_run(model: Model, state: State, dt: np.ndarray, integrator: Integrator,
              max_steps: int) -> list[str]:
    """Refuse a step the integrator cannot keep stable, a contact so soft the spheres pass
    through each other, or a run that would take too many steps. Returns warnings."""
    warnings: list[str] = []
    pair_w, wall_w = contact_frequencies(model)
    omega = max_frequency(model)
    limit = integrator.stability / omega
    bad = dt > limit
    if bad.any():
        b = int(np.argmax(bad))
        raise RunError(f"dt = {dt[b]:.3g} s is beyond the stability limit of '{integrator.name}' "
                       f"for this contact (omega = {omega[b]:.4g} rad/s); the largest safe step is "
                       f"{limit[b]:.3g} s (use --dt auto to choose one)")
    pair_d, wall_d = energy_bounds(model, state)
    reach = model.radius[:, model.pair_i] + model.radius[:, model.pair_j]
    if model.n_pairs and (pair_d >= reach).any():
        b, p = np.unravel_index(np.argmax(pair_d / reach), pair_d.shape)
        names = model.contact_names()[p]
        raise RunError(f"contact.k = {model.k_pair[b, p] * 2:.4g} N/m is too soft for {names}: the "
                       f"overlap could reach {pair_d[b, p]:.3g} m, beyond the distance between "
                       f"centres at touch ({reach[b, p]:.3g} m); the spheres would pass through "
                       "each other. Use a stiffer contact.k")
    if model.n_walls and (wall_d >= model.radius).any():
        b, n = np.unravel_index(np.argmax(wall_d / model.radius), wall_d.shape)
        raise RunError(f"contact.k = {model.k_wall[b, n]:.4g} N/m is too soft for body "
                       f"{model.body_names[n]} on a wall: the overlap could reach {wall_d[b, n]:.3g} m, "
                       f"more than its radius; it would pass through the wall. Use a stiffer contact.k")
    small = np.minimum(model.radius[:, model.pair_i], model.radius[:, model.pair_j])
    if model.n_pairs and (pair_d > small).any():
        warnings.append("the contact is soft: an overlap could exceed the smaller radius")
    # Steps one contact takes; the slowest spring sets the longest contact.
    slowest = np.minimum(pair_w.min(axis=1, initial=np.inf), wall_w.min(axis=1, initial=np.inf))
    per_contact = math.pi / (slowest * dt)
    if (per_contact > max_steps).any():
        b = int(np.argmax(per_contact))
        raise RunError(f"dt = {dt[b]:.3g} s is so small that one contact would take "
                       f"{per_contact[b]:.3g} steps (limit {max_steps:.3g}); use a larger dt or auto")
    return warnings


# ---------------------------------------------------------------------------------------------
# Events


def _hermite_root(d0: np.ndarray, d1: np.ndarray, r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
    """Root in (0, 1) of the cubic Hermite through (0, d0, r0) and (1, d1, r1); r in per-step units.
    Safeguarded Newton on the cubic in Horner form, kept inside the bracket."""
    if d0.size == 1:  # one run, one contact: the same iteration in floats
        return np.full(d0.shape, _hermite_root_1(float(d0.flat[0]), float(d1.flat[0]), float(r0.flat[0]),
                                                 float(r1.flat[0])))
    c2 = 3.0 * (d1 - d0) - 2.0 * r0 - r1
    c3 = 2.0 * (d0 - d1) + r0 + r1
    theta = np.clip(d0 / np.where(d0 != d1, d0 - d1, 1.0), 0.0, 1.0)
    lo, hi = np.zeros_like(theta), np.ones_like(theta)
    positive = d0 > 0
    bracketed = positive != (d1 > 0)  # the others have no root to find: they do not hold it up
    for _ in range(60):  # Newton converges in a few; bisection bounds the rest
        p = d0 + theta * (r0 + theta * (c2 + theta * c3))
        dp = r0 + theta * (2.0 * c2 + 3.0 * c3 * theta)
        same = (p > 0) == positive
        lo = np.where(same, theta, lo)
        hi = np.where(same, hi, theta)
        newton = theta - p / np.where(dp != 0, dp, np.inf)
        step = np.where((newton >= lo) & (newton <= hi), newton, 0.5 * (lo + hi))
        done = np.abs(step - theta)[bracketed].max(initial=0.0) <= 1e-15
        theta = step
        if done:
            break
    return theta

def _hermite_root_1(d0: float, d1: float, r0: float, r1: float) -> float:
    """`_hermite_root` for one cubic."""
    c2 = 3.0 * (d1 - d0) - 2.0 * r0 - r1
    c3 = 2.0 * (d0 - d1) + r0 + r1
    theta = min(max(d0 / (d0 - d1 if d0 != d1 else 1.0), 0.0), 1.0)
    if (d0 > 0) == (d1 > 0):
        return theta  # no root to find
    lo, hi = 0.0, 1.0
    positive = d0 > 0
    for _ in range(60):
        p = d0 + theta * (r0 + theta * (c2 + theta * c3))
        dp = r0 + theta * (2.0 * c2 + 3.0 * c3 * theta)
        if (p > 0) == positive:
            lo = theta
        else:
            hi = theta
        newton = theta - p / dp if dp != 0 else math.inf
        step = newton if lo <= newton <= hi else 0.5 * (lo + hi)
        done = abs(step - theta) <= 1e-15
        theta = step
        if done:
            break
    return theta


def _scaled_overlaps(model: Model, state: State, g: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """Overlaps and their rates (B, C), pairs then walls, relative to the touching distance."""
    c = g.c
    rate_pair, rate_wall = ph.contact_rates(model, state, c)
    reach = model.pair_reach
    if not model.n_walls:
        return c.overlap / reach, rate_pair / reach
    radius = np.tile(model.radius, (1, model.n_walls))
    b = model.batch
    d = np.concatenate((c.overlap / reach, c.wall_overlap.reshape(b, -1) / radius), axis=1)
    r = np.concatenate((rate_pair / reach, rate_wall.reshape(b, -1) / radius), axis=1)
    return d, r


def _mode_events(model: Model, state: State, g: Geometry, scale: np.ndarray, rates: bool = False):
    """The friction modes' event values (and rates) at a geometry, or None without friction."""
    if g.modes is None:
        return None
    if g.speeds is not None:  # computed by the step that ended here
        values, slopes = g.speeds
        return (values / scale[:, None], slopes / scale[:, None]) if rates else values / scale[:, None]
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    return fr.frame_events(model, friction_frame(model, g), state, acc, scale, rates, g.engaged)


def step_with_events(model: Model, integrator: Integrator, state: State, h: np.ndarray,
                     start: Geometry, scale: np.ndarray) -> tuple[State, StepForces, Geometry, np.ndarray]:
    """One step; where an event would happen inside it, shorten it to land there.

    Events: a contact starts or ends (overlap crosses zero: located with a cubic Hermite
    through both ends of the trial step), or a contact's friction mode must change (a mode
    event function crosses zero: located by a bracketing secant, the Illinois method). Each
    refinement re-steps from the start with a shorter step.
    """
    new, forces, end = integrator.step(model, state, h, start)
    if not integrator.events:
        return new, forces, end, h
    d0, r0 = _scaled_overlaps(model, state, start)
    e0 = start.events if start.events is not None else _mode_events(model, state, start, scale)
    mode_tol = 0.5 * fr.EDGE_TOL
    live = None if e0 is None else e0 > mode_tol  # a mode entered on its own boundary is not watched
    b = model.batch
    rows = np.arange(b)
    h_full = np.where(h != 0, h, 1.0)
    pending = np.zeros(b, bool)  # a mode event is bracketed
    col = np.zeros(b, int)  # the event function being solved for
    lo, hi = np.zeros(b), np.ones(b)
    f_lo, f_hi = np.zeros(b), np.zeros(b)
    # The two trials before the latest (fraction of h, value): interpolation through the latest
    # points converges fastest; the bracket keeps it safe.
    t1, f1 = np.full(b, np.nan), np.full(b, np.nan)
    t2, f2 = np.full(b, np.nan), np.full(b, np.nan)
    # The shortest trial that crossed a contact's start or end (fraction, overlaps and rates at
    # its end): a re-step that falls just short of the crossing refines between the two.
    past = np.full(b, np.inf)
    d_past, r_past = np.zeros_like(d0), np.zeros_like(r0)
    accepted = np.zeros(b, bool)
    shortest = np.where(h != 0, 16 * np.spacing(np.abs(state.t) + np.abs(h)), 0.0)
    for _ in range(30):
        frac = h / h_full
        d1, r1 = _scaled_overlaps(model, new, end)
        tol = ph.TOUCH_TOL
        crossing = ((d0 > tol) & (d1 < -tol)) | ((d0 < -tol) & (d1 > tol))
        theta = np.full(b, np.inf)  # where to re-step to; inf: accept this trial
        if crossing.any():
            root = _hermite_root(d0, d1, r0 * h[:, None], r1 * h[:, None])
            first = np.where(crossing, root, np.inf).min(axis=1)
            theta = np.full(b, np.inf)
            np.multiply(first, frac, out=theta, where=np.isfinite(first))
            crossed = crossing.any(axis=1) & (frac < past)
            past = np.where(crossed, frac, past)
            d_past = np.where(crossed[:, None], d1, d_past)
            r_past = np.where(crossed[:, None], r1, r_past)
        short = np.isfinite(past) & (frac < past) & ~crossing.any(axis=1)
        if short.any():
            # Fell short: the crossing lies between this trial's end and the shorter crossing one.
            gap = np.where(short, past - frac, 0.0)
            ahead = ((d1 > tol) & (d_past < -tol)) | ((d1 < -tol) & (d_past > tol))
            root = _hermite_root(d1, d_past, r1 * (gap * h_full)[:, None], r_past * (gap * h_full)[:, None])
            first = np.where(ahead, root, np.inf).min(axis=1)
            found = short & np.isfinite(first)
            theta = np.where(found, frac + np.where(found, first, 0.0) * gap, theta)
        if e0 is not None:
            e1, rate1 = _mode_events(model, new, end, scale, True)
            beyond = live & (e1 < -mode_tol)
            fresh = beyond.any(axis=1) & ~pending
            if fresh.any():
                # The function that crosses first (by linear estimate) is the one to solve for.
                guess = np.where(beyond, e0 / np.where(beyond, e0 - e1, 1.0), np.inf)
                col = np.where(fresh, guess.argmin(axis=1), col)
                lo = np.where(fresh, 0.0, lo)
                f_lo = np.where(fresh, e0[rows, col], f_lo)
                pending = pending | fresh
                hi = np.where(fresh, frac, hi)
                f_hi = np.where(fresh, e1[rows, col], f_hi)
                t1, f1 = np.where(fresh, 0.0, t1), np.where(fresh, e0[rows, col], f1)
                t2, f2 = np.where(fresh, np.nan, t2), np.where(fresh, np.nan, f2)
            f = e1[rows, col]
            update = pending & ~fresh
            if update.any():
                # Keep the bracket [lo, hi] around the root of the critical function.
                hi = np.where(update & (f < 0), frac, hi)
                f_hi = np.where(update & (f < 0), f, f_hi)
                lo = np.where(update & (f >= 0), frac, lo)
                f_lo = np.where(update & (f >= 0), f, f_lo)
            others_fine = ~(beyond & (np.arange(e1.shape[1])[None, :] != col[:, None])).any(axis=1)
            landed = pending & (np.abs(f) <= mode_tol) & others_fine
            pending = pending & ~landed
            # A mode change landed short of a contact crossing: it comes first; stop here.
            theta = np.where(landed & short, np.inf, theta)
            if pending.any():
                estimate = _bracketed_root(lo, f_lo, hi, f_hi, (t2, f2), (t1, f1), (frac, f))
                # Slide and band events have analytic rates: a cubic Hermite through both ends of
                # the first trial, then Newton from the latest trial, kept inside the bracket.
                slope = rate1[rows, col] * h_full
                if fresh.any():
                    rate0 = _mode_events(model, state, start, scale, True)[1]
                    s0 = rate0[rows, col] * h
                    known = fresh & np.isfinite(s0) & np.isfinite(slope)
                    if known.any():
                        cubic = _hermite_root(e0[rows, col][:, None], f[:, None], s0[:, None],
                                              (slope * frac)[:, None])[:, 0] * frac
                        estimate = np.where(known, cubic, estimate)
                with np.errstate(divide="ignore", invalid="ignore"):
                    newton = frac - f / slope
                usable = update & np.isfinite(newton) & (newton > lo) & (newton < hi)
                estimate = np.where(usable, newton, estimate)
                theta = np.where(pending, np.minimum(theta, estimate), theta)
                t2, f2 = np.where(pending, t1, t2), np.where(pending, f1, f2)
                t1, f1 = np.where(pending, frac, t1), np.where(pending, f, f1)
        # A run that accepted its trial keeps it while others refine theirs (its trial is taken
        # again unchanged, but the bookkeeping above has moved on).
        redo = np.isfinite(theta) & (np.abs(theta - frac) > 1e-12 * np.maximum(frac, 1e-300)) & ~accepted
        accepted = accepted | ~redo
        if not redo.any():
            break
        # Never shorter than a few ticks of the clock: an event closer than that is taken as
        # passed (by under 1e-15 s of a 0.1 s run), or the step would not move the time at all.
        h = np.where(redo, np.maximum(h_full * np.maximum(theta, 1e-12), shortest), h)
        new, forces, end = integrator.step(model, state, h, start)
    return new, forces, end, h


def _bracketed_root(lo: np.ndarray, f_lo: np.ndarray, hi: np.ndarray, f_hi: np.ndarray,
                    older: tuple, previous: tuple, latest: tuple) -> np.ndarray:
    """Next estimate of a root bracketed in [lo, hi] (f_lo >= 0 > f_hi), from the latest three
    trials (t, f): inverse quadratic interpolation through them (exact for the quadratic onset
    of an event at a tangency), else the secant through the latest two; where that falls outside
    the bracket, false position on it, nudged off its ends, or bisection."""
    (a, fa), (b, fb), (c, fc) = older, previous, latest
    with np.errstate(divide="ignore", invalid="ignore"):
        iqi = (a * fb * fc / ((fa - fb) * (fa - fc)) + b * fa * fc / ((fb - fa) * (fb - fc))
               + c * fa * fb / ((fc - fa) * (fc - fb)))
        secant = c - fc * (c - b) / (fc - fb)
        estimate = np.where(np.isfinite(iqi) & (iqi > lo) & (iqi < hi), iqi, secant)
        width = hi - lo
        position = lo + width * f_lo / (f_lo - f_hi)
        position = np.where(np.isfinite(position), np.clip(position, lo + 0.01 * width, hi - 0.01 * width),
                            0.5 * (lo + hi))
        inside = np.isfinite(estimate) & (estimate > lo) & (estimate < hi)
    return np.where(inside, estimate, position)

def _active(model: Model, state: State, g: Geometry) -> np.ndarray:
    pair, wall = ph.active_contacts(model, state, g.c)
    return pair.any(axis=1) | wall.any(axis=(1, 2))


# ---------------------------------------------------------------------------------------------
# The loop


def _masked(new: State, old: State, keep_old: np.ndarray) -> State:
    """Runs where keep_old is set keep their old state (a no-op step for finished runs)."""
    if not keep_old.any():
        return new
    k3 = keep_old[:, None, None]
    return State(np.where(keep_old, old.t, new.t), np.where(k3, old.s, new.s), np.where(k3, old.v, new.v),
                 np.where(k3, old.w, new.w), np.where(k3, old.q, new.q),
                 np.where(keep_old, old.work, new.work))


def default_tail(contacts: ContactLog) -> np.ndarray:
    """After the last separation, keep going long enough to see the bodies part."""
    span = contacts.last_end - contacts.first_start
    tail = np.maximum(2.0 * span, 0.1 * contacts.last_end)
    return np.where(np.isfinite(tail), tail, NO_CONTACT_TAIL)


def simulate(model: Model, initial: State, *, integrator: str, dt: np.ndarray,
             duration: np.ndarray | None = None, tail: np.ndarray | None = None,
             record: bool = True, max_steps: int = MAX_STEPS_DEFAULT,
             event_tol: np.ndarray | float = fr.EDGE_TOL) -> RunResult:
    """Run B scenes to their end. `duration` and `tail` are (B,) with NaN meaning 'not set'.
    `event_tol` (relative to the fastest initial speed): how close a friction mode change must
    land (the slip to the band's edge, a stuck contact's force to its limits)."""
    integ = INTEGRATORS[integrator]
    b = model.batch
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (b,)).copy()
    warnings = check_run(model, initial, dt, integ, max_steps)
    t_end = np.full(b, np.inf) if duration is None else np.where(np.isnan(duration), np.inf, duration)
    tail_set = np.full(b, np.nan) if tail is None else np.asarray(tail, dtype=float)
    state = initial.copy()
    done = np.zeros(b, bool)
    steps = np.zeros(b, dtype=np.int64)
    jumps = np.zeros(b, dtype=np.int64)
    log = ContactLog(np.full(b, np.nan), np.full(b, np.nan), np.zeros(b), np.zeros(b), np.zeros(b, np.int64))
    in_contact = np.zeros(b, bool)
    contact_began = np.zeros(b)
    zero_forces = no_friction(model)
    rows: list[tuple] = []

    def snapshot(s: State, free: np.ndarray, forces: StepForces) -> None:
        if record:
            # Lock-step rows repeat runs that did not move; `free` marks them as zero-length.
            rows.append((s.t, s.s, s.v, s.w, s.q, s.work, free, forces.pair, forces.wall))

    snapshot(state, np.ones(b, bool), zero_forces)
    # Scale of the friction events: the fastest body at the start (at least the band), times the
    # tolerance asked for over the one the events are located to.
    speed = np.maximum(np.sqrt(np.max(np.sum(initial.v ** 2, -1), axis=1)), 10 * model.eps + 1e-300)
    scale = speed * np.broadcast_to(np.asarray(event_tol, dtype=float), (b,)) / fr.EDGE_TOL
    started = time.perf_counter()
    passes = 0
    while not done.all():
        tau = ph.time_to_contact(model, state)
        contact = (tau == 0.0) & ~done
        if not integ.events:
            # The seed integrator only sees contact on its grid: step when it begins within one.
            t_next = state.t + dt
            contact = contact | (~done & (tau < dt) & (t_next <= t_end * (1 + 1e-15)))
        # Contact bookkeeping: starts and ends, for the summary and the tail.
        began = contact & ~in_contact
        ended = ~contact & in_contact & ~done
        log.first_start = np.where(began & np.isnan(log.first_start), state.t, log.first_start)
        contact_began = np.where(began, state.t, contact_began)
        log.count += began
        log.last_end = np.where(ended, state.t, log.last_end)
        log.duration += np.where(ended, state.t - contact_began, 0.0)
        in_contact = contact
        if ended.any():
            _check_energy(model, initial, state, ended, dt, integ)

        free = ~contact & ~done
        # A free run with no contact ahead ends a tail after its last contact.
        ending = free & np.isinf(tau) & np.isinf(t_end)
        if ending.any():
            tails = np.where(np.isnan(tail_set), default_tail(log), tail_set)
            if not integ.events:
                tails = np.ceil(tails / dt) * dt
            t_end = np.where(ending, state.t + tails, t_end)
        to_contact = tau if integ.events else np.floor(tau / dt) * dt
        if free.any():
            jump = np.where(free, np.minimum(to_contact, t_end - state.t), 0.0)
            state = _masked(ph.free_flight(model, state, jump), state, ~free)
            jumps += free
            snapshot(state, free, zero_forces)
        if contact.any():
            state, passes = _contact_phase(model, integ, state, contact, dt, t_end, steps, log,
                                           snapshot, passes, max_steps, scale)
        done = done | (state.t >= t_end * (1 - 1e-15))
    wall_time = time.perf_counter() - started
    # A contact still pressing at the end (resting on a wall) counts up to the end.
    log.duration += np.where(in_contact, state.t - contact_began, 0.0)
    trajectory = None
    if record:
        trajectory = Trajectory(*(np.stack(col) for col in zip(*rows)))
        if not model.friction:
            trajectory.friction_pair = trajectory.friction_wall = None
    return RunResult(model=model, initial=initial, final=state, integrator=integrator, dt=dt,
                     steps=steps, jumps=jumps, wall_time_s=wall_time, contacts=log,
                     trajectory=trajectory, warnings=warnings)


def _contact_phase(model: Model, integ: Integrator, state: State, contact: np.ndarray, dt: np.ndarray,
                   t_end: np.ndarray, steps: np.ndarray, log: ContactLog, snapshot, passes: int,
                   max_steps: int, scale: np.ndarray) -> tuple[State, int]:
    """Step the runs in `contact` until one of them leaves contact or reaches its end."""
    g = _engage(model, integ, state, geometry(model, state.s), scale)
    not_stepping = ~contact
    all_stepping = not not_stepping.any()
    free_flags = np.zeros(model.batch, bool) | not_stepping
    stalled = 0
    while True:
        passes += 1
        if passes > max_steps:
            raise RunError(f"the run did not end within {max_steps} steps; set a duration or a larger dt")
        h = np.where(contact, np.minimum(dt, t_end - state.t), 0.0)
        before = state.t
        new, forces, g, h = step_with_events(model, integ, state, h, g, scale)
        stalled = stalled + 1 if (contact & (new.t == before)).any() else 0
        if stalled > 64:
            raise RunError(f"the run stopped advancing at t = {float(before.max()):.6g} s (events closer than the "
                           "clock resolves); report this scene, or try a looser --tol or a given --dt")
        g = _engage(model, integ, new, g, scale)
        state = new if all_stepping else _masked(new, state, not_stepping)
        steps += contact
        snapshot(state, free_flags, forces)
        d = g.c.overlap
        log.max_overlap = np.maximum(log.max_overlap, d.max(axis=1, initial=0.0))
        if model.n_walls:
            log.max_overlap = np.maximum(log.max_overlap, g.c.wall_overlap.max(axis=(1, 2), initial=0.0))
        if passes % 256 == 0 and not (np.isfinite(state.s).all() and np.isfinite(state.v).all()):
            _non_finite(model, integ, state)
        active = _active(model, state, g) if integ.events else _active_seed(model, state, g, dt)
        if ((contact & active & (state.t < t_end * (1 - 1e-15))) != contact).any():
            if not (np.isfinite(state.s).all() and np.isfinite(state.v).all()):
                _non_finite(model, integ, state)
            return state, passes


def _engage(model: Model, integ: Integrator, state: State, g: Geometry, scale: np.ndarray) -> Geometry:
    """Geometry whose engaged contacts are those pressing or touching and approaching now, with
    the friction mode of each decided from the state (events land exactly on mode changes)."""
    if not integ.events:
        return g  # the seed's own law: springs clamped at zero overlap, explicit friction
    pair, wall = ph.active_contacts(model, state, g.c)
    engaged = ph.Engaged(pair.astype(float), wall.astype(float))
    same = g.engaged is not None and np.array_equal(engaged.pair, g.engaged.pair) and \
        np.array_equal(engaged.wall, g.engaged.wall)
    if not same:
        g = geometry(model, state.s, engaged)
    if model.friction:
        if integrators.SCALAR_PAIRS and pairstep.applies(model):
            g.modes, g.speeds = pairstep.decide(model, state, bool(engaged.pair[0, 0] > 0), float(scale[0]))
            g.frame, g.events = None, g.speeds[0] / scale[:, None]
        else:
            rows = fr.contact_rows(model, g.c, g.fn, g.fw)
            acc = ph.normal_accel(model, g.c, g.fn, g.fw)
            g.frame, g.events = fr.decide_modes(model, rows, state, acc, engaged, scale)
            g.modes, g.speeds = g.frame.modes, None
    return g


def _active_seed(model: Model, state: State, g: Geometry, dt: np.ndarray) -> np.ndarray:
    """On the seed's grid a run stays in its contact phase while anything overlaps."""
    return (g.c.overlap > 0).any(axis=1) | (g.c.wall_overlap > 0).any(axis=(1, 2))


def _non_finite(model: Model, integ: Integrator, state: State) -> None:
    bad = int(np.argmax(~(np.isfinite(state.v).all(axis=(1, 2)) & np.isfinite(state.s).all(axis=(1, 2)))))
    raise RunError(f"non-finite numbers at t = {state.t[bad]:.6g} s: the step is unstable; "
                   f"try a smaller dt (largest safe step {_safe_step(model, integ)[bad]:.3g} s)")


def _safe_step(model: Model, integ: Integrator) -> np.ndarray:
    return integ.stability / max_frequency(model)


def _check_energy(model: Model, initial: State, state: State, members: np.ndarray, dt: np.ndarray,
                  integ: Integrator) -> None:
    """Stop a run whose energy has grown far beyond its start: the step is unstable."""
    e0 = ph.kinetic_energy(model, initial.v, initial.w)
    e1 = ph.kinetic_energy(model, state.v, state.w)
    if model.gravity is not None:
        e0 = e0 - np.einsum("bn,bnd,bd->b", model.mass, initial.s, model.gravity)
        e1 = e1 - np.einsum("bn,bnd,bd->b", model.mass, state.s, model.gravity)
    grown = members & (e1 - e0 > 0.5 * np.abs(e0) + 1e-300)
    if grown.any():
        b = int(np.argmax(grown))
        raise RunError(f"energy grew from {e0[b]:.4g} J to {e1[b]:.4g} J during a contact at "
                       f"dt = {dt[b]:.3g} s: the step is unstable; the largest safe step is "
                       f"{_safe_step(model, integ)[b]:.3g} s")
