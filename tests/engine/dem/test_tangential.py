"""The tangential laws (collide/engine/dem/tangential.py): Coulomb slip through a whole impact, the
history spring's reversal, against closed forms."""

from __future__ import annotations

import math

import pytest

from collide import diagnostics as dg
from collide.run import run_scene
from collide.scene import parse_scene
from tests.dem_scenes import _wall_scene


@pytest.mark.parametrize("angle", [70.0, 80.0, 85.0])
def test_oblique_impact_in_gross_sliding_matches_rigid_body(angle):
    """A sphere sliding through the whole impact (Chung & Ooi test 4, their e = 0.98): the
    tangential speed drops by mu (1 + e) v_n and the spin grows by 5/2 of that over r (solid
    sphere), within 1 %. (With strong damping the contact pulls as it ends, which friction does
    not follow, so the friction impulse exceeds mu times the net normal impulse: README.)"""
    speed, mu, e, r = 3.9, 0.3, 0.98, 0.1
    vn, vt = speed * math.cos(math.radians(angle)), speed * math.sin(math.radians(angle))
    # Gross sliding needs the slip not to reverse: vt > 7/2 mu (1 + e) vn.
    assert vt > 3.5 * mu * (1 + e) * vn
    raw = _wall_scene(restitution=e, mu=mu)
    raw["body"][0]["velocity"] = [vt, 0.0, -vn]
    raw["dt"] = 1e-7
    result = run_scene(parse_scene(raw), record=False).result
    v, w = result.final.v[0, 0], result.final.w[0, 0]
    dv = mu * (1 + e) * vn
    assert v[0] == pytest.approx(vt - dv, rel=1e-2)
    assert v[2] == pytest.approx(e * vn, rel=1e-2)
    assert w[1] == pytest.approx(2.5 * dv / r, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-5


def test_tangential_spring_without_slip_reverses_the_contact_point_as_the_closed_form_says():
    """Linear normal and tangential springs, no slip, no damping: the contact point's tangential
    speed u oscillates at omega_t = sqrt(3.5 k_t / m) (a solid sphere on a wall) while the normal
    contact lasts pi / omega_n, so u_out = u_in cos(pi sqrt(3.5 k_t / k_n)): -u_in at the
    classic k_t / k_n = 2/7 (Chung & Ooi's near-sticking regime: the rebound reverses the slip,
    which Coulomb slip cannot). No slip needs u_in < 3.5 mu v_n. Within 1 % at 3000 steps per
    contact; the energy balance includes what the spring holds."""
    raw = _wall_scene(model="linear", k=1e7, mu=0.3, tangential="spring")
    raw["body"][0]["velocity"] = [0.02, 0.0, -0.2]
    raw["dt"] = 1e-6
    result = run_scene(parse_scene(raw), record=False).result
    v, w, r = result.final.v[0, 0], result.final.w[0, 0], 0.1
    assert v[0] - w[1] * r == pytest.approx(-0.02, rel=1e-2)
    assert dg.residuals(result).energy[0] < 1e-6
