"""Running scenes through the fixed-step DEM kernel (`collide.engine.dem`): the contact laws of
docs/design.md section 9 (Hertz, restitution, tangential springs, rolling resistance, materials).

The event engine (`collide.engine.event`) locates every contact start and end and every
friction mode change, which makes the report's law exact to the tolerance; a DEM step does not
(contacts switch at steps, as in LIGGGHTS or YADE), so its error is set by the steps per contact
time: `contact_time` estimates the shortest one from the fastest approach the scene allows, and
`auto_dt` divides it by what the tolerance needs (`STEPS_PER_CONTACT`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from collide.engine import layout, tier
from collide.engine.dem import layout as dk
from collide.engine.dem import loop as dem_loop
from collide.model import (
    KISSING,
    TABLE_ESTAR,
    TABLE_K,
    TABLE_KTR,
    TABLE_REST,
    Model,
    State,
    damping_ratio,
    select_model,
)
from collide.periodic import NEIGHBOUR_SKIN
from collide.results import ContactLog, RunResult, Trajectory
from collide.settings import FRAME_STEPS_VARIABLE, THREADS_VARIABLE, count_setting
from collide.stepper import (
    Progress,
    RunError,
    _pad3,
    approach_bound,
    cores,
    run_members,
    step_limit_error,
)

HERTZ_TIME = 2.868  # t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5): Johnson, Contact Mechanics, 11.4
# The outcome's relative error against steps per contact time n: ERROR_CONSTANT / n^ERROR_ORDER.
# Measured on a damped Hertz impact on a wall and a frictional oblique impact (benchmarks/
# bench_dem.py prints it); padded by about 2x. Contacts switch at steps, so the error is first
# order in dt whatever the integrator's own order.
ERROR_CONSTANT, ERROR_ORDER = 1.2, 1
MIN_STEPS_PER_CONTACT, MAX_STEPS_PER_CONTACT = 50, 20_000
FRAME_BUDGET = 2_000_000  # body-frames a recording keeps at most
# From FRAME_STEPS_FROM bodies on, where a body's share of both costs dominates, a frame is taken
# at most once each FRAME_STEPS steps, so that writing the recording costs at most the run: a
# body's frame costs about 50 times its step to write (CPU, a 10 000-sphere pour whose spheres
# mostly fly: the cheapest steps; benchmarks/bench_recording.py --many). `collide run
# --frame-steps K` (COLLIDE_FRAME_STEPS) asks for a frame each K steps.
FRAME_STEPS, FRAME_STEPS_FROM = 100, 1000
SKIN = NEIGHBOUR_SKIN  # neighbour-list skin, in smallest radii (a periodic box's shortest period needs it)


def _extremes(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per member (B,): lightest mass, smallest radius, largest E* and largest linear k_eff
    over the pairs and walls the scene can have."""
    light = model.mass.min(axis=1)
    small = model.radius.min(axis=1)
    e_star = model.pair_table[..., TABLE_ESTAR].reshape(model.batch, -1).max(axis=1)
    k_lin = model.pair_table[..., TABLE_K].reshape(model.batch, -1).max(axis=1)
    if model.n_walls:
        e_star = np.maximum(e_star, model.wall_table[..., TABLE_ESTAR].reshape(model.batch, -1).max(axis=1))
        k_lin = np.maximum(k_lin, model.wall_table[..., TABLE_K].reshape(model.batch, -1).max(axis=1))
    return light, small, e_star, k_lin


def contact_time(model: Model, state: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shortest contact time (B,) s the scene can produce, the stiffest contact frequency
    (B,) rad/s and the deepest overlap (B,) m, from the fastest approach `approach_bound`
    allows. A wall counts as a pair of the lightest and smallest sphere with itself (m* = m,
    R* = r): the stiffest case of either kind."""
    light, small, e_star, k_lin = _extremes(model)
    m_star, r_star = light, small
    if model.n_bodies > 1 and not model.n_walls:
        m_star, r_star = 0.5 * light, 0.5 * small
    speed = approach_bound(model, state)
    if model.n_walls:  # a wall stays put: a sphere's own speed is its approach
        speed = np.maximum(speed, np.sqrt((state.v**2).sum(-1)).max(axis=1))
    speed = np.maximum(speed, 1e-12)
    if model.hertz:
        overlap = (15.0 * m_star * speed**2 / (16.0 * e_star * np.sqrt(r_star))) ** 0.4
        omega = np.sqrt(2.0 * e_star * np.sqrt(r_star * overlap) / m_star)
        duration = HERTZ_TIME * (m_star**2 / (r_star * e_star**2 * speed)) ** 0.2
    else:
        omega = np.sqrt(k_lin / m_star)
        duration = math.pi / omega
        overlap = speed / omega
    return duration, omega, overlap


def predicted_error(steps_per_contact: np.ndarray) -> np.ndarray:
    return ERROR_CONSTANT / np.asarray(steps_per_contact, dtype=float) ** ERROR_ORDER


TOL_FLOOR = float(predicted_error(np.array([MAX_STEPS_PER_CONTACT]))[0])  # the finest tol auto_dt reaches


def auto_dt(model: Model, state: State, tol: np.ndarray) -> np.ndarray:
    """The step (B,) that meets tol by the error model, within MIN..MAX_STEPS_PER_CONTACT."""
    duration, _, _ = contact_time(model, state)
    needed = (ERROR_CONSTANT / np.asarray(tol, dtype=float)) ** (1.0 / ERROR_ORDER)
    if (needed > MAX_STEPS_PER_CONTACT).any():
        b = int(np.argmax(needed))
        raise RunError(f"--tol {float(np.asarray(tol).reshape(-1)[b]):.3g} would need {needed[b]:.3g} DEM steps per "
                       f"contact (contacts switch at steps: first order); the DEM kernel reaches about {TOL_FLOOR:.0e} "
                       f"at {MAX_STEPS_PER_CONTACT} steps per contact. Use a looser --tol or give a --dt")
    return duration / np.clip(needed, MIN_STEPS_PER_CONTACT, MAX_STEPS_PER_CONTACT)


def check_dem(model: Model, state: State, dt: np.ndarray, max_steps: int, duration: np.ndarray) -> np.ndarray:
    """Refuse a step beyond Verlet's stability for the stiffest contacts together, a contact so
    soft the spheres pass through, or a run longer than max_steps. Returns steps per contact."""
    t_c, omega, overlap = contact_time(model, state)
    # Several contacts on the lightest sphere at once stiffen it: Gershgorin over its neighbours.
    together = omega * math.sqrt(1 + min(model.n_bodies - 1, KISSING[model.dim]) + model.n_walls)
    damped = model.pair_table[..., TABLE_REST].min(axis=(1, 2))
    if model.n_walls:
        damped = np.minimum(damped, model.wall_table[..., TABLE_REST].min(axis=1))
    zeta = damping_ratio(damped, model.hertz)
    # Velocity Verlet with a dashpot: stable while omega dt < 2 (sqrt(1 + zeta^2) - zeta).
    limit = 2.0 * (np.sqrt(1.0 + zeta**2) - zeta) / together
    if (dt > limit).any():
        b = int(np.argmax(dt / limit))
        raise RunError(f"dt = {dt[b]:.3g} s is beyond the stability limit of the DEM step for these contacts "
                       f"(several at once on the lightest sphere, {together[b]:.4g} rad/s); the largest safe step "
                       f"is {limit[b]:.3g} s (use --dt auto to choose one)")
    reach = model.radius.min(axis=1) * (2.0 if model.n_bodies > 1 and not model.n_walls else 1.0)
    if not np.all(np.isfinite(overlap)):
        raise RunError("the speeds are too large to judge whether the spheres would pass through each other "
                       "(the bound overflows); use smaller velocities")
    if (overlap >= reach).any():
        b = int(np.argmax(overlap / reach))
        what = "contact.youngs_modulus (or the materials')" if model.hertz else "contact.k"
        raise RunError(f"{what} is too soft: the overlap could reach {overlap[b]:.3g} m, beyond "
                       f"{reach[b]:.3g} m; the spheres would pass through. Use a stiffer contact")
    # "In contact" is an overlap at a step: a pair that closes by more than the distance between
    # centres at touch within one step can cross unseen (the stability limit allows twice that).
    speed = approach_bound(model, state)
    if model.n_walls:
        speed = np.maximum(speed, np.sqrt((state.v ** 2).sum(-1)).max(axis=1))
    if (speed * dt >= reach).any():
        b = int(np.argmax(speed * dt / reach))
        raise RunError(f"dt = {dt[b]:.3g} s is too long for the approach speeds (up to {speed[b]:.3g} m/s): a pair "
                       f"closes by {speed[b] * dt[b]:.3g} m in one step, beyond {reach[b]:.3g} m, and could pass "
                       "through unseen; use a smaller dt or auto")
    per_contact = t_c / dt
    if np.isfinite(duration).all():
        steps = duration / dt
        if (steps > max_steps).any():
            b = int(np.argmax(steps))
            raise RunError(f"dt = {dt[b]:.3g} s over {duration[b]:.3g} s is {steps[b]:.3g} steps (limit "
                           f"{max_steps:.3g}); use a larger dt or a shorter duration, or allow more (--max-steps)")
    return per_contact


def kernel_tables(model: Model, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Member b's pair and wall tables with restitution turned into the damping ratio, and the
    tangential stiffness ratio's square root added (`collide.engine.dem.layout`)."""
    pair, wall = model.pair_table[b].copy(), model.wall_table[b].copy()
    pair[..., TABLE_REST] = damping_ratio(pair[..., TABLE_REST], model.hertz)
    wall[..., TABLE_REST] = damping_ratio(wall[..., TABLE_REST], model.hertz)
    pair = np.concatenate([pair, np.sqrt(pair[..., TABLE_KTR:TABLE_KTR + 1])], axis=-1)
    wall = np.concatenate([wall, np.sqrt(wall[..., TABLE_KTR:TABLE_KTR + 1])], axis=-1)
    return pair, wall


def _bodies(model: Model, b: int) -> np.ndarray:
    bd = np.zeros((model.n_bodies, int(dk.NB)))
    bd[:, dk.B_IM] = model.inv_mass[b]
    bd[:, dk.B_II] = model.inv_inertia[b] if model.spin_dim else 0.0
    bd[:, dk.B_R] = model.radius[b]
    bd[:, dk.B_M] = model.mass[b]
    bd[:, dk.B_I] = model.inertia[b]
    bd[:, dk.B_MAT] = model.material[b]
    return bd


def simulate_dem(model: Model, initial: State, *, dt: np.ndarray, duration: np.ndarray, tail: np.ndarray,
                 rest: np.ndarray, record: bool, max_steps: int, progress: Progress | None = None) -> RunResult:
    """Run B scenes through the DEM kernel at their fixed steps dt (B,). `duration`, `tail` and
    `rest` are (B,) with NaN meaning 'not set'."""
    b_count = model.batch
    if model.gravity is not None and (np.isnan(duration) & np.isnan(rest)).any():
        raise RunError("duration: a DEM run under gravity needs a duration (or rest, to end when it settles)")
    check_dem(model, initial, dt, max_steps, duration)
    t_c, _, _ = contact_time(model, initial)
    finals, trajectories = [], [] if record else None
    stats = np.zeros((b_count, int(dk.NSTAT)), np.int64)
    figures = np.zeros((b_count, int(dk.NFIG)))
    members = [kernel_args(model, initial, b, dt=dt, duration=duration, rest=rest, record=record,
                           max_steps=max_steps, t_c=t_c) for b in range(b_count)]
    _load_compiled(*members[0][0])
    # One run takes the cores itself (`dem_threads`); a batch's members go one a core.
    threads = run_threads(model.n_bodies) if b_count == 1 and tier.COMPILED else 1
    started = time.perf_counter()
    if threads > 1:
        from collide.dem_threads import dem_run_threaded

        def run_member(b: int) -> tuple:
            return dem_run_threaded(*members[b][0], threads)
    else:
        def run_member(b: int) -> tuple:
            return dem_loop.dem_run(*members[b][0])
    watched = [(m[0][-1], int(dk.P_NOW), m[1], int(dk.P_NOW_KINETIC)) for m in members]
    outcomes = run_members(b_count, run_member, progress, watched)
    wall_time = time.perf_counter() - started
    ends = _final_arrays(model)  # (the state's own columns: no table of every body's columns beside them)
    for b, (t, WK, KN, REC, IV, EP, st, fg) in enumerate(outcomes):
        (X, V, W, Q, _, _, _, _, grav, _, _), t_end = members[b]
        if st[dk.S_STATUS] == dk.NONFINITE:
            raise RunError(f"non-finite numbers at t = {fg[dk.G_STATUS_T]:.6g} s: the DEM step is unstable; "
                           "try a smaller dt")
        if st[dk.S_STATUS] == dk.MAXSTEPS:
            raise step_limit_error(int(st[dk.S_STEPS]), float(t), not np.isfinite(t_end))
        if not np.isfinite(t_end) and np.isnan(rest[b]) and np.isfinite(tail[b]) and tail[b] > 0:
            X += V * tail[b] + 0.5 * grav * tail[b] ** 2  # free flight after the last contact
            V += grav * tail[b]
            t += tail[b]
            if record:
                KN = _tail_knots(KN, t, X, V, grav)
        _fill_final(model, ends, b, X, V, W, Q)
        finals.append((t, float(WK.sum()), float(fg[dk.G_STORED])))
        stats[b], figures[b] = st, fg
        if record:
            # A phase's peak is recorded when the phase ends: records in time order again.
            REC = REC[np.argsort(REC[:, layout.R_T], kind="stable")]
            traj = Trajectory(KN, REC, IV, select_model(model, b))
            traj.energy_parts = EP
            trajectories.append(traj)
    final = State(np.array([f[0] for f in finals]), *ends,
                  # The kernel's friction work includes what the tangential springs still hold:
                  # that is elastic energy (State.stored), not dissipated.
                  initial.work + np.array([f[1] - f[2] for f in finals]), np.array([f[2] for f in finals]))
    log = ContactLog(figures[:, dk.G_FIRST].copy(), figures[:, dk.G_LAST].copy(), figures[:, dk.G_TOUCH].copy(),
                     figures[:, dk.G_OVERLAP].copy(), stats[:, dk.S_CONTACTS].copy(), figures[:, dk.G_FORCE].copy())
    result = RunResult(model=model, initial=initial, final=final, integrator="dem", dt=dt.copy(),
                       steps=stats[:, dk.S_STEPS].copy(), jumps=stats[:, dk.S_JUMPS].copy(), wall_time_s=wall_time,
                       contacts=log, trajectories=trajectories, warnings=_never_met(stats, finals, duration),
                       dt_min=dt.copy(),
                       windows=np.zeros(b_count, np.int64))
    result.dissipation = figures[:, [dk.G_DAMP, dk.G_FRIC, dk.G_ROLL]].copy()
    result.threads = threads
    result.frame_steps = frame_steps(model.n_bodies)[0] if record else 0
    return result


def _final_arrays(model: Model) -> tuple[np.ndarray, ...]:
    """The members' final s, v, w, q, shaped as `stepper.unpack_state` returns them."""
    b, n, d = model.batch, model.n_bodies, model.dim
    spin = {1: (1, 1), 3: (3, 4)}.get(model.spin_dim, (0, 0))
    return np.zeros((b, n, d)), np.zeros((b, n, d)), np.zeros((b, n, spin[0])), np.zeros((b, n, spin[1]))


def _fill_final(model: Model, ends: tuple[np.ndarray, ...], b: int, X: np.ndarray, V: np.ndarray, W: np.ndarray,
                Q: np.ndarray) -> None:
    """Member b's final state from the kernel's arrays (N, 3), (N, 4) into `ends`."""
    s, v, w, q = ends
    s[b], v[b] = X[:, :model.dim], V[:, :model.dim]
    if model.spin_dim == 1:
        w[b], q[b] = W[:, 2:3], Q[:, 0:1]
    elif model.spin_dim == 3:
        w[b], q[b] = W, Q


def run_threads(n_bodies: int) -> int:
    """The threads one run of n_bodies steps on: COLLIDE_THREADS if set (`collide run
    --threads`), else every core from THREADS_FROM bodies and one below."""
    from collide.dem_threads import THREADS_FROM
    from collide.engine.dem.barrier import HAVE_BARRIER

    if not HAVE_BARRIER:
        return 1
    asked = count_setting(THREADS_VARIABLE)
    if asked is not None:
        return asked
    return cores() if n_bodies >= THREADS_FROM else 1


def kernel_args(model: Model, initial: State, b: int, *, dt: np.ndarray, duration: np.ndarray, rest: np.ndarray,
                record: bool, max_steps: int, t_c: np.ndarray) -> tuple[tuple, float]:
    """Member b's arguments of `loop.dem_run` (X, V, W, Q, bodies, tables, walls, gravity, flags,
    figures), and its end time."""
    X, V = _pad3(initial.s[b]), _pad3(initial.v[b])
    W = np.zeros((model.n_bodies, 3))
    Q = np.zeros((model.n_bodies, 4))
    if model.spin_dim == 1:
        W[:, 2] = initial.w[b, :, 0]
        Q[:, 0] = initial.q[b, :, 0]
    elif model.spin_dim == 3:
        W[:] = initial.w[b]
        Q[:] = initial.q[b]
    WP = np.zeros((model.n_walls, 6))
    if model.n_walls:
        WP[:, :3] = _pad3(model.wall_point)
        WP[:, 3:] = _pad3(model.wall_normal)
    grav = _pad3(model.gravity[b]) if model.gravity is not None else np.zeros(3)
    t_end = duration[b] if np.isfinite(duration[b]) else np.inf
    frames = int(np.clip(FRAME_BUDGET // max(model.n_bodies, 1), 100, 1500))
    frame = t_end / frames if np.isfinite(t_end) else t_c[b] / 10.0
    steps, asked = frame_steps(model.n_bodies)
    # Steps are dt long: frames on a grid k dt apart are about k steps apart; a coast records its
    # two ends only a grid spacing after the last frame (P_COAST_GAP; every coast when k is 1).
    frame = steps * dt[b] if asked else max(frame, steps * dt[b])
    fl = np.array([model.dim, model.spin_dim > 0, model.hertz, model.tangential_spring, record, max_steps],
                  dtype=np.int64)
    fp = np.array([dt[b], t_end, rest[b] if np.isfinite(rest[b]) else 0.0, frame if steps > 1 else 0.0, frame,
                   SKIN * float(model.radius[b].min()), 0.0, 0.0, *model.period, 1.0 if model.periodic else 0.0,
                   0.0, 0.0])
    pair, wall = kernel_tables(model, b)
    return (X, V, W, Q, _bodies(model, b), pair, wall, WP, grav, fl, fp), t_end


def frame_steps(n_bodies: int) -> tuple[int, bool]:
    """The least steps between a recorded run's frames, and whether the user asked for it
    (COLLIDE_FRAME_STEPS: then it is the frames' spacing, not only their least)."""
    asked = count_setting(FRAME_STEPS_VARIABLE)
    if asked is not None:
        return asked, True
    return (FRAME_STEPS if n_bodies >= FRAME_STEPS_FROM else 1), False


def _tail_knots(KN: np.ndarray, t: float, X: np.ndarray, V: np.ndarray, grav: np.ndarray) -> np.ndarray:
    """The knots with the free flight after the last contact (the tail) recorded: every body's
    last frame marked as followed by free flight, and a knot at the run's end t where X, V (N,
    3) are (a trajectory that stopped at the last frame ended the view and the recording there,
    short of the run). Spin and orientation are the frame's: the flight turns them in closed form."""
    last = KN[KN[:, layout.K_T] == KN[:, layout.K_T].max()] if len(KN) else KN
    if not len(last) or last[0, layout.K_T] >= t:
        return KN
    KN = KN.copy()
    KN[KN[:, layout.K_T] == last[0, layout.K_T], layout.K_FREE] = 1.0
    KN[KN[:, layout.K_T] == last[0, layout.K_T], layout.K_AN:layout.K_AN + 3] = grav
    end = last.copy()
    body = end[:, layout.K_BODY].astype(np.int64)
    end[:, layout.K_T] = t
    end[:, layout.K_FREE] = 1.0
    end[:, layout.K_S:layout.K_S + 3] = X[body]
    end[:, layout.K_V:layout.K_V + 3] = V[body]
    end[:, layout.K_A:layout.K_A + 3] = grav
    end[:, layout.K_AN:layout.K_AN + 3] = grav
    return np.concatenate((KN, end))


def _never_met(stats: np.ndarray, finals: list[tuple], duration: np.ndarray) -> list[str]:
    """Say why a run with no duration ended where it began: nothing in it can ever touch."""
    out = []
    for b, (t, _, _) in enumerate(finals):
        if np.isnan(duration[b]) and stats[b, dk.S_CONTACTS] == 0 and t == 0.0:
            member = f"run {b}: " if len(finals) > 1 else ""
            out.append(f"{member}no two spheres, and no sphere and wall, can ever meet (all part or fly clear): "
                       "the run ends at its start; set a duration to see them fly")
    return out


_LOADED: list[bool] = []


def _load_compiled(*args) -> None:
    """Load the compiled DEM kernel from numba's cache before the clock starts (once a process)."""
    if _LOADED or not tier.COMPILED:
        return
    import numba

    with tier.loading():
        dem_loop.dem_run.compile(tuple(numba.typeof(a) for a in args))
    _LOADED.append(True)
