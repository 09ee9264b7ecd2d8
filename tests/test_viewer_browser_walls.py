"""Walls drawn where the scene puts them after a scene change, in a real browser (Debian's
chromium through Playwright, headless): picking break-3d (one wall, its floor) and then the pile
(five walls) drew the pile's first side wall flat, in the pose break-3d's floor of the same node
name had, because viser leaves a node's default pose unsent and the browser kept the old one.

What is checked is the browser's own scene graph: each wall box's turn and place as three.js
holds them, against the wall (point, normal) of the scene shown.
"""

from __future__ import annotations

import numpy as np

from tests.conftest import BROWSER_MARKS
from viewer.testing import canvas_shot, choose, screenshot_dir, wait_for_text, wait_until

pytestmark = BROWSER_MARKS

# Each wall box in the scene's own frame (z up): the browser's root turns z up into three.js's y
# up, so each box's world matrix is taken relative to the root's. Column 0 is the box's x axis
# (its thickness, along the wall's normal), column 3 its centre.
WALLS_JS = """() => {
    const m = window.__viserMutable, root = m.nodeRefFromName[''];
    if (!root) return null;
    root.updateWorldMatrix(true, true);
    const undo = root.matrixWorld.clone().invert(), out = {};
    for (const [name, obj] of Object.entries(m.nodeRefFromName)) {
        if (!obj || !name.startsWith('/world/walls/')) continue;
        const e = obj.matrixWorld.clone().premultiply(undo).elements;
        out[name] = {x: [e[0], e[1], e[2]], centre: [e[12], e[13], e[14]],
                     dims: window.__viserSceneTree.getState()[name]?.message?.props?.dimensions};
    }
    return out;
}"""
FRAME_JS = "() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(1))))"


def _pick(page, name: str, walls: int) -> dict:
    """Pick a scene in the page's picker; the browser's wall boxes once it shows that scene's
    `walls` walls and has drawn two frames after."""
    session = page.session
    choose(page, session.panel.picker, name)
    wait_for_text(page, f"{name} · ", timeout=300)
    wait_until(lambda: session.view is not None and session.view.scene.name == name, 300, name)
    wait_until(lambda: len(page.evaluate(WALLS_JS) or {}) == walls, 120, f"{name}'s {walls} walls in the browser")
    page.evaluate(FRAME_JS)
    page.evaluate(FRAME_JS)
    return page.evaluate(WALLS_JS)


def _check_walls(drawn: dict, session) -> None:
    walls = session.view.walls
    assert sorted(drawn) == [f"/world/walls/{k}" for k in range(len(walls))]
    for k, (point, normal) in enumerate(walls):
        box = drawn[f"/world/walls/{k}"]
        x = np.asarray(box["x"], float)
        assert np.allclose(x, normal, atol=1e-6), f"wall {k} (normal {normal}) is drawn with its normal along {x}"
        # Its face lies on the wall's plane: the centre half a thickness behind it.
        behind = float(np.dot(np.asarray(box["centre"], float) - point, normal))
        assert abs(behind + 0.5 * float(box["dims"][0])) <= 1e-6 * max(1.0, float(box["dims"][1])), (k, behind)


def test_pile_after_break_3d_draws_every_wall_upright(page):
    session = page.session
    drawn = _pick(page, "break-3d", 1)
    _check_walls(drawn, session)
    drawn = _pick(page, "pile", 5)
    (screenshot_dir() / "walls-pile-after-break-3d.png").write_bytes(canvas_shot(page))
    _check_walls(drawn, session)
    # And back: break-3d's one floor again, the pile's side walls gone.
    _check_walls(_pick(page, "break-3d", 1), session)
