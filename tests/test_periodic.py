"""Periodic boundaries (docs/design.md section 10): a sphere leaving one side enters the other at
the position free flight gives, a periodic box conserves momentum to round-off and energy as the
closed box does, a collision across a side comes out as the same collision in the middle of the
box, in the event engine and in DEM; a chute (periodic in x, a floor) rolls as the closed form
says; bad input is refused in one line."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from collide.periodic import wrap
from collide.run import run_scene
from collide.scene import SceneError, parse_scene
from collide.summary import run_summary

REPO = Path(__file__).resolve().parents[1]
ENGINES = {"event": {}, "dem": {"integrator": "dem", "tol": 1e-4}}


def _scene(bodies: list[dict], *, dim: int = 2, size: float = 1.0, periodic: tuple[str, ...] = ("x", "y"),
           duration: float = 1.0, engine: str = "event", **more) -> dict:
    raw = {"name": "periodic", "dim": dim, "duration": duration, "body": bodies,
           "domain": {"lower": [0.0] * dim, "upper": [size] * dim, "periodic": list(periodic)}}
    raw.update({k: v for k, v in ENGINES[engine].items() if k != "tol"})
    raw.update(more)
    return raw


def _run(raw: dict, engine: str = "event") -> dict:
    tol = ENGINES[engine].get("tol")
    run = run_scene(parse_scene(copy.deepcopy(raw)), record=False, **({"tol": tol} if tol else {}))
    return run_summary(run)


def _ball(name: str, position: list[float], velocity: list[float], radius: float = 0.05, mass: float = 1.0) -> dict:
    return {"name": name, "radius": radius, "mass": mass, "position": position, "velocity": velocity}


@pytest.mark.parametrize("engine", ENGINES)
def test_a_free_sphere_leaves_one_side_and_enters_the_other(engine: str) -> None:
    """Two spheres moving together never meet: each ends where free flight puts it, wrapped into
    the box, with the periods it crossed counted."""
    v = [1.3, -0.7, 2.9]
    starts = [[0.5, 0.5, 0.5], [0.2, 0.8, 0.3]]
    raw = _scene([_ball(f"b{i}", s, v) for i, s in enumerate(starts)], dim=3, periodic=("x", "y", "z"),
                 duration=1.7, engine=engine)
    out = _run(raw, engine)
    for body, start in zip(out["bodies"], starts):
        exact = np.array(start) + 1.7 * np.array(v)
        placed, images = wrap(exact, np.zeros(3), np.ones(3))
        assert np.allclose(body["position"], placed, rtol=0, atol=1e-12)
        assert body["images"] == images.tolist()
        assert np.all(np.array(body["position"]) >= 0.0) and np.all(np.array(body["position"]) < 1.0)
    assert out["bodies"][0]["images"] == [2, -1, 5]  # crossed: 0.5 + 1.7 (1.3, -0.7, 2.9)


@pytest.mark.parametrize("engine", ENGINES)
def test_only_the_periodic_axes_wrap(engine: str) -> None:
    """Periodic in x only: y runs on past the box (nothing holds it there), x wraps."""
    raw = _scene([_ball("a", [0.9, 0.5], [1.0, 0.25]), _ball("b", [0.3, 0.5], [1.0, 0.25])], periodic=("x",),
                 duration=1.0, engine=engine)
    out = _run(raw, engine)
    assert np.allclose(out["bodies"][0]["position"], [0.9, 0.75], atol=1e-12)
    assert out["bodies"][0]["images"] == [1, 0]
    assert np.allclose(out["bodies"][1]["position"], [0.3, 0.75], atol=1e-12)


def _gas(engine: str, periodic: bool) -> dict:
    """Nine spheres on a lattice with random velocities, in a periodic box or the same box closed
    by four walls."""
    rng = np.random.default_rng(7)
    bodies = [_ball(f"b{3 * i + j}", [0.2 + 0.3 * i, 0.2 + 0.3 * j], rng.uniform(-1.0, 1.0, 2).tolist(),
                    radius=0.08, mass=float(rng.uniform(0.5, 2.0))) for i in range(3) for j in range(3)]
    more = {"contact": {"k": 1e4}}
    if engine == "dem":
        more["contact"]["restitution"] = 0.7
    if periodic:
        return _scene(bodies, duration=2.0, engine=engine, **more)
    walls = [{"point": [0.0, 0.0], "normal": [1.0, 0.0]}, {"point": [1.0, 0.0], "normal": [-1.0, 0.0]},
             {"point": [0.0, 0.0], "normal": [0.0, 1.0]}, {"point": [0.0, 1.0], "normal": [0.0, -1.0]}]
    raw = _scene(bodies, duration=2.0, engine=engine, wall=walls, **more)
    del raw["domain"]
    return raw


@pytest.mark.parametrize("engine", ENGINES)
def test_a_periodic_box_conserves_momentum_and_energy_as_the_closed_box(engine: str) -> None:
    periodic, closed = _run(_gas(engine, True), engine), _run(_gas(engine, False), engine)
    assert periodic["contact"]["count"] >= 5 and closed["contact"]["count"] >= 5
    assert any(any(b["images"]) for b in periodic["bodies"])  # bodies went across the sides
    # Round-off, summed over the steps (the closed box's walls take momentum: it has none to keep).
    assert periodic["residuals"]["momentum"] < 1e-13
    bound = 10.0 * (ENGINES[engine].get("tol") or 1e-6)  # the run's tolerance, for both boxes
    assert periodic["residuals"]["energy"] < bound and closed["residuals"]["energy"] < bound
    assert not any("energy balance" in w for w in periodic["warnings"] + closed["warnings"])


def _oblique(shift: float, engine: str) -> dict:
    """Two spheres meeting obliquely, the whole scene moved along x by `shift` (wrapped)."""
    a, b = np.array([0.3, 0.45]), np.array([0.7, 0.5])
    bodies = [_ball("a", wrap(a + [shift, 0.0], np.zeros(2), np.ones(2))[0].tolist(), [1.0, 0.1], mass=1.0),
              _ball("b", wrap(b + [shift, 0.0], np.zeros(2), np.ones(2))[0].tolist(), [-0.5, 0.0], mass=2.0,
                    radius=0.07)]
    more = {"contact": {"k": 1e4, "mu": 0.3, **({"restitution": 0.6} if engine == "dem" else {})}}
    return _run(_scene(bodies, duration=0.6, engine=engine, **more), engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_collision_across_a_side_is_the_collision_in_the_middle(engine: str) -> None:
    """Moved by half the box, the contact happens across x = 0: the outcome is the same (the
    positions the same once moved back), to the tolerance's rounding."""
    middle, across = _oblique(0.0, engine), _oblique(0.5, engine)
    assert middle["contact"]["count"] == across["contact"]["count"] == 1
    for m, c in zip(middle["bodies"], across["bodies"]):
        assert np.allclose(m["velocity"], c["velocity"], rtol=0, atol=1e-9)
        assert np.allclose(m["spin"], c["spin"], rtol=0, atol=1e-8)
        back = wrap(np.array(c["position"]) - [0.5, 0.0], np.zeros(2), np.ones(2))[0]
        assert np.allclose(m["position"], back, rtol=0, atol=1e-9)
    assert middle["contact"]["first_start"] == pytest.approx(across["contact"]["first_start"], abs=1e-9)


def test_a_chute_periodic_in_x_with_a_floor_rolls_as_the_closed_form() -> None:
    """A ball resting on an inclined chute's floor (gravity tilted, the floor y = 0, periodic in
    x) rolls without slipping (mu above 2/7 tan theta): x = x0 + (5/14) g sin(theta) t^2,
    wrapped, while it goes round the chute several times (the spring stiff enough that the
    lever's shortening by the overlap, 1e-8 of the radius, is below the check)."""
    g, theta, r, t = 9.81, 0.3, 0.05, 1.5
    raw = _scene([{"name": "ball", "radius": r, "mass": 1.0, "position": [0.2, r], "velocity": [0.0, 0.0]}],
                 periodic=("x",), size=0.5, duration=t, gravity=[g * np.sin(theta), -g * np.cos(theta)],
                 wall=[{"point": [0.0, 0.0], "normal": [0.0, 1.0]}], contact={"k": 1e9, "mu": 0.5})
    out = _run(raw)
    x = 0.2 + 5.0 / 14.0 * g * np.sin(theta) * t * t
    placed, images = wrap(np.array([x]), np.zeros(1), np.array([0.5]))
    assert out["bodies"][0]["images"][0] == images[0] >= 4
    # The run's tolerance (1e-6 of the speeds) held over the run: v t 1e-6, ten times over.
    assert out["bodies"][0]["position"][0] == pytest.approx(placed[0], abs=10 * 1e-6 * (x - 0.2) * 2)
    assert out["bodies"][0]["position"][1] == pytest.approx(r, abs=1e-4)


def _cli(tmp_path: Path, raw_toml: str) -> subprocess.CompletedProcess:
    path = tmp_path / "scene.toml"
    path.write_text(raw_toml)
    return subprocess.run([sys.executable, "-m", "cli.main", "run", str(path), "--no-record"],
                          capture_output=True, text=True, cwd=REPO, timeout=120)


BALLS = """
[[body]]
name = "a"
radius = 0.1
mass = 1.0
position = [0.3, 0.5]
[[body]]
name = "b"
radius = 0.1
mass = 1.0
position = [0.6, 0.5]
velocity = [-1.0, 0.0]
"""


@pytest.mark.parametrize(("domain", "words"), [
    ('lower = [0.0, 0.0]\nupper = [0.4, 1.0]\nperiodic = ["x"]', "too short for the nearest image"),
    ('upper = [1.0, 1.0]\nperiodic = ["x"]', "domain.lower: missing"),
    ('lower = [0.0, 0.0]\nupper = [1.0, 1.0]\nperiodic = ["z"]', "domain.periodic"),
])
def test_bad_periodic_input_is_one_line_and_exit_2(tmp_path: Path, domain: str, words: str) -> None:
    done = _cli(tmp_path, f'name = "bad"\ndim = 2\nduration = 1.0\n[domain]\n{domain}\n{BALLS}')
    assert done.returncode == 2, done.stderr
    lines = [line for line in (done.stderr + done.stdout).splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0], lines
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(("change", "words"), [
    ({"wall": [{"point": [0.0, 0.0], "normal": [1.0, 0.0]}]}, "wall[0].normal"),
    ({"integrator": "seed", "dt": 1e-4}, "integrator 'seed'"),
    ({"duration": None}, "needs a duration"),
])
def test_what_a_periodic_box_cannot_answer_is_refused(change: dict, words: str) -> None:
    raw = _scene([_ball("a", [0.3, 0.5], [1.0, 0.0]), _ball("b", [0.7, 0.5], [0.0, 0.0])], periodic=("x",))
    raw["body"][0]["position"] = [0.6, 0.5] if "wall" in change else [0.3, 0.5]
    for key, value in change.items():
        if value is None:
            raw.pop(key)
        else:
            raw[key] = value
    with pytest.raises(SceneError, match=words.replace("[", r"\[").replace("]", r"\]")):
        parse_scene(raw)


def test_spheres_overlapping_across_a_side_at_the_start_are_refused() -> None:
    raw = _scene([_ball("a", [0.02, 0.5], [0.0, 0.0]), _ball("b", [0.97, 0.5], [0.0, 0.0])], periodic=("x",))
    with pytest.raises(SceneError, match="overlaps body.b across a periodic side"):
        parse_scene(raw)
    raw["domain"]["periodic"] = []
    parse_scene(raw)  # not periodic: they are far apart


def test_the_saved_state_is_wrapped_into_the_box(tmp_path: Path) -> None:
    raw_toml = f'name = "s"\ndim = 2\nduration = 2.0\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n' \
               f'periodic = ["x", "y"]\n{BALLS}'.replace("velocity = [-1.0, 0.0]", "velocity = [-1.0, 0.35]")
    path = tmp_path / "scene.toml"
    path.write_text(raw_toml)
    state = tmp_path / "state.csv"
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", str(path), "--no-record", "--json",
                           "--save-state", str(state)], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    rows = state.read_text().splitlines()[1:]
    for body, row in zip(out["bodies"], rows):
        x, y = (float(v) for v in row.split(",")[4:6])
        assert [x, y] == body["position"] and 0.0 <= x < 1.0 and 0.0 <= y < 1.0


def test_the_viewer_draws_bodies_in_the_box_and_a_copy_across_each_side_crossed(tmp_path: Path) -> None:
    """Read back from its recording, a periodic run's frames hold the bodies wrapped into the box
    (the recording keeps the unwrapped trajectory: the same run exactly) and their contacts with
    them; a sphere across a side is drawn a second time on the other side (at a corner, four
    times in all), and the drawing takes them all."""
    import viser

    from collide.recording import read_recording, write_recording
    from viewer.scene3d import SceneDrawer
    from viewer.state import ViewRun

    raw = _scene([_ball("a", [0.15, 0.5], [-1.0, 0.0], radius=0.1), _ball("b", [0.7, 0.52], [0.0, 0.0], radius=0.1),
                  _ball("c", [0.5, 0.93], [0.3, 0.0], radius=0.1)], periodic=("x", "y"), duration=0.5)
    run = run_scene(parse_scene(raw))
    view = ViewRun(read_recording(write_recording(run, tmp_path / "periodic.rrd")))
    assert np.array_equal(view.result.final.s, run.result.final.s)
    t = 0.2  # a is across x = 0, c across y = 1
    frame = view.frame(t)
    exact = np.array([0.15 - t, 0.5])
    assert np.allclose(frame.positions[0, :2], exact + [1.0, 0.0], atol=1e-12)  # wrapped
    body, centre = view.images(frame.positions)
    assert body.tolist() == [0, 2] and np.allclose(centre[0, :2], exact, atol=1e-12)
    assert np.allclose(centre[1, :2], frame.positions[2, :2] - [0.0, 1.0])
    touching = view.frame(0.3)  # a, come round through x = 0, meets b (its contact: 0.251 to 0.345 s)
    assert len(touching.contacts) == 1 and touching.contacts[0].normal[0] < -0.99  # from a to b: -x
    assert np.linalg.norm(touching.contacts[0].point - touching.positions[0]) < 0.1  # at a, not across the box
    corner = view.images(np.array([[0.05, 0.95, 0.0], [0.5, 0.5, 0.0], [0.5, 0.5, 0.0]]))
    assert corner[0].tolist() == [0, 0, 0]
    assert {tuple(np.round(p[:2], 12)) for p in corner[1]} == {(1.05, 0.95), (0.05, -0.05), (1.05, -0.05)}
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(view)
        for time in np.linspace(view.t0, view.t1, 7):
            drawer.show_frame(view.frame(time))
    finally:
        server.stop()


def test_the_seed_integrator_asked_on_the_command_line_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(f'name = "s"\ndim = 2\nduration = 0.1\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n'
                    f'periodic = ["x"]\n{BALLS}')
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", str(path), "--no-record", "--integrator", "seed",
                           "--dt", "1e-4"], capture_output=True, text=True, cwd=REPO, timeout=120)
    lines = [line for line in (done.stderr + done.stdout).splitlines() if line.strip()]
    assert done.returncode == 2 and len(lines) == 1 and "integrator 'seed'" in lines[0], lines
