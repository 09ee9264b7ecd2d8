"""What the browser test modules share: their marks (skipped where Playwright or Debian's
chromium is missing) and one browser per module, closed before that module's server stops."""

from __future__ import annotations

import pytest

from viewer.testing import CHROMIUM, hide_notifications, launch, open_page, wait_until

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
def app(tmp_path_factory):
    """A viewer server on demo-bonus for a browser test module, saving into a scratch folder (a
    module that needs another scene or folder defines its own `app`)."""
    from viewer.app import ViewerApp

    app = ViewerApp("demo-bonus", host="127.0.0.1", port=0, recordings_dir=tmp_path_factory.mktemp("recordings"))
    app.start()
    yield app
    app.stop()


@pytest.fixture
def page(browser, app):
    """A fresh 1280 x 800 tab on the module's server, closed (and its session gone) after the test."""
    page = open_page(browser, app, width=1280, height=800)
    hide_notifications(page)
    yield page
    page.close()
    wait_until(lambda: page.session.client.client_id not in app.sessions, 30, "the tab to close")


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
