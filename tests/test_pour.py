"""The heavy built-in `pour` (100 000 spheres poured into a box, docs/design.md section 6) and how
heavy built-ins are kept out of what runs every built-in. The full scene runs for minutes: the
tests run the same file with a box a fraction of its width and the fill's count cut in
proportion (the same loose packing and the same drop), through the command line a user has."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial import cKDTree

from cli.common import progress_part
from collide.scene import HEAVY_BODIES, SceneError, builtin_names, declared_bodies, is_heavy, load_scene, read_raw

SIDE = 0.05  # m: the small variant's box (the built-in's: 0.5 m), 1 000 spheres


def _small(side: float = SIDE) -> list[str]:
    """Overrides that cut the built-in to a box `side` wide, its fill's count in proportion."""
    raw, _ = read_raw("pour")
    width = raw["wall"][1]["point"][0]
    count = round(raw["fill"][0]["count"] * (side / width) ** 2)
    return [f"fill.0.count={count}", f"fill.0.upper.x={side}", f"fill.0.upper.y={side}", f"wall.1.point.x={side}",
            f"wall.3.point.y={side}"]


def _interior_fraction(pos: np.ndarray, radius: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """Solid fraction of the box lower..upper, from points drawn uniformly in it: the share that
    lies inside a sphere. A point is within the largest radius of every sphere holding it, and
    a dense packing has about one centre within that distance of a point: the 8 nearest centres
    hold every sphere that can contain it."""
    points = np.random.default_rng(0).uniform(lower, upper, (200_000, 3))
    dist, index = cKDTree(pos).query(points, k=8, distance_upper_bound=radius.max())
    inside = dist < np.append(radius, 0.0)[index]  # (missing neighbours: index n, distance inf)
    return float(inside.any(axis=1).mean())  # standard error below 0.0011 for 2e5 points


def test_the_small_pour_settles_inside_its_box_at_rest_at_a_random_packing() -> None:
    """The scene run from the command line (two threads, progress on): it ends at rest (before its
    duration), every sphere in the box, the kinetic energy below its rest fraction of the energy
    the fall released, the balance within the run's error estimate, no guard raised, and the
    bed's interior at a random packing of frictional spheres (loose 0.55 to close 0.64)."""
    overrides = _small()
    args = [a for o in overrides for a in ("--set", o)]
    env = dict(os.environ, COLLIDE_PROGRESS="1", COLLIDE_PROGRESS_AFTER="0")
    done = subprocess.run([sys.executable, "-m", "cli.main", "run", "pour", *args, "--threads", "2", "--json",
                           "--no-record"], capture_output=True, text=True, env=env, timeout=1200)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "kinetic energy" in done.stderr and "of its peak (at rest below 1e-05)" in done.stderr
    summary = json.loads(done.stdout)
    scene = load_scene("pour", overrides)
    radius = np.array([b.radius for b in scene.bodies])
    mass = np.array([b.mass for b in scene.bodies])
    start = np.array([b.position for b in scene.bodies])
    pos = np.array([b["position"] for b in summary["bodies"]])
    vel = np.array([b["velocity"] for b in summary["bodies"]])
    assert summary["sim_time"] < scene.duration  # ended by `rest`
    # Inside: every centre within the walls, pressed into them by less than a tenth of its radius
    # (the bed's weight, Hertz at E = 5 MPa, gives a few percent; a pass-through its whole radius).
    lows = pos - radius[:, None]
    highs = pos + radius[:, None]
    assert (lows > -0.1 * radius[:, None]).all()
    assert (highs[:, :2] < SIDE + 0.1 * radius[:, None]).all()
    released = float(np.sum(mass * 9.81 * (start[:, 2] - pos[:, 2])))
    assert released > 0
    # The peak kinetic energy is at most what the fall had released by then, less than the whole
    # drop's: at rest the run's kinetic energy is below rest x peak.
    kinetic = 0.5 * float(np.sum(mass * np.sum(vel**2, axis=1)))
    assert kinetic < scene.rest * released
    assert summary["residuals"]["energy"] < summary["error_estimate"]
    assert all(w.startswith("the error was not measured") for w in summary["warnings"]), summary["warnings"]
    # The interior: two largest diameters from the side walls and the floor, and clear of the
    # surface (the mean top of the highest 5 %) by as much.
    margin = 4 * radius.max()
    top = float(np.mean(np.sort(highs[:, 2])[-len(highs) // 20:]))
    fraction = _interior_fraction(pos, radius, np.array([margin, margin, margin]),
                                  np.array([SIDE - margin, SIDE - margin, top - margin]))
    assert 0.55 < fraction < 0.64


def test_progress_of_a_run_to_rest_is_the_larger_of_time_and_the_energy_fall() -> None:
    # The kinetic energy 1e-3 of its peak with rest at 1e-6: half way down on a log scale.
    line = progress_part(0.1, 2.0, 1e-3, 1e-6)
    assert line.startswith("[" + "#" * 10 + "-" * 10 + "] 50 % 0.1 s of at most 2 s")
    assert "kinetic energy 1.0e-03 of its peak (at rest below 1e-06)" in line
    assert progress_part(1.5, 2.0, 1e-3, 1e-6).startswith("[" + "#" * 15 + "-" * 5 + "] 75 %")
    assert progress_part(3.0, 12.0, math.nan, None).startswith("[#####---------------] 25 % 3 s of 12 s")
    assert progress_part(3.0, math.inf, math.nan, None) == "3 s"


def test_heavy_builtins_are_listed_but_left_out_of_what_runs_every_builtin() -> None:
    raw, _ = read_raw("pour")
    assert declared_bodies(raw) == 100_000 > HEAVY_BODIES
    assert is_heavy("pour") and not is_heavy("pile")
    assert "pour" in builtin_names() and "pour" not in builtin_names(heavy=False)
    assert set(builtin_names()) - set(builtin_names(heavy=False)) == {"pour"}


def test_the_viewer_offers_a_heavy_builtin_as_a_recording_only() -> None:
    from viewer.files import scene_choices

    assert "pour" not in [c.label for c in scene_choices(None)]
    done = subprocess.run([sys.executable, "-m", "cli.main", "view", "pour", "--port", "0"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "collide view recordings/pour.rrd" in done.stderr


def test_fills_are_overridden_by_index() -> None:
    scene = load_scene("pour", _small())
    assert len(scene.bodies) == round(100_000 * (SIDE / 0.5) ** 2)
    assert max(b.position[0] + b.radius for b in scene.bodies) <= SIDE
    with pytest.raises(SceneError, match=r"override key 'fill\.1\.count': the scene has 1 fill\(s\)"):
        load_scene("pour", ["fill.1.count=5"])
    with pytest.raises(SceneError, match=r"use fill\.INDEX\.FIELD"):
        load_scene("pour", ["fill.count=5"])


def test_a_random_fill_is_stored_in_space_order() -> None:
    """Spheres near in space are near in the body list (a Z-order of cells), so a contact pass
    over many bodies reads memory nearby: the median index gap of the pairs within a largest
    diameter is a few bodies, where the order drawn would give about 0.29 N (the median of |i - j|
    for random i, j: 1 - 1/sqrt(2) of N)."""
    scene = load_scene("pour", _small())
    pos = np.array([b.position for b in scene.bodies])
    radius = np.array([b.radius for b in scene.bodies])
    pairs = cKDTree(pos).query_pairs(2 * radius.max(), output_type="ndarray")
    assert len(pairs) > len(pos) / 2
    assert np.median(np.abs(pairs[:, 0] - pairs[:, 1])) < len(pos) / 50
