"""The rigid-body reference against closed forms and conservation laws."""

from __future__ import annotations

import math

import numpy as np
import pytest

from collide import rigid
from collide.scene import load_scene, parse_scene

M, R = 0.0254, 0.03021
I_SOLID = 0.4 * M * R * R


def touching_pair_2d(offset: float, r1: float = R, r2: float = R) -> tuple[np.ndarray, np.ndarray]:
    """Centres touching with the line of centres at `offset` (impact parameter) below x."""
    reach = r1 + r2
    return np.array([0.0, offset]), np.array([math.sqrt(reach**2 - offset**2), 0.0])


def angular_momentum_3d(s: list[np.ndarray], v: list[np.ndarray], w: list[np.ndarray],
                        m: list[float], inertia: list[float]) -> np.ndarray:
    """L about the origin: sum s x m v + I w (3-vectors)."""
    parts = zip(s, v, w, m, inertia, strict=True)
    return sum(np.cross(si, mi * vi) + ii * wi for si, vi, wi, mi, ii in parts)


def test_equal_mass_head_on_exchanges_velocities() -> None:
    out = rigid.impact_pair(M, R, I_SOLID, [0.0], [1.0], None, M, R, I_SOLID, [2 * R], [-2.0], None)
    assert out.v1 == pytest.approx([-2.0]) and out.v2 == pytest.approx([1.0])
    assert out.regime == rigid.FRICTIONLESS
    # The same in 2D, with friction: a head-on impact has no slip, so friction does nothing.
    out = rigid.impact_pair(M, R, I_SOLID, [0, 0], [1, 0], 0.0, M, R, I_SOLID, [2 * R, 0], [-2, 0], 0.0,
                            mu=0.5)
    assert out.v1 == pytest.approx([-2.0, 0.0]) and out.v2 == pytest.approx([1.0, 0.0])
    assert out.w1 == pytest.approx([0.0]) and out.tangential_impulse == 0.0


@pytest.mark.parametrize("offset", [0.005, 0.02, 0.05])
def test_equal_mass_oblique_target_at_rest_exits_at_right_angles(offset: float) -> None:
    # Start apart: free flight to the touch is part of what is tested.
    impact, t = rigid.collide_pair(1.0, R, 0.4 * R * R, [-0.3, offset], [5.0, 0.0], 0.0,
                                   1.0, R, 0.4 * R * R, [0.2, 0.0], [0.0, 0.0], 0.0)
    assert impact is not None and t is not None
    assert t == pytest.approx((0.5 - math.sqrt((2 * R) ** 2 - offset**2)) / 5.0)
    cos = impact.v1 @ impact.v2 / np.linalg.norm(impact.v1) / np.linalg.norm(impact.v2)
    angle = math.degrees(math.acos(cos))
    assert angle == pytest.approx(90.0, abs=1e-9)
    # Target moves along the line of centres at touch.
    assert impact.v2 / np.linalg.norm(impact.v2) == pytest.approx(impact.normal)


def test_spheres_that_miss_never_touch() -> None:
    assert rigid.touch_time_pair([0, 0.1], [1, 0], R, [1, 0], [0, 0], R) is None
    assert rigid.touch_time_pair([0, 0], [-1, 0], R, [1, 0], [0, 0], R) is None  # receding
    assert rigid.touch_time_wall([0, 1], [1, 0.5], R, [0, 0], [0, 1]) is None


@pytest.mark.parametrize("m1, m2, u1, u2", [(1.0, 3.0, 1.0, -1.0), (0.34, 0.0987, 1.2, 0.0),
                                            (2.0, 0.5, 0.7, 0.1)])  # the last: a chase
def test_unequal_mass_1d_elastic_formula(m1: float, m2: float, u1: float, u2: float) -> None:
    impact, _ = rigid.collide_pair(m1, R, 0.4 * m1 * R * R, [0.0], [u1], None,
                                   m2, R, 0.4 * m2 * R * R, [0.5], [u2], None)
    assert impact is not None
    assert impact.v1 == pytest.approx([((m1 - m2) * u1 + 2 * m2 * u2) / (m1 + m2)])
    assert impact.v2 == pytest.approx([((m2 - m1) * u2 + 2 * m1 * u1) / (m1 + m2)])


def test_wall_sliding_regime_changes_tangential_velocity_by_mu_times_normal_change() -> None:
    mu, v_n, v_t = 0.05, 2.0, 1.0
    impact, _ = rigid.collide_wall(M, R, I_SOLID, [0.0, 0.1], [v_t, -v_n], 0.0, [0.0, 0.0], [0.0, 1.0], mu)
    assert impact is not None and impact.regime == rigid.SLIDING
    dv = impact.v1 - np.array([v_t, -v_n])
    assert dv[1] == pytest.approx(2 * v_n)  # elastic: the normal velocity reverses
    assert dv[0] == pytest.approx(-mu * 2 * v_n)  # Coulomb: opposes the slip, mu times the normal change
    # Friction at the contact point (below the centre) spins the sphere: I dw = r m |dv_t|, clockwise.
    assert impact.w1[0] == pytest.approx(-R * M * mu * 2 * v_n / I_SOLID)


def test_wall_rolling_regime_ends_with_zero_slip_at_five_sevenths() -> None:
    v_t0 = 1.5
    impact, _ = rigid.collide_wall(M, R, I_SOLID, [0.0, 0.1], [v_t0, -2.0], 0.0, [0.0, 0.0], [0.0, 1.0],
                                   mu=0.8)
    assert impact is not None and impact.regime == rigid.STICKING
    assert impact.v1[0] == pytest.approx(5.0 / 7.0 * v_t0)
    # Slip at the contact point (0, -r): v_x + w r = 0, i.e. rolling.
    assert impact.v1[0] + impact.w1[0] * R == pytest.approx(0.0, abs=1e-12)
    assert impact.slip_after == pytest.approx(0.0, abs=1e-12)


def test_dead_band_leaves_slip_at_its_edge() -> None:
    eps = 0.01
    impact, _ = rigid.collide_wall(M, R, I_SOLID, [0.0, 0.1], [1.0, -2.0], 0.0, [0.0, 0.0], [0.0, 1.0],
                                   mu=0.8, eps=eps)
    assert impact is not None and impact.regime == rigid.STICKING
    assert impact.v1[0] + impact.w1[0] * R == pytest.approx(eps)
    # Slip already inside the band: no friction at all.
    inside, _ = rigid.collide_wall(M, R, I_SOLID, [0.0, 0.1], [0.005, -2.0], 0.0, [0.0, 0.0], [0.0, 1.0],
                                   mu=0.8, eps=eps)
    assert inside is not None and inside.regime == rigid.FRICTIONLESS and inside.v1[0] == 0.005


def random_pair_3d(rng: np.random.Generator) -> dict:
    """Two touching, approaching spheres with random masses, radii, velocities and spins."""
    m1, m2 = rng.uniform(0.5, 3.0, 2)
    r1, r2 = rng.uniform(0.02, 0.08, 2)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    s1 = rng.normal(size=3)
    s2 = s1 + (r1 + r2) * n
    v1, v2 = rng.normal(size=3), rng.normal(size=3)
    v1 += (abs((v2 - v1) @ n) + 1.0) * n  # make sure they approach
    return dict(m1=m1, r1=r1, i1=0.4 * m1 * r1 * r1, s1=s1, v1=v1, w1=rng.normal(size=3) * 20,
                m2=m2, r2=r2, i2=2 / 3 * m2 * r2 * r2, s2=s2, v2=v2, w2=rng.normal(size=3) * 20)


@pytest.mark.parametrize("mu", [0.0, 0.1, 0.5, 5.0])
def test_momentum_and_angular_momentum_balance_3d(mu: float) -> None:
    rng = np.random.default_rng(7)
    regimes = set()
    for _ in range(20):
        p = random_pair_3d(rng)
        out = rigid.impact_pair(p["m1"], p["r1"], p["i1"], p["s1"], p["v1"], p["w1"],
                                p["m2"], p["r2"], p["i2"], p["s2"], p["v2"], p["w2"], mu=mu)
        regimes.add(out.regime)
        m, inertia, s = [p["m1"], p["m2"]], [p["i1"], p["i2"]], [p["s1"], p["s2"]]
        before = angular_momentum_3d(s, [p["v1"], p["v2"]], [p["w1"], p["w2"]], m, inertia)
        after = angular_momentum_3d(s, [out.v1, out.v2], [out.w1, out.w2], m, inertia)
        assert after == pytest.approx(before, rel=1e-12, abs=1e-12)
        assert p["m1"] * out.v1 + p["m2"] * out.v2 == pytest.approx(p["m1"] * p["v1"] + p["m2"] * p["v2"])

        def energy(v1: np.ndarray, v2: np.ndarray, w1: np.ndarray, w2: np.ndarray, p: dict = p) -> float:
            return 0.5 * (p["m1"] * v1 @ v1 + p["m2"] * v2 @ v2 + p["i1"] * w1 @ w1 + p["i2"] * w2 @ w2)

        # Slip of the surfaces at the contact point, from the outputs: rolling ends at zero slip,
        # sliding keeps the slip's direction.
        n = (p["s2"] - p["s1"]) / (p["r1"] + p["r2"])

        def slip(v1: np.ndarray, v2: np.ndarray, w1: np.ndarray, w2: np.ndarray, p: dict = p,
                 n: np.ndarray = n) -> np.ndarray:
            u = v1 + np.cross(w1, p["r1"] * n) - v2 - np.cross(w2, -p["r2"] * n)
            return u - (u @ n) * n

        u0, u1 = slip(p["v1"], p["v2"], p["w1"], p["w2"]), slip(out.v1, out.v2, out.w1, out.w2)
        if out.regime == rigid.STICKING:
            assert np.linalg.norm(u1) == pytest.approx(0.0, abs=1e-9)
        elif out.regime == rigid.SLIDING:
            assert np.cross(u0, u1) == pytest.approx(np.zeros(3), abs=1e-9) and u0 @ u1 > 0
        e0, e1 = energy(p["v1"], p["v2"], p["w1"], p["w2"]), energy(out.v1, out.v2, out.w1, out.w2)
        if mu == 0.0:
            assert e1 == pytest.approx(e0, rel=1e-12)
        else:
            assert e1 <= e0 * (1 + 1e-12)  # friction only dissipates
    if mu == 0.0:
        assert regimes == {rigid.FRICTIONLESS}
    if mu == 5.0:
        assert regimes == {rigid.STICKING}
    if mu == 0.1:
        assert rigid.SLIDING in regimes


def test_momentum_and_angular_momentum_balance_2d_with_spin() -> None:
    s1, s2 = touching_pair_2d(0.02)
    s1, s2 = s1 + [0.3, -0.7], s2 + [0.3, -0.7]  # away from the origin: the orbital part matters
    out = rigid.impact_pair(M, R, I_SOLID, s1, [1.0, 0.2], 3.0, 2 * M, R, 2 * I_SOLID, s2, [-2.0, 0.0], -5.0,
                            mu=0.5)
    assert out.tangential_impulse > 0

    def lz(s: np.ndarray, v: np.ndarray, w: float, m: float, i: float) -> float:
        return m * (s[0] * v[1] - s[1] * v[0]) + i * w

    v1, v2 = np.array([1.0, 0.2]), np.array([-2.0, 0.0])
    before = lz(s1, v1, 3.0, M, I_SOLID) + lz(s2, v2, -5.0, 2 * M, 2 * I_SOLID)
    after = lz(s1, out.v1, out.w1[0], M, I_SOLID) + lz(s2, out.v2, out.w2[0], 2 * M, 2 * I_SOLID)
    assert after == pytest.approx(before, rel=1e-12)
    assert M * out.v1 + 2 * M * out.v2 == pytest.approx(M * v1 + 2 * M * v2)


@pytest.mark.parametrize("mu", [0.0, 0.1, 0.5])
def test_2d_and_3d_agree(mu: float) -> None:
    s1, s2 = touching_pair_2d(0.03)
    args2 = (M, R, I_SOLID, s1, [1.0, 0.0], 3.0, M, R, I_SOLID, s2, [-2.0, 0.0], -5.0)
    args3 = (M, R, I_SOLID, [*s1, 0.0], [1.0, 0.0, 0.0], [0, 0, 3.0], M, R, I_SOLID, [*s2, 0.0],
             [-2.0, 0.0, 0.0], [0, 0, -5.0])
    a = rigid.impact_pair(*args2, mu=mu)
    b = rigid.impact_pair(*args3, mu=mu)
    assert a.regime == b.regime
    assert b.v1[:2] == pytest.approx(a.v1) and b.v2[:2] == pytest.approx(a.v2)
    assert b.v1[2] == 0.0 and b.w1[:2] == pytest.approx([0.0, 0.0])
    assert b.w1[2] == pytest.approx(a.w1[0]) and b.w2[2] == pytest.approx(a.w2[0])


def test_rigid_outcome_of_textbook_scenes_is_the_textbook_answer() -> None:
    # The scene files carry the textbook set-ups: the rigid limit must give docs/design.md section 8's numbers.
    glancing = rigid.rigid_outcome(load_scene("textbook-glancing"))
    speeds = np.linalg.norm(glancing.v, axis=1)
    assert speeds == pytest.approx([5 * math.cos(math.radians(37)), 5 * math.sin(math.radians(37))], rel=1e-9)
    unequal = rigid.rigid_outcome(load_scene("textbook-unequal"))
    assert np.linalg.norm(unequal.v, axis=1) == pytest.approx([math.sqrt(2), math.sqrt(6) / 3], rel=1e-9)
    v2 = unequal.v[1]
    assert math.degrees(math.atan2(abs(v2[0]), abs(v2[1]))) == pytest.approx(54.7356, abs=1e-4)
    one_d = rigid.rigid_outcome(load_scene("textbook-1d"))
    assert one_d.v[:, 0] == pytest.approx([0.66, 1.86], rel=1e-12) and one_d.w.shape == (2, 0)


def test_rigid_outcome_regimes_and_shapes() -> None:
    bonus = rigid.rigid_outcome(load_scene("demo-bonus"))
    assert bonus.regime == rigid.STICKING and bonus.v.shape == (2, 2) and bonus.w.shape == (2, 1)
    slides = rigid.rigid_outcome(load_scene("demo-bonus", ["contact.mu=0.01"]))
    assert slides.regime == rigid.SLIDING
    wall = parse_scene({"dim": 3, "contact": {"mu": 0.8, "eps": 0.0},
                        "body": [{"name": "b", "mass": M, "radius": R, "position": [0, 0.1, 0],
                                  "velocity": [1.0, -1.0, 0.0]}],
                        "wall": [{"point": [0, 0, 0], "normal": [0, 1, 0]}]})
    out = rigid.rigid_outcome(wall)
    assert out.regime == rigid.STICKING and out.v.shape == (1, 3) and out.w.shape == (1, 3)
    assert out.v[0] == pytest.approx([5 / 7, 1.0, 0.0])


def test_rigid_outcome_refuses_what_it_cannot_do() -> None:
    three = parse_scene({"dim": 2, "body": [{"name": f"b{i}", "mass": 1.0, "radius": 0.1,
                                             "position": [i * 1.0, 0.0]} for i in range(3)]})
    with pytest.raises(ValueError, match="2 spheres"):
        rigid.rigid_outcome(three)
    falling = parse_scene({"dim": 2, "gravity": [0.0, -9.81], "body": [
        {"name": "a", "mass": 1.0, "radius": 0.1, "position": [0.0, 0.0]},
        {"name": "b", "mass": 1.0, "radius": 0.1, "position": [1.0, 0.0]}]})
    with pytest.raises(ValueError, match="gravity"):
        rigid.rigid_outcome(falling)


def test_softness_estimate_scales_as_inverse_root_k() -> None:
    base = rigid.softness_estimate(load_scene("demo-2d-stationary"))
    stiff = rigid.softness_estimate(load_scene("demo-2d-stationary", ["contact.k=100000.0"]))
    assert stiff == pytest.approx(base / 10, rel=1e-9)
    assert rigid.softness_estimate(load_scene("demo-1d")) == 0.0
