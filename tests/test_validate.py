"""Validation tables: textbook residuals, rigid cross-check, softness against k, and the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app as collide_app
from collide import rigid
from collide import validate as v
from collide.scene import builtin_names, builtin_text, load_scene, parse_scene


@pytest.fixture(scope="module")
def textbook() -> list[v.TextbookRow]:
    return v.textbook_table()


def test_textbook_residuals_against_exact_values_are_within_tolerance(textbook: list[v.TextbookRow]) -> None:
    assert [r.figure for r in textbook] == ["Fig 3"] * 2 + ["Fig 4"] * 2 + ["Fig 5"] * 2 + ["Fig 6"]
    for row in textbook:
        assert row.residual_exact_pct == pytest.approx(100 * abs(row.simulated - row.exact) / row.exact)
        assert row.residual_exact_pct <= row.tolerance_pct, row
        assert row.passed
    # The tolerances are tight enough to mean something: below the report's own residuals.
    assert max(r.tolerance_pct for r in textbook) < 1.0
    # 1D: a linear spring collision is exactly elastic for any k.
    assert all(r.residual_exact_pct < 1e-6 for r in textbook if r.scene == "textbook-1d")


def test_textbook_exact_values_are_design_numbers(textbook: list[v.TextbookRow]) -> None:
    exact = [r.exact for r in textbook]
    assert exact == pytest.approx([0.66, 1.86, 3.993178, 3.009075, math.sqrt(2), math.sqrt(6) / 3, 54.7356],
                                  rel=1e-6)
    printed = [r.printed for r in textbook]
    assert printed == [0.66, 1.86, 4.00, 3.01, 1.4142, 0.8165, 54.7]


def test_exit_angle_is_measured_from_the_y_axis() -> None:
    assert v.exit_angle_deg(np.array([-2 / 3, -math.sqrt(2) / 3])) == pytest.approx(54.7356, abs=1e-4)
    assert v.exit_angle_deg(np.array([0.0, 1.0])) == 0.0


def test_a_wrong_simulator_value_fails_the_textbook_table() -> None:
    # Feed a velocity 1 % off: the row must fail against its tolerance.
    finals = {"textbook-1d": np.array([[0.66 * 1.01], [1.86]])}
    rows = v.textbook_table(["textbook-1d"], finals=finals)
    assert [r.passed for r in rows] == [False, True]


def test_cross_check_with_friction_separates_discretisation_from_softness() -> None:
    check = v.cross_check(load_scene("demo-bonus"))
    assert check.regime == rigid.STICKING and check.converged and check.passed
    quantities = [r.quantity for r in check.rows]
    assert quantities == ["ball1.velocity", "ball1.spin", "ball2.velocity", "ball2.spin"]
    for row in check.rows:
        assert row.discretisation < row.discretisation_tol
        assert row.softness < row.softness_tol
    # At k = 1500 the soft balls are far from rigid; the stepper is far more accurate than that.
    assert max(r.softness for r in check.rows) > 100 * max(r.discretisation for r in check.rows)


def test_cross_check_sphere_on_wall_3d_rolls_like_the_rigid_limit() -> None:
    scene = parse_scene({"dim": 3, "dt": 4e-6, "contact": {"k": 1.5e6, "mu": 0.8, "eps": 1e-6},
                         "body": [{"name": "ball", "mass": 0.0254, "radius": 0.03021, "position": [0, 0.1, 0],
                                   "velocity": [1.0, -2.0, 0.5], "spin": [1.0, 2.0, 3.0]}],
                         "wall": [{"point": [0, 0, 0], "normal": [0, 1, 0]}]})
    check = v.cross_check(scene)
    assert check.regime == rigid.STICKING and check.passed
    rigid_v = np.array(check.rows[0].rigid)
    assert rigid_v[1] == pytest.approx(2.0)  # elastic bounce
    assert np.array(check.rows[0].simulated) == pytest.approx(rigid_v, abs=2e-3)


def test_tight_tolerance_fails_without_grinding() -> None:
    # The ladder (kahan6) stalls at round-off: a 1e-15 target (changes below 1e-16) is out of reach.
    check = v.cross_check(load_scene("demo-bonus", ["dt=4e-5", "integrator=verlet"]), tol=1e-15)
    assert not check.passed and not check.converged
    # After dt/4 the changes have stopped shrinking (round-off) or shrink too slowly to reach
    # 1e-16 in the halvings left: stop.
    assert len(check.ladder_dt) == 3
    first, second = check.ladder_change
    assert second > 1e-16
    assert second >= first or math.log(second / 1e-16) / math.log(first / second) > v.MAX_HALVINGS - 2


def test_coarse_step_fails_on_discretisation() -> None:
    check = v.cross_check(load_scene("demo-2d-stationary", ["integrator=verlet", "dt=2e-3"]))
    assert check.converged and not check.passed
    assert all(r.discretisation > r.discretisation_tol for r in check.rows)
    assert all(r.softness < r.softness_tol for r in check.rows)


def test_softness_shrinks_as_inverse_root_k() -> None:
    scan = v.softness_scan("textbook-glancing")
    soft = [p.softness for p in scan.points]
    assert soft[0] > soft[1] > soft[2]
    assert scan.exponent == pytest.approx(-0.5, abs=0.01)
    assert all(p.softness <= p.estimate for p in scan.points)
    assert scan.passed


def test_cli_validate_json_and_exit_codes(tmp_path: Path) -> None:
    runner = CliRunner()
    ok = runner.invoke(collide_app, ["validate", "--scene", "textbook-unequal", "--json", "--no-scan"])
    assert ok.exit_code == 0, ok.output
    data = json.loads(ok.stdout)
    assert data["passed"] is True and len(data["textbook"]) == 3 and data["cross_check"][0]["converged"]
    text = runner.invoke(collide_app, ["validate", "--scene", "textbook-1d", "--no-scan"])
    assert text.exit_code == 0 and "Fig 3" in text.stdout and "PASS" in text.stdout
    coarse = tmp_path / "coarse.toml"
    text = builtin_text("demo-2d-stationary")
    assert 'dt = "auto"' in text and 'integrator = "kahan6"' in text
    coarse_text = text.replace('dt = "auto"', "dt = 2e-3").replace('integrator = "kahan6"', 'integrator = "verlet"')
    coarse.write_text(coarse_text)
    failing = runner.invoke(collide_app, ["validate", "--scene", str(coarse), "--no-scan"])
    assert failing.exit_code == 1 and "FAIL" in failing.stdout


def test_cli_validate_bad_input_is_one_line_and_exit_2() -> None:
    result = CliRunner().invoke(collide_app, ["validate", "--scene", "no-such-scene"])
    assert result.exit_code == 2
    assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1
    assert "Traceback" not in result.output
    help_text = CliRunner().invoke(collide_app, ["validate", "--help"])
    assert help_text.exit_code == 0 and "Example" in help_text.stdout


def test_head_on_soft_collision_is_already_rigid() -> None:
    # v_t = 0: the linear spring gives the rigid answer for every k, and the bound says so.
    scene = load_scene("demo-2d-stationary", ["body.ball1.position=[0.0, 0.0]"])
    assert rigid.softness_estimate(scene) == 0.0
    check = v.cross_check(scene)
    assert check.passed and max(r.softness for r in check.rows) < 1e-9
    scan = v.softness_scan(scene)
    assert scan.passed and math.isnan(scan.exponent)


# ---------------------------------------------------------------------------------------------
# Scene checks: every built-in, a user's scene file, a scene with nothing to check, and checks
# that must fail

CRADLE3 = """name = "my-cradle"
dim = 1
{settings}
[contact]
k = 1e6

[[body]]
name = "a"
mass = 0.1
radius = 0.01
position = 0.0
velocity = 0.5

[[body]]
name = "b"
mass = 0.1
radius = 0.01
position = 0.05
velocity = 0.0

[[body]]
name = "c"
mass = 0.1
radius = 0.01
position = 0.075
velocity = 0.0
"""

APART = """name = "apart"
dim = 2

[[body]]
name = "a"
mass = 1.0
radius = 0.1
position = [0.0, 0.0]
velocity = [-1.0, 0.0]

[[body]]
name = "b"
mass = 1.0
radius = 0.1
position = [0.5, 0.0]
velocity = [1.0, 0.0]
"""


def _scene_rows(output: str) -> list[str]:
    """The rows of the scene table (after its header's dashes, up to the blank line)."""
    lines = output.split("Scene checks:")[1].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("----")) + 1
    rows = []
    for line in lines[start:]:
        if not line.strip() or line.startswith("Not applicable"):
            break
        rows.append(line)
    return rows


def test_full_validate_passes_with_a_row_per_builtin() -> None:
    result = CliRunner().invoke(collide_app, ["validate"])
    assert result.exit_code == 0, result.output
    rows = _scene_rows(result.stdout)
    first_cells = [row.split()[0] for row in rows if not row.startswith(" ")]
    assert first_cells == builtin_names(heavy=False)
    assert all(row.rstrip().split("  ")[-1] for row in rows)  # every row says what and why
    named = {row.split()[0]: row for row in rows if not row.startswith(" ")}
    assert "whole run" in named["pile"] and "whole run" in named["gas-box"]
    checks = " ".join(rows)
    for name in ("velocity exchange", "bounce heights", "tolerance ladder", "energy balance",
                 "energy conservation", "rigid limit", "momentum"):
        assert name in checks, name
    assert "FAIL" not in result.stdout and result.stdout.rstrip().splitlines()[-1].startswith("PASS")


def test_a_user_scene_file_gets_the_checks_that_apply(tmp_path: Path) -> None:
    path = tmp_path / "cradle3.toml"
    path.write_text(CRADLE3.format(settings=""))
    result = CliRunner().invoke(collide_app, ["validate", str(path), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    (report,) = data["scene_checks"]
    names = [c["check"] for c in report["checks"]]
    assert names == ["energy conservation", "momentum", "velocity exchange", "tolerance ladder"]
    assert all(c["passed"] and c["deviation"] <= c["bound"] for c in report["checks"])
    assert report["not_applicable"][0].startswith("rigid reference: handles 2 spheres")
    assert data["cross_check"] == [] and data["textbook"] == []
    # The velocity exchange against its closed form: the last ball leaves at 0.5 m/s.
    exchange = report["checks"][2]
    assert 0 < exchange["deviation"] < 1e-5


def test_a_scene_with_nothing_to_check_says_why(tmp_path: Path) -> None:
    path = tmp_path / "apart.toml"
    path.write_text(APART)
    result = CliRunner().invoke(collide_app, ["validate", str(path), "--no-scan"])
    assert result.exit_code == 0, result.output
    (row,) = _scene_rows(result.stdout)
    assert row.split()[0] == "apart" and "no check applies" in row and "never touch" in row
    assert "PASS" in result.stdout


def test_a_wrong_expected_value_fails_the_exchange() -> None:
    from collide import scene_checks as sc
    from collide.run import run_scene

    scene = load_scene("newtons-cradle")
    run = run_scene(scene, record=False)
    assert sc.exchange_check(scene, run).passed
    # The same run judged against a first ball that came in 1 % faster: the last ball's speed is off.
    wrong = load_scene("newtons-cradle", ["body.ball1.velocity=1.01"])
    check = sc.exchange_check(wrong, run)
    assert not check.passed and check.deviation == pytest.approx(0.01 / 1.01, rel=1e-3)


def test_a_gross_step_with_the_seed_integrator_fails(tmp_path: Path) -> None:
    # omega dt = 0.22 with the report's first-order update: energy drifts far beyond tol. (Coarser
    # or some finer steps send a ball through its neighbour: that run is refused, exit 2.)
    path = tmp_path / "coarse-cradle.toml"
    path.write_text(CRADLE3.format(settings='integrator = "seed"\ndt = 7e-5\ntol = 1e-4\n'))
    result = CliRunner().invoke(collide_app, ["validate", str(path), "--json"])
    assert result.exit_code == 1, result.output
    (report,) = json.loads(result.stdout)["scene_checks"]
    failed = {c["check"] for c in report["checks"] if not c["passed"]}
    assert "energy conservation" in failed
    energy = next(c for c in report["checks"] if c["check"] == "energy conservation")
    assert energy["deviation"] > 10 * energy["bound"]


def test_a_shortened_run_says_so_and_drops_what_needs_the_whole_run() -> None:
    result = CliRunner().invoke(collide_app, ["validate", "bounce", "--duration", "1", "--json"])
    assert result.exit_code == 0, result.output
    (report,) = json.loads(result.stdout)["scene_checks"]
    assert report["span"] == "first 1 s"
    # Two flights in the first second: one apex ratio, too few to judge the restitution law.
    assert any(n.startswith("bounce heights: only 2 flights") for n in report["not_applicable"])
    assert [c["check"] for c in report["checks"]] == ["energy balance", "tolerance ladder"]
    bad = CliRunner().invoke(collide_app, ["validate", "bounce", "--duration", "-1"])
    assert bad.exit_code == 2 and bad.stderr.startswith("error: --duration")


def test_a_pile_cut_before_it_settles_is_not_at_rest() -> None:
    from collide import scene_checks as sc
    from collide.run import run_scene
    from tests.dem_scenes import _pile

    raw = _pile(3, 3)
    settled = parse_scene(raw)
    run = run_scene(settled, record=False)
    assert float(run.result.final.t[0]) < settled.duration  # it stopped at rest
    assert sc.rest_check(settled, run).passed
    falling = parse_scene(dict(raw, duration=0.05))  # still falling: kinetic energy far above rest
    check = sc.rest_check(falling, run_scene(falling, record=False))
    assert not check.passed and check.deviation > 1e3 * check.bound
