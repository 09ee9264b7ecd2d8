"""Running scenes through the compiled event engine (`collide.engine.event`).

`simulate` packs a batch of runs into the kernels' tables, runs each member, and unpacks a
`RunResult` (`collide.results`): final states, counters, contact log and (when recording) a
`Trajectory` per member. DEM runs go through `collide.dem` instead (`collide.run` chooses).
The engine itself (windows, islands, closed-form free flight, event-located steps; the seed's
fixed grid) is described in docs/engine.md and the README.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np

from collide.engine import jit, layout, tier
from collide.engine.event import run as event_run
from collide.errors import RunError, SawtoothError
from collide.integrators import INTEGRATORS, Integrator
from collide.limits import MAX_STEPS_DEFAULT
from collide.model import (
    TABLE_K,
    TABLE_REST,
    Model,
    State,
    damping_ratio,
    max_frequency,
    plane_of_motion,
    reference_frequency,
    select_model,
    turned_quaternions,
)
from collide.results import ContactLog, RunResult
from collide.settings import THREADS_VARIABLE, count_setting
from collide.trajectory import Trajectory

if TYPE_CHECKING:
    from concurrent.futures import ThreadPoolExecutor

EDGE_TOL = float(layout.EDGE_TOL)
EDGE_BAND_SHARE = 0.5  # of eps: the widest a band's edge may count (see simulate)


def step_limit_error(steps: int, t: float, open_ended: bool) -> RunError:
    """The refusal of a run that reached its step limit, naming the way out."""
    at = f" (at t = {t:.6g} s)" if np.isfinite(t) else ""
    if open_ended:
        return RunError(f"the run had not ended after {steps} steps{at}: a run with no duration goes on until "
                        "nothing can meet again; give it one (--set duration=SECONDS) or allow more steps "
                        "(--max-steps)")
    return RunError(f"the run reached its limit of {steps} steps{at}; use a larger dt or a shorter duration, or "
                    "allow more (--max-steps)")


# A progress display: called about 4 times a second while a run is going, with (member, members,
# simulated time reached, simulated end (inf if open), steps so far, seconds since it started,
# the kinetic energy over its peak so far: how far a run to rest has settled, NaN where unknown).
Progress = Callable[[int, int, float, float, int, float, float], None]
PROGRESS_PERIOD = 0.25
# Set to a file name: the process appends one JSON line to it when its first kernel step starts,
# with the process's CPU time so far (benchmarks/bench_startup.py measures start-up with it).
STARTUP_PROBE_VARIABLE = "COLLIDE_STARTUP_PROBE"
_STARTUP_PROBE = [os.environ.get(STARTUP_PROBE_VARIABLE, "")]



@contextmanager
def watch(progress: Progress | None, fp: np.ndarray, now: int, t_end: float, member: int, members: int,
          settling: int = -1):
    """Report a kernel's progress from a thread while it runs: the compiled kernels release the
    GIL and write the time reached and their step count into fp[now], fp[now + 1] (and the DEM
    kernel its kinetic energy and peak into fp[settling], fp[settling + 1])."""
    if progress is None:
        yield
        return
    done = threading.Event()
    started = time.perf_counter()

    def poll() -> None:
        while not done.wait(PROGRESS_PERIOD):
            peak = fp[settling + 1] if settling >= 0 else 0.0
            ratio = float(fp[settling] / peak) if peak > 0.0 else math.nan
            progress(member, members, float(fp[now]), t_end, int(fp[now + 1]), time.perf_counter() - started, ratio)

    thread = threading.Thread(target=poll, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


# ---------------------------------------------------------------------------------------------
# Before a run: refuse what cannot be trusted


def approach_bound(model: Model, state: State) -> np.ndarray:
    """A bound (B,) on the normal approach speed a contact can reach: twice the fastest centre
    speed relative to the centre of mass (spin adds no normal approach), plus a fall under
    gravity onto a wall from the highest start."""
    p = np.einsum("bn,bnd->bd", model.mass, state.v)
    com = p / model.mass.sum(axis=1)[:, None]
    with np.errstate(over="ignore", invalid="ignore"):
        rel = np.sqrt(((state.v - com[:, None, :]) ** 2).sum(-1)).max(axis=1)
        speed = 2.0 * rel
        if model.gravity is not None and model.n_walls:
            height = np.einsum("bnd,wd->bwn", state.s, model.wall_normal) - \
                (model.wall_point * model.wall_normal).sum(-1)[None, :, None]
            into = np.maximum(-np.einsum("bd,wd->bw", model.gravity, model.wall_normal), 0.0)
            fall = np.sqrt(2.0 * into[:, :, None] * np.maximum(height, 0.0)).max(axis=(1, 2))
            speed = speed + fall + np.sqrt((state.v ** 2).sum(-1)).max(axis=1)
    return speed


def _damped_peak(restitution: np.ndarray) -> np.ndarray:
    """The largest overlap of a linear spring-dashpot contact of this restitution against the
    undamped one's, v / omega: exp(-zeta phi / sqrt(1 - zeta^2)), phi = atan2(sqrt(1 - zeta^2),
    zeta) (1 for e = 1; the least damping of a scene's contacts bounds them all)."""
    zeta = np.minimum(damping_ratio(restitution, False), 1.0 - 1e-9)
    root = np.sqrt(1.0 - zeta**2)
    return np.exp(-zeta * np.arctan2(root, zeta) / root)


def check_pass_through(model: Model, state: State) -> None:
    """Refuse a contact so soft that the spheres would pass through each other or a wall."""
    # Pass-through: the overlap a head-on approach at the bound would reach, against the
    # distance between centres at touch (the stiffest wall: the sphere's own radius).
    speed = approach_bound(model, state)
    k_pair = model.pair_table[..., 0].reshape(model.batch, -1).min(axis=1)
    damped = _damped_peak(model.pair_table[..., TABLE_REST].reshape(model.batch, -1).max(axis=1))
    heavy = np.sort(model.mass, axis=1)[:, -2:] if model.n_bodies > 1 else model.mass
    reduced = heavy.prod(axis=1) / heavy.sum(axis=1) if model.n_bodies > 1 else model.mass[:, 0]
    with np.errstate(over="ignore", invalid="ignore"):
        overlap = speed * np.sqrt(reduced / k_pair) * damped
    reach = 2.0 * model.radius.min(axis=1)
    if model.n_bodies > 1 and not np.all(np.isfinite(overlap)):
        raise RunError("the speeds are too large to judge whether the spheres would pass through each other "
                       "(the bound overflows); use smaller velocities")
    if model.n_bodies > 1 and (overlap >= reach).any():
        b = int(np.argmax(overlap / reach))
        raise RunError(f"contact.k = {model.k[b]:.4g} N/m is too soft: the overlap could reach {overlap[b]:.3g} m, "
                       f"beyond the distance between centres at touch ({reach[b]:.3g} m); the spheres would pass "
                       "through each other. Use a stiffer contact.k")
    if model.n_walls:
        k_wall = model.wall_table[..., 0].reshape(model.batch, -1).min(axis=1)
        with np.errstate(over="ignore", invalid="ignore"):
            wall_overlap = speed * np.sqrt(model.mass.max(axis=1) / k_wall) * _damped_peak(
                model.wall_table[..., TABLE_REST].reshape(model.batch, -1).max(axis=1))
        if not np.all(np.isfinite(wall_overlap)):
            raise RunError("the speeds are too large to judge whether a sphere would pass through a wall "
                           "(the bound overflows); use smaller velocities")
        if (wall_overlap >= model.radius.min(axis=1)).any():
            b = int(np.argmax(wall_overlap / model.radius.min(axis=1)))
            raise RunError(f"contact.k = {model.k[b]:.4g} N/m is too soft for a sphere on a wall: the overlap could "
                           f"reach {wall_overlap[b]:.3g} m, more than its radius; it would pass through the wall. "
                           "Use a stiffer contact.k")


def check_run(model: Model, state: State, dt: np.ndarray, integrator: Integrator, max_steps: int,
              auto: np.ndarray) -> list[str]:
    """Refuse a step the integrator cannot keep stable, a contact so soft the spheres would pass
    through each other, or a run that would take too many steps. Returns warnings."""
    warnings: list[str] = []
    omega = max_frequency(model)
    limit = integrator.stability / omega
    bad = (dt > limit) & ~auto
    if bad.any():
        b = int(np.argmax(bad))
        raise RunError(f"dt = {dt[b]:.3g} s is beyond the stability limit of '{integrator.name}' "
                       f"for this contact (omega = {omega[b]:.4g} rad/s); the largest safe step is "
                       f"{limit[b]:.3g} s (use --dt auto to choose one)")
    check_pass_through(model, state)
    k_pair = model.pair_table[..., 0].reshape(model.batch, -1).min(axis=1)
    slowest = reference_frequency(model)
    slowest = np.where(slowest > 0, slowest, np.inf)
    per_contact = math.pi / (np.sqrt(k_pair / model.mass.max(axis=1)) * dt) if model.n_bodies > 1 else \
        math.pi / (slowest * dt)
    if (per_contact > max_steps).any():
        b = int(np.argmax(per_contact))
        raise RunError(f"dt = {dt[b]:.3g} s is so small that one contact would take {per_contact[b]:.3g} steps "
                       f"(limit {max_steps:.3g}); use a larger dt (or a looser --tol), or allow more (--max-steps)")
    return warnings


# ---------------------------------------------------------------------------------------------
# The run


def _pad3(x: np.ndarray) -> np.ndarray:
    out = np.zeros(x.shape[:-1] + (3,))
    out[..., :x.shape[-1]] = x
    return out


def kernel_inputs(model: Model, state: State) -> tuple:
    """The batch's body tables G (B, N, NG), walls WP (N_W, 6) and gravity (B, 3), as the kernels
    take them (member b: G[b], its contact tables model.pair_table[b], model.wall_table[b])."""
    b_count, n = model.batch, model.n_bodies
    G = np.zeros((b_count, n, int(layout.NG)))
    G[..., layout.G_S:layout.G_S + 3] = _pad3(state.s)
    G[..., layout.G_V:layout.G_V + 3] = _pad3(state.v)
    if model.spin_dim == 1:
        G[..., layout.G_W + 2] = state.w[..., 0]
        G[..., layout.G_Q] = state.q[..., 0]
    elif model.spin_dim == 3:
        G[..., layout.G_W:layout.G_W + 3] = state.w
        G[..., layout.G_Q:layout.G_Q + 4] = state.q
    G[..., layout.G_TB] = state.t[:, None]
    G[..., layout.G_IM] = model.inv_mass
    G[..., layout.G_II] = model.inv_inertia if model.spin_dim else 0.0
    G[..., layout.G_R] = model.radius
    G[..., layout.G_M] = model.mass
    G[..., layout.G_I] = model.inertia
    G[..., layout.G_MAT] = model.material
    WP = np.zeros((model.n_walls, 6))
    if model.n_walls:
        WP[:, :3] = _pad3(model.wall_point)
        WP[:, 3:] = _pad3(model.wall_normal)
    grav = _pad3(model.gravity) if model.gravity is not None else np.zeros((b_count, 3))
    return G, WP, grav


def into_plane(Gb: np.ndarray, WP: np.ndarray, gravity: np.ndarray, normal: np.ndarray) -> tuple:
    """Turn one member's bodies (Gb, in place), gravity (in place) and walls so that its plane of
    motion (unit `normal`) is z = const, what is out of it exactly zero (it is round-off: see
    `plane_of_motion`). Returns (turn R: x' = R x, the turned walls, the initial orientations);
    orientations become the planar path's angle about z, from 0."""
    turn = np.eye(3)
    if abs(normal[2]) < 1.0 - 1e-15:  # z = const already: left as it is, to the bit
        first = np.cross(normal, np.eye(3)[int(np.abs(normal).argmin())])
        first /= np.linalg.norm(first)
        turn = np.array([first, np.cross(normal, first), normal])
    for col in (layout.G_S, layout.G_V, layout.G_W):
        Gb[:, col:col + 3] = Gb[:, col:col + 3] @ turn.T
    Gb[:, layout.G_S + 2] = Gb[0, layout.G_S + 2]
    Gb[:, layout.G_V + 2] = 0.0
    Gb[:, layout.G_W:layout.G_W + 2] = 0.0
    orientation = Gb[:, layout.G_Q:layout.G_Q + 4].copy()
    Gb[:, layout.G_Q:layout.G_Q + 4] = 0.0
    gravity[:] = turn @ gravity
    gravity[2] = 0.0
    walls = WP.copy()
    walls[:, :3] = WP[:, :3] @ turn.T
    walls[:, 3:] = WP[:, 3:] @ turn.T
    walls[:, 5] = 0.0
    walls[:, 3:] /= np.maximum(np.linalg.norm(walls[:, 3:], axis=1), 1e-300)[:, None]
    return turn, walls, orientation


def out_of_plane(Gb: np.ndarray, knots: np.ndarray, records: np.ndarray, turn: np.ndarray,
                 orientation: np.ndarray, spin_dim: int) -> None:
    """Undo `into_plane` on one member's final bodies, knots and contact records (in place)."""
    for col in (layout.G_S, layout.G_V, layout.G_W):
        Gb[:, col:col + 3] = Gb[:, col:col + 3] @ turn
    for col in (layout.K_S, layout.K_V, layout.K_W, layout.K_A, layout.K_AN):
        knots[:, col:col + 3] = knots[:, col:col + 3] @ turn
    records[:, layout.R_FX:layout.R_FZ + 1] = records[:, layout.R_FX:layout.R_FZ + 1] @ turn
    if spin_dim == 3:  # the angle turned about the plane's normal, onto each body's start
        axis = turn[2]
        Gb[:, layout.G_Q:layout.G_Q + 4] = turned_quaternions(orientation, np.broadcast_to(axis, (len(Gb), 3)),
                                                              Gb[:, layout.G_Q])
        body = knots[:, layout.K_BODY].astype(np.int64)
        knots[:, layout.K_Q:layout.K_Q + 4] = turned_quaternions(orientation[body],
                                                                 np.broadcast_to(axis, (len(knots), 3)),
                                                                 knots[:, layout.K_Q])


def unpack_state(model: Model, G: np.ndarray) -> tuple:
    """s, v, w, q of the members from their final body tables G (B, N, NG)."""
    d = model.dim
    s, v = G[..., layout.G_S:layout.G_S + d].copy(), G[..., layout.G_V:layout.G_V + d].copy()
    if model.spin_dim == 1:
        w, q = G[..., layout.G_W + 2:layout.G_W + 3].copy(), G[..., layout.G_Q:layout.G_Q + 1].copy()
    elif model.spin_dim == 3:
        w, q = G[..., layout.G_W:layout.G_W + 3].copy(), G[..., layout.G_Q:layout.G_Q + 4].copy()
    else:
        w, q = np.zeros(G.shape[:2] + (0,)), np.zeros(G.shape[:2] + (0,))
    return s, v, w, q


def event_tables(model: Model) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each member's pair and wall tables for the event engine: the model's, with the restitution
    turned into the dashpot's damping ratio (`collide.dem.damping_ratio`, as the DEM kernel's)."""
    out = []
    for b in range(model.batch):
        pair, wall = model.pair_table[b].copy(), model.wall_table[b].copy()
        pair[..., layout.TP_ZETA] = damping_ratio(pair[..., layout.TP_ZETA], model.hertz)
        wall[..., layout.TP_ZETA] = damping_ratio(wall[..., layout.TP_ZETA], model.hertz)
        out.append((np.ascontiguousarray(pair), np.ascontiguousarray(wall)))
    return out


def periodic_settings(model: Model, fp: np.ndarray, box: int, cap: int) -> None:
    """The periodic box into the kernels' settings fp (B, ...) from column `box`: the periods, 1.0
    if any axis wraps; and at `cap` how far a body may move between two looks at the nearest
    images: while two bodies close or part by less than L / 2 - (r_i + r_j), the image of the
    other that can touch one stays the nearest (docs/design.md section 10)."""
    if not model.periodic:
        return
    period = np.array(model.period)
    fp[:, box:box + 3] = period
    fp[:, box + 3] = 1.0
    shortest = period[period > 0.0].min()
    fp[:, cap] = 0.45 * (0.5 * shortest - 2.0 * model.radius.max(axis=1))


def simulate(model: Model, initial: State, *, integrator: str, dt: np.ndarray,
             duration: np.ndarray | None = None, tail: np.ndarray | None = None,
             record: bool = True, max_steps: int = MAX_STEPS_DEFAULT,
             event_tol: np.ndarray | float = EDGE_TOL, auto: np.ndarray | None = None,
             omega_h: np.ndarray | None = None,
             progress: Progress | None = None, resolved: np.ndarray | float = 0.0) -> RunResult:
    """Run B scenes to their end. `duration` and `tail` are (B,) with NaN meaning 'not set'.
    `dt` (B,) is the step; where `auto` is set each island steps by omega_h over its own stiffest
    frequency instead (dt is then the step of the stiffest single contact). `event_tol`
    (relative to the fastest initial speed): how close a friction mode change must land.
    `resolved` (B,), relative to the same speed: the velocity error the run's steps leave (its
    tolerance); a run that ends by itself ends when nothing approaches faster than that."""
    b_count = model.batch
    integ = INTEGRATORS[integrator]
    if integrator == "dem":  # the fixed-step DEM kernel is its own engine
        raise ValueError("the DEM integrator runs through collide.dem.simulate_dem (collide.run chooses it)")
    if model.periodic and not integ.events:
        raise RunError("domain.periodic: integrator 'seed' (the report's update) has no periodic boundaries; "
                       "use the default integrator or 'dem'")
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (b_count,)).copy()
    auto = np.zeros(b_count, bool) if auto is None else np.broadcast_to(np.asarray(auto, bool), (b_count,))
    if omega_h is None:
        omega_h = dt * reference_frequency(model)
    omega_h = np.broadcast_to(np.asarray(omega_h, dtype=float), (b_count,))
    warnings = check_run(model, initial, dt, integ, max_steps, auto if integ.events else np.zeros(b_count, bool))
    duration = np.full(b_count, np.nan) if duration is None else np.asarray(duration, dtype=float)
    tail = np.full(b_count, np.nan) if tail is None else np.asarray(tail, dtype=float)
    speed = np.maximum(np.sqrt((initial.v ** 2).sum(-1)).max(-1), 10 * model.eps + 1e-300)
    # A slip within speed x event_tol of the band's edge counts as on it: kept within half the
    # band (eps), a slip in the band's inner half is never taken as on its edge. Wider (the break
    # at --tol 1e-4, 6 eps), slips passing through the band were held instead and the outcome
    # missed by 1.5e-3; within it, 7e-6 at --tol 1e-2 to 1e-4.
    event_tol = np.maximum(EDGE_TOL, np.minimum(np.broadcast_to(np.asarray(event_tol, dtype=float), (b_count,)),
                                                EDGE_BAND_SHARE * model.eps / speed))
    weights = np.asarray(integ.weights, dtype=float)
    trajectories = [] if record else None
    stats = np.zeros((b_count, int(layout.NS)), np.int64)
    figures = np.zeros((b_count, int(layout.NF)))
    # The members' tables, built for the whole batch at once (per member they cost as much Python
    # as a small member's run).
    G, WP, grav = kernel_inputs(model, initial)
    spin = model.spin_dim > 0
    friction = model.friction & (model.mu > 0) & (model.dim > 1)
    # (A periodic box is not turned: its axes are the scene's.)
    planes = [plane_of_motion(model, initial, b) if friction[b] and model.dim == 3 and not model.periodic else None
              for b in range(b_count)]
    turns = friction & np.array([model.dim == 3 and plane is None for plane in planes])
    fl = np.zeros((b_count, int(layout.NFL)), np.int64)
    fl[:, layout.FL_SPIN], fl[:, layout.FL_FRICTION], fl[:, layout.FL_SEED] = spin, friction, model.seed_lever
    fl[:, layout.FL_PLANAR], fl[:, layout.FL_RECORD], fl[:, layout.FL_AUTO] = model.dim < 3, record, auto & integ.events
    fl[:, layout.FL_MAXSTEPS], fl[:, layout.FL_DIM], fl[:, layout.FL_TURNS] = max_steps, model.dim, turns
    # The restitution's dashpots: a velocity-dependent normal force, stepped with the friction.
    tables = event_tables(model)
    damped = np.array([(pair[..., layout.TP_ZETA] > 0).any() or (wall[..., layout.TP_ZETA] > 0).any()
                       for pair, wall in tables])
    fl[:, layout.FL_DAMPED] = damped
    fl[:, layout.FL_HERTZ] = model.hertz
    fl[:, layout.FL_SPRING] = friction & model.tangential_spring
    fl[:, layout.FL_FRICTION] |= damped
    t_end = np.where(np.isfinite(duration), duration, np.inf)
    fp = np.zeros((b_count, int(layout.NFP)))
    fp[:, layout.FP_DT], fp[:, layout.FP_OMEGA_H] = dt, omega_h
    fp[:, layout.FP_TEND], fp[:, layout.FP_TAIL] = t_end, tail
    fp[:, layout.FP_SCALE] = speed * event_tol / EDGE_TOL
    fp[:, layout.FP_EVENT_TOL] = event_tol
    # A pair closing at under 1e-9 of its own speeds closes by round-off, not an approach (a share
    # of the pair's own: of the fastest body's, or of a dead band 1e9 times the speeds, slow pairs
    # passed through each other unseen).
    fp[:, layout.FP_SLOW] = 1e-9
    fastest = np.sqrt((initial.v ** 2).sum(-1)).max(-1)
    fp[:, layout.FP_END_SLOW] = np.where(np.asarray(resolved) > 1e-9, resolved, 0.0) * fastest
    periodic_settings(model, fp, layout.FP_BOX, layout.FP_CAP)
    walls = [WP] * b_count
    # A frictional 3D run in one plane runs turned into z = const, on the planar path (half the
    # cost of the general one for a rack: a smaller hold system, smooth band values, substeps).
    flat = {b: into_plane(G[b], WP, grav[b], plane) for b, plane in enumerate(planes)
            if plane is not None and integ.events}
    for b, (_, turned_walls, _) in flat.items():
        walls[b] = turned_walls
        fl[b, layout.FL_PLANAR] = layout.YES
    _load_compiled(integ.events, G[0], tables[0], WP, grav[0], weights, fl[0], fp[0])  # loading is not simulating
    if not integ.events:
        from collide.engine import seed  # the seed's kernels: imported by the runs that use them

    def run_member(b: int) -> tuple:
        if integ.events:
            return event_run.simulate(G[b], tables[b], walls[b], grav[b], weights, fl[b], fp[b])
        return seed.seed_run(G[b], tables[b], WP, grav[b], fl[b], fp[b])

    started = time.perf_counter()
    outcomes = run_members(b_count, run_member, progress,
                           [(fp[b], int(layout.FP_NOW), t_end[b], -1) for b in range(b_count)])
    wall_time = time.perf_counter() - started
    t_final = np.zeros(b_count)
    ivals = []
    for b, (turn, _, orientation) in flat.items():
        out_of_plane(G[b], outcomes[b][1], outcomes[b][2], turn, orientation, model.spin_dim)
    for b, (t, knots, recs, ival, st, fg) in enumerate(outcomes):
        _check_status(model, b, st, fg, dt, integ, open_ended=not np.isfinite(t_end[b]), t=t)
        t_final[b] = t
        stats[b], figures[b] = st, fg
        ivals.append(ival)
        if record:
            trajectories.append(Trajectory(knots, recs, ival, select_model(model, b)))
    logs = contact_logs(ivals, t_final)
    free_since = last_contacts(ivals, t_final, model.n_bodies)
    for b in np.flatnonzero(stats[:, layout.S_UNLOCATED]):
        member = f"run {b}: " if b_count > 1 else ""
        count = int(stats[b, layout.S_UNLOCATED])
        warnings.append(f"{member}{count} step(s) ran out of trials locating an event (first at t = "
                        f"{figures[b, layout.F_UNLOCATED_T]:.6g} s) and may have passed it: the outcome can be off "
                        "by more than its error estimate; try another --tol")
    final = State(t_final, *unpack_state(model, G), initial.work + G[..., layout.G_WK].sum(-1))
    if integ.events:
        max_force = figures[:, layout.F_MAX_FORCE].copy()
    elif not model.n_walls:  # the seed's grid: pairs only, each a spring k_pair delta
        max_force = model.pair_table[:, 0, 0, 0] * figures[:, layout.F_MAX_OVERLAP]
    else:
        max_force = np.full(b_count, np.nan)
    log = ContactLog(logs[:, 0], logs[:, 1], logs[:, 2], figures[:, layout.F_MAX_OVERLAP].copy(),
                     stats[:, layout.S_CONTACTS].copy(), max_force, longest_contacts(model, ivals, t_final))
    dt_min = np.where(np.isfinite(figures[:, layout.F_DT_MIN]), figures[:, layout.F_DT_MIN], dt)
    return RunResult(model=model, initial=initial, final=final, integrator=integrator, dt=dt,
                     steps=stats[:, layout.S_STEPS].copy(), jumps=stats[:, layout.S_JUMPS].copy(),
                     wall_time_s=wall_time, contacts=log, trajectories=trajectories, warnings=warnings,
                     dt_min=dt_min, windows=stats[:, layout.S_WINDOWS].copy(),
                     closed_steps=stats[:, layout.S_REST].copy(),
                     attempts=stats[:, layout.S_ATTEMPTS].copy(), free_since=free_since)


def cores() -> int:
    """The cores this process may use, capped by COLLIDE_THREADS if set: a batch's threads, and
    a DEM run's (`collide.dem.run_threads`)."""
    count = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    cap = count_setting(THREADS_VARIABLE)
    return count if cap is None else min(count, cap)


def run_members(b_count: int, run_member: Callable[[int], tuple], progress: Progress | None,
                watched: list[tuple[np.ndarray, int, float, int]]) -> list[tuple]:
    """run_member(b) for every member, in order. A batch of compiled runs goes side by side,
    one thread per core the process may use (the kernels release the GIL; each member is
    stepped exactly as alone), every thread taking every threads-th member (a task per member
    cost 40 us of locking; COLLIDE_THREADS caps the threads). Interpreted kernels hold the GIL,
    and a run that reports progress (watched: each member's (fp, index of its time reached,
    end, index of its kinetic energy or -1)) is one member at a time."""
    threads = min(cores(), b_count) if progress is None and tier.COMPILED else 1
    if _STARTUP_PROBE[0]:
        _probe_startup()
    if threads < 2:
        outcomes = []
        for b in range(b_count):
            fp, now, t_end, settling = watched[b]
            with watch(progress, fp, now, t_end, b, b_count, settling):
                outcomes.append(run_member(b))
        return outcomes
    outcomes: list[tuple] = [()] * b_count

    def run_share(first: int) -> None:
        for b in range(first, b_count, threads):
            outcomes[b] = run_member(b)

    list(_pool(threads).map(run_share, range(threads)))
    return outcomes


def _probe_startup() -> None:
    """Record the process's CPU time (user + sys) at its first kernel step, once."""
    import json

    path, _STARTUP_PROBE[0] = _STARTUP_PROBE[0], ""
    line = {"cpu": time.process_time(), "compiled": tier.COMPILED, "load_wall": tier.load_seconds()}
    with open(path, "a") as probe:
        probe.write(json.dumps(line) + "\n")


_POOLS: dict[int, tuple[int, ThreadPoolExecutor]] = {}
_POOLS_LOCK = threading.Lock()


def _pool(threads: int) -> ThreadPoolExecutor:
    """A process's pool of `threads` threads, kept for its later batches (starting two threads
    cost a batch of ten small runs as much as running them). A forked child makes its own: the
    parent's threads are not in it."""
    from concurrent.futures import ThreadPoolExecutor  # a batch's: a single run needs no pool

    with _POOLS_LOCK:
        entry = _POOLS.get(threads)
        if entry is None or entry[0] != os.getpid():
            entry = (os.getpid(), ThreadPoolExecutor(threads, thread_name_prefix="collide-members"))
            _POOLS[threads] = entry
        return entry[1]


_LOADED: set[bool] = set()


def _load_compiled(events: bool, *args) -> None:
    """Load the compiled kernel from numba's cache before the clock starts (once a process)."""
    if events in _LOADED or not tier.COMPILED:
        return
    import numba

    from collide.engine import seed

    kernel = event_run.simulate if events else seed.seed_run
    types = tuple(numba.typeof(a) for a in (args if events else (args[0], args[1], args[2], args[3], args[5],
                                                                  args[6])))
    with tier.loading():
        jit.compile_with_entry(kernel, types)
    _LOADED.add(events)


def contact_logs(ivals: list[np.ndarray], t_end: np.ndarray) -> np.ndarray:
    """Each member's (B, 3) first contact start, last end (an open one ends at t_end) and time
    with any contact engaged (the union of its intervals)."""
    out = np.zeros((len(ivals), 3))
    out[:, :2] = np.nan
    for b, iv in enumerate(ivals):
        if len(iv) == 1:  # a sweep's usual member: plain floats (numpy calls cost 10 us a member)
            start, end = float(iv[0, layout.V_START]), float(iv[0, layout.V_END])
            end = float(t_end[b]) if math.isnan(end) else end
            out[b] = start, end, end - start
        elif len(iv):
            start, end = iv[:, layout.V_START], np.where(np.isnan(iv[:, layout.V_END]), t_end[b], iv[:, layout.V_END])
            order = np.argsort(start, kind="stable")
            s, e = start[order], end[order]
            # Each interval adds what reaches past the ends of those that started before it.
            reached = np.maximum.accumulate(e)[:-1]
            added = np.maximum(e[1:] - np.maximum(s[1:], reached), 0.0)
            out[b] = start.min(), end.max(), (e[0] - s[0]) + added.sum()
    return out


def last_contacts(ivals: list[np.ndarray], t_end: np.ndarray, n: int) -> np.ndarray:
    """(B, N) when each body's last contact ended: 0 for none, t_end for one still open (the
    free flight to the end that `collide.invariant` checks). The seed's fixed steps log any contact
    as one row of no body (-1): it counts for every body."""
    out = np.zeros((len(ivals), n))
    for b, iv in enumerate(ivals):
        if len(iv):
            end = np.where(np.isnan(iv[:, layout.V_END]), t_end[b], iv[:, layout.V_END])
            anyone = iv[:, layout.V_I] < 0
            if anyone.any():
                out[b] = end[anyone].max()
            for col in (layout.V_I, layout.V_J):
                body = iv[:, col].astype(np.int64)
                mine = body >= 0
                np.maximum.at(out[b], body[mine], end[mine])
    return out


def longest_contacts(model: Model, ivals: list[np.ndarray], t_end: np.ndarray) -> np.ndarray:
    """Each member's (B,) longest single contact in collision times, pi / omega with omega =
    sqrt(k / reduced mass) of its pair (an open contact ends at t_end). The whole batch at once:
    per member, numpy calls would cost a sweep's small member more than its run."""
    counts = np.array([len(iv) for iv in ivals], np.int64)
    out = np.zeros(len(ivals))
    if not counts.any():
        return out
    iv = np.concatenate(ivals)
    member = np.repeat(np.arange(len(ivals)), counts)
    i, j = iv[:, layout.V_I].astype(np.int64), iv[:, layout.V_J].astype(np.int64)
    wall = j < 0
    other = np.where(wall, i, j)
    mat_i, mat_j = model.material[member, i], model.material[member, other]
    m_i, m_j = model.mass[member, i], model.mass[member, other]
    k = np.where(wall, model.wall_table[member, mat_i, TABLE_K], model.pair_table[member, mat_i, mat_j, TABLE_K])
    reduced = np.where(wall, m_i, m_i * m_j / (m_i + m_j))
    end = np.where(np.isnan(iv[:, layout.V_END]), t_end[member], iv[:, layout.V_END])
    np.maximum.at(out, member, (end - iv[:, layout.V_START]) * np.sqrt(k / reduced) / math.pi)
    return out


def _check_status(model: Model, b: int, st: np.ndarray, fg: np.ndarray, dt: np.ndarray, integ: Integrator, *,
                  open_ended: bool, t: float) -> None:
    """Turn a kernel's status into a RunError naming the cause."""
    status = int(st[layout.S_STATUS])
    if status == layout.OK:
        return
    safe = integ.stability / max_frequency(model)[b]
    at = f"t = {fg[layout.F_STATUS_T]:.6g} s"
    if status == layout.NONFINITE:
        raise RunError(f"non-finite numbers at {at}: the step is unstable; try a smaller dt "
                       f"(largest safe step {safe:.3g} s)")
    if status == layout.ENERGY:
        raise RunError(f"energy grew from {fg[layout.F_STATUS_A]:.4g} J to {fg[layout.F_STATUS_B]:.4g} J during "
                       f"a contact at dt = {dt[b]:.3g} s: the step is unstable; the largest safe step is {safe:.3g} s")
    if status == layout.STALL:
        way = "give it a duration (--set duration=SECONDS)" if open_ended else "try a looser --tol or a given --dt"
        raise RunError(f"the run stopped advancing at {at} (events closer than the clock resolves); {way}, or "
                       "report this scene")
    if status == layout.MAXSTEPS:
        raise step_limit_error(int(st[layout.S_STEPS]), t, open_ended)
    if status == layout.SAWTOOTH:
        raise SawtoothError(f"a damped tangential spring sticks on at a cap that falls faster than it relaxes at {at}: "
                            "its stretch is reset to the cap again and again (a sawtooth whose teeth shrink to "
                            "nothing), which the islands do not follow yet")
    if status == layout.SINGULAR:
        raise RunError(f"the stuck contacts' friction could not be solved at {at} (a singular hold system)")
    raise RunError(f"the engine stopped with status {status} at {at}")
