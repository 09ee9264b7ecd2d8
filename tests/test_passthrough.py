"""Issue 53 (item 2): bodies never end a run passed through one another. Each case either runs
with the order kept (1D) and no overlap deeper than the contact law can store from the
scene's energy (2D, 3D), or is refused with the cause; never a run that exits 0 passed
through. The engine is checked on its own (the run's final check turned off), so that a
pass-through the engine still makes fails here instead of hiding behind the refusal."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import collide.run as run_module
from collide.invariant import SLACK, available_energy, check_invariant
from collide.run import run_scene
from collide.scene import load_scene, parse_scene
from collide.stepper import RunError
from tests.random_scenes import random_scene

MASS, RADIUS = 0.0254, 0.03


def _engine_only(scene, monkeypatch: pytest.MonkeyPatch):
    """The run as the engine leaves it (no final check): the result, or the RunError's text."""
    monkeypatch.setattr(run_module, "check_invariant", lambda result: None)
    try:
        return run_scene(scene, record=False)
    except RunError as exc:
        return str(exc)


def _depths(run) -> tuple[np.ndarray, np.ndarray]:
    """Each pair's (i < j) distance between centres at the end and the deepest overlap a linear
    spring stores from the scene's energy, computed here from the definitions."""
    model, final = run.result.model, run.result.final
    energy = float(available_energy(model, run.result.initial)[0])
    n = model.n_bodies
    i, j = np.triu_indices(n, 1)
    dist = np.linalg.norm(final.s[0][j] - final.s[0][i], axis=-1)
    k = model.pair_table[0, model.material[0, i], model.material[0, j], 0]
    return dist, model.radius[0, i] + model.radius[0, j] - SLACK * np.sqrt(2 * energy / k)


def _assert_not_through(run) -> None:
    """Order kept in 1D; no pair deeper than its energy allows."""
    s0, s1 = run.result.initial.s[0], run.result.final.s[0]
    if run.result.model.dim == 1:
        order = np.argsort(s0[:, 0])
        assert np.all(np.diff(s1[order, 0]) > 0), f"order lost: {s1[order, 0]}"
    dist, floor = _depths(run)
    assert np.all(dist >= floor), f"overlap too deep: {np.min(dist - floor)}"


def _main(args: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
          cwd: Path) -> tuple[int, str, str]:
    from cli.main import main

    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", ["collide", *args])
    with warnings.catch_warnings(record=True), pytest.raises(SystemExit) as info:
        warnings.simplefilter("always")
        main()
    out, err = capsys.readouterr()
    return int(info.value.code or 0), out, err


# --- case 1: a dead band far wider than the speeds (demo-bonus, contact.eps = 1e9)

@pytest.mark.parametrize("eps", [1e3, 1e9])
def test_a_wide_dead_band_still_collides(eps: float, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = load_scene("demo-bonus", [f"contact.eps={eps}"])
    run = _engine_only(scene, monkeypatch)
    if isinstance(run, str):
        assert "pass" not in run  # refused for its own cause, not a pass-through caught late
        return
    assert int(run.result.contacts.count[0]) >= 1
    # Head-on along x (1 m/s against -2 m/s, equal masses): momentum kept, ball1 sent back.
    v = run.result.final.v[0]
    assert v[:, 0].sum() == pytest.approx(-1.0, abs=1e-9)
    assert v[0, 0] < 0 < v[1, 0]
    _assert_not_through(run)


def test_a_wide_dead_band_exits_zero_only_after_a_contact(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture) -> None:
    code, out, err = _main(["run", "demo-bonus", "--set", "contact.eps=1e9", "--no-record"], monkeypatch, capsys,
                           tmp_path)
    if code == 0:
        assert "contacts: none" not in out
    else:
        assert err.startswith("error: ") and err.count("\n") == 1


# --- case 2: one body far faster than a slow pair

def _fast_and_slow(ratio: float, dim: int) -> object:
    """A pair closing at 2 m/s head-on and a third body `ratio` m/s away from them."""
    def at(x: float) -> float | list:
        return x if dim == 1 else [x] + [0.0] * (dim - 1)
    fast = ratio
    k = 4.0 * MASS * (fast / (2 * RADIUS)) ** 2  # stiff enough for the fast body's energy
    bodies = [{"name": "a", "mass": MASS, "radius": RADIUS, "position": at(0.0), "velocity": at(1.0)},
              {"name": "b", "mass": MASS, "radius": RADIUS, "position": at(0.5), "velocity": at(-1.0)},
              {"name": "c", "mass": MASS, "radius": RADIUS, "position": at(-10.0), "velocity": at(-fast)}]
    return parse_scene({"name": "fast-and-slow", "dim": dim, "contact": {"k": k}, "body": bodies, "tol": 1e-6})


@pytest.mark.parametrize(("ratio", "dim"), [(1e10, 1), (1e10, 2), (1e7, 1), (1e12, 3)])
def test_a_slow_pair_beside_a_fast_body_collides(ratio: float, dim: int, monkeypatch: pytest.MonkeyPatch) -> None:
    run = _engine_only(_fast_and_slow(ratio, dim), monkeypatch)
    if isinstance(run, str):
        assert "pass" not in run
        return
    assert int(run.result.contacts.count[0]) >= 1
    v = run.result.final.v[0][:, 0]
    # A bounce, not a pass-through: the pair's momentum kept (equal and opposite forces), each sent
    # back. Equal masses, elastic, head-on: it exchanges velocities (closed form), to within what
    # --tol leaves of the fastest speed (1e-6 of it: vacuous beyond 1e9 m/s, measured 2e-5 at 1e10).
    assert v[0] + v[1] == pytest.approx(0.0, abs=1e-9)
    assert v[0] < 0 < v[1]
    if ratio <= 1e10:
        assert v[0] == pytest.approx(-1.0, abs=1e-3) and v[1] == pytest.approx(1.0, abs=1e-3)
    _assert_not_through(run)


# --- case 3: 1D chains of 5-12 spheres

def chain(seed: int, n: int, spread: float = 0.0):
    """n equal spheres in a row, 0.1-20 mm apart, about half at rest and the rest at velocities
    of 2 m/s scale (over `spread` decades more). A sphere at rest next to one that is hit is
    sent on within the same window of steps, faster than the window took it to move."""
    rng = np.random.default_rng(seed)
    bodies, x = [], 0.0
    for i in range(n):
        v = float(rng.normal() * 2) if rng.random() < 0.5 else 0.0
        bodies.append({"name": f"b{i}", "mass": MASS, "radius": RADIUS, "position": x,
                       "velocity": v * 10 ** -float(rng.uniform(0, spread))})
        x += 2 * RADIUS + float(rng.uniform(0.0001, 0.02))
    return parse_scene({"name": f"chain-{seed}", "dim": 1, "contact": {"k": 1e4}, "body": bodies})


@pytest.mark.parametrize("seed", [17, 18])
def test_nine_sphere_chains_that_swapped_keep_their_order(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # These two swapped a pair (b1-b2, b7-b8) and exited 0 before: the order is kept now.
    run = _engine_only(chain(seed, 9), monkeypatch)
    assert not isinstance(run, str), run
    _assert_not_through(run)
    assert not any("measured error" in w for w in run.result.warnings)


@pytest.mark.parametrize("seed", range(8))
def test_random_chains_keep_their_order(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    n = 5 + seed
    for spread in (0.0, 3.0):
        run = _engine_only(chain(100 + seed, n, spread), monkeypatch)
        if isinstance(run, str):
            assert "pass" not in run
            continue
        _assert_not_through(run)


# --- random 2D and 3D scenes

@pytest.mark.parametrize("index", range(6))
def test_random_small_scenes_never_end_inside_one_another(index: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(53)
    for skipped in range(index):
        random_scene(rng, skipped)
    run = _engine_only(random_scene(rng, index, k=1e5), monkeypatch)
    if isinstance(run, str):
        assert "pass" not in run
        return
    _assert_not_through(run)


# --- the final check itself

def test_the_final_check_refuses_a_swapped_order() -> None:
    run = run_scene(load_scene("newtons-cradle"), record=False)
    check_invariant(run.result)  # the real run keeps it
    s = run.result.final.s[0]
    s[[1, 2]] = s[[2, 1]]
    with pytest.raises(RunError, match="ball2 and body.ball3 ended the run passed through each other"):
        check_invariant(run.result)


def test_the_final_check_refuses_a_pass_through_in_free_flight() -> None:
    scene = load_scene("demo-bonus", ["body.ball1.position=[0, 0]", "contact.mu=0"])
    run = run_scene(scene, record=False)
    check_invariant(run.result)
    final = run.result.final
    # The same end as if the two had flown through each other from the start: both free since 0.
    final.s[0] = run.result.initial.s[0] + run.result.initial.v[0] * final.t[0]
    final.v[0] = run.result.initial.v[0]
    run.result.free_since[0] = 0.0
    with pytest.raises(RunError, match="passed through each other in free flight"):
        check_invariant(run.result)


def test_the_final_check_refuses_an_overlap_the_energy_cannot_make() -> None:
    run = run_scene(load_scene("demo-bonus"), record=False)
    run.result.contacts.max_overlap[0] = 0.05  # the real one is 6 mm; 1.1 J can press 11 mm at most
    with pytest.raises(RunError, match="overlap of 0.05 m"):
        check_invariant(run.result)


# --- the DEM kernel: a given step longer than a pair closes across

@pytest.mark.parametrize("offset", [0.0, 0.01, 0.02, 0.03])
def test_a_dem_step_a_pair_closes_across_is_refused(offset: float, monkeypatch: pytest.MonkeyPatch) -> None:
    # A soft pair (overlap bound 48 mm of 60) at a given step within Verlet's stability limit that
    # closes 66 mm a step: two of these four starts swapped order before.
    bodies = [{"name": "a", "mass": MASS, "radius": RADIUS, "position": 0.0, "velocity": 1.0},
              {"name": "b", "mass": MASS, "radius": RADIUS, "position": 0.1 + offset, "velocity": -1.0}]
    scene = parse_scene({"name": "dem-pair", "dim": 1, "integrator": "dem", "dt": 0.033, "contact": {"k": 44.0},
                         "body": bodies})
    run = _engine_only(scene, monkeypatch)
    assert isinstance(run, str) and "could pass through unseen" in run
    # At a step it can resolve, the order is kept.
    run = _engine_only(parse_scene({"name": "dem-pair", "dim": 1, "integrator": "dem", "dt": 0.002,
                                    "contact": {"k": 44.0}, "body": bodies}), monkeypatch)
    assert not isinstance(run, str), run
    _assert_not_through(run)


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_spheres_at_rest_touching_to_round_off_are_no_pass_through(dim: int) -> None:
    """Touching spheres placed in decimal overlap by a few ulps (2.8e-17 m here), with no energy
    to press them: that is the scene's own touching, not a pass-through (the viewer's round-off
    scene was refused)."""
    def place(x: float) -> list[float] | float:
        return x if dim == 1 else [x] + [0.0] * (dim - 1)

    raw = {"name": "touching", "dim": dim, "duration": 0.05, "contact": {"k": 1500.0},
           "body": [{"name": f"ball{n + 1}", "mass": 0.0254, "radius": 0.03021, "position": place(x)}
                    for n, x in enumerate([0.0, 0.1, 0.16041999999999998])]}
    result = run_scene(parse_scene(raw, "touching"))
    assert result.result.final.s[0, 2, 0] - result.result.final.s[0, 1, 0] < 2 * 0.03021  # they do overlap
    check_invariant(result.result)  # and that is no pass-through


@pytest.mark.parametrize("e", [0.95, 0.6, 0.2, 0.01])
def test_the_pass_through_bound_of_a_damped_contact_is_its_largest_overlap(e):
    """The event engine's pass-through check scales the undamped overlap v / omega by the
    spring-dashpot's peak (collide.stepper._damped_peak): it must be the largest overlap of the
    damped oscillator, integrated independently."""
    from scipy.integrate import solve_ivp

    from collide.model import damping_ratio
    from collide.stepper import _damped_peak

    zeta = float(damping_ratio(np.array(e), False))
    sol = solve_ivp(lambda t, y: [y[1], -y[0] - 2 * zeta * y[1]], [0.0, 4.0], [0.0, 1.0], rtol=1e-12, atol=1e-14,
                    events=lambda t, y: y[1], dense_output=True)
    peak = sol.sol(sol.t_events[0][0])[0]
    assert abs(float(_damped_peak(np.array([e]))[0]) - peak) <= 1e-9
