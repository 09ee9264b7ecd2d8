"""The work-precision study: observed orders match each integrator's order (frictionless)."""

from __future__ import annotations

import numpy as np
import pytest

from collide.accuracy import Point, WorkPrecision, plot_work_precision, work_precision
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


def test_the_observed_order_leaves_out_round_off() -> None:
    """A sixth-order ladder that levels off at 1e-11 and rises again at many steps (a Newton's
    cradle's kahan6): the slope is the converging part's, not 0.87 from the flat tail."""
    wp = WorkPrecision("ladder", 1.0, np.zeros(1), 0.0)
    for omega_dt in (1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001, 0.0003, 0.0001):
        error = max(1e-5 * omega_dt ** 6, 2e-12 * (0.03 / omega_dt) ** 0.5)
        wp.points.append(Point("kahan6", omega_dt, omega_dt, int(1 / omega_dt), 0.0, error))
    assert wp.orders()["kahan6"] == pytest.approx(6.0, abs=0.1)
