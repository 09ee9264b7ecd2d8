"""What the browser test modules share: their marks (skipped where Playwright or Debian's
chromium is missing) and one browser per module, closed before that module's server stops."""

from __future__ import annotations

import pytest

from viewer.testing import CHROMIUM, launch

try:
    from playwright.sync_api import sync_playwright
except ImportError:  # pragma: no cover - depends on the machine
    sync_playwright = None

BROWSER_MARKS = [
    pytest.mark.browser,
    pytest.mark.skipif(sync_playwright is None, reason="the playwright Python package is not installed "
                       "(pip install playwright; never `playwright install`)"),
    pytest.mark.skipif(not CHROMIUM.exists(), reason="/usr/bin/chromium is missing (apt-get install -y chromium)"),
]


@pytest.fixture(scope="module")
def browser(app):
    with sync_playwright() as p:
        browser = launch(p)
        yield browser
        browser.close()  # before the server stops: an open connection makes stop() wait


@pytest.fixture
def measuring_runs(monkeypatch) -> list[float]:
    """The tolerances of the runs a measured run starts to measure its error (collide.run's
    tighter runs, `measure=False`), in order."""
    import collide.run as run_module

    tolerances: list[float] = []
    real = run_module.run_scenes

    def counting(scenes, **kwargs):
        if kwargs.get("measure") is False:
            tolerances.append(kwargs["tol"])
        return real(scenes, **kwargs)

    monkeypatch.setattr(run_module, "run_scenes", counting)
    return tolerances
