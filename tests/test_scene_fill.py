"""Scenes of many bodies (docs/design.md section 10): the linear set-up gives the verdicts the
pairwise checks gave, `[[fill]]` places what it is asked without overlap, `[bodies] file` and
`--save-state` carry a state from one run to the next. Speed is measured in
benchmarks/bench_scene_load.py, not here."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from collide.scene import SceneError, load_scene, parse_scene
from collide.scene_bodies import parse_body
from collide.scene_toml import QUICK_MIN_BODIES, loads_scene

REPO = Path(__file__).resolve().parents[1]


def _old_overlap_verdict(raw: dict) -> str | None:
    """The pairwise start-overlap check the parser had before the cell grid (the reference), on
    a raw scene's bodies and walls (normals normalised as the parser does)."""
    bodies = [(b["name"], tuple(map(float, b["position"])), float(b["radius"])) for b in raw["body"]]
    walls = []
    for w in raw.get("wall", []):
        norm = math.sqrt(sum(c * c for c in w["normal"]))
        walls.append((tuple(map(float, w["point"])), tuple(c / norm for c in w["normal"])))
    for i, (name, pos, radius) in enumerate(bodies):
        for other, pos_b, radius_b in bodies[i + 1:]:
            gap = math.dist(pos, pos_b) - radius - radius_b
            if gap < -1e-12 * (radius + radius_b):
                return f"body.{name}.position: overlaps body.{other} at the start by {-gap:.3g} m"
        for index, (point, normal) in enumerate(walls):
            height = sum((p - q) * n for p, q, n in zip(pos, point, normal))
            if height < radius * (1 - 1e-12):
                return (f"body.{name}.position: overlaps wall[{index}] at the start "
                        f"(distance {height:.3g} m < radius {radius:.3g} m)")
    return None


def _random_raw(rng: np.random.Generator, dim: int, n: int) -> dict:
    """Spheres of radii spread over three decades, some touching exactly, some overlapping, a wall."""
    bodies = []
    for i in range(n):
        r = float(10 ** rng.uniform(-3, 0))
        bodies.append({"name": f"b{i}", "mass": 1.0, "radius": r, "position": rng.uniform(-3, 3, dim).tolist()})
    if n > 2:  # a pair touching to the last decimal, the case TOUCHING is for
        a, b = bodies[0], bodies[1]
        direction = np.eye(dim)[0]
        b["position"] = (np.array(a["position"]) + (a["radius"] + b["radius"]) * direction).tolist()
    normal = [0.0] * dim
    normal[-1] = 1.0
    return {"dim": dim, "body": bodies, "wall": [{"point": [0.0] * (dim - 1) + [-3.5], "normal": normal}]}


def _verdict(raw: dict) -> str | None:
    try:
        parse_scene(raw)
    except SceneError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_start_overlaps_are_judged_as_the_pairwise_check_judged(dim):
    rng = np.random.default_rng(dim)
    refused = 0
    for _ in range(60):
        raw = _random_raw(rng, dim, int(rng.integers(2, 40)))
        expected = _old_overlap_verdict(raw)
        assert _verdict(raw) == expected
        refused += expected is not None
    assert 0 < refused < 60  # both verdicts were exercised


def test_a_large_lattice_with_one_overlap_names_that_pair():
    side = 30
    idx = np.arange(side**3)
    pos = np.stack([idx % side, idx // side % side, idx // side**2], axis=1) * 2.0
    bodies = [{"name": f"s{i}", "mass": 1.0, "radius": 1.0, "position": p} for i, p in enumerate(pos.tolist())]
    assert parse_scene({"dim": 3, "body": bodies}).bodies[-1].name == f"s{side**3 - 1}"  # touching: fine
    bodies[20000]["position"] = [pos[123][0] + 0.5, pos[123][1], pos[123][2]]
    with pytest.raises(SceneError, match=r"body\.s123\.position: overlaps body\.s20000 at the start by 1\.5 m$"):
        parse_scene({"dim": 3, "body": bodies})


def test_the_first_name_used_twice_is_named():
    bodies = [{"name": n, "mass": 1.0, "radius": 0.1, "position": [float(i), 0.0]}
              for i, n in enumerate(["a", "b", "c", "b", "a"])]
    with pytest.raises(SceneError, match=r"^body\.a: the name is used twice$"):
        parse_scene({"body": bodies})


BODY_VALUES = [
    {"name": "x", "mass": 2, "radius": 1, "position": [1, 2], "velocity": [0.5, -1e-3], "spin": 3},
    {"radius": 0.5, "material": "steel", "position": [0.0, 9.0], "spin": [1.0]},
    {"name": "y", "mass": 1.0, "radius": 0.1, "inertia": "shell", "position": [5.0, 5.0]},
    {"name": "z", "mass": 1.0, "radius": 0.1, "inertia": 0.25, "position": [7.0, 5.0]},
]
BAD_BODIES = [
    ({"name": "q", "mass": True, "radius": 0.1, "position": [0.0, 0.0]}, "body.q.mass: expected a number"),
    ({"name": "q", "mass": 1.0, "radius": "0.1", "position": [0.0, 0.0]}, "body.q.radius: expected a number"),
    ({"name": "q", "mass": 1.0, "radius": 0.1, "position": [0.0]}, "body.q.position: expected 2 component(s)"),
    ({"name": "q", "mass": 1.0, "radius": 0.1, "position": [0.0, math.inf]}, "body.q.position[1]: must be finite"),
    ({"name": "", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0]}, "body[2].name: expected a name"),
    ({"name": "q", "radius": 0.1, "position": [0.0, 0.0]}, "body.q.mass: missing"),
    ({"name": "q", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0], "material": "wood"},
     "body.q.material: unknown 'wood'"),
    ({"name": "q", "mass": 1.0, "radius": 1e-31, "position": [0.0, 0.0]}, "body.q.radius: too small"),
    ({"name": "q", "mass": 10**400, "radius": 0.1, "position": [0.0, 0.0]}, "body.q.mass: out of range"),
]


def test_bodies_read_in_bulk_equal_bodies_read_one_by_one():
    materials = {"steel": type("M", (), {"density": 7800.0})()}
    tables = BODY_VALUES * 20
    tables = [dict(t, name=f"n{i}", position=[20.0 * i, 0.0]) for i, t in enumerate(tables)]
    raw = {"material": [{"name": "steel", "density": 7800.0}], "body": tables}
    assert list(parse_scene(raw).bodies) == [parse_body(t, i, 2, materials) for i, t in enumerate(tables)]


@pytest.mark.parametrize("bad,message", BAD_BODIES)
def test_a_bad_body_among_many_is_named(bad, message):
    good = [{"name": f"g{i}", "mass": 1.0, "radius": 0.1, "position": [float(i), 5.0]} for i in range(200)]
    with pytest.raises(SceneError, match=f"^{message}".replace(".", r"\.").replace("[", r"\[").replace("(", r"\(")
                       .replace(")", r"\)")):
        parse_scene({"body": good[:2] + [bad] + good[2:]})


def _many(lines: list[str], n: int = QUICK_MIN_BODIES + 6) -> str:
    head = 'name = "t"\ndim = 3\n[contact]\nk = 1e4 # stiff\n'
    return head + "".join("[[body]]\n" + "\n".join(lines).replace("@", str(i)) + "\n" for i in range(n)) + \
        "[[wall]]\npoint = [0, 0, -1]\nnormal = [0, 0, 1]\n"


QUICK_CASES = [
    ['name = "b@"', "mass = 1", "radius = 0.5e-1", "position = [@, 0.0, -1.5E+2]"],
    ["  name = 'b@'  # a comment", "", "# only a comment", "radius = +0.1", "position = [ 1 , 2 , 3 , ]"],
    ['name = "b@"', "velocity = []", "spin = true", "mass = -0", "position = [1e5,2,3]"],
    ['name = "b@"', "radius = 01.5"],  # invalid TOML: tomllib's error
    ['name = "b@"', "radius = 1_000.0"],  # underscores: tomllib reads them
    ['name = "b@"', "radius = inf", "mass = nan"],
    ['name = "b@"', "position = [1, 2,", "  3]"],  # a multi-line array
    ['name = "b@"', "radius = 1", "radius = 2"],  # a key twice: tomllib's error
    ['name = "b@"', "radius = [,]"],
    ['name = "b@"', 'label = """x', '[[body]]', 'y"""'],
    ['name = "b@"', "material.x = 1"],
    ['"name" = "b@"', "radius = 1"],
]


@pytest.mark.parametrize("lines", QUICK_CASES, ids=range(len(QUICK_CASES)))
def test_the_quick_toml_path_reads_what_tomllib_reads(lines):
    text = _many(lines)
    try:
        expected = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        with pytest.raises(tomllib.TOMLDecodeError, match=re_escape(str(exc))):
            loads_scene(text)
        return
    # as JSON text: NaN equals itself, 1 differs from 1.0, the order of keys does not matter
    assert json.dumps(loads_scene(text), sort_keys=True) == json.dumps(expected, sort_keys=True)


def test_plain_body_tables_take_the_quick_path():
    from collide.scene_toml import _quick

    for lines in QUICK_CASES[:3]:
        assert _quick(_many(lines)) is not None
    assert _quick(_many(QUICK_CASES[0], QUICK_MIN_BODIES - 1)) is None  # a few bodies: tomllib


def re_escape(text: str) -> str:
    import re

    return re.escape(text)


# ---------------------------------------------------------------------------------------------
# Fills


def _fill(dim: int = 3, **keys) -> dict:
    table = {"name": "g", "lower": [0.0] * dim, "upper": [1.0] * dim, "count": 300, "radius": 0.03,
             "mass_density": 2500.0, "seed": 7}
    table.update(keys)
    return {"dim": dim, "fill": [table]}


def _no_overlap(scene) -> None:
    p = np.array([b.position for b in scene.bodies])
    r = np.array([b.radius for b in scene.bodies])
    d = np.sqrt(((p[:, None] - p[None]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    assert (d >= (r[:, None] + r[None]) * (1 - 1e-12)).all()


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("arrangement", ["random", "lattice"])
def test_a_box_fill_places_its_count_inside_without_overlap(dim, arrangement):
    count = {1: 8, 2: 150, 3: 300}[dim]
    scene = parse_scene(_fill(dim, count=count, arrangement=arrangement, velocity=[0.5] * dim))
    assert [b.name for b in scene.bodies] == [f"g{i}" for i in range(count)]
    p = np.array([b.position for b in scene.bodies])
    assert (p >= 0.03).all() and (p <= 1 - 0.03).all()
    _no_overlap(scene)
    b = scene.bodies[0]
    assert b.mass == pytest.approx(4 / 3 * math.pi * 0.03**3 * 2500.0, rel=1e-15)
    assert b.inertia == pytest.approx(0.4 * b.mass * 0.03**2, rel=1e-15)
    assert b.velocity == (0.5,) * dim and b.spin == (0.0,) * {1: 0, 2: 1, 3: 3}[dim]


def test_the_same_seed_gives_the_same_bodies_and_another_seed_others():
    raw = _fill(distribution="lognormal", radius_median=0.02, radius_sigma=0.3, radius_max=0.05, count=200)
    del raw["fill"][0]["radius"]
    first, again = parse_scene(raw), parse_scene(raw)
    assert first.bodies == again.bodies
    raw["fill"][0]["seed"] = 8
    assert parse_scene(raw).bodies != first.bodies


@pytest.mark.parametrize("distribution,keys,bounds", [
    ("uniform", {"radius_min": 0.01, "radius_max": 0.03}, (0.01, 0.03)),
    ("normal", {"radius_mean": 0.02, "radius_std": 0.01, "radius_min": 0.012, "radius_max": 0.025}, (0.012, 0.025)),
    ("lognormal", {"radius_median": 0.02, "radius_sigma": 0.5, "radius_min": 0.01, "radius_max": 0.04}, (0.01, 0.04)),
])
def test_size_distributions_stay_within_their_cuts(distribution, keys, bounds):
    raw = _fill(distribution=distribution, count=400, **keys)
    del raw["fill"][0]["radius"]
    r = np.array([b.radius for b in parse_scene(raw).bodies])
    assert bounds[0] <= r.min() and r.max() <= bounds[1]
    assert r.std() > 0.1 * (bounds[1] - bounds[0]) / math.sqrt(12)  # spread, not one size


def test_a_packing_fraction_fills_that_share_of_the_region():
    for distribution in (None, "uniform"):
        raw = _fill(count=None, packing_fraction=0.2)
        del raw["fill"][0]["count"]
        if distribution:
            del raw["fill"][0]["radius"]
            raw["fill"][0].update(distribution="uniform", radius_min=0.02, radius_max=0.04)
        r = np.array([b.radius for b in parse_scene(raw).bodies])
        volume = 4 / 3 * math.pi * r**3
        assert abs(volume.sum() - 0.2) <= volume.max() / 2 + 1e-12


def test_a_cylinder_fill_keeps_every_sphere_inside_it():
    axis = np.array([1.0, 1.0, 0.5]) / np.linalg.norm([1.0, 1.0, 0.5])
    raw = {"dim": 3, "fill": [{"name": "c", "region": "cylinder", "centre": [1.0, 2.0, 3.0], "axis": axis.tolist(),
                               "cylinder_radius": 0.3, "height": 1.0, "count": 250, "radius": 0.025,
                               "mass_density": 1000.0}]}
    for arrangement in ("random", "lattice"):
        raw["fill"][0]["arrangement"] = arrangement
        scene = parse_scene(raw)
        rel = np.array([b.position for b in scene.bodies]) - [1.0, 2.0, 3.0]
        along = rel @ axis
        across = np.linalg.norm(rel - along[:, None] * axis, axis=1)
        assert len(scene.bodies) == 250
        assert (np.abs(along) <= 0.5 - 0.025 + 1e-12).all() and (across <= 0.3 - 0.025 + 1e-12).all()
        _no_overlap(scene)


def test_fills_avoid_the_bodies_and_walls_before_them_and_take_their_material():
    raw = _fill(count=150, material="glass")
    del raw["fill"][0]["mass_density"]
    raw["material"] = [{"name": "glass", "density": 2500.0}, {"name": "steel", "density": 7800.0}]
    raw["fill"].append(dict(raw["fill"][0], name="s", material="steel", seed=3))
    raw["body"] = [{"name": "big", "mass": 1.0, "radius": 0.2, "position": [0.5, 0.5, 0.5]}]
    raw["wall"] = [{"point": [0.0, 0.0, 0.3], "normal": [0.0, 0.0, 1.0]}]
    scene = parse_scene(raw)
    assert Counter(b.material for b in scene.bodies) == {"glass": 150, "steel": 150, None: 1}
    assert min(b.position[2] - b.radius for b in scene.bodies) >= 0.3
    _no_overlap(scene)


@pytest.mark.parametrize("keys,message", [
    ({"packing_fraction": 0.2}, "fill.g.count: give a count or a packing_fraction (both given)"),
    ({"count": 10**9}, "fill.g.count: at most"),
    ({"count": 20000}, "fill.g: only "),
    ({"count": 20000, "arrangement": "lattice"}, "fill.g.count: 20000 spheres asked for; the lattice holds 4096"),
    ({"distribution": "uniform", "radius_min": 0.01, "radius_max": 0.02},
     "fill.g.radius: give one radius or a distribution"),
    ({"radius_mean": 0.1}, "fill.g.radius_mean: belongs to a distribution"),
    ({"region": "sphere"}, "fill.g.region: unknown 'sphere'"),
    ({"cylinder_radius": 0.2}, "fill.g.cylinder_radius: belongs to region 'cylinder'"),
    ({"material": "glass"}, "fill.g.mass_density: give a material or a mass_density, not both"),
    ({"arrangement": "hex"}, "fill.g.arrangement: unknown 'hex'"),
    ({"seed": -1}, "fill.g.seed: expected a whole number"),
    ({"upper": [1.0, 1.0, 0.0]}, "fill.g.upper: must exceed lower"),
    ({"radius": 0.6}, "fill.g: a sphere of radius 0.6 m does not fit in the box"),
    ({"colour": 1}, "fill[0]: unknown key 'colour'"),
])
def test_bad_fills_are_refused_in_one_line(keys, message):
    raw = _fill(**keys)
    with pytest.raises(SceneError) as caught:
        parse_scene(raw)
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)


def test_an_unnamed_fill_is_named_by_its_place_in_messages():
    raw = _fill(upper=[1.0, 1.0, 0.0])
    del raw["fill"][0]["name"]
    with pytest.raises(SceneError, match=r"^fill\[0\]\.upper: must exceed lower"):
        parse_scene(raw)


def test_a_fill_refused_for_too_many_says_how_many_fit():
    with pytest.raises(SceneError, match=r"only (\d+) of 20000 spheres fit without overlap") as caught:
        parse_scene(_fill(count=20000))
    fitted = int(str(caught.value).split("only ")[1].split(" ")[0])
    assert 0.25 < fitted * 4 / 3 * math.pi * 0.03**3 < 0.45  # near random insertion's jamming, 0.38


def test_neither_count_nor_fraction_and_other_scene_level_refusals():
    raw = _fill()
    del raw["fill"][0]["count"]
    assert _verdict(raw).startswith("fill.g.count: give a count or a packing_fraction (neither given)")
    assert _verdict({**_fill(), "domain": {"lower": [0, 0, 0], "upper": [1, 1, 1], "periodic": ["x"]}}) == \
        "domain.periodic: a periodic scene needs a duration (bodies wrapping round may meet again forever, so " \
        "the run would not end by itself)"
    assert _verdict({"dim": 2, "fill": [dict(_fill(2)["fill"][0], region="cylinder", centre=[0, 0], axis=[0, 1],
                                             cylinder_radius=1.0, height=1.0, lower=None)]}) is not None
    assert _verdict({"dim": 2}) == "body: a scene needs at least one body ([[body]], [[fill]] or [bodies] file)"


def test_a_domain_is_what_a_fill_without_corners_fills_and_holds_the_start():
    raw = _fill()
    del raw["fill"][0]["lower"], raw["fill"][0]["upper"]
    raw["domain"] = {"lower": [0.0, 0.0, 0.0], "upper": [2.0, 1.0, 1.0], "periodic": []}
    scene = parse_scene(raw)
    assert scene.domain.upper == (2.0, 1.0, 1.0)
    assert max(b.position[0] for b in scene.bodies) > 1.0
    raw["body"] = [{"name": "out", "mass": 1.0, "radius": 0.01, "position": [3.0, 0.5, 0.5]}]
    assert _verdict(raw).startswith("body.out.position: outside the domain at the start")


# ---------------------------------------------------------------------------------------------
# Body tables and the saved state


def _pile_scene(tmp_path: Path) -> Path:
    scene = tmp_path / "pile.toml"
    scene.write_text("""
dim = 2
integrator = "dem"
dt = 2e-5
duration = 0.02
gravity = [0.0, -9.81]
[contact]
k = 2000.0
mu = 0.3
restitution = 0.5
[[wall]]
point = [0.0, 0.0]
normal = [0.0, 1.0]
[[fill]]
name = "grain"
lower = [0.0, 0.0]
upper = [0.2, 0.2]
count = 8
radius = 0.02
mass_density = 1000.0
seed = 4
""")
    return scene


def test_a_saved_state_loads_as_the_bodies_of_the_next_scene(tmp_path):
    scene_file = _pile_scene(tmp_path)
    out = subprocess.run([sys.executable, "-m", "cli.main", "run", str(scene_file), "--no-record", "--json",
                          "--save-state", str(tmp_path / "settled.csv")], capture_output=True, text=True,
                         cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr
    from collide.run import run_scene

    first = load_scene(scene_file)
    final = run_scene(first, record=False).result.final  # the same run in this process
    (tmp_path / "next").mkdir()
    text = scene_file.read_text().split("[[fill]]")[0] + '[bodies]\nfile = "../settled.csv"\n'
    (tmp_path / "next" / "next.toml").write_text(text)
    second = load_scene(tmp_path / "next" / "next.toml")
    assert [b.name for b in second.bodies] == [f"grain{i}" for i in range(8)]
    assert np.array_equal([b.position for b in second.bodies], final.s[0])
    assert np.array_equal([b.velocity for b in second.bodies], final.v[0])
    assert np.array_equal([b.spin for b in second.bodies], final.w[0])
    assert [(b.mass, b.radius, b.inertia) for b in second.bodies] == \
        [(b.mass, b.radius, b.inertia) for b in first.bodies]
    assert not np.array_equal(final.s[0], [b.position for b in first.bodies])  # the pile moved


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_a_body_table_reads_back_exactly(tmp_path, suffix, dim):
    from collide.bodies_file import write_state

    raw = _fill(dim, count=20, radius=0.01)
    raw["material"] = [{"name": "glass", "density": 2500.0}]
    raw["body"] = [{"name": "m", "radius": 0.01, "material": "glass", "position": [0.99] * dim,
                    "inertia": "shell"}]
    scene = parse_scene(raw)
    rng = np.random.default_rng(1)
    n, spin = len(scene.bodies), {1: 0, 2: 1, 3: 3}[dim]
    pos = np.array([b.position for b in scene.bodies])
    vel, w = rng.normal(size=(n, dim)) / 3, rng.normal(size=(n, spin)) * 1e-7
    write_state(tmp_path / f"s{suffix}", scene, pos, vel, w)
    again = parse_scene({"dim": dim, "material": raw["material"], "bodies": {"file": str(tmp_path / f"s{suffix}")}})
    assert [(b.name, b.mass, b.radius, b.inertia, b.material) for b in again.bodies] == \
        [(b.name, b.mass, b.radius, b.inertia, b.material) for b in scene.bodies]
    assert np.array_equal([b.velocity for b in again.bodies], vel)
    assert np.array_equal(np.array([b.spin for b in again.bodies]).reshape(n, spin), w)


@pytest.mark.parametrize("text,message", [
    ("name,radius,mass,position_x,position_y\na,0.1,1,0,0\nb,0.1,x,1,0\n", "row 2, mass: expected a number, got 'x'"),
    ("name,radius,mass,position_x\na,0.1,1,0\n", "column 'position_y' missing"),
    ("name,radius,mass,position_x,position_y,colour\na,0.1,1,0,0,red\n", "unknown column 'colour'"),
    ("name,radius,position_x,position_y\na,0.1,0,0\n", "row 1, mass: missing"),
    ("name,radius,mass,position_x,position_y\na,-0.1,1,0,0\n", "row 1, radius: expected a positive number"),
    ("name,radius,mass,position_x,position_y\na b,0.1,1,0,0\n", "row 1, name: expected letters"),
    ("name,radius,mass,position_x,position_y\na,0.1,1,0\n", "row 1 has 4 cells, the header 5"),
    ("name,radius,mass,position_x,position_y\na,0.1,1,0,0\na,0.1,1,1,0\n", "body.a: the name is used twice"),
    ("name,radius,mass,position_x,position_y\na,0.1,1,0,0\nb,0.1,1,0.1,0\n", "overlaps body.b"),
])
def test_bad_body_tables_are_named_in_one_line(tmp_path, text, message):
    (tmp_path / "t.csv").write_text(text)
    (tmp_path / "s.toml").write_text('[bodies]\nfile = "t.csv"\n')
    with pytest.raises(SceneError, match=re_escape(message)):
        load_scene(tmp_path / "s.toml")


def test_a_bad_table_file_exits_2_in_one_line(tmp_path):
    (tmp_path / "s.toml").write_text('[bodies]\nfile = "missing.csv"\n')
    out = subprocess.run([sys.executable, "-m", "cli.main", "run", str(tmp_path / "s.toml"), "--no-record"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 2 and "missing.csv" in out.stderr and "does not exist" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def test_the_design_documents_example_scene_loads(tmp_path):
    """docs/design.md section 10's TOML example, as written there."""
    text = (REPO / "docs" / "design.md").read_text().split("## 10.", 1)[1]
    block = text.split("```toml\n", 1)[1].split("```", 1)[0]
    scene = parse_scene(tomllib.loads(block))
    assert len(scene.bodies) > 100
    assert {b.material for b in scene.bodies} >= {"glass", "steel"}


def test_a_saved_state_may_start_in_its_contacts_in_dem_only(tmp_path):
    """A settled pile rests pressed into its contacts: its table may start overlapping by up to a
    tenth of the smaller radius in a DEM scene; deeper, or in the event engine, is refused."""
    def scene(gap: float, integrator: str) -> dict:
        (tmp_path / "t.csv").write_text("name,radius,mass,position_x,position_y\n"
                                        f"a,0.1,1,0,0.1\nb,0.1,1,{0.2 + gap!r},0.1\n")
        return {"integrator": integrator, "contact": {"restitution": 0.5} if integrator == "dem" else {},
                "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}], "bodies": {"file": str(tmp_path / "t.csv")}}

    assert len(parse_scene(scene(-0.009, "dem")).bodies) == 2
    assert _verdict(scene(-0.011, "dem")) == ("body.a.position: overlaps body.b at the start by 0.011 m (deeper "
                                              "than a saved state's contacts may start)")
    assert _verdict(scene(-0.009, "kahan6")) == "body.a.position: overlaps body.b at the start by 0.009 m"


def test_masses_from_densities_are_each_rows_own_and_a_lacking_one_is_named(tmp_path):
    """A body table's rows without a mass take 4/3 pi r^3 rho of their material, the same bits
    as a [[body]] table's; the first row whose material gives no density is named."""
    materials = '[[material]]\nname = "glass"\ndensity = 2500.0\n\n[[material]]\nname = "cork"\ndensity = 240.0\n\n'
    rows = ["name,radius,mass,material,position_x,position_y"]
    radii = np.random.default_rng(4).uniform(0.01, 0.02, 40).tolist()
    for i, r in enumerate(radii):
        rows.append(f"b{i},{r!r},{'' if i % 3 else 1.5},{('glass', 'cork')[i % 2]},{0.1 * i},0")
    (tmp_path / "t.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "s.toml").write_text(materials + '[bodies]\nfile = "t.csv"\n')
    scene = load_scene(tmp_path / "s.toml")
    density = {"glass": 2500.0, "cork": 240.0}
    for i, body in enumerate(scene.bodies):
        expected = 1.5 if i % 3 == 0 else 4.0 / 3.0 * math.pi * radii[i] ** 3 * density[body.material]
        assert body.mass == expected, i
    (tmp_path / "s.toml").write_text(materials.replace("density = 240.0\n", "") + '[bodies]\nfile = "t.csv"\n')
    with pytest.raises(SceneError, match=re_escape("row 2, mass: missing")):
        load_scene(tmp_path / "s.toml")


def test_bodies_held_as_columns_read_as_the_bodies_they_hold():
    """A scene's bodies made in bulk (a fill) index, slice, iterate, join and compare as a tuple
    of Body does, and pack into the same model as that tuple."""
    from dataclasses import replace

    from collide.body_columns import Bodies
    from collide.model import compile_scenes

    raw = {"dim": 3, "fill": [{"name": "g", "region": "box", "lower": [0, 0, 0], "upper": [0.1, 0.1, 0.1],
                               "count": 30, "radius": 0.005, "mass_density": 2500.0, "seed": 3,
                               "velocity": [0.1, 0.0, -0.2]}]}
    scene = parse_scene(raw)
    bodies = scene.bodies
    assert isinstance(bodies, Bodies) and len(bodies) == 30
    listed = tuple(bodies)
    assert bodies == listed and listed == bodies and bodies[-1] == listed[-1] and bodies[3] == listed[3]
    assert tuple(bodies[5:9]) == listed[5:9] and tuple(bodies[:2] + bodies[28:]) == listed[:2] + listed[28:]
    assert bodies != listed[:-1] + (replace(listed[-1], mass=2 * listed[-1].mass),)
    with pytest.raises(IndexError):
        bodies[30]
    a, a_state = compile_scenes([scene])
    b, b_state = compile_scenes([replace(scene, bodies=listed)])
    for name in ("mass", "radius", "inertia", "material"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.body_names == b.body_names and np.array_equal(a_state.s, b_state.s) \
        and np.array_equal(a_state.v, b_state.v)
