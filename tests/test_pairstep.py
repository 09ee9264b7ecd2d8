"""The plain-float step for one run of two spheres (`collide.pairstep`) against the numpy kernels
it mirrors: the same step to round-off in every friction mode, and the same runs."""

from __future__ import annotations

import numpy as np
import pytest

from collide import friction as fr
from collide import integrators
from collide import physics as ph
from collide.accuracy import outcome, speed_scale
from collide.integrators import INTEGRATORS, geometry
from collide.model import compile_scenes
from collide.run import run_scene
from collide.scene import builtin_names, load_scene, parse_scene


def both_paths(monkeypatch, run):
    """`run()` through the numpy kernels, then through `pairstep`."""
    monkeypatch.setattr(integrators, "SCALAR_PAIRS", False)
    numpy_result = run()
    monkeypatch.setattr(integrators, "SCALAR_PAIRS", True)
    return numpy_result, run()


def pressed(lever: str, gravity: bool, mode: int):
    """Two spinning spheres of different size and mass pressed together, in a given mode."""
    raw = {"dim": 2, "contact": {"k": 1500.0, "mu": 0.4, "lever": lever},
           "body": [{"name": "a", "mass": 0.03, "radius": 0.03, "position": [0.0, 0.5],
                     "velocity": [1.0, 0.3], "spin": 3.0},
                    {"name": "b", "mass": 0.02, "radius": 0.025, "position": [0.5, 0.5],
                     "velocity": [-1.0, 0.5], "spin": -5.0}]}
    if gravity:
        raw["gravity"] = [0.0, -9.81]
    model, state = compile_scenes([parse_scene(raw)])
    state.s[0] = [[0.0, 0.031], [0.04, 0.0]]  # overlapping by 4.4 mm
    c = ph.contact_geometry(model, state.s)
    engaged = ph.Engaged((c.overlap > 0).astype(float), c.wall_overlap)
    g = geometry(model, state.s, engaged)
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    frame, _ = fr.decide_modes(model, fr.contact_rows(model, g.c, g.fn, g.fw), state, acc, engaged,
                               np.array([2.0]))
    g.modes = fr.Modes(np.full((1, 1), mode, np.int8), frame.modes.side, frame.modes.entry)
    return model, state, g


@pytest.mark.parametrize("mode", [fr.BAND, fr.SLIDE, fr.STICK])
@pytest.mark.parametrize("lever", ["seed", "contact"])
@pytest.mark.parametrize("gravity", [False, True])
@pytest.mark.parametrize("integrator", ["verlet", "kahan6"])
def test_one_step_matches_the_numpy_kernels(monkeypatch, mode, lever, gravity, integrator):
    model, state, g = pressed(lever, gravity, mode)
    h = np.array([2e-4])
    (a, fa, _), (b, fb, end) = both_paths(monkeypatch, lambda: INTEGRATORS[integrator].step(model, state, h, g))
    for x, y in ((a.s, b.s), (a.v, b.v), (a.w, b.w), (a.q, b.q), (a.t, b.t)):
        assert np.abs(x - y).max() <= 1e-14 * max(1.0, np.abs(x).max())
    assert a.work == pytest.approx(b.work, rel=1e-12, abs=1e-18)
    assert fa.pair == pytest.approx(fb.pair, rel=1e-12, abs=1e-12)
    if mode != fr.BAND:
        assert a.work[0] > 0  # friction did work, so the comparison covered it
    # The event values and rates the plain-float step hands the stepper are frame_events'.
    acc = ph.normal_accel(model, end.c, end.fn, end.fw)
    frame = fr.geometry_frame(model, end.c, end.fn, end.fw, end.modes)
    values, rates = fr.frame_events(model, frame, b, acc, np.ones(1), rates=True)
    assert end.speeds[0] == pytest.approx(values, rel=1e-10, abs=1e-13)
    if mode == fr.STICK:
        # numpy leaves a stuck contact's rates unknown; the plain-float step differentiates
        # along the motion: compare with the event values a short step either way.
        assert np.isnan(rates).all()
        assert end.speeds[1] == pytest.approx(stick_rates_along_motion(model, b, end), rel=1e-5)
        # Given the contact phase, numpy's path differentiates along the motion the same way.
        differenced = fr.frame_events(model, frame, b, acc, np.ones(1), rates=True, engaged=end.engaged)[1]
        assert differenced == pytest.approx(end.speeds[1], rel=1e-6)
    else:
        assert end.speeds[1] == pytest.approx(rates, rel=1e-10, abs=1e-12)


def stick_rates_along_motion(model, state, g) -> np.ndarray:
    """The stuck contact's event values' rates by a central difference over two short numpy
    steps (+-1e-7 s, verlet: the values move by 1e-7 of themselves, the steps' error is 1e-14)."""
    ends = []
    saved, integrators.SCALAR_PAIRS = integrators.SCALAR_PAIRS, False
    try:
        for h in (1e-7, -1e-7):
            new, _, end = INTEGRATORS["verlet"].step(model, state, np.array([h]), g)
            acc = ph.normal_accel(model, end.c, end.fn, end.fw)
            frame = fr.geometry_frame(model, end.c, end.fn, end.fw, g.modes)
            ends.append(fr.frame_events(model, frame, new, acc, np.ones(1)))
    finally:
        integrators.SCALAR_PAIRS = saved
    return (ends[0] - ends[1]) / 2e-7


def random_scene(rng: np.random.Generator) -> dict:
    """A glancing 2D collision with random masses, sizes, speeds, spins and friction."""
    r1, r2 = rng.uniform(0.01, 0.05, 2)
    return {"dim": 2, "contact": {"k": float(rng.choice([500.0, 1500.0, 1e5])), "mu": float(rng.uniform(0, 1)),
                                  "lever": str(rng.choice(["seed", "contact"]))},
            "body": [{"name": "a", "mass": float(rng.uniform(0.01, 0.1)), "radius": float(r1),
                      "position": [0.0, float(rng.uniform(-0.9, 0.9) * (r1 + r2))],
                      "velocity": [float(rng.uniform(0.5, 3.0)), 0.0], "spin": float(rng.uniform(-20, 20))},
                     {"name": "b", "mass": float(rng.uniform(0.01, 0.1)), "radius": float(r2),
                      "position": [0.3, 0.0], "velocity": [float(rng.uniform(-2, 0)), 0.0],
                      "spin": float(rng.uniform(-20, 20))}]}


@pytest.mark.parametrize("name", [*builtin_names(), "random-0", "random-1", "random-2", "random-3"])
def test_runs_match_the_numpy_kernels(monkeypatch, name):
    """Whole runs agree to round-off. A mode change or contact end may land a hair earlier on one
    path (within the event tolerance) and take one more short step."""
    if name.startswith("random"):
        scene = parse_scene(random_scene(np.random.default_rng(int(name[-1]))))
    else:
        scene = load_scene(name)
    a, b = both_paths(monkeypatch, lambda: run_scene(scene, record=False).result)
    assert np.abs(outcome(a) - outcome(b)).max() <= 1e-12 * speed_scale(scene)
    assert np.abs(a.final.s - b.final.s).max() <= 1e-12 * max(1.0, np.abs(a.final.s).max())
    assert a.final.work == pytest.approx(b.final.work, rel=1e-9, abs=1e-15)
    assert abs(int(a.steps[0]) - int(b.steps[0])) <= 1


@pytest.mark.parametrize("lever", ["seed", "contact"])
@pytest.mark.parametrize("gravity", [False, True])
def test_decide_matches_the_numpy_kernels(lever, gravity):
    """The plain-float mode decision equals friction.decide_modes, on the band's edge (where the
    hold force decides) and off it, with its event values and rates."""
    from collide import pairstep

    model, state, g = pressed(lever, gravity, fr.STICK)
    rows = fr.contact_rows(model, g.c, g.fn, g.fw)
    acc = ph.normal_accel(model, g.c, g.fn, g.fw)
    scale = np.array([2.0])
    vel = np.concatenate((state.v.reshape(1, -1), state.w.reshape(1, -1)), axis=1)
    slip = fr.slip(model, rows, vel)[0, 0, 0]
    for target in (slip, 1e-6, -1e-6, 0.5e-6):  # off the edge, on either edge, inside the band
        moved = state.copy()
        moved.w[0, 0, 0] += (target - slip) / float(rows.slip_rows[0, 0, 4])  # the first body's spin
        frame, events = fr.decide_modes(model, rows, moved, acc, g.engaged, scale)
        modes, (values, rates) = pairstep.decide(model, moved, True, 2.0)
        assert modes.mode[0, 0] == frame.modes.mode[0, 0] and modes.side[0, 0] == frame.modes.side[0, 0]
        assert values / 2.0 == pytest.approx(events, rel=1e-9, abs=1e-12)
        numpy_values, numpy_rates = fr.frame_events(model, frame, moved, acc, scale, rates=True)
        if modes.mode[0, 0] == fr.STICK:
            assert np.isnan(numpy_rates).all()
            g.modes = modes
            assert rates == pytest.approx(stick_rates_along_motion(model, moved, g), rel=1e-5)
        else:
            assert rates / 2.0 == pytest.approx(numpy_rates, rel=1e-9, abs=1e-9)
