"""Which engine runs a scene, and a sphere alone among walls under the laws beyond the report's
(Hertz, the restitution's dashpot) in the event engine (`collide.engine.event.alone`).

The event engine locates every contact and steps it at the composition's order; for the
report's linear spring it runs every scene, and its islands take Hertz and the restitution's
dashpot with Coulomb friction, and in 2D a tangential spring (`collide.scene.island_blocker`,
`collide.engine.event.spring`). A sphere alone among walls
never forms an island: each contact is one normal contact (`collide.engine.event.impact`, order
8) between closed-form flights, with a tangential spring and rolling resistance too
(`collide.engine.event.oblique`), so such a scene runs there at full order whatever its tolerance;
so do two spheres and no walls (`event.pair`: head-on, or with a tangential spring and friction
at any angle; off-centre without one, the islands). Scenes with these laws that none of these
take run in the fixed-step, first-order DEM kernel (docs/method.md, "Which engine runs a scene").
"""

from __future__ import annotations

import math
import time

import numpy as np

from collide.engine import jit, layout, tier
from collide.model import TABLE_ESTAR, TABLE_K, TABLE_KTR, TABLE_MU, TABLE_REST, TABLE_ROLL, Model, State, select_model
from collide.results import ContactLog, RunResult
from collide.scene import Scene, alone_blocker, dem_reason, island_blocker
from collide.stepper import (
    RunError,
    approach_bound,
    contact_logs,
    kernel_inputs,
    last_contacts,
    longest_contacts,
    step_limit_error,
)
from collide.trajectory import Trajectory

EVENT, DEM, SEED = "event", "dem", "seed"
# The finest tolerance a sphere's contacts reach: each is solved to round-off (1e-16 of its
# speeds, 1e-15 of the run's speed scale over ten bounces); a run at a tenth of it, its
# measurement, stays above that (the built-in bounce at --tol 1e-11 measures 4e-12).
TOL_FLOOR = 1e-13


def engine_choice(scene: Scene, integrator: str, forced: bool, blocker: str | None = None,
                  islands: bool = False) -> tuple[str, str]:
    """(engine, why) for a scene run with `integrator`; `forced`: the integrator was asked for
    (the scene's `integrator` or --integrator), not chosen; `blocker`: why the event engine
    could not take it (else `alone_blocker`'s); `islands`: a law beyond the report's ran in the
    islands (else as `alone_blocker` says)."""
    if integrator == "dem":
        if forced:
            return DEM, "integrator 'dem' asked for: the fixed-step DEM kernel (first order)"
        why = blocker or "; ".join(w for w in (alone_blocker(scene), island_blocker(scene)) if w)
        return DEM, f"{dem_reason(scene)}, and {why}: the fixed-step DEM kernel (first order)"
    if integrator == "seed":
        return SEED, "integrator 'seed' asked for: the report's own update on its fixed grid"
    islands = islands or alone_blocker(scene) is not None
    # The tangential spring in the islands: its stretches stepped with the bodies, stick (the spring)
    # and slip (the cap) each change located.
    sprung = (" with the tangential spring (its stretches stepped with the bodies, the cap reached and each "
              "slip's end located)" if scene.contact.tangential == "spring" and scene.has_friction else "")
    if scene.needs_dem and islands and scene.contact.model != "linear":
        damped = " and its dashpot" if scene.damped else ""
        return EVENT, (f"{dem_reason(scene)}: Hertz's force{damped} (the DEM kernel's law){sprung} in the islands' "
                       f"steps of order {_order(integrator)} ({integrator}), each contact's start and end stepped "
                       "over s (t - t_0 ~ s^2, damped s^4: the force smooth in s), every contact's start and end"
                       f"{' and each friction mode change' if scene.has_friction else ''} located")
    if scene.needs_dem and islands:
        what = "the DEM kernel's law" + (", its dashpot" if scene.damped else "")
        return EVENT, (f"{dem_reason(scene)} with the linear spring: {what}{sprung} in the islands' steps of order "
                       f"{_order(integrator)} ({integrator}), every contact, its end and each friction mode change "
                       "located")
    rolls = scene.has_rolling and scene.has_spin  # (where nothing spins there is no rolling resistance to take)
    if scene.needs_dem and len(scene.bodies) == 2 and (scene.has_friction or rolls):
        rubs = ", friction's stick and slip located, the tangential spring" if scene.has_friction else ""
        if rolls:
            rubs += (", rolling resistance (its cap mu_r R* F_n against the relative spin, or that spin held within "
                     "it) with each change between rolling and held located")
        return EVENT, (f"{dem_reason(scene)} with two spheres and no walls: their contact in the relative coordinate "
                       "(reduced mass, the line of centres turning, each sphere's spin) at order 6 (Gauss-Legendre), "
                       f"its start and end located{rubs}, flights in closed form")
    if scene.needs_dem and len(scene.bodies) == 2:
        return EVENT, (f"{dem_reason(scene)} with two spheres and no walls, no friction: their contact in the "
                       "relative coordinate (reduced mass and radius, head-on) at order 8 (DOP853's Runge-Kutta), its "
                       "start and end located, flights in closed form")
    if scene.needs_dem:
        rubs = (", friction's stick and slip located, the tangential spring at order 6 (Gauss-Legendre)"
                if scene.contact.tangential == "spring" and scene.has_friction else "")
        if rolls:
            rubs += (", rolling resistance (its cap mu_r R* F_n against the spin, or the spin held within it) with "
                     "each change between rolling and held located, at order 6 (Gauss-Legendre)")
        return EVENT, (f"{dem_reason(scene)} with a sphere alone among walls: each contact at order 8 "
                       f"(DOP853's Runge-Kutta), its start and end located{rubs}, flights in closed form")
    return EVENT, (f"the report's contact law: every contact and friction mode change located, steps of "
                   f"order {_order(integrator)} ({integrator})")


def _order(integrator: str) -> int:
    from collide.integrators import INTEGRATORS

    return INTEGRATORS[integrator].order


def law_rows(model: Model, b: int = 0) -> np.ndarray:
    """The law of the sphere's contact with each wall (W, impact.NP) as impact.contact takes it:
    a wall is rigid, so m* = m and R* = r (the DEM kernel's wall contact)."""
    from collide.dem import damping_ratio
    from collide.engine.event import impact

    row = model.wall_table[b, int(model.material[b, 0])]
    zeta = float(damping_ratio(np.array(row[TABLE_REST]), model.hertz))
    params = impact.impact_params(hertz=model.hertz, mstar=float(model.mass[b, 0]), k=float(row[TABLE_K]),
                                  estar=float(row[TABLE_ESTAR]), rstar=float(model.radius[b, 0]), zeta=zeta)
    # One type for every count of walls, the compiled kernel's: C order (a copy of the broadcast
    # keeps its strides, F order from two walls on) and read-only (numba types that apart).
    rows = np.array(np.broadcast_to(params, (model.n_walls, params.size)), order="C")
    rows.setflags(write=False)
    return rows


def pair_row(model: Model, b: int = 0) -> np.ndarray:
    """The law of two spheres' contact (impact.NP) in their relative coordinate: m* and R* the
    reduced mass and radius, E*, k and the restitution from the pair table (the DEM kernel's)."""
    from collide.dem import damping_ratio
    from collide.engine.event import impact

    m, r = model.mass[b, :2], model.radius[b, :2]
    row = model.pair_table[b, int(model.material[b, 0]), int(model.material[b, 1])]
    zeta = float(damping_ratio(np.array(row[TABLE_REST]), model.hertz))
    params = impact.impact_params(hertz=model.hertz, mstar=float(m[0] * m[1] / (m[0] + m[1])), k=float(row[TABLE_K]),
                                  estar=float(row[TABLE_ESTAR]), rstar=float(r[0] * r[1] / (r[0] + r[1])), zeta=zeta)
    rows = params[None, :].copy()
    rows.setflags(write=False)  # the type `law_rows` gives (one compiled signature)
    return rows


def rub_rows(model: Model, b: int = 0) -> np.ndarray:
    """Each wall's tangential spring and rolling resistance as `alone.alone_run` takes them (W, 4):
    mu, k_t / k_n and its root, mu_r; mu 0 (no rubbing) without a spring (the scene's choice
    sends friction with the dead band elsewhere), mu_r 0 without rolling resistance."""
    rows = np.zeros((model.n_walls, 4))
    if model.spin_dim:
        row = model.wall_table[b, int(model.material[b, 0])]
        rows[:] = row[TABLE_MU] if model.tangential_spring else 0.0, row[TABLE_KTR], math.sqrt(row[TABLE_KTR]), \
            row[TABLE_ROLL]
    rows.setflags(write=False)
    return rows


def pair_rub_row(model: Model, b: int = 0) -> np.ndarray:
    """The two spheres' tangential spring and rolling resistance as `pair.pair_run` takes them
    (1, 4), from the pair table as `rub_rows` from the wall table."""
    row = np.zeros((1, 4))
    if model.spin_dim:
        tab = model.pair_table[b, int(model.material[b, 0]), int(model.material[b, 1])]
        row[0] = tab[TABLE_MU] if model.tangential_spring else 0.0, tab[TABLE_KTR], math.sqrt(tab[TABLE_KTR]), \
            tab[TABLE_ROLL]
    row.setflags(write=False)
    return row


def contact_tol(model: Model, state: State, tol: float, duration: float = math.nan) -> float:
    """The tolerance of each contact (relative to its approach speed) for a run's tol (relative
    to the fastest initial speed, docs/method.md): tol times that speed over the fastest approach
    the scene allows (a ball thrown at 0.3 m/s along a floor lands at 4.4 m/s from 1 m), over
    the chain's gain where gravity brings the sphere back for `duration`: an error d of a rebound
    speed shifts every later contact by 2 d / g, and the velocity at the end by g times that; the
    rebounds' speeds sum to at most g T / 2 (their flights fill at most the run), so the end's
    velocity moves by up to 1 + g T / approach times one contact's error (measured: ten bounces
    of a Hertz ball at e = 0.8 ended 6 to 9 times the contact's tolerance away from a run at a
    thousandth of it without this, and so fell to the measurement's finer runs)."""
    speed = float(np.sqrt((state.v[0] ** 2).sum(-1)).max())
    approach = float(approach_bound(model, state)[0])
    share = tol * min(1.0, speed / approach) if speed > 0.0 and approach > 0.0 else tol
    if model.gravity is not None and model.n_walls and math.isfinite(duration) and approach > 0.0:
        share /= 1.0 + float(np.linalg.norm(model.gravity[0])) * duration / approach
    return share


def alone_step(model: Model, state: State, tol: float, duration: float = math.nan) -> float:
    """The time step of a contact's middle at tol: the shortest contact time the scene can
    produce over the steps per contact time (`impact.steps_for`); the ends step over sigma."""
    from collide import dem

    if not model.n_walls and model.n_bodies < 2:
        return math.inf
    t_c, _, _ = dem.contact_time(model, state)
    return float(t_c[0]) / contact_steps(model, contact_tol(model, state, tol, duration))[1]


def contact_laws(model: Model) -> np.ndarray:
    """The law rows the kernel takes: two spheres' (`pair_row`) or each wall's (`law_rows`)."""
    return pair_row(model) if model.n_bodies == 2 else law_rows(model)


def contact_steps(model: Model, share: float, laws: np.ndarray | None = None) -> tuple[int, int, int, int]:
    """The kernel's `ends` for a contact tolerance `share` (`contact_tol`): the normal contact's
    steps (`impact.steps_for`, for these laws) and a rubbing one's (`oblique.rub_steps`)."""
    from collide.engine.event import impact, oblique

    return impact.steps_for(share, contact_laws(model) if laws is None else laws) + oblique.rub_steps(share)


def check_tol(tol: float) -> None:
    if tol < TOL_FLOOR:
        raise RunError(f"--tol {tol:.3g} is finer than a sphere's contacts reach (about {TOL_FLOOR:.0e}: each is "
                       "solved to round-off); use a looser --tol")


def simulate_alone(model: Model, state: State, *, tol: float, duration: float, tail: float, record: bool,
                   max_steps: int) -> RunResult:
    """Run one scene of one sphere among walls, or of two spheres and no walls (a batch of one),
    in the event engine."""
    from collide.engine.event import alone, pair

    check_tol(tol)
    G, WP, grav = kernel_inputs(model, state)
    fl = np.zeros(int(layout.NFL), np.int64)
    fl[layout.FL_SPIN], fl[layout.FL_PLANAR] = model.spin_dim > 0, model.dim < 3
    fl[layout.FL_RECORD], fl[layout.FL_MAXSTEPS], fl[layout.FL_DIM] = record, max_steps, model.dim
    fp = np.zeros(int(layout.NFP))
    fp[layout.FP_TEND] = duration if math.isfinite(duration) else math.inf
    fp[layout.FP_TAIL] = tail
    laws = contact_laws(model)
    ends = np.array(contact_steps(model, contact_tol(model, state, tol, duration), laws), np.int64)
    two = model.n_bodies == 2
    args = (G[0], laws, pair_rub_row(model), grav[0], fl, fp, ends) if two else \
        (G[0], WP, laws, rub_rows(model), grav[0], fl, fp, ends)
    kernel = pair.pair_run if two else alone.alone_run
    _load_compiled(kernel, args)  # loading is not simulating
    started = time.perf_counter()
    t, knots, recs, ivals, st, fg = kernel(*args)
    wall_time = time.perf_counter() - started
    _check(model, st, fg, t, open_ended=not math.isfinite(duration))
    from collide.stepper import unpack_state

    final = State(np.array([t]), *unpack_state(model, G[:1]), state.work + G[:1, :, layout.G_WK].sum(-1))
    t_final = np.array([t])
    logs = contact_logs([ivals], t_final)
    log = ContactLog(logs[:, 0], logs[:, 1], logs[:, 2], np.array([fg[layout.F_MAX_OVERLAP]]),
                     np.array([st[layout.S_CONTACTS]]), np.array([fg[layout.F_MAX_FORCE]]),
                     longest_contacts(model, [ivals], t_final))
    dt = alone_step(model, state, tol, duration)
    trajectories = [Trajectory(knots, recs, ivals, select_model(model, 0))] if record else None
    return RunResult(model=model, initial=state, final=final, integrator="impact", dt=np.array([dt]),
                     steps=np.array([st[layout.S_STEPS]]), jumps=np.array([st[layout.S_JUMPS]]),
                     wall_time_s=wall_time, contacts=log, trajectories=trajectories, warnings=[],
                     dt_min=np.array([fg[layout.F_DT_MIN] if math.isfinite(fg[layout.F_DT_MIN]) else dt]),
                     windows=np.zeros(1, np.int64), closed_steps=np.zeros(1, np.int64),
                     attempts=np.array([st[layout.S_STEPS]]),
                     free_since=last_contacts([ivals], t_final, model.n_bodies))


_LOADED: set = set()


def _load_compiled(kernel, args: tuple) -> None:
    """Load the compiled kernel from numba's cache before the clock starts (once a process).
    The warm-up leaves it out (about 18 s of CPU, which took the first compile past its 90 s):
    the first compiled run of a sphere alone compiles it here and caches it."""
    if kernel in _LOADED or not tier.COMPILED:
        return
    import numba

    with tier.loading():
        jit.compile_with_entry(kernel, tuple(numba.typeof(a) for a in args))
    _LOADED.add(kernel)


def _check(model: Model, st: np.ndarray, fg: np.ndarray, t: float, open_ended: bool) -> None:
    """Turn the kernel's status into a RunError naming the cause (AloneError where the DEM kernel
    can take the scene instead)."""
    from collide.engine.event import alone, pair

    status = int(st[layout.S_STATUS])
    at = f"t = {fg[layout.F_STATUS_T]:.6g} s"
    if status == layout.OK:
        return
    if status == layout.MAXSTEPS:
        raise step_limit_error(int(st[layout.S_STEPS]), t, open_ended)
    stops = {
        pair.PAIR_OBLIQUE: "the spheres touch at {at} not head-on (moving across the line of their centres): the "
                           "line turns during the contact, which is DEM's so far",
        pair.PAIR_FAILED: "the spheres' contact at {at} could not be integrated (its steps did not converge)",
        pair.PAIR_TWIST: "the spheres touch at {at} spinning against each other about the line of their centres: "
                         "rolling resistance against a twist and a roll at once is DEM's so far",
        pair.PAIR_CHATTER: "the spheres' contact at {at} alternates between stick and slip without end (beyond "
                           "the sliding and the saw of the spring's law that the event engine takes)",
        pair.PAIR_PLANE: "the spheres' slip at {at} is not along one line (their motion not in one plane): such a "
                         "contact is DEM's so far",
        alone.ALONE_WALLS: "the sphere's contact with wall {wall} at {at} comes within reach of another wall: "
                           "two contacts at once under these laws are DEM's so far",
        alone.ALONE_CHATTER: "the sphere's contact with wall {wall} at {at} alternates between stick and slip "
                             "without end (beyond the sliding and the saw of the spring's law that the event engine "
                             "takes)",
        alone.ALONE_PLANE: "the sphere's slip on wall {wall} at {at} is not along one line of the wall (spin about "
                           "an axis along it, or gravity across it): such a contact is DEM's so far",
        alone.ALONE_TWIST: "the sphere touches wall {wall} at {at} spinning about the wall's normal: rolling "
                           "resistance against a twist and a roll at once is DEM's so far",
    }
    failed = "the sphere's contact with wall {wall} at {at} could not be integrated (its steps did not converge)"
    cause = PairTurns if status == pair.PAIR_OBLIQUE else AloneError
    raise cause(stops.get(status, failed).format(wall=int(fg[layout.F_STATUS_A]), at=at))


class AloneError(RunError):
    """A sphere alone among walls met what the event engine cannot take at full order yet."""


class PairTurns(AloneError):
    """Two spheres met off-centre: the line of their centres turns during the contact, which the
    pair's relative coordinate does not take (the islands do, where their laws allow)."""
