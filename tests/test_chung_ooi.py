"""The Chung & Ooi (2011) suite: its closed forms against independent numbers, then a few of its
runs within their bars (the full sweep is `collide validate --suite chung-ooi`)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app as collide_app
from collide import chung_ooi as co

# ---------------------------------------------------------------------------------------------
# Closed forms


def test_hertz_closed_form_matches_energy_and_johnsons_duration():
    """Test 1 (glass, 10 m/s each): delta_max from the energy balance 1/2 m* v^2 = 8/15 E*
    sqrt(R*) delta^(5/2), F_max from the force law, and t_c = 2.94 delta_max / v (Johnson 11.24's
    other form, 2.868 = 2.94 (15/16)^(2/5) ... checked numerically, not by the same formula)."""
    m = 4.0 / 3.0 * math.pi * 0.01**3 * 2800.0
    e_star = 1.0 / (2 * (1 - 0.2**2) / 4.8e10)
    assert e_star == pytest.approx(2.5e10)
    got = co.hertz_impact(m / 2, 0.005, e_star, 20.0)
    energy = 0.5 * (m / 2) * 20.0**2
    assert 8.0 / 15.0 * e_star * math.sqrt(0.005) * got["delta_max"] ** 2.5 == pytest.approx(energy, rel=1e-12)
    assert got["f_max"] == pytest.approx(4.0 / 3.0 * e_star * math.sqrt(0.005) * got["delta_max"] ** 1.5)
    assert got["contact_time"] == pytest.approx(2.94 * got["delta_max"] / 20.0, rel=2e-3)
    # Hand-computed for this case: 0.274 mm, 10.7 kN, 40.3 us.
    assert got["delta_max"] == pytest.approx(2.741e-4, rel=1e-3)
    assert got["f_max"] == pytest.approx(1.0697e4, rel=1e-3)
    assert got["contact_time"] == pytest.approx(4.034e-5, rel=1e-3)


def test_hertz_duration_constant_from_quadrature():
    """HERTZ_TIME (Johnson's 2.868) is 2 int_0^1 dx / sqrt(1 - x^(5/2)) (= 2 x 1.4716) times
    (15/16)^(2/5): the contact time in units of (m*^2 / (R* E*^2 v))^(1/5), to round-off.
    Adaptive quadrature with x = 1 - s^2 (a smooth integrand), not the Beta function."""
    from scipy.integrate import quad

    half, _ = quad(lambda s: 2.0 * s / math.sqrt(1.0 - (1.0 - s * s) ** 2.5), 0.0, 1.0, epsabs=0.0, epsrel=1e-13)
    assert 2.0 * half * (15.0 / 16.0) ** 0.4 == pytest.approx(co.HERTZ_TIME, rel=1e-12)
    assert co.HERTZ_TIME == pytest.approx(2.868, rel=1e-4)


def test_effective_modulus_of_a_wall_is_the_sphere_alone():
    assert co.effective_modulus(co.AL_ALLOY) == pytest.approx(7.0e10 / (1 - 0.33**2))
    # Two of the same: half that.
    assert co.effective_modulus(co.AL_ALLOY, co.AL_ALLOY) == pytest.approx(0.5 * 7.0e10 / (1 - 0.33**2))


def _ball(vx: float, vy: float, w: float = 0.0, r: float = 0.1, m: float = 2.0) -> co.Sphere2D:
    return co.Sphere2D(m, r, 0.4 * m * r**2, (vx, vy), w)


def test_rigid_wall_sliding_and_rolling_relations():
    """On a wall: gross sliding gives v_t' = v_t - mu (1 + e) v_n and w' = -5/2 mu (1 + e) v_n / r;
    below the threshold 7/2 mu (1 + e) the slip stops: v_t' = 5/7 v_t, w' = -v_t' / r."""
    mu, e, vn = 0.1, 0.8, 2.0
    assert co.slip_threshold(e, mu) == pytest.approx(3.5 * mu * (1 + e))
    fast = co.rigid_impact(_ball(3.0, -vn), None, e, mu)[0]
    assert fast.velocity == pytest.approx((3.0 - mu * (1 + e) * vn, e * vn))
    assert fast.spin == pytest.approx(-2.5 * mu * (1 + e) * vn / 0.1)
    slow = co.rigid_impact(_ball(0.5, -vn), None, e, mu)[0]
    assert slow.velocity[0] == pytest.approx(5.0 / 7.0 * 0.5)
    assert slow.velocity[0] + 0.1 * slow.spin == pytest.approx(0.0, abs=1e-15)
    # Angular momentum about the contact point (0, -r) from the centre, I w - m r v_x, is
    # conserved either way: both impulses act there.
    for out, vx in ((fast, 3.0), (slow, 0.5)):
        before = -2.0 * 0.1 * vx
        after = out.inertia * out.spin - 2.0 * 0.1 * out.velocity[0]
        assert after == pytest.approx(before, abs=1e-12)


def test_rigid_pair_conserves_momentum_and_has_the_wall_threshold_in_m_star():
    a, b = _ball(1.0, 0.3, w=2.0, r=0.1, m=3.0), _ball(0.0, -0.1, w=-1.0, r=0.05, m=0.5)
    a2, b2 = co.rigid_impact(a, b, 0.6, 0.4)
    for k in (0, 1):
        assert 3.0 * a2.velocity[k] + 0.5 * b2.velocity[k] == pytest.approx(3.0 * a.velocity[k] + 0.5 * b.velocity[k])
    # Normal: relative velocity reversed times e.
    assert a2.velocity[1] - b2.velocity[1] == pytest.approx(-0.6 * (0.3 + 0.1))
    # Slip before: (b's contact point) - (a's) = (0 + 0.05 (-1)) - (1 - 0.1 * 2) = -0.85; the
    # threshold is 7/2 mu (1 + e) v_n = 0.896 > 0.85: the slip stops.
    slip = (b2.velocity[0] + 0.05 * b2.spin) - (a2.velocity[0] - 0.1 * a2.spin)
    assert slip == pytest.approx(0.0, abs=1e-12)


def test_lever_factor_from_the_energy_integral():
    """c = int x^(5/2) dt / int x^(3/2) dt over the dimensionless impact, with dt = dx / x' and
    x'^2 = 1 - 4/5 x^(5/2): an independent quadrature of the RK4 figure."""
    top = 1.25**0.4
    s = np.linspace(0.0, 1.0, 400_001)[1:]
    x = top * (1.0 - s**2)
    weight = 2.0 * top * s / np.sqrt(1.0 - 0.8 * x**2.5)
    c = np.trapezoid(x**2.5 * weight, s) / np.trapezoid(x**1.5 * weight, s) / top
    assert co.lever_factor() == pytest.approx(c, rel=1e-3)


# ---------------------------------------------------------------------------------------------
# The suite's runs


def _check(rows: list[co.Row]) -> None:
    assert rows
    for row in rows:
        assert row.passed, row


def test_suite_tests_1_and_2_hertz_within_one_percent():
    rows, fig = co.test1()
    _check(rows)
    rows2, _ = co.test2()
    _check(rows2)
    assert {r.quantity for r in rows2} == {"delta_max (m)", "F_max (N)", "t_c (s)", "steps per contact"}
    # Each also at full order in the event engine, at --tol 1e-8 within 1e-7 and 50 steps.
    for got in (rows, rows2):
        full = [r for r in got if "event engine" in r.note]
        assert len(full) == 4 * len({r.case for r in got})
        assert all(r.tolerance == (1.0 if r.quantity == "steps per contact" else 1e-7) for r in full)


@pytest.mark.parametrize("seed", range(4))
def test_full_order_impacts_of_other_materials_sizes_and_speeds(seed):
    """Tests 1 (head-on, unequal spheres) and 2 (on a plane) for random materials (E 1e6 to 1e12
    Pa), radii (0.1 mm to 0.1 m) and speeds (1 mm/s to 100 m/s) at --tol 1e-8: within 1e-7 of
    the closed forms in at most 50 steps, in the event engine."""
    rng = np.random.default_rng(seed)
    mats = [co.Material(f"m{i}", float(10 ** rng.uniform(6, 12)), float(rng.uniform(0.1, 0.45)),
                        float(rng.uniform(500, 9000))) for i in range(2)]
    radii = tuple(float(r) for r in 10 ** rng.uniform(-4, -1, 2))
    speed = float(10 ** rng.uniform(-3, 2))
    pair = co.pair_scene((mats[0], mats[1]), radii, ((0.0, speed), (0.0, -speed / 3)), full=True)
    masses = [co.sphere_mass(m, r) for m, r in zip(mats, radii)]
    mstar, rstar = masses[0] * masses[1] / sum(masses), radii[0] * radii[1] / sum(radii)
    exp = co.hertz_impact(mstar, rstar, co.effective_modulus(mats[0], mats[1]), 4 * speed / 3)
    wall = co.wall_scene(mats[0], radii[0], (0.0, -speed), full=True)
    exp_wall = co.hertz_impact(masses[0], radii[0], co.effective_modulus(mats[0]), speed)
    for rows in (co.full_order_rows(1, "random", pair, exp), co.full_order_rows(2, "random", wall, exp_wall)):
        _check(rows)


def test_suite_test_3_restitution_out_equals_in():
    rows, fig = co.test3(restitutions=(0.1, 0.5, 0.9))
    _check(rows)
    for data in fig.values():
        assert np.allclose(data["e_out"], data["e_in"], rtol=co.BAR)


def test_suite_test_4_sliding_rolling_and_the_spring_regime():
    rows, fig = co.test4(angles=(10.0, 20.0, 50.0, 80.0))
    _check(rows)
    cases = {r.case for r in rows}
    assert {"coulomb, gross sliding", "coulomb, rolling", "spring, near sticking"} <= cases
    # The spring's contact patch rebounds backwards near sticking; Coulomb's stops.
    near = ~fig["sliding"]
    assert fig["spring"]["psi2"][near].min() < -0.5
    assert np.abs(fig["coulomb"]["psi2"][near]).max() < 1e-2


def test_suite_tests_6_to_8_in_the_sliding_regime():
    for run, kwargs in ((co.test6, {"spins": (2.0, 12.0, 21.0)}), (co.test7, {"spins": (3.0, 21.0)}),
                        (co.test8, {"tangential_speeds": (0.2, 0.7, 2.0)})):
        rows, fig = run(**kwargs)
        _check(rows)
        assert any(r.case.startswith("coulomb, sliding") for r in rows)


def test_cli_chung_ooi_json_and_plots(tmp_path):
    result = CliRunner().invoke(collide_app, ["validate", "--suite", "chung-ooi", "--test", "2", "--json",
                                              "--plots", str(tmp_path)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    # Two materials: three DEM rows and four full-order ones (three quantities, steps) each.
    assert data["passed"] and len(data["rows"]) == 14
    assert (tmp_path / "test2.png").stat().st_size > 10_000


def test_cli_chung_ooi_bad_input_is_one_line():
    for args in (["--test", "9"], ["--scene", "bounce"]):
        result = CliRunner().invoke(collide_app, ["validate", "--suite", "chung-ooi", *args])
        assert result.exit_code == 2
        assert result.output.strip().count("\n") == 0 and "error:" in result.output
    result = CliRunner().invoke(collide_app, ["validate", "--suite", "nope"])
    assert result.exit_code == 2 and "chung-ooi" in result.output
