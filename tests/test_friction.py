"""Friction in whole runs: events located, and the order the compositions keep with friction, in
the plane and out of it (the hold rate against a finite difference of the slip: tests/engine)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.accuracy import outcome, speed_scale
from collide.engine import layout as kn
from collide.model import compile_scenes, reference_frequency
from collide.run import run_scene
from collide.scene import generic_turn, load_scene, parse_scene, turned_source


def falling_box(seed: int, tol: float):
    """27 spheres (r 2 cm, 0.1 kg, k 1e5 N/m, mu 0.3) from a jittered 3 x 3 x 3 lattice with random
    velocities into an open box of five walls, 16 cm wide, under gravity for 0.5 s: a pile whose
    contacts stick, slide and turn together, many at a time."""
    rng = np.random.default_rng(seed)
    bodies = []
    for n, (i, j, k) in enumerate(np.ndindex(3, 3, 3)):
        position = [0.03 + 0.05 * i + rng.uniform(-0.004, 0.004), 0.03 + 0.05 * j + rng.uniform(-0.004, 0.004),
                    0.03 + 0.05 * k]
        bodies.append({"name": f"s{n + 1}", "mass": 0.1, "radius": 0.02, "position": [float(x) for x in position],
                       "velocity": [float(x) for x in rng.normal(0.0, 0.2, 3)]})
    origin = [0.0, 0.0, 0.0]
    walls = [(origin, [0.0, 0.0, 1.0]), (origin, [1.0, 0.0, 0.0]), ([0.16, 0.0, 0.0], [-1.0, 0.0, 0.0]),
             (origin, [0.0, 1.0, 0.0]), ([0.0, 0.16, 0.0], [0.0, -1.0, 0.0])]
    return parse_scene({"name": f"box27-{seed}", "dim": 3, "dt": "auto", "integrator": "kahan6", "tol": tol,
                        "duration": 0.5, "gravity": [0.0, 0.0, -9.81], "contact": {"k": 1e5, "mu": 0.3, "eps": 1e-6},
                        "body": bodies, "wall": [{"point": p, "normal": n} for p, n in walls]})


@pytest.mark.parametrize(("seed", "tol"), [(1, 1e-2), (1, 1e-4), (1, 1e-5), (2, 1e-5), (0, 1e-7), (38, 1e-3)])
def test_a_3d_pile_locates_every_event(seed, tol):
    """Every step of a settling pile lands its events: before (2026-12-03) the runs at 1e-4 and
    1e-5 warned of 34 and 41 steps that ran out of trials, where a stuck contact's hold force
    jumps as a neighbour's slip passes zero (bisected with interpolation in between, two trials a
    halving) or a slip turned past a right angle near the band; the run at 1e-2 of one, where a
    trial ending just past such a jump looked for dips on cubics that spanned it and was sent far
    back; lattice 2 at 1e-5 and lattice 0 at 1e-7 of one and two, where two jumping values took
    turns, each bisected again from the step's start. Lattice 38 at 1e-3 stalled (2026-12-05) on a
    slip grazing the band's edge, landed over and over in shorter steps (see GRAZE_SHARE). The
    energy balance holds to ten times the tolerance (measured 6.4e-8 to 8.9e-6; the chaotic
    outcome can only be compared with itself)."""
    from collide.engine import tier

    if not tier.compiled_ready():
        pytest.skip("needs the compiled engine (python -m collide.warmup): 7 000 steps of 27 bodies")
    run = run_scene(falling_box(seed, tol), record=False, measure=False)
    assert not [w for w in run.result.warnings if "ran out of trials" in w], run.result.warnings
    assert int(run.result.steps[0]) > 1000  # the pile really was stepped
    energy = float(dg.residuals(run.result).energy[0])
    assert energy <= 10 * tol, energy



def _order(scene, fractions=(0.4, 0.2)):
    omega = float(reference_frequency(compile_scenes([scene])[0])[0])
    reference = outcome(run_scene(scene, dt=0.01 / omega, record=False).result)
    errors = [np.abs(outcome(run_scene(scene, dt=x / omega, record=False).result) - reference).max()
              / speed_scale(scene) for x in fractions]
    return errors, np.log2(errors[0] / errors[1])


def test_friction_keeps_sixth_order():
    """The bonus demo slides, sticks on the band's edge, leaves it and slides again: kahan6 keeps
    its order through all of it, because a stuck contact is held symmetrically."""
    errors, order = _order(load_scene("demo-bonus"))
    assert errors[1] < 1e-8
    assert order > 5.0


def tilted_bonus(**changes) -> dict:
    """The bonus demo in 3D with the first ball thrown and both spinning out of the plane: the
    slip turns as the contact goes on."""
    raw = {"name": "tilted", "dim": 3, "contact": {"k": 1500.0, "mu": 0.5, "lever": "seed"},
           "body": [{"name": "ball1", "mass": 0.0254, "radius": 0.03021, "position": [0.0, 0.01, 0.0],
                     "velocity": [1.0, 0.0, 0.3], "spin": [2.0, -1.0, 3.0]},
                    {"name": "ball2", "mass": 0.0254, "radius": 0.03021, "position": [0.5, 0.0, 0.0],
                     "velocity": [-2.0, 0.0, 0.0], "spin": [-1.0, 4.0, -5.0]}]}
    raw.update(changes)
    return raw


def turned_scene(name: str = "demo-bonus", overrides: tuple[str, ...] = ()) -> tuple[dict, dict, np.ndarray]:
    """A built-in 2D scene and the same turned as a whole into a tilted plane (3D), with the turn."""
    raw2 = load_scene(name, list(overrides)).source
    return raw2, turned_source(raw2), generic_turn()


def test_bonus_demo_in_any_plane_is_the_2d_run():
    """No preferred axes: the bonus demo turned as a whole into a tilted plane takes the same
    steps as in z = 0 and gives the turned 2D answer."""
    raw2, raw3, turn = turned_scene()
    flat = run_scene(parse_scene(raw2), record=False).result
    tilted = run_scene(parse_scene(raw3), record=False).result
    back = tilted.final.v[0] @ turn
    assert back[:, :2] == pytest.approx(flat.final.v[0], abs=1e-9)
    assert np.abs(back[:, 2]).max() < 1e-12
    assert int(tilted.steps[0]) == int(flat.steps[0])


def test_a_run_in_a_tilted_plane_records_the_turned_2d_motion():
    """A 3D run in a tilted plane goes through the planar path turned into z = const, and comes
    back turned: its recorded motion (sampled between knots too), spins and orientations are the
    2D run's turned, to round-off and the event tolerance."""
    from collide.diagnostics import sample
    from collide.model import turned_quaternions

    raw2, raw3, turn = turned_scene()
    flat = run_scene(parse_scene(raw2)).result
    tilted = run_scene(parse_scene(raw3)).result
    times = np.linspace(0.0, float(flat.final.t[0]), 57)
    s2 = sample(flat.model, flat.trajectories[0], times)
    s3 = sample(tilted.model, tilted.trajectories[0], times)
    size = float(np.abs(s2.s).max())
    assert np.abs(s3.s[:, 0] @ turn - np.pad(s2.s[:, 0], ((0, 0), (0, 0), (0, 1)))).max() < 1e-9 * size
    assert np.abs(s3.v[:, 0] @ turn - np.pad(s2.v[:, 0], ((0, 0), (0, 0), (0, 1)))).max() < 1e-9
    assert np.abs(s3.w[:, 0] - s2.w[:, 0] * turn[:, 2]).max() < 1e-9
    # Orientation at the knots (between them 2D turns an angle, 3D a quaternion, by the spin
    # interpolated in the step: they differ by 5e-9): the 2D angle turned about the plane's
    # normal (turn's z column), from the start.
    knots = np.unique(flat.trajectories[0].knots[:, kn.K_T])
    angle = sample(flat.model, flat.trajectories[0], knots).q[:, 0, :, 0].ravel()
    q3 = sample(tilted.model, tilted.trajectories[0], knots).q[:, 0].reshape(-1, 4)
    expected = turned_quaternions(np.broadcast_to(q3[0], q3.shape), np.broadcast_to(turn[:, 2], q3[:, 1:].shape),
                                  angle)
    assert len(knots) > 10 and np.abs(q3 - expected).max() < 1e-12
    friction2 = flat.trajectories[0].records[:, kn.R_FX:kn.R_FY + 1]
    friction3 = tilted.trajectories[0].records[:, kn.R_FX:kn.R_FZ + 1] @ turn
    assert np.abs(friction3[:, :2] - friction2).max() < 1e-9 * np.abs(friction2).max()
    assert np.abs(friction3[:, 2]).max() < 1e-12 * np.abs(friction2).max()


def test_a_ball_on_a_tilted_floor_is_the_turned_2d_ball():
    """No preferred axes with walls and gravity: a ball set down sliding on a floor, the scene
    turned as a whole (floor, gravity and all), takes the 2D run's steps to its turned outcome."""
    raw2 = {"name": "slide", "dim": 2, "duration": 0.1, "gravity": [0.0, -9.81], "contact": {"k": 1e6, "mu": 0.3},
            "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.05], "velocity": [1.0, 0.0]}],
            "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}
    turn = turned_scene()[2]
    flat = run_scene(parse_scene(raw2), record=False, measure=False).result
    tilted = run_scene(parse_scene(turned_source(raw2, turn)), record=False, measure=False).result
    assert np.abs(tilted.final.v[0, 0] @ turn - [*flat.final.v[0, 0], 0.0]).max() < 1e-12
    assert np.abs(tilted.final.w[0, 0] - flat.final.w[0, 0, 0] * turn[:, 2]).max() * 0.05 < 1e-12
    assert int(tilted.steps[0]) == int(flat.steps[0])


def test_billiards_in_a_tilted_plane_costs_what_it_does_in_2d():
    """The billiards break turned into a tilted plane takes about the 2D run's steps and gives
    its turned outcome within the tolerance (the break amplifies the turn's round-off)."""
    raw2, raw3, turn = turned_scene("billiards-break")
    flat = run_scene(parse_scene(raw2), record=False, measure=False).result
    tilted = run_scene(parse_scene(raw3), record=False, measure=False).result
    back = tilted.final.v[0] @ turn
    assert np.abs(back[:, :2] - flat.final.v[0]).max() < 1e-6 * 6.0
    assert np.abs(back[:, 2]).max() < 1e-12
    assert abs(int(tilted.steps[0]) - int(flat.steps[0])) <= 2


def test_friction_out_of_the_plane_keeps_the_order():
    """Out of the plane the sliding friction follows the slip as it turns and a stuck contact is
    held in both tangent directions: kahan6 keeps (nearly) its sixth order. Just after the
    stick-to-slide change the slip's direction is a stiff layer that kahan6 follows at about
    third order; there the steps are shortened as (omega dt)^0.9. Before: 2.7e-7 at omega dt 0.4,
    0.2 and 0.1 alike (one step from the change to the contact's end)."""
    errors, order = _order(parse_scene(tilted_bonus()))
    assert errors[1] < 1e-7
    assert order > 4.5


def test_sliding_friction_out_of_the_plane_keeps_sixth_order():
    """A 3D contact that slides throughout while its friction turns by 20 degrees (the tilted
    bonus at mu = 0.3): the friction follows the slip as it turns at the integrator's order."""
    scene = load_scene(str(Path(__file__).parents[1] / "docs" / "scenes" / "tilted-slide.toml"))
    errors, order = _order(scene)
    assert errors[1] < 1e-8
    assert order > 5.5


def barely_yielding_break() -> dict:
    """The billiards break's cue ball and first three balls, the cue 5 mm above their plane:
    contacts slide on while their friction barely yields (slips of about a thousandth of a m/s
    against friction impulses of a few thousandths a step), in the stiff layer for many steps."""
    r = 0.028575
    x = 0.5 + math.sqrt(3.0) * r
    ball = {"mass": 0.17, "radius": r, "velocity": [0.0, 0.0, 0.0]}
    return {"name": "barely-yielding", "dim": 3, "contact": {"k": 1e7, "mu": 0.1},
            "body": [ball | {"name": "cue", "position": [0.0, 0.0, 0.005], "velocity": [6.0, 0.0, 0.0]},
                     ball | {"name": "b1", "position": [0.5, 0.0, 0.0]},
                     ball | {"name": "b2", "position": [x, -r, 0.0]},
                     ball | {"name": "b3", "position": [x, r, 0.0]}]}


def test_a_slip_that_barely_yields_out_of_the_plane_meets_the_tolerance():
    """Steps of a few of the stiff layer's time scales (|slip| / (mu F_n K)) followed it worst:
    each took up to 30 % off such a slip, and this scene ended 525 times the tolerance off at tol
    1e-6 and 3 300 times at 1e-8 (measured 1.2 and 8.5 times now). The bounds leave the room that
    the measured error estimate leaves a run (within 10 times its tolerance, README "Choosing the
    step") at 1e-6, and ten times that at 1e-8, two orders below the old errors."""
    scene = parse_scene(barely_yielding_break())
    reference = outcome(run_scene(scene, tol=1e-11, record=False, measure=False).result)
    for tol, bound in ((1e-6, 10.0), (1e-8, 100.0)):
        result = run_scene(scene, tol=tol, record=False, measure=False).result
        assert np.abs(outcome(result) - reference).max() / speed_scale(scene) < bound * tol


def test_stiff_friction_at_a_tight_tolerance_does_not_stall():
    """At k = 1e12 N/m a stick-to-slide change came due closer than the clock resolves at
    t = 0.147 s (2.8e-17 s): the step to it did not move the time, and the run stalled. Such an
    event is taken as passed (by under 1e-15 s)."""
    run = run_scene(load_scene("demo-bonus", ["contact.k=1e12"]), tol=1e-9, record=False)
    assert int(run.result.steps[0]) < 60
    # (At k = 1e12 the positions resolve the overlap to 2.3e-10: a tol of 1e-11 is refused.)
    reference = run_scene(load_scene("demo-bonus", ["contact.k=1e12"]), tol=1e-10, record=False)
    scene = load_scene("demo-bonus")
    assert np.abs(outcome(run.result) - outcome(reference.result)).max() / speed_scale(scene) < 1e-8


def _wall_impact(normal, velocity, spin, k: float, lever: str, dim: int, mu: float = 0.3) -> dict:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    point = np.full(dim, 1.0)
    body = {"name": "b", "mass": 0.1, "radius": 0.05, "position": (point + n * 0.06).tolist(),
            "velocity": list(velocity), "spin": spin if dim == 2 else list(spin)}
    return {"name": "wall-impact", "dim": dim, "tol": 1e-8, "contact": {"k": k, "mu": mu, "lever": lever},
            "body": [body], "wall": [{"point": point.tolist(), "normal": n.tolist()}]}


def random_wall_frame(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A wall's unit normal of random orientation and a random unit direction along it."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    along = np.cross(n, rng.normal(size=3))
    return n, along / np.linalg.norm(along)


def _rigid_error(raw: dict) -> tuple[float, int]:
    from collide.rigid import reference_speed, rigid_outcome
    scene = parse_scene(raw)
    result = run_scene(scene, record=False).result
    rigid = rigid_outcome(scene)
    error = max(np.abs(result.final.v[0, 0] - rigid.v[0]).max(),
                np.abs(result.final.w[0, 0] - rigid.w[0]).max() * 0.05) / reference_speed(scene)
    return float(error), int(result.steps[0])


@pytest.mark.parametrize("raw", [
    # The slip reaches the band's edge within a 1e-6 s contact: the root find crept along the
    # smoothed friction's flat side for 40 trials and the step ended past the edge, slipping
    # backwards (1.3e-3 off, reported as 1e-8).
    _wall_impact([0.6686698923736786, -0.7435593957667224], [0.5790303221917384, 2.1431307040394487],
                 22.798433087383184, 1e12, "seed", 2),
    # A stuck contact's hold force jumped at a step's start: bisected below the clock's tick,
    # never met, and the run stopped ("events closer than the clock resolves").
    _wall_impact([0.0, 0.0, 1.0], [-1.5576832453556286, 0.655183566839429, -1.1137987045537419],
                 [0.0, 0.0, 0.0], 1e12, "contact", 3),
])
def test_stiff_oblique_wall_impacts_land_on_the_rigid_answer(raw: dict) -> None:
    """At k = 1e12 N/m the soft model is within ~1e-6 of the rigid closed form (overlap / radius)."""
    error, steps = _rigid_error(raw)
    assert error < 1e-5
    assert steps < 40


def test_oblique_wall_impacts_in_3d_match_the_rigid_answer_like_2d() -> None:
    """Issue 10: a sphere hitting a wall of any orientation with spin about any axis, tol 1e-8,
    lands within 1e-5 of the rigid closed form (k = 1e12: the soft model's own distance from it,
    about overlap / radius, is ~1e-6), in as many steps as the same impact in a 2D scene: both
    run in closed form, the 3D one's slip turning (a spin out of the plane) held along its mean
    direction over each interval (measured: 5-8 intervals in 3D, 6-8 in 2D; 14-21 steps when the
    3D slide was stepped)."""
    rng = np.random.default_rng(10)
    for _ in range(6):
        n, along = random_wall_frame(rng)
        speed_n, speed_t, spin = rng.uniform(0.5, 2.0), rng.uniform(0.2, 2.0), rng.normal(size=3) * 20
        error, steps = _rigid_error(_wall_impact(n, -speed_n * n + speed_t * along, spin, 1e12, "contact", 3))
        n2 = np.array([n[0], n[1]]) / np.hypot(n[0], n[1])
        flat = -speed_n * n2 + speed_t * np.array([-n2[1], n2[0]])
        error2, steps2 = _rigid_error(_wall_impact(n2, flat, float(np.linalg.norm(spin)), 1e12, "contact", 2))
        assert error < 1e-5 and error2 < 1e-5
        assert steps2 < 12 and steps < 2 * steps2


def test_a_run_knows_whether_it_stays_in_a_plane_of_any_orientation():
    """Only out of every plane can a slip turn (and its stiff layer need shorter steps)."""
    from collide.model import compile_scenes, plane_of_motion

    def planar(raw: dict) -> bool:
        model, state = compile_scenes([parse_scene(raw)])
        return plane_of_motion(model, state, 0) is not None

    floor = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]

    def ball(spin) -> dict:
        return {"name": "b", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.0, 0.2], "velocity": [1.0, 0.0, 0.0],
                "spin": spin}

    assert not planar(tilted_bonus())
    assert planar(load_scene("demo-bonus").source)
    # A ball bouncing along x on a floor moves in the x-z plane; topspin about y keeps it there.
    bounce = {"dim": 3, "gravity": [0.0, 0.0, -9.81], "contact": {"k": 1e6, "mu": 0.3}, "wall": floor}
    assert planar(bounce | {"body": [ball([0.0, 3.0, 0.0])]})
    assert not planar(bounce | {"body": [ball([0.0, 3.0, 1.0])]})
    # The bonus demo turned as a whole into a tilted plane.
    assert planar(turned_scene()[1])


def test_friction_events_in_the_plane_cost_few_step_attempts():
    """Each friction mode event of the billiards break re-steps its island until it lands: the
    search must aim well. A slip crossing the band is aimed at through its far edge (the near
    edge's value of |slip| rose and fell back: 11 trials for one event), and refinements close
    to a trial's end are one Verlet substep from there. With these, 154 steps from a step's start
    against 78 without friction (261 before). Out of the plane they are taken as far as the slips'
    turning allows (`turning_nudges`): the tilted bonus demo tries 16 steps from a step's start
    and 6 substeps (41 and none before 2026-12-05); in a tilted plane the planar path takes them.
    Counted with the interpreted kernels, where `step` can be wrapped."""
    code = """
import sys
import collide.engine.event.locate as locate
from collide.run import run_scene
from collide.scene import load_scene, parse_scene
sys.path.insert(0, {tests!r})
from test_friction import tilted_bonus
count = {{"full": 0, "substep": 0}}
step = locate.step
def counted(*args):
    count["full" if len(args[6]) > 1 else "substep"] += 1
    return step(*args)
locate.step = counted
from test_friction import turned_scene
scenes = [load_scene("billiards-break", ["tol=1e-6", "contact.mu=" + mu]) for mu in ("0.1", "0")]
turned = parse_scene(turned_scene("billiards-break", ("tol=1e-6",))[1])
for scene in scenes + [parse_scene(tilted_bonus(tol=1e-7)), turned]:
    count.update(full=0, substep=0)
    run_scene(scene, record=False, measure=False)
    print(count["full"], count["substep"])
"""
    env = {**os.environ, "COLLIDE_JIT": "0"}
    out = subprocess.run([sys.executable, "-c", code.format(tests=str(Path(__file__).parent))], env=env,
                         capture_output=True, text=True, check=True)
    (full, substeps), (full_without, _), (full_3d, substeps_3d), (full_tilted, substeps_tilted) = [
        map(int, line.split()) for line in out.stdout.splitlines()]
    assert full_without > 0 and full_3d > 0
    assert full <= 2.2 * full_without
    assert substeps > 0
    # Half again the 16 counted, where 41 were tried without nudges out of the plane.
    assert substeps_3d > 0 and full_3d <= 24
    # In a tilted plane the break runs on the planar path too (turned into z = const).
    assert substeps_tilted > 0 and full_tilted <= 1.1 * full
