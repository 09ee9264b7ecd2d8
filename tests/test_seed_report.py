"""`--integrator seed` at the report's time steps reproduces every printed digit of its tables."""

from __future__ import annotations

from decimal import Decimal
from functools import cache

import numpy as np
import pytest

from collide.run import SceneRun, run_scene
from collide.scene import load_scene
from collide.summary import csv_table, run_summary
from tests.data.report_tables import FINALS, TABLES, TRUNCATED


@cache
def seed_run(scene: str, dt: float) -> SceneRun:
    return run_scene(load_scene(scene), integrator="seed", dt=dt)


def matches_printed(value: float, printed: str, truncated: bool = False) -> bool:
    """Agrees with the printed number to its last printed digit: rounded (the report used %f
    and its tables drop trailing zeros, so within half a unit of the last printed place), or
    cut towards zero where the table truncated its numbers."""
    unit = 10.0 ** Decimal(printed).as_tuple().exponent
    shown = float(printed)
    if truncated:
        return abs(shown) - 1e-12 <= abs(value) < abs(shown) + unit and (value * shown >= 0)
    return abs(value - shown) <= 0.5 * unit * (1 + 1e-9)


@pytest.mark.parametrize("figure, scene, dt, times, columns, rows", TABLES, ids=[t[0] for t in TABLES])
def test_table_rows(figure, scene, dt, times, columns, rows):
    names, table = csv_table(seed_run(scene, dt), np.array(times), layout="report")
    mismatches = []
    for r, printed_row in enumerate(rows):
        for column, printed in zip(columns, printed_row):
            value = table[r, names.index(column)]
            if not matches_printed(value, printed, (figure, column) in TRUNCATED):
                mismatches.append(f"row {r + 1} {column}: {value:.7f} vs printed {printed}")
    assert not mismatches, f"{figure}: " + "; ".join(mismatches)


@pytest.mark.parametrize("figure, scene, dt, finals", FINALS, ids=[f[0] for f in FINALS])
def test_final_conditions(figure, scene, dt, finals):
    summary = run_summary(seed_run(scene, dt))
    bodies = {b["name"]: b for b in summary["bodies"]}
    for key, printed in finals.items():
        name, field = key.split(".")
        value = np.atleast_1d(bodies[name][field])
        for component, text in zip(value, printed):
            assert matches_printed(component, text), f"{figure} {key}: {component:.7f} vs {text}"


def test_matching_is_strict():
    """The comparison can fail: one unit in the last printed digit is a mismatch."""
    assert matches_printed(-2.0046824, "-2.004682")
    assert not matches_printed(-2.004681, "-2.004682")
    assert not matches_printed(0.0129, "0.0127")
    assert matches_printed(-10.674836, "-10.67483", truncated=True)
    assert not matches_printed(-10.674836, "-10.67484", truncated=True)
