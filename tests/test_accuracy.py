"""The work-precision study: observed orders match each integrator's order (frictionless)."""

from __future__ import annotations

import pytest

from collide.accuracy import plot_work_precision, work_precision
from collide.scene import load_scene


@pytest.fixture(scope="module")
def study():
    return work_precision(load_scene("demo-2d-moving"), ("seed", "verlet", "yoshida4"), repeats=1,
                          time_budget_s=0.5)


def test_observed_orders(study) -> None:
    orders = study.orders()
    assert orders["seed"] == pytest.approx(1.0, abs=0.3)
    assert orders["verlet"] == pytest.approx(2.0, abs=0.3)
    assert orders["yoshida4"] == pytest.approx(4.0, abs=0.5)
    assert study.reference_check < 1e-11


def test_higher_order_wins_at_equal_step(study) -> None:
    by = {(p.integrator, p.omega_dt): p.error for p in study.points}
    assert by[("yoshida4", 0.1)] < by[("verlet", 0.1)] < by[("seed", 0.1)]


def test_plot_is_written(study, tmp_path) -> None:
    path = tmp_path / "wp.png"
    plot_work_precision(study, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
