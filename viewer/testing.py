"""Driving the viewer in headless Chromium (Debian's /usr/bin/chromium through Playwright).

Shared by the browser tests and `benchmarks/bench_viewer_latency.py`. Nothing here runs in a
normal `collide view`; playwright is imported only by the callers.

    with sync_playwright() as p:
        browser = launch(p)
        page = open_page(browser, app, width=1280, height=800)
"""

from __future__ import annotations

import io
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM = Path("/usr/bin/chromium")
_ROOT = Path(__file__).resolve().parents[1]


def screenshot_dir() -> Path:
    """Where the browser tests save their screenshots: build/screenshots (ignored by git), so a
    test run leaves the work tree as it found it; COLLIDE_UPDATE_DOCS=1 writes docs/'s pictures."""
    import os

    folder = _ROOT / "docs" if os.environ.get("COLLIDE_UPDATE_DOCS") == "1" else _ROOT / "build" / "screenshots"
    folder.mkdir(parents=True, exist_ok=True)
    return folder
# Flags measured to render viser's WebGL canvas headless through SwiftShader (TESTING.md).
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-quic",
                 "--no-first-run", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--disable-dev-shm-usage"]


def launch(playwright: Any) -> Any:
    """Debian's chromium, headless (never a downloaded browser)."""
    return playwright.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)


def open_page(browser: Any, app: Any, *, width: int = 1280, height: int = 800, query: str = "",
              count: int = 1) -> Any:
    """A new tab on the app, waited until its session has drawn its first run. `count` is the
    number of sessions expected once it has connected. The page's `session` attribute is that
    tab's `Session`."""
    known = set(app.sessions)
    page = browser.new_page(viewport={"width": width, "height": height}, accept_downloads=True)
    page.goto(app.url + (f"/?{query}" if query else ""))
    page.wait_for_selector("canvas", timeout=60_000)
    app.wait_for_session(count, timeout=60)
    wait_until(lambda: set(app.sessions) - known, 30, "the tab's session")
    session = app.sessions[next(iter(set(app.sessions) - known))]
    assert session.worker.wait_idle(120)
    page.wait_for_function("() => document.body.innerText.includes('simulated in') || "
                           "document.body.innerText.includes('replayed')", timeout=60_000)
    settle(page)
    page.session = session
    return page


# One frame drawn: rAF runs before a frame is drawn, the timeout after it.
_FRAME_JS = ("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame("
             "() => setTimeout(() => r(1), 0))))")


def settle(page: Any, timeout: float = 180.0, quick: float = 0.5, rounds: int = 3) -> None:
    """Wait until the page draws frames at a steady pace again: `rounds` frames in a row, none
    slower than twice the quickest of them (or than `quick` s).

    Software WebGL compiles the scene's shaders at its first frames after the page (or a new
    scene) arrives: the page's one thread is then busy for 4-8 s on a quiet machine and far
    longer under load, and the first click, scroll or locator in a test waited on it until its
    own timeout (issue 12: one browser test timed out per full run, a different one each time).
    Waiting here, once, with a long limit, leaves the tests' own waits for what they check. A
    page that is slow at every frame (1 000 spheres) is steady too."""
    deadline = time.monotonic() + timeout
    times: list[float] = []
    while True:
        last = times[-rounds:]
        if len(last) == rounds and max(last) <= max(quick, 2 * min(last)):
            return
        left = deadline - time.monotonic()
        if left <= 0:
            raise AssertionError(f"the page's frames did not settle in {timeout:g} s ({times})")
        start = time.monotonic()
        page.wait_for_function(_FRAME_JS, timeout=left * 1e3)
        times.append(time.monotonic() - start)


def wait_for_text(page: Any, *texts: str, timeout: float = 60.0) -> str:
    """Wait until the page's text holds every one of `texts`; the text then."""
    page.wait_for_function("(texts) => texts.every(t => document.body.innerText.includes(t))", arg=list(texts),
                           timeout=timeout * 1e3)
    return visible_text(page)


def focus_input(page: Any, box: Any) -> None:
    """Scroll a text input into view, focus it and select what it holds, as a click and Ctrl+A
    would, through the DOM (no wait for the element to stop moving, which rarely happens while
    software WebGL draws)."""
    box.evaluate("e => { e.scrollIntoView({block: 'center'}); e.focus(); e.select(); }")


class ServerClient:
    """Stands in for a browser tab (benchmarks and tests without a browser): a `Session` given
    it draws into the server's own scene and GUI, watched by nobody."""

    def __init__(self, server: Any) -> None:
        self.gui, self.scene, self.client_id = server.gui, server.scene, 0
        self.atomic, self.flush = server.atomic, server.flush
        self.camera = type("Camera", (), {"on_update": staticmethod(lambda cb: cb)})()


def dom_id(handle: Any) -> str:
    """The DOM id viser gives a GUI element (its uuid)."""
    return handle._impl.uuid


def wait_until(predicate: Callable[[], Any], timeout: float = 30.0, what: str = "condition") -> Any:
    """Poll `predicate` until it is truthy; its value, or AssertionError after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


_ROW = "xpath=ancestor::div[contains(@class,'mantine-Flex-root')][1]"


def text_box(page: Any, handle: Any) -> Any:
    """The <input> of a viser text element (found through its label, which points at the
    element's uuid)."""
    return page.locator(f'label[for="{dom_id(handle)}"]').locator(_ROW).locator("input:visible").first


def row_input(page: Any, label: str) -> Any:
    """The visible input in the GUI row labelled exactly `label` (what a user types into).
    viser breaks labels after '/' with <wbr>, so the match is on the text content."""
    pattern = re.compile("^" + re.escape(label) + "$")
    return page.locator("label").filter(has_text=pattern).first.locator(_ROW).locator("input:visible").first


def type_into(page: Any, handle: Any, text: str) -> None:
    """Clear a text box and type `text` key by key, as a user would."""
    box = text_box(page, handle)
    box.scroll_into_view_if_needed()
    box.click()
    box.press("Control+a")
    box.press("Backspace")
    box.press_sequentially(text, delay=30)


def click_slider(page: Any, handle: Any, fraction: float) -> None:
    """Click a slider's track at `fraction` of its width."""
    slider = page.locator(f'[id="{dom_id(handle)}"]')
    slider.scroll_into_view_if_needed()
    box = slider.bounding_box()
    page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)


def choose(page: Any, handle: Any, option: str) -> None:
    """Pick an option of a viser dropdown (a Mantine Select)."""
    box = page.locator(f'[id="{dom_id(handle)}"]')
    box.scroll_into_view_if_needed()
    box.click()
    page.get_by_role("option", name=option, exact=True).click()


def click(page: Any, handle: Any) -> None:
    """Click a viser button (or a checkbox)."""
    node = page.locator(f'[id="{dom_id(handle)}"]')
    node.scroll_into_view_if_needed()
    node.click()


def upload(page: Any, handle: Any, name: str, content: bytes, mime: str = "application/octet-stream") -> None:
    page.set_input_files(f'[id="file_upload_{dom_id(handle)}"]',
                         files=[{"name": name, "mimeType": mime, "buffer": content}])


PLOTS_JS = """() => Object.values(window.__viserTestpoints?.uplots || {}).map(u => {
    const c = u.chart;
    return {title: (c.root.querySelector('.u-title') || {}).innerText || '',
            x: [c.scales.x.min, c.scales.x.max], y: [c.scales.y?.min, c.scales.y?.max],
            data: c.data.map(a => Array.from(a)), created: u.createCount,
            axes: c.axes.map(a => a.label || ''),
            legend: [...c.root.querySelectorAll('.u-legend .u-value')].map(e => e.innerText)};
})"""


def plots(page: Any) -> dict[str, dict]:
    """Every uPlot chart on the page by title: its scales, data, axis labels and legend values."""
    return {p["title"]: p for p in page.evaluate(PLOTS_JS)}


def plot(page: Any, prefix: str) -> dict | None:
    """The chart whose title starts with `prefix`."""
    return next((p for t, p in plots(page).items() if t.startswith(prefix)), None)


def canvas_box(page: Any) -> dict:
    """The 3D canvas's bounding box on the page (x, y, width, height in CSS pixels): the
    largest canvas."""
    return page.evaluate("""() => {
        const cs = [...document.querySelectorAll('canvas')];
        cs.sort((a, b) => b.clientWidth * b.clientHeight - a.clientWidth * a.clientHeight);
        const r = cs[0].getBoundingClientRect();
        return {x: r.x, y: r.y, width: r.width, height: r.height};
    }""")


def canvas_shot(page: Any, timeout: float = 120.0) -> bytes:
    """A screenshot of the 3D canvas. (A clip of the page: a locator screenshot waits for the
    element to be "stable", which a canvas re-rendering under software GL may never be. Many
    spheres under software GL take seconds a frame: hence the long timeout.)"""
    box = canvas_box(page)
    return page.screenshot(clip=box, animations="allow", timeout=timeout * 1e3)


def image(png: bytes) -> np.ndarray:
    """A PNG as an (H, W, 3) int array."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def colour_mask(png: bytes | np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> np.ndarray:
    """Pixels within `tol` of a colour (per channel), as a boolean (H, W) mask."""
    img = image(png) if isinstance(png, bytes) else png
    return np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1)


def colour_fraction(png: bytes | np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> float:
    return float(np.mean(colour_mask(png, rgb, tol)))


def visible_text(page: Any) -> str:
    return page.evaluate("() => document.body.innerText")


def project(camera: Any, points: np.ndarray, width: float, height: float) -> np.ndarray:
    """World points (K, 3) to pixel coordinates (K, 2) in a canvas of this size, through the
    client's camera (position, look_at, up_direction, vertical fov)."""
    pos = np.asarray(camera.position, float)
    forward = np.asarray(camera.look_at, float) - pos
    forward /= np.linalg.norm(forward)
    up = np.asarray(camera.up_direction, float)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    rel = np.asarray(points, float) - pos
    z = rel @ forward
    f = 0.5 * height / np.tan(0.5 * camera.fov)
    x = width / 2 + f * (rel @ right) / z
    y = height / 2 - f * (rel @ true_up) / z
    return np.stack((x, y), axis=-1)


def group_button(page: Any, handle: Any, option: str) -> Any:
    """A button of a viser button group (found through the group's label row)."""
    row = page.locator(f'label[for="{dom_id(handle)}"]').locator(_ROW)
    return row.get_by_role("button", name=option, exact=True)


def hide_notifications(page: Any) -> None:
    """Hide toasts (viser's "Software WebGL rendering detected" covers the 3D view)."""
    page.add_style_tag(content=".mantine-Notifications-root{display:none !important}")


def scroll_to_text(page: Any, text: str) -> None:
    """Scroll the GUI so an element holding `text` is in view (plain DOM: no waiting for the
    page to be idle, which a page drawing many spheres under software GL rarely is)."""
    page.evaluate("""(text) => {
        const all = [...document.querySelectorAll('div, p, span')]
            .filter(e => e.innerText && e.innerText.includes(text));
        const inner = all.filter(e => ![...e.children].some(c => c.innerText && c.innerText.includes(text)));
        if (inner.length) inner[0].scrollIntoView({block: 'center'});
    }""", text)
