"""Viewer latency: from a slider change to the new run drawn, for every built-in scene.

    python benchmarks/bench_viewer_latency.py [--repeats 9] [--no-browser]

Starts the viewer in-process (127.0.0.1, any free port), opens it in headless Chromium
(Debian's /usr/bin/chromium through Playwright) and, per scene at its default settings, moves
the contact.k slider back and forth `repeats` times. Each change goes through the same path as
a user's: the session reads the controls, the worker re-simulates, the 3D scene, plots and
status are redrawn and flushed to the browser. Printed per scene (medians, milliseconds):

  server   change -> run drawn and flushed (what the viewer controls)
  browser  change -> the browser holds the new plot data (adds transfer and React/uPlot work)
  sim      the core's simulate() wall time;  prepare  ViewRun (sampling, plots, residuals)
  draw     scene + plot + status messages;   first    change -> first run drawn (a preview when
           the full run is expected to take longer than the preview budget)

Without a browser (--no-browser, or when Chromium/Playwright are missing) the session draws
into the server's scene with no client connected: the server column only.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from collide.scene import builtin_names  # noqa: E402
from viewer.app import ViewerApp  # noqa: E402

CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-quic",
        "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--disable-dev-shm-usage"]
PLOT_SUM_JS = """() => {
    const charts = Object.values(window.__viserTestpoints?.uplots || {}).map(u => u.chart);
    const c = charts.find(c => (c.root.innerText || '').startsWith('energy'));
    if (!c) return null;
    let s = 0; for (const a of c.data.slice(1)) for (const x of a) s += x; return s;
}"""


class _ServerClient:
    """Stands in for a browser tab: the session draws into the server's (unwatched) scene."""

    def __init__(self, server) -> None:
        self.gui, self.scene, self.client_id = server.gui, server.scene, 0
        self.atomic, self.flush = server.atomic, server.flush
        self.camera = type("Camera", (), {"on_update": staticmethod(lambda cb: cb)})()


def median_ms(values: list[float]) -> str:
    return f"{statistics.median(values) * 1e3:8.1f}" if values else "     n/a"


def bench_scene(session, page, name: str, repeats: int) -> dict[str, list[float]]:
    session.load_scene(name)
    session.worker.wait_idle(120)
    handle = session._param_handles["contact.k"]
    k0 = float(handle.value)
    out: dict[str, list[float]] = {k: [] for k in ("server", "browser", "first", "sim", "prepare", "draw")}
    for r in range(repeats):
        n_before = len(session.timings)
        before = page.evaluate(PLOT_SUM_JS) if page is not None else None
        handle.value = k0 * (1.02 if r % 2 == 0 else 0.98)  # what a slider drag sets
        t0 = time.perf_counter()
        session.request_run()
        browser_t = None
        if page is not None:
            page.wait_for_function(f"() => {{ const f = {PLOT_SUM_JS}; const v = f(); "
                                   f"return v !== null && v !== {before!r}; }}", polling="raf", timeout=60_000)
            browser_t = time.perf_counter() - t0
        session.worker.wait_idle(120)
        drawn = list(session.timings)[n_before:]
        if not drawn:
            print(f"  {name}: no run drawn ({session.error})")
            continue
        final = drawn[-1]
        out["server"].append(final["total"])
        out["first"].append(drawn[0]["total"])
        out["sim"].append(final["simulate"])
        out["prepare"].append(final["prepare"])
        out["draw"].append(final["draw"])
        if browser_t is not None:
            out["browser"].append(browser_t)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--no-browser", action="store_true")
    args = parser.parse_args()
    use_browser = not args.no_browser and CHROMIUM.exists()
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        use_browser = False

    app = ViewerApp("demo-bonus", port=0, recordings_dir=Path("recordings"))
    app.start()
    results = {}
    try:
        if use_browser:
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url + "/?fixedDpr=0.5")
                session = app.wait_for_session(1, timeout=60)[0]
                page.wait_for_function("() => document.body.innerText.includes('simulated in')", timeout=60_000)
                for name in builtin_names():
                    results[name] = bench_scene(session, page, name, args.repeats)
                browser.close()
        else:
            from viewer.session import Session

            session = Session(app, _ServerClient(app.server))  # type: ignore[arg-type]
            session.fit_camera = lambda *a, **k: None  # no camera without a browser
            for name in builtin_names():
                results[name] = bench_scene(session, None, name, args.repeats)
            session.close()
    finally:
        app.stop()

    mode = "headless Chromium (software GL)" if use_browser else "no browser"
    print(f"\nViewer latency, slider change -> new run drawn; median of {args.repeats} changes of "
          f"contact.k (ms), {mode}")
    print(f"{'scene':<20} {'server':>8} {'browser':>8} {'first':>8} {'sim':>8} {'prepare':>8} {'draw':>8}")
    for name, r in results.items():
        print(f"{name:<20} {median_ms(r['server'])} {median_ms(r['browser'])} {median_ms(r['first'])} "
              f"{median_ms(r['sim'])} {median_ms(r['prepare'])} {median_ms(r['draw'])}")


if __name__ == "__main__":
    main()
