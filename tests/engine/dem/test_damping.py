"""Damping for a restitution (collide/engine/dem/damping.py): the restitution out equals the one in."""

from __future__ import annotations

import pytest

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import parse_scene
from tests.dem_scenes import _wall_scene


@pytest.mark.parametrize("model", ["linear", "hertz"])
@pytest.mark.parametrize("e", [0.1, 0.3, 0.6, 0.9, 1.0])
def test_restitution_out_equals_restitution_in(model, e):
    """Damping chosen for e gives e (force not clipped: a contact may pull as it ends), within
    1 % at 3000+ steps per contact; the work of the dashpot keeps the energy balance."""
    raw = _wall_scene(model=model, restitution=e, k=1e7)
    raw["dt"] = 1e-6 if model == "linear" else 2e-7
    result = run_scene(parse_scene(raw), record=False).result
    assert result.final.v[0, 0, 2] / 0.2 == pytest.approx(e, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-5
    damping = result.dissipation[0, 0]
    assert damping == pytest.approx(0.5 * 10.0 * 0.2**2 * (1 - e**2), rel=2e-2, abs=1e-12)
