"""Contact laws beyond the report's (docs/design.md section 9), run by the DEM kernel: Hertz, restitution,
tangential springs, rolling resistance, materials. Each test compares with a closed form or a
conservation law; tolerances are stated where they are set."""

from __future__ import annotations

import math

import numpy as np
import pytest

from collide import diagnostics as dg
from collide.model import TABLE_ESTAR, TABLE_MU, TABLE_REST, compile_scenes
from collide.run import RunError, run_scene, run_scenes
from collide.scene import SceneError, load_scene, parse_scene

GLASS = {"youngs_modulus": 4.8e10, "poisson_ratio": 0.2}


def _wall_scene(**contact) -> dict:
    law = {"model": "hertz", "youngs_modulus": 7e10, "poisson_ratio": 0.3}
    law.update(contact)
    return {"dim": 3, "integrator": "dem", "dt": 2e-7,
            "contact": law,
            "body": [{"name": "a", "radius": 0.1, "mass": 10.0, "position": [0.0, 0.0, 0.1],
                      "velocity": [0.0, 0.0, -0.2]}],
            "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]}


def hertz_closed_form(m_star: float, r_star: float, e_star: float, speed: float) -> tuple[float, float, float]:
    """delta_max, F_max and contact time of an elastic Hertz impact at this approach speed."""
    delta = (15.0 * m_star * speed**2 / (16.0 * e_star * math.sqrt(r_star))) ** 0.4
    force = 4.0 / 3.0 * e_star * math.sqrt(r_star) * delta**1.5
    # The integral of the Hertz impact: t_c = 2.9432 delta_max / v (2.868 (m*^2/(R* E*^2 v))^(1/5)).
    time = 2.9432 * delta / speed
    return delta, force, time


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
    assert scene.integrator == "dem"  # chosen for a law beyond the report's
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
    ({"contact": {"restitution": 0.0}}, "contact.restitution: must be positive"),
    ({"contact": {"model": "hertz", "poisson_ratio": 0.5, "youngs_modulus": 1e9}}, "contact.poisson_ratio"),
    ({"contact": {"model": "hertz"}}, "contact.youngs_modulus: missing"),
    ({"contact": {"model": "hooke"}}, "contact.model: unknown 'hooke'"),
    ({"contact": {"tangential": "mindlin"}}, "contact.tangential: unknown 'mindlin'"),
    ({"contact": {"restitution": 0.5}, "integrator": "kahan6"}, "integrator: 'kahan6' runs the report's"),
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


def test_integrator_override_that_cannot_run_the_law_is_refused():
    with pytest.raises(SceneError, match="runs with --integrator dem"):
        run_scene(load_scene("bounce"), integrator="kahan6", record=False)


# ---------------------------------------------------------------------------------------------
# Normal laws against closed forms


@pytest.mark.parametrize("wall", [False, True])
def test_hertz_impact_matches_closed_form(wall):
    """delta_max, F_max and contact time within 1 % (Chung & Ooi tests 1 and 2); at ~4000 steps
    per contact the step adds under 0.1 %."""
    r, m, v = 0.01, 0.011728, 10.0
    bodies = [{"name": "a", "radius": r, "mass": m, "position": [0.0, 0.0, r + (0.0 if wall else 0.0)],
               "velocity": [0.0, 0.0, -v]}]
    if wall:
        walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
        bodies[0]["position"] = [0.0, 0.0, r * 1.0001]
        m_star, r_star, e_star, speed = m, r, GLASS["youngs_modulus"] / (1 - 0.2**2), v
    else:
        walls = []
        bodies[0]["position"] = [0.0, 0.0, 0.0]
        bodies[0]["velocity"] = [v, 0.0, 0.0]
        bodies.append({"name": "b", "radius": r, "mass": m, "position": [2.0001 * r, 0.0, 0.0],
                       "velocity": [-v, 0.0, 0.0]})
        m_star, r_star, e_star, speed = m / 2, r / 2, GLASS["youngs_modulus"] / (2 * (1 - 0.2**2)), 2 * v
    delta, force, time = hertz_closed_form(m_star, r_star, e_star, speed)
    raw = {"dim": 3, "integrator": "dem", "dt": time / 4000, "contact": {"model": "hertz", **GLASS},
           "body": bodies, "wall": walls}
    result = run_scene(parse_scene(raw), record=False).result
    assert result.contacts.max_overlap[0] == pytest.approx(delta, rel=1e-3)
    assert result.contacts.max_normal_force[0] == pytest.approx(force, rel=1e-3)
    assert result.contacts.duration[0] == pytest.approx(time, rel=1e-3)
    assert dg.residuals(result).energy[0] < 1e-6  # elastic: nothing is lost but round-off and O(dt^2)


@pytest.mark.parametrize("model", ["linear", "hertz"])
@pytest.mark.parametrize("e", [0.1, 0.3, 0.6, 0.9, 1.0])
def test_restitution_out_equals_restitution_in(model, e):
    """Damping chosen for e gives e (force not clipped: a contact may pull as it ends), within
    1 % at 3000+ steps per contact; the work of the dashpot keeps the energy balance."""
    raw = _wall_scene(model=model, restitution=e, k=1e7)
    raw["dt"] = 1e-6 if model == "linear" else 2e-7
    result = run_scene(parse_scene(raw), record=False).result
    assert result.final.v[0, 0, 2] / 0.2 == pytest.approx(e, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-5
    damping = result.dissipation[0, 0]
    assert damping == pytest.approx(0.5 * 10.0 * 0.2**2 * (1 - e**2), rel=2e-2, abs=1e-12)


# ---------------------------------------------------------------------------------------------
# Tangential laws and rolling resistance


@pytest.mark.parametrize("angle", [70.0, 80.0, 85.0])
def test_oblique_impact_in_gross_sliding_matches_rigid_body(angle):
    """A sphere sliding through the whole impact (Chung & Ooi test 4, their e = 0.98): the
    tangential speed drops by mu (1 + e) v_n and the spin grows by 5/2 of that over r (solid
    sphere), within 1 %. (With strong damping the contact pulls as it ends, which friction does
    not follow, so the friction impulse exceeds mu times the net normal impulse: README.)"""
    speed, mu, e, r = 3.9, 0.3, 0.98, 0.1
    vn, vt = speed * math.cos(math.radians(angle)), speed * math.sin(math.radians(angle))
    # Gross sliding needs the slip not to reverse: vt > 7/2 mu (1 + e) vn.
    assert vt > 3.5 * mu * (1 + e) * vn
    raw = _wall_scene(restitution=e, mu=mu)
    raw["body"][0]["velocity"] = [vt, 0.0, -vn]
    raw["dt"] = 1e-7
    result = run_scene(parse_scene(raw), record=False).result
    v, w = result.final.v[0, 0], result.final.w[0, 0]
    dv = mu * (1 + e) * vn
    assert v[0] == pytest.approx(vt - dv, rel=1e-2)
    assert v[2] == pytest.approx(e * vn, rel=1e-2)
    assert w[1] == pytest.approx(2.5 * dv / r, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-5


def test_tangential_spring_without_slip_reverses_the_contact_point_as_the_closed_form_says():
    """Linear normal and tangential springs, no slip, no damping: the contact point's tangential
    speed u oscillates at omega_t = sqrt(3.5 k_t / m) (a solid sphere on a wall) while the normal
    contact lasts pi / omega_n, so u_out = u_in cos(pi sqrt(3.5 k_t / k_n)): -u_in at the
    classic k_t / k_n = 2/7 (Chung & Ooi's near-sticking regime: the rebound reverses the slip,
    which Coulomb slip cannot). No slip needs u_in < 3.5 mu v_n. Within 1 % at 3000 steps per
    contact; the energy balance includes what the spring holds."""
    raw = _wall_scene(model="linear", k=1e7, mu=0.3, tangential="spring")
    raw["body"][0]["velocity"] = [0.02, 0.0, -0.2]
    raw["dt"] = 1e-6
    result = run_scene(parse_scene(raw), record=False).result
    v, w, r = result.final.v[0, 0], result.final.w[0, 0], 0.1
    assert v[0] - w[1] * r == pytest.approx(-0.02, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-6


def test_rolling_resistance_stops_a_rolling_ball_where_the_closed_form_says():
    """A solid ball rolling without slip under a torque mu_r r F_n decelerates at 5/7 mu_r g:
    it stops after v^2 / (2 a). Within 2 %: the contact's own compliance and the step."""
    g, mu_r, r, v0 = 9.81, 0.05, 0.02, 0.5
    raw = {"dim": 3, "integrator": "dem", "dt": 2e-5, "duration": 2.0, "gravity": [0.0, 0.0, -g],
           "contact": {"model": "hertz", "youngs_modulus": 1e7, "poisson_ratio": 0.3, "restitution": 0.3,
                       "mu": 0.8, "tangential": "spring", "rolling_friction": mu_r},
           "body": [{"name": "a", "radius": r, "mass": 0.1, "position": [0.0, 0.0, r],
                     "velocity": [v0, 0.0, 0.0], "spin": [0.0, v0 / r, 0.0]}],
           "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]}
    scene = parse_scene(raw)
    result = run_scene(scene, record=False).result
    a = 5.0 / 7.0 * mu_r * g
    assert result.final.s[0, 0, 0] == pytest.approx(v0**2 / (2 * a), rel=2e-2)
    assert abs(result.final.v[0, 0, 0]) < 1e-3 * v0
    assert result.dissipation[0, 2] == pytest.approx(0.5 * 0.1 * v0**2 * 1.4, rel=5e-2)


# ---------------------------------------------------------------------------------------------
# Built-in scenes and batches


def test_bounce_heights_fall_by_e_squared():
    scene = load_scene("bounce")
    run = run_scene(scene, record=True)
    traj = run.result.trajectory
    y = traj.s[:, 0, 0, 1] - scene.bodies[0].radius
    peaks = [y[k] for k in range(1, len(y) - 1) if y[k] >= y[k - 1] and y[k] > y[k + 1] and y[k] > 0.01]
    assert len(peaks) >= 4
    ratios = np.array(peaks[1:4]) / np.array(peaks[0:3])
    # Frames every 1.7 ms miss an apex by under (g dt^2 / 8) / h: 4e-6 m on 0.2-0.6 m.
    assert ratios == pytest.approx(0.8**2, rel=1e-2)
    assert dg.residuals(run.result).energy[0] < 1e-3


def _pile(per_side: int, layers: int) -> dict:
    """Spheres on a loose lattice above the floor of a box open at the top, like `pile`."""
    r, spacing = 0.005, 0.012
    side = per_side * spacing
    rng = np.random.default_rng(5)
    bodies = []
    for k in range(layers):
        for i in range(per_side):
            for j in range(per_side):
                x, y = (i + 0.5) * spacing + rng.uniform(-1e-4, 1e-4), (j + 0.5) * spacing + rng.uniform(-1e-4, 1e-4)
                bodies.append({"name": f"g{len(bodies)}", "material": "glass", "radius": r,
                               "position": [x, y, r + 0.002 + k * spacing], "velocity": [0.0, 0.0, 0.0]})
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    for axis in range(2):
        for value, sign in ((0.0, 1.0), (side, -1.0)):
            point, normal = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
            point[axis], normal[axis] = value, sign
            walls.append({"point": point, "normal": normal})
    return {"dim": 3, "integrator": "dem", "dt": "auto", "tol": 2e-2, "duration": 5.0, "rest": 1e-6,
            "gravity": [0.0, 0.0, -9.81],
            "contact": {"model": "hertz", "restitution": 0.5, "tangential": "spring", "mu": 0.5,
                        "rolling_friction": 0.02},
            "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6, "poisson_ratio": 0.25}],
            "body": bodies, "wall": walls}


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


def test_one_pass_between_force_passes_changes_no_bit():
    """Between two force passes the DEM kernel makes one pass over the bodies (a step's closing
    kick, the next one's opening kick and drift) unless it must read the velocities at the step's
    end, as a scene that ends at rest does after every step. The same settling pile (rolling
    resistance and tangential springs: every part of the work booked) run both ways, its rest
    test never met, ends with the same state and work to the last bit."""
    fused = _pile(3, 3)
    fused["duration"] = 0.3
    del fused["rest"]
    unfused = dict(fused, rest=1e-30)
    runs = [run_scene(parse_scene(raw), record=False).result for raw in (fused, unfused)]
    assert runs[0].steps[0] == runs[1].steps[0] > 1000 and runs[0].final.t[0] == 0.3
    first, second = runs
    for name in ("s", "v", "w", "q", "work"):
        assert np.array_equal(getattr(first.final, name), getattr(second.final, name)), name
    assert np.array_equal(first.dissipation, second.dissipation)
    assert np.abs(first.final.v).max() > 1e-3  # still moving: the passes had work to do


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


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("far", [False, True])
def test_neighbour_lists_hold_every_pair_within_reach(dim, far):
    """The DEM neighbour search against every pair: spheres of unequal radii packed in a small
    region (a dense cell grid) and, with `far`, one of them 100 km away (the grid is hashed
    instead); keys ascending, each with its pair's (i, j)."""
    from collide.engine.dem.layout import B_R, NB
    from collide.engine.dem.neighbours import DENSE_CELLS, build_pairs

    rng = np.random.default_rng(dim)
    for n in (1, 2, 40, 300):
        P = np.zeros((n, 3))
        P[:, :dim] = rng.uniform(-1.0, 1.0, (n, dim)) * n ** (1 / dim) * 0.4
        if far:
            P[0, :dim] = 1e5
        bodies = np.zeros((n, int(NB)))
        bodies[:, B_R] = rng.uniform(0.1, 0.5, n)
        pad = 0.1
        size = 2 * bodies[:, B_R].max() + pad
        cells = np.prod(np.ptp(P[:, :dim], axis=0) / size + 1.0)
        assert (cells > DENSE_CELLS * n) == (far and n > 1)  # the grid kind this case is for
        keys, rows, partners = build_pairs(P, bodies, n, dim, pad)
        gap = np.linalg.norm(P[:, None] - P[None], axis=-1) - bodies[:, None, B_R] - bodies[None, :, B_R]
        i, j = np.nonzero(np.triu(gap < pad, 1))
        assert n < 40 or len(i) > n // 2  # not vacuous
        assert np.array_equal(keys, i * n + j) and np.array_equal(rows, i) and np.array_equal(partners, j)


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
