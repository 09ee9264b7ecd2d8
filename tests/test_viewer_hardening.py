"""Issue 14 for the viewer, in a real browser against a real `collide view` process: damaged
uploads (one of which aborts rerun's reader) leave the server running with one line of
feedback and no file behind; a refused 250 MB upload does not stay in the server's memory."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import BROWSER_MARKS, sync_playwright
from viewer.testing import hide_notifications, upload, visible_text, wait_until

pytestmark = BROWSER_MARKS
ROOT = Path(__file__).resolve().parent.parent
CRASH = ROOT / "tests" / "data" / "viewer-reader-crash.rrd"


def rss_mb(pid: int) -> float:
    text = Path(f"/proc/{pid}/status").read_text()
    return int(re.search(r"VmRSS:\s+(\d+) kB", text).group(1)) / 1024


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """`collide view` as the user runs it, in its own process."""
    folder = tmp_path_factory.mktemp("recordings")
    proc = subprocess.Popen([sys.executable, "-m", "cli.main", "view", "demo-bonus", "--port", "0",
                             "--recordings", str(folder)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    line = proc.stdout.readline()
    match = re.search(r"(http://127\.0\.0\.1:\d+)", line)
    assert match, (line, proc.stderr.read() if proc.poll() is not None else "")
    proc.url, proc.folder = match.group(1), folder
    yield proc
    proc.terminate()
    proc.wait(30)


@pytest.fixture(scope="module")
def page(server):
    from viewer.testing import launch

    with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(server.url)
        page.wait_for_function("() => document.body.innerText.includes('simulated in')", timeout=60_000)
        hide_notifications(page)
        yield page
        browser.close()


def upload_button(page) -> str:
    """The upload button's uuid (read from the page: the server is another process)."""
    return page.evaluate("""() => [...document.querySelectorAll('input[type=file]')]
                            .map(i => i.id.replace('file_upload_', ''))[0]""")


class _Handle:  # what viewer.testing.upload needs of a handle
    def __init__(self, uuid: str) -> None:
        self._impl = type("Impl", (), {"uuid": uuid})()


def damaged_recordings(tmp: Path) -> dict[str, bytes]:
    from collide.recording import write_recording
    from collide.run import run_scene
    from collide.scene import load_scene

    good = write_recording(run_scene(load_scene("demo-1d")), tmp / "good.rrd").read_bytes()
    flipped = bytearray(good)
    for i in range(100, len(flipped), len(flipped) // 7):
        flipped[i] ^= 0x10
    return {"crash.rrd": CRASH.read_bytes(), "truncated.rrd": good[: len(good) // 3], "flipped.rrd": bytes(flipped),
            "noise.rrd": os.urandom(50_000), "header-only.rrd": good[:64]}


def test_server_survives_every_damaged_upload(server, page, tmp_path):
    button = _Handle(upload_button(page))
    for name, content in damaged_recordings(tmp_path).items():
        upload(page, button, name, content)
        stem = name.removesuffix(".rrd")
        page.wait_for_function(f"() => document.body.innerText.includes('Cannot open {stem}.rrd')", timeout=90_000)
        assert server.poll() is None, f"the server died on {name}"
        text = visible_text(page)
        line = next(ln for ln in text.splitlines() if f"Cannot open {stem}.rrd" in ln)
        assert ".upload-" not in line and str(server.folder) not in line
        if name == "crash.rrd":
            assert "crashed" in line and "damaged" in line
    # Nothing left behind, and the server still simulates.
    assert list(server.folder.iterdir()) == []
    box = page.locator("label").filter(has_text=re.compile(r"^k \(N/m\)$")).first.locator(
        "xpath=ancestor::div[contains(@class,'mantine-Flex-root')][1]").locator("input:visible").first
    box.click()
    box.press("Control+a")
    box.press_sequentially("1800", delay=30)
    page.wait_for_function("() => document.body.innerText.includes('simulated in') && "
                           "!document.body.innerText.includes('Not run')", timeout=60_000)
    wait_until(lambda: "1800" in box.input_value(), 10, "the typed k")
    assert server.poll() is None


def test_a_refused_large_upload_does_not_stay_in_memory(server, page, tmp_path):
    """Issue 14, item 7: a refused 250 MB upload took the server from 84 to 584 MB, for good."""
    big = tmp_path / "big.rrd"
    with big.open("wb") as f:
        f.truncate(250 * 2**20)  # sparse: no 250 MB in this test's memory either
    before = rss_mb(server.pid)
    page.set_input_files(f'[id="file_upload_{upload_button(page)}"]', files=[str(big)])
    page.wait_for_function("() => document.body.innerText.includes('Upload refused')", timeout=60_000)
    assert "above the 200 MB limit" in visible_text(page)
    # The browser still sends every part; wait until it is done, then look at the server.
    time.sleep(5)
    peak = rss_mb(server.pid)
    page.wait_for_timeout(15_000)
    after = rss_mb(server.pid)
    assert max(peak, after) - before < 60, (before, peak, after)
    assert list(server.folder.iterdir()) == []
    assert server.poll() is None
