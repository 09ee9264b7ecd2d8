"""Stiff and extreme cases (issue 4): each matches a closed form or the rigid limit, or is refused
with a message naming the cause; the step count per contact does not grow with stiffness."""

from __future__ import annotations

import math

import pytest

from collide import stress
from collide.run import run_scene
from collide.scene import parse_scene

CASES = stress.cases()


@pytest.mark.parametrize("case", CASES, ids=[f"{c.group}: {c.setting}" for c in CASES])
def test_case(case: stress.Case) -> None:
    result = stress.run_case(case)
    assert result.verdict == "PASS", f"{result.outcome}; error {result.error}, tolerance {result.tolerance}"
    if case.kind == "refuse":
        assert "too soft" in result.outcome and "\n" not in result.outcome
    else:
        assert result.error is not None and math.isfinite(result.error)


def test_steps_per_contact_do_not_grow_with_stiffness() -> None:
    steps = []
    for k in (1500.0, 1e6, 1e12):
        scene = parse_scene({**stress.head_on(stress.M, stress.M, 1.0, -2.0, k), "dt": "auto"})
        steps.append(int(run_scene(scene, record=False).result.steps[0]))
    assert max(steps) - min(steps) <= 1, steps
