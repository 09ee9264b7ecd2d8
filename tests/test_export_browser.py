"""The viewer's export downloads in a real browser: VTK (a zip), TOML and MP4, as `collide export`
makes them. Headless Chromium; one server for the module."""

from __future__ import annotations

import tomllib
import zipfile
from pathlib import Path

import pytest

from tests.conftest import BROWSER_MARKS
from viewer.testing import group_button, settle, wait_until

pytestmark = BROWSER_MARKS


def _download(page, session, label: str, timeout_ms: int = 120_000) -> tuple[str, Path]:
    with page.expect_download(timeout=timeout_ms) as info:
        group_button(page, session.export_buttons, label).click()
    return info.value.suggested_filename, Path(info.value.path())


def test_export_downloads(page):
    session = page.session
    wait_until(lambda: session.view is not None and session.worker.idle(), 120, "demo-bonus")
    settle(page)
    name, path = _download(page, session, "VTK")
    assert name == "demo-bonus-vtk.zip"
    names = zipfile.ZipFile(path).namelist()
    assert "demo-bonus.pvd" in names and sum(n.endswith(".vtp") for n in names) > 2
    name, path = _download(page, session, "TOML")
    assert name == "demo-bonus.toml" and tomllib.loads(path.read_text())["name"] == "demo-bonus"
    pytest.importorskip("imageio_ffmpeg")
    name, path = _download(page, session, "MP4")
    assert name == "demo-bonus.mp4" and path.read_bytes()[4:8] == b"ftyp"
