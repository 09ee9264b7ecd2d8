"""Substeps and kicks (collide/engine/event/substep.py): an implicit kick's root for a slide out of
the plane."""

from __future__ import annotations

from tests.tolerance_ladders import _tolerance_ladder


def test_a_slide_out_of_the_plane_keeps_its_kick_root():
    """Six spinning spheres on a floor in 3D. An implicit kick started from the last kick's
    friction instead of none settled, for a slide out of the plane, on the kick's other root:
    runs at 1e-10 and 1e-11 then differed by 6.6e-6 (against 8e-10 before). Such kicks start
    cold; the ladder must converge."""
    tight, = _tolerance_ladder("warm-slide-3d", (1e-10,))
    assert tight < 1e-7
