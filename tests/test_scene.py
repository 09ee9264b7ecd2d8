"""Scene files: every bad input gets one clear message naming the key (docs/design.md section 3)."""

from __future__ import annotations

import tomllib

import pytest

from collide.run import run_scene
from collide.scene import SceneError, builtin_names, builtin_text, load_scene, parse_scene, read_raw
from collide.stepper import RunError


@pytest.mark.parametrize("override, key", [
    ("foo=1", "foo"),
    ("contact.kk=3", "kk"),
    ("body.ball1.colour=1", "colour"),
    ("body.ball1.mass=0", "body.ball1.mass"),
    ("body.ball1.mass=-1", "body.ball1.mass"),
    ("body.ball1.radius=0", "body.ball1.radius"),
    ("contact.k=0", "contact.k"),
    ("contact.mu=-0.1", "contact.mu"),
    ("dt=0", "dt"),
    ("dt=-1e-5", "dt"),
    ("contact.k=nan", "contact.k"),
    ("body.ball1.velocity=[inf, 0]", "body.ball1.velocity"),
    ("body.ball1.velocity=[1, 0, 0]", "body.ball1.velocity"),
    ("body.ball1.position=[0.45, 0.01]", "body.ball1.position"),
    ("dim=4", "dim"),
    ("integrator=rk99", "integrator"),
    ("body.ball9.mass=1", "ball9"),
    ("body.ball1.spin=[1, 2]", "body.ball1.spin"),
    ("body.ball1.mass=heavy", "body.ball1.mass"),
])
def test_bad_input_names_the_key(override, key):
    with pytest.raises(SceneError) as err:
        load_scene("demo-bonus", [override])
    message = str(err.value)
    assert key in message
    assert "\n" not in message


def test_unstable_dt_is_refused_with_the_safe_step():
    with pytest.raises(RunError, match="largest safe step"):
        run_scene(load_scene("demo-bonus", ["dt=0.05"]))


def test_too_soft_spring_is_refused():
    with pytest.raises(RunError, match="too soft"):
        run_scene(load_scene("demo-1d", ["contact.k=0.1"]))


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("dim = = 2")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(bad)
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "missing.toml")
    with pytest.raises(SceneError, match="unknown scene"):
        load_scene("no-such-scene")


def test_overrides_set_vectors_and_components():
    scene = load_scene("demo-bonus", ["body.ball1.velocity=[1.5, 0.25]", "body.ball2.velocity.y=0.5",
                                      "contact.mu=0.3", "dt=auto", "integrator=seed"])
    assert scene.bodies[0].velocity == (1.5, 0.25)
    assert scene.bodies[1].velocity == (-2.0, 0.5)
    assert scene.contact.mu == 0.3 and scene.dt == "auto" and scene.integrator == "seed"


@pytest.mark.parametrize("name", builtin_names(heavy=False))
def test_builtins_round_trip_through_toml(name, tmp_path):
    scene = load_scene(name)
    path = tmp_path / f"{name}.toml"
    path.write_text(scene.to_toml())
    again = load_scene(path)
    assert again == scene
    assert tomllib.loads(builtin_text(name))["name"] == name


def test_report_set_ups_of_the_demos():
    """docs/design.md section 8: the demos' physical set-ups that reproduce the report's figures."""
    expect = {"demo-1d": (1000, 0.0), "demo-2d-stationary": (1000, 0.0), "demo-2d-moving": (1000, 0.0),
              "demo-bonus": (1500, 0.5)}
    for name, (k, mu) in expect.items():
        scene = load_scene(name)
        assert (scene.contact.k, scene.contact.mu, scene.contact.eps) == (k, mu, 1e-6)
        assert scene.contact.lever == "seed"
        for body in scene.bodies:
            assert body.mass == 0.0254 and body.radius == 0.03021
            assert body.inertia == pytest.approx(0.4 * 0.0254 * 0.03021**2)


def test_missing_body_fields():
    raw, _ = read_raw("demo-1d")
    del raw["body"][0]["mass"]
    with pytest.raises(SceneError, match="body.ball1.mass: missing"):
        parse_scene(raw)
