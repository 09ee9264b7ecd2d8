"""Screenshot the viewer on the 1 000-sphere recordings, in headless Chromium (TESTING.md):
`python scripts/viewer_screenshots.py` writes docs/viewer-gas-box.png and
docs/viewer-background-run.png.

Needs recordings/gas-box.rrd and recordings/pile.rrd (`collide run gas-box`, `collide run pile`).
gas-box mid-run, coloured by speed; pile settled with its force chains, a slider moved so that
its run of a minute goes to the background (the progress line and the Stop button show), then
stopped.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from playwright.sync_api import sync_playwright  # noqa: E402

from viewer.app import ViewerApp  # noqa: E402
from viewer.testing import (  # noqa: E402
    hide_notifications,
    launch,
    open_page,
    scroll_to_text,
    settle,
    wait_for_text,
    wait_until,
)


@contextmanager
def viewer_page(browser, recording: Path) -> Iterator:
    """A 1280 x 800 page of a viewer on `recording`, notifications hidden; the viewer stops after."""
    app = ViewerApp(str(recording), port=0)
    app.start()
    try:
        page = open_page(browser, app, width=1280, height=800)
        hide_notifications(page)
        yield page
        page.close()
    finally:
        app.stop()


def gas_box(browser, recording: Path, out: Path) -> None:
    with viewer_page(browser, recording) as page:
        session = page.session
        session.seek(0.25)
        session.set_show(colour_by="speed", chains=False)
        wait_for_text(page, "colour: speed")
        scroll_to_text(page, "colour: speed")
        settle(page)
        page.wait_for_timeout(3000)
        page.screenshot(path=str(out), timeout=180_000)


def background_run(browser, recording: Path, out: Path) -> None:
    with viewer_page(browser, recording) as page:
        session = page.session
        session.seek(session.view.t1)
        session.set_show(colour_by="contacts", chains=True)
        settle(page)
        session.values["contact.mu"] = 0.3
        session.request_run()
        wait_for_text(page, f"Running {session.view.name}", "simulated", timeout=180)
        scroll_to_text(page, f"Running {session.view.name}")
        page.wait_for_timeout(4000)
        page.screenshot(path=str(out), timeout=180_000)
        session.stop_run()
        wait_until(lambda: session.worker.idle(), 60, "the run to stop")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gas-box", type=Path, default=ROOT / "recordings" / "gas-box.rrd")
    parser.add_argument("--pile", type=Path, default=ROOT / "recordings" / "pile.rrd")
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    args = parser.parse_args()
    with sync_playwright() as p:
        browser = launch(p)
        gas_box(browser, args.gas_box, args.out / "viewer-gas-box.png")
        background_run(browser, args.pile, args.out / "viewer-background-run.png")
        browser.close()


if __name__ == "__main__":
    main()
