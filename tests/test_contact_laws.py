"""Contact laws beyond the report's (docs/design.md section 9), run by the DEM kernel: Hertz, restitution,
tangential springs, rolling resistance, materials. Each test compares with a closed form or a
conservation law; tolerances are stated where they are set."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.model import TABLE_ESTAR, TABLE_MU, TABLE_REST, compile_scenes
from collide.run import RunError, run_scene, run_scenes
from collide.scene import DEFAULT_INTEGRATOR, SceneError, island_blocker, load_scene, parse_scene
from collide.trajectory import sample
from tests.dem_scenes import GLASS, _pile, _wall_scene

# ---------------------------------------------------------------------------------------------
# Scene keys, materials and mixing


def test_materials_give_masses_moduli_and_mixed_pair_values():
    raw = {"dim": 3, "contact": {"model": "hertz", "mu": 0.4, "restitution": 0.9},
           "material": [{"name": "glass", "density": 2800.0, **GLASS, "mu": 0.2, "restitution": 0.5},
                        {"name": "steel", "density": 7800.0, "youngs_modulus": 2e11, "poisson_ratio": 0.3}],
           "pair": [{"materials": ["steel", "steel"], "mu": 0.05}],
           "body": [{"name": "a", "material": "glass", "radius": 0.01, "position": [0, 0, 0]},
                    {"name": "b", "material": "steel", "radius": 0.02, "position": [0.1, 0, 0]},
                    {"name": "c", "material": "steel", "radius": 0.02, "position": [0.2, 0, 0], "mass": 1.0}]}
    scene = parse_scene(raw)
    # A law beyond the report's (Hertz, its dashpot, Coulomb friction) that the islands step.
    assert scene.needs_dem and scene.integrator == DEFAULT_INTEGRATOR
    assert scene.bodies[0].mass == pytest.approx(4 / 3 * math.pi * 0.01**3 * 2800.0, rel=1e-15)
    assert scene.bodies[2].mass == 1.0  # a given mass wins
    model, _ = compile_scenes([scene])
    glass, steel = 1, 2
    table = model.pair_table[0]
    e_star = 1.0 / ((1 - 0.2**2) / 4.8e10 + (1 - 0.3**2) / 2e11)
    assert table[glass, steel, TABLE_ESTAR] == pytest.approx(e_star, rel=1e-14)
    assert table[glass, steel, TABLE_MU] == pytest.approx(0.5 * (0.2 + 0.4))  # steel gives none: [contact]'s
    assert table[glass, glass, TABLE_REST] == pytest.approx(0.5)
    assert table[glass, steel, TABLE_REST] == pytest.approx(math.sqrt(0.5 * 0.9))
    assert table[steel, steel, TABLE_MU] == 0.05  # the [[pair]] table overrides
    assert model.wall_table[0, glass, TABLE_ESTAR] == pytest.approx(4.8e10 / (1 - 0.2**2))


@pytest.mark.parametrize("change, message", [
    ({"contact": {"restitution": 1.5}}, "contact.restitution: a restitution is at most 1"),
    ({"contact": {"restitution": -0.2}}, "contact.restitution: must not be negative"),
    ({"contact": {"restitution": 0.0}}, "restitution = 0 (perfectly inelastic): the bodies stay in contact"),
    ({"contact": {"model": "hertz", "poisson_ratio": 0.5, "youngs_modulus": 1e9}}, "contact.poisson_ratio"),
    ({"contact": {"model": "hertz"}}, "contact.youngs_modulus: missing"),
    ({"contact": {"model": "hooke"}}, "contact.model: unknown 'hooke'"),
    ({"contact": {"tangential": "mindlin"}}, "contact.tangential: unknown 'mindlin'"),
    ({"contact": {"rolling_friction": 0.1, "mu": 0.3}, "integrator": "kahan6"},
     "integrator: 'kahan6' cannot run this scene's contact law (rolling_friction): rolling resistance with Coulomb "
     "friction's dead band is DEM's so far"),
    ({"body": [{"name": "a", "radius": 0.1, "position": [0, 0, 0], "material": "wood"}]}, "body.a.material: unknown"),
    ({"body": [{"name": "a", "radius": 0.1, "position": [0, 0, 0]}]}, "body.a.mass: missing"),
    ({"rest": 1e-6}, "rest: ends a DEM run"),
])
def test_bad_contact_laws_are_refused_by_key(change, message):
    raw = {"dim": 3, "body": [{"name": "a", "mass": 1.0, "radius": 0.1, "position": [0, 0, 0]}]}
    raw.update(change)
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_scene(raw)


def test_report_scenes_keep_their_integrator_and_law():
    for name in ("demo-bonus", "billiards-break", "gas-box"):
        scene = load_scene(name)
        assert not scene.needs_dem and scene.integrator != "dem"


def test_a_tangential_spring_between_two_spheres_chooses_the_event_engine():
    """Two spheres and no walls with a tangential spring and friction: the event engine's
    integrator (event/pair.py); Coulomb friction with a dead band there: the islands'; a third
    sphere with the spring (an island): the islands' in 2D, DEM's in 3D, where an event integrator
    asked for is refused."""
    contact = {"model": "hertz", "restitution": 0.8, "mu": 0.3, "tangential": "spring",
               "tangential_stiffness_ratio": 0.5}
    body = [{"name": n, "material": "glass", "radius": 0.01, "position": [0.03 * k, 0.005 * k]}
            for k, n in enumerate("abc")]
    body[0]["velocity"] = [1.0, 0.0]
    pair = {"dim": 2, "contact": contact, "material": [{"name": "glass", "density": 2800.0, **GLASS}],
            "body": body[:2]}
    assert parse_scene(copy.deepcopy(pair)).integrator != "dem"
    assert parse_scene({**copy.deepcopy(pair), "body": copy.deepcopy(body)}).integrator != "dem"
    trio3 = {**copy.deepcopy(pair), "dim": 3, "body": [{**b, "position": b["position"] + [0.0]} for b in body]}
    trio3["body"][0]["velocity"] = [1.0, 0.0, 0.0]
    assert parse_scene(copy.deepcopy(trio3)).integrator == "dem"
    coulomb = {**copy.deepcopy(pair), "contact": {**contact, "tangential": "coulomb"}}
    assert parse_scene(coulomb).integrator not in ("dem", "seed")
    assert island_blocker(parse_scene(coulomb)) is None
    with pytest.raises(SceneError, match="kahan6. cannot run this scene.s contact law"):
        parse_scene({**trio3, "integrator": "kahan6"})


def test_integrator_override_that_cannot_run_the_law_is_refused():
    # (Rolling resistance with the dead band's Coulomb friction is DEM's; the bounce itself runs in
    # the event engine, with rolling resistance alone too, and with Coulomb friction during its
    # damped Hertz contacts in the islands.)
    with pytest.raises(SceneError, match="runs with --integrator dem"):
        run_scene(load_scene("bounce", ["contact.rolling_friction=0.01", "contact.mu=0.3"]), integrator="kahan6",
                  record=False)
    # (spinning: rolling resistance acts only on a spin, and a reason names it only where one can be)
    run = run_scene(load_scene("bounce", ["contact.rolling_friction=0.01", "body.ball.spin=5.0"]), integrator="kahan6",
                    record=False)
    assert run.result.engine == "event" and "between rolling and held located" in run.result.engine_reason
    run = run_scene(load_scene("bounce", ["contact.mu=0.3"]), integrator="kahan6", record=False)
    assert run.result.engine == "event" and "each friction mode change located" in run.result.engine_reason


# ---------------------------------------------------------------------------------------------
# Normal laws against closed forms


# ---------------------------------------------------------------------------------------------
# Tangential laws and rolling resistance


# ---------------------------------------------------------------------------------------------
# Built-in scenes and batches


def test_bounce_heights_fall_by_e_squared():
    scene = load_scene("bounce")
    run = run_scene(scene, record=True)
    # (The event engine runs it: its trajectory sampled at frames, as the viewer does.)
    states = sample(run.result.model, run.result.trajectory, np.arange(0.0, scene.duration, 1.7e-3))
    y = states.s[:, 0, 0, 1] - scene.bodies[0].radius
    peaks = [y[k] for k in range(1, len(y) - 1) if y[k] >= y[k - 1] and y[k] > y[k + 1] and y[k] > 0.01]
    assert len(peaks) >= 4
    ratios = np.array(peaks[1:4]) / np.array(peaks[0:3])
    # Frames every 1.7 ms miss an apex by under (g dt^2 / 8) / h: 4e-6 m on 0.2-0.6 m.
    assert ratios == pytest.approx(0.8**2, rel=1e-2)
    assert dg.residuals(run.result).energy[0] < 1e-3


def test_settling_pile_comes_to_rest_with_its_energy_balanced():
    """A small pile (4 x 4 x 4 spheres): the run ends at rest (kinetic energy under 1e-6 of its
    peak) well before its duration, every sphere inside the box, and the balance (kinetic +
    potential + elastic + dissipated) holds to 1e-4 of the energy it started with."""
    scene = parse_scene(_pile(4, 4))
    result = run_scene(scene, record=False).result
    assert result.final.t[0] < 5.0
    kinetic = 0.5 * np.sum(result.model.mass[0] * np.sum(result.final.v[0] ** 2, axis=-1))
    peak = max(0.5 * b.mass * 9.81 * b.position[2] for b in scene.bodies) * len(scene.bodies)
    assert kinetic < 1e-6 * peak
    z = result.final.s[0, :, 2]
    assert (z > 0).all() and (z < 0.06).all()
    assert dg.residuals(result).energy[0] < 1e-4
    assert 0.3 < dg.packing_fraction(result.model, result.final.s[0]) < 0.74  # loose to densest


def test_dem_batch_members_equal_single_runs():
    base = _wall_scene(restitution=0.5, mu=0.3, tangential="spring")
    base["body"][0]["velocity"] = [0.1, 0.0, -0.2]
    scenes = []
    for e in (0.3, 0.7):
        raw = dict(base)
        raw["contact"] = dict(base["contact"], restitution=e)
        scenes.append(parse_scene(raw))
    batch = run_scenes(scenes, record=False).result
    for b, scene in enumerate(scenes):
        alone = run_scene(scene, record=False).result
        assert np.array_equal(batch.final.v[b], alone.final.v[0])
        assert np.array_equal(batch.final.w[b], alone.final.w[0])


def test_too_large_a_dem_step_is_refused():
    raw = _wall_scene(restitution=0.5)
    raw["dt"] = 1e-3
    with pytest.raises(RunError, match="beyond the stability limit of the DEM step"):
        run_scene(parse_scene(raw), record=False)


def test_long_run_shows_progress_on_stderr_and_keeps_json_on_stdout():
    """Progress (simulated time, steps, rate) goes to stderr; stdout stays one JSON object."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, COLLIDE_PROGRESS="1", COLLIDE_PROGRESS_AFTER="0")
    # Ten times break-3d's own duration: seconds of stepping, far more than the 0.25 s between polls.
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", "break-3d", "--set", "duration=12", "--json",
                           "--no-record"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["scene"] == "break-3d" and summary["contact"]["max_normal_force"] > 0
    assert "break-3d: " in done.stderr and "steps/s" in done.stderr and "of 12 s" in done.stderr


def test_materials_are_overridden_by_name():
    from collide.scene import apply_overrides, read_raw

    raw, _ = read_raw("break-3d")
    scene = parse_scene(apply_overrides(raw, ["material.phenolic.restitution=0.7"]))
    assert scene.materials[0].restitution == 0.7
    with pytest.raises(SceneError, match="no material named 'wood' \\(materials: phenolic\\)"):
        apply_overrides(raw, ["material.wood.mu=1"])


def test_a_law_override_lets_a_builtin_choose_its_engine():
    # demo-bonus recommends kahan6 for the report's law; rolling resistance (DEM's only) must be
    # taken by the engine that runs it, not refused by the recommendation.
    changed = load_scene("demo-bonus", ["contact.rolling_friction=0.01"])
    assert "integrator" not in changed.source and changed.integrator == "dem"
    run = run_scene(changed, record=False, tol=1e-3)
    assert run.result.engine == "dem" and "rolling" in run.result.engine_reason
    # Bodies moved, law kept: the recommendation stands.
    assert load_scene("demo-bonus", ["body.ball1.velocity.x=2"]).source["integrator"] == "kahan6"
    # Named with the override, it is the user's: refused where it cannot run the law.
    with pytest.raises(SceneError, match="cannot run this scene's contact law"):
        load_scene("demo-bonus", ["contact.rolling_friction=0.01", "integrator=kahan6"])
