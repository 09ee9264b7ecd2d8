"""Viewer latency and replay rate: a slider change to the new run drawn, for every built-in
scene; and a 1 000-sphere run replayed frame by frame.

    python benchmarks/bench_viewer_latency.py [--repeats 9] [--no-browser] [--replay FILE.rrd | --synthetic N]
                                              [--seconds 10] [--only latency|replay|many|lod]

Starts the viewer in-process (127.0.0.1, any free port), opens it in headless Chromium
(Debian's /usr/bin/chromium through Playwright) unless --no-browser.

Latency, per built-in scene of at most 200 bodies (gas-box and pile, 1 000 spheres, are runs of
seconds to minutes that go to the background) at its default settings, contact.k (a Hertz scene
has none: its restitution, or where the materials set every contact's (break-3d) the first
material's or pair's) moved back and forth `repeats` times.
Each change goes through the same path as a user's: the session reads the values, the worker
re-simulates, the 3D scene, plots, values table and status are redrawn and flushed. Printed
per scene (medians, milliseconds):

  first    change -> the first run drawn and flushed, server side: what a drag shows (the
           scene's own run, or a coarse preview when its own run takes more than 80 ms)
  final    change -> the scene's own run drawn, when a preview came first (it runs once the
           slider has rested for 0.3 s: a drag shows previews, the release refines)
  browser  change -> the browser holds the new plot data (adds transfer and React/uPlot work)
  preview  how many of the changes were answered by a preview first
  sim      the first run's simulate() wall time;  prepare  its ViewRun (sampling, plots, residuals)
  draw     its scene + plot + table + status messages

Level of detail (`--only lod --synthetic N`, default 100 000): a synthetic pile of N spheres (one
second of frames at 30 a second) shown as `collide view` shows frames: how it is drawn (points
above 20 000 bodies), the time until the page shows it, the server's peak memory.

Replay: a real recording (`--replay`, default recordings/gas-box.rrd when it exists: 1 000
spheres, 78 506 steps; `collide run gas-box` writes it), opened as `collide view FILE` opens
it (read in a child process, then prepared), or a synthetic pile of N spheres (`--synthetic N`,
`viewer.frames.settling_pile`: frames, not physics), played for `seconds` with force chains
and colour by contact count, the player asked for 30 and then 120 frames a second. Printed:
the time to read and prepare the recording, frame updates sent per second (server side:
positions, colours, shadows and chains of every sphere queued to the browser), and the
server's work per frame (median, 95th percentile) with the rate it allows. Without a browser
the session draws into the server's scene with no client connected: the server columns only.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

from collide.scene import builtin_names, load_scene  # noqa: E402
from viewer.app import ViewerApp  # noqa: E402
from viewer.frames import settling_pile  # noqa: E402
from viewer.reading import read_untrusted  # noqa: E402
from viewer.state import MEASURING, ViewRun  # noqa: E402
from viewer.testing import CHROMIUM, ServerClient, launch, screenshot_dir  # noqa: E402

DEFAULT_REPLAY = Path("recordings/gas-box.rrd")
PLOT_SUM_JS = """() => {
    const charts = Object.values(window.__viserTestpoints?.uplots || {}).map(u => u.chart);
    const c = charts.find(c => (c.root.innerText || '').startsWith('energy'));
    if (!c) return null;
    let s = 0; for (const a of c.data.slice(1)) for (const x of a) s += x; return s;
}"""


def median_ms(values: list[float]) -> str:
    return f"{statistics.median(values) * 1e3:8.1f}" if values else "     n/a"


def bench_scene(session, page, name: str, repeats: int) -> dict[str, list[float]]:
    print(f"  {name}...", file=sys.stderr, flush=True)
    session.load_scene(name)
    session.worker.wait_idle(120)
    # contact.k; a Hertz scene has none: its restitution, or the first material's or pair's own
    # when the materials set every contact's (break-3d).
    usable = [p.ident for p in session.controls.params if not p.unused]
    key = next(k for k in usable if k == "contact.k" or k.endswith(".restitution"))
    k0 = float(session.values[key])
    out: dict[str, list[float]] = {k: [] for k in ("first", "final", "browser", "preview", "sim", "prepare", "draw")}
    for r in range(repeats):
        n_before = len(session.timings)
        before = page.evaluate(PLOT_SUM_JS) if page is not None else None
        # What a slider drag sets (a restitution moves down: 1 is its top).
        up, down = (0.98, 0.96) if key.endswith("restitution") else (1.02, 0.98)
        session.values[key] = k0 * (up if r % 2 == 0 else down)
        t0 = time.perf_counter()
        session.request_run()
        browser_t = None
        if page is not None:
            try:
                page.wait_for_function(f"() => {{ const f = {PLOT_SUM_JS}; const v = f(); "
                                       f"return v !== null && v !== {before!r}; }}", polling="raf", timeout=30_000)
                browser_t = time.perf_counter() - t0
            except Exception:  # the plots did not change
                browser_t = None
        session.worker.wait_idle(120)
        drawn = list(session.timings)[n_before:]
        if not drawn:
            print(f"  {name}: no run drawn ({session.error})")
            continue
        first = drawn[0]
        out["first"].append(first["total"])
        out["preview"].append(float(first["preview"]))
        if first["preview"] and len(drawn) > 1:
            out["final"].append(drawn[-1]["total"])
        out["sim"].append(first["simulate"])
        out["prepare"].append(first["prepare"])
        out["draw"].append(first["draw"])
        if browser_t is not None:
            out["browser"].append(browser_t)
    return out


def open_replay(session, spheres: int, path: Path | None) -> tuple[int, float, float]:
    """Show the run to replay: (bodies, s to read the recording, s to prepare its view)."""
    if path is None:
        run = settling_pile(spheres, duration=4.0, fps=60)
        session.show_frames(run)
        return run.n_bodies, 0.0, 0.0
    print(f"  reading {path}...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    run = read_untrusted(path)
    t1 = time.perf_counter()
    view = ViewRun(run, origin=f"recording {path.name}")
    t2 = time.perf_counter()
    session.show_recording(view, path.name)
    return view.n_bodies, t1 - t0, t2 - t1


def bench_replay(session, seconds: float) -> list[tuple[float, float, float, float]]:
    """(asked fps, frames sent per second, median and 95th-percentile work per frame in s)."""
    session.set_show(colour_by="contacts", chains=True, shadows=True)
    session.speed.value = "0.3x"
    session.loop.value = True
    rows = []
    for fps in (30.0, 120.0):
        session.fps = fps
        session.frame_times.clear()
        session.frame_costs.clear()
        session.toggle_play(True)
        time.sleep(seconds)
        session.toggle_play(False)
        times = list(session.frame_times)
        costs = list(session.frame_costs)
        rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
        rows.append((fps, rate, float(np.median(costs)), float(np.percentile(costs, 95))))
    session.fps = 30.0
    return rows


# -- many bodies: first frames, colour modes, slider changes, memory, recordings ----------------

MANY_SCENES = ("demo-bonus", "break-3d", "gas-box", "pile")
COLOURS_JS = """() => {
    const node = window.__viserSceneTree?.getState()['/bodies/spheres'];
    const c = node?.message?.props?.batched_colors;
    if (!c) return null;
    let h = c.length; for (let i = 0; i < c.length; i++) h = (Math.imul(h, 31) + c[i]) >>> 0;
    return h;
}"""
FRAME_JS = ("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame("
            "() => setTimeout(() => r(1), 0))))")


def shown(page, *texts: str, timeout: float = 600.0) -> None:
    """Wait until the page's text holds every one of `texts`, then for a frame drawn after."""
    page.wait_for_function("(texts) => texts.every(t => document.body.innerText.includes(t))", arg=list(texts),
                           timeout=timeout * 1e3, polling=50)
    page.evaluate(FRAME_JS)


def rss_mb(pid: int | None = None) -> float:
    """Resident memory of the server and its Python children (its run and reader processes; not
    Playwright's driver and browser, which this benchmark starts too), MB."""
    import psutil

    proc = psutil.Process(pid)
    total = proc.memory_info().rss
    for child in proc.children(recursive=True):
        try:
            if child.exe() == proc.exe():
                total += child.memory_info().rss
        except psutil.Error:
            pass
    return total / 1e6


def first_frames(app, session, page, repeats: int) -> dict[str, list[float]]:
    """Scene picked (what the picker calls) -> the page shows its first frame (its start for
    many bodies, else its run, its error estimate pending where it is measured), s; and -> the
    page shows its own run with its error estimate."""
    labels = {c.source: c.label for c in app.scene_choices}
    out: dict[str, list[float]] = {}
    for name in MANY_SCENES:
        for _ in range(repeats):
            session.load_scene("demo-1d", label=labels["demo-1d"])  # another scene between repeats
            shown(page, "demo-1d · 1D", "simulated in")
            session.worker.wait_idle(60)
            print(f"  first frame of {name}...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            session.load_scene(name, label=labels[name])
            page.wait_for_function("(name) => { const t = document.body.innerText; return t.includes(name + ' · ') "
                                   "&& (t.includes('at the start') || t.includes('simulated in')); }", arg=name,
                                   timeout=600_000, polling=50)
            page.evaluate(FRAME_JS)
            out.setdefault(f"{name} first", []).append(time.perf_counter() - t0)
            shown(page, f"{name} · ", "simulated in")
            # Its own run with its error estimate in (a measured one is shown first, pending).
            page.wait_for_function("(m) => !document.body.innerText.includes(m)", arg=MEASURING, timeout=600_000,
                                   polling=50)
            page.evaluate(FRAME_JS)
            out.setdefault(f"{name} run", []).append(time.perf_counter() - t0)
            session.worker.wait_idle(600)
        # What the page shows once the run is in (build/screenshots/bench-<scene>.png).
        page.screenshot(path=str(screenshot_dir() / f"bench-{name}.png"))
    return out


def colour_changes(session, page, repeats: int) -> list[float]:
    """A colour mode chosen (what the dropdown calls) -> the page holds the spheres' new colours
    and has drawn a frame, s."""
    times = []
    modes = ("contacts", "speed", "body")
    for r in range(repeats * len(modes)):
        before = page.evaluate(COLOURS_JS)
        t0 = time.perf_counter()
        session.set_show(colour_by=modes[r % len(modes)])
        page.wait_for_function(f"() => {{ const f = {COLOURS_JS}; const v = f(); "
                               f"return v !== null && v !== {before!r}; }}", timeout=300_000, polling=50)
        page.evaluate(FRAME_JS)
        times.append(time.perf_counter() - t0)
    return times


def slider_changes(session, page, changes: int) -> dict[str, list[float]]:
    """A parameter moved (the worker's path) -> the page shows the new start (preview), and ->
    the page shows the new run; the server's memory (with its children) after each."""
    usable = [p.ident for p in session.controls.params if not p.unused]
    key = "contact.mu" if "contact.mu" in usable else usable[0]
    x0 = float(session.values[key])
    out: dict[str, list[float]] = {"preview": [], "full": [], "rss": [], "server preview": [], "server full": []}
    for r in range(changes):
        print(f"  slider change {r + 1} of {changes} ({key})...", file=sys.stderr, flush=True)
        n = len(session.timings)
        session.values[key] = x0 * (0.9 if r % 2 == 0 else 1.1)
        t0 = time.perf_counter()
        session.request_run()
        shown(page, "at the start")
        out["preview"].append(time.perf_counter() - t0)
        shown(page, "simulated in")
        out["full"].append(time.perf_counter() - t0)
        session.worker.wait_idle(600)
        drawn = list(session.timings)[n:]
        if drawn and drawn[0]["preview"]:
            out["server preview"].append(drawn[0]["total"])
        if drawn and not drawn[-1]["preview"]:
            out["server full"].append(drawn[-1]["total"])
        out["rss"].append(rss_mb())
    return out


def recording_opens(session, page, folder: Path, repeats: int) -> dict[str, list[float]]:
    """The shown run written as a recording (s, against the run's own time), and the recording
    opened (what the recordings list calls) -> the page shows it, s."""
    from collide.recording import write_recording

    view = session.view
    path = folder / f"{view.name}.rrd"
    t0 = time.perf_counter()
    write_recording(view.run, path)
    out = {"write": [time.perf_counter() - t0], "run": [view.result.wall_time_s], "open": [],
           "size MB": [path.stat().st_size / 1e6]}
    for _ in range(repeats):
        session.load_scene("demo-1d")
        shown(page, "demo-1d · 1D", "simulated in")
        print("  opening the recording...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        session.open_recording(path)
        shown(page, f"recording {path.name}")
        out["open"].append(time.perf_counter() - t0)
    return out


def bench_many(repeats: int, changes: int) -> None:
    import tempfile

    from playwright.sync_api import sync_playwright

    def med(xs: list[float]) -> str:
        return f"{statistics.median(xs):.2f}" if xs else "n/a"

    def spread(xs: list[float]) -> str:
        return f"{min(xs):.2f}-{max(xs):.2f}" if xs else ""

    with tempfile.TemporaryDirectory() as tmp:
        app = ViewerApp("demo-bonus", port=0, recordings_dir=Path(tmp))
        app.start()
        try:
            with sync_playwright() as p:
                browser = launch(p)
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                t0 = time.perf_counter()
                page.goto(app.url + "/?fixedDpr=0.5")
                session = app.wait_for_session(1, timeout=120)[0]
                shown(page, "demo-bonus · ", "simulated in")
                opened = time.perf_counter() - t0
                frames = first_frames(app, session, page, repeats)
                colours = colour_changes(session, page, repeats)  # on the pile, shown last
                sliders = slider_changes(session, page, changes)
                recs = recording_opens(session, page, Path(tmp), repeats)
                browser.close()
        finally:
            app.stop()
    load = "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\nMany bodies in headless Chromium (software GL, fixedDpr=0.5), seconds, median of {repeats} "
          f"(range); {load}")
    print(f"page opened to its first run shown: {opened:.2f}")
    print(f"{'scene':<12} {'first frame':>12} {'range':>12} {'own run, error in':>18} {'range':>12}")
    for name in MANY_SCENES:
        a, b = frames[f"{name} first"], frames[f"{name} run"]
        print(f"{name:<12} {med(a):>12} {spread(a):>12} {med(b):>18} {spread(b):>12}")
    print(f"colour mode on the pile (1 000 spheres), chosen -> page has the colours: {med(colours)} "
          f"({spread(colours)}, {len(colours)} changes)")
    print(f"slider on the pile ({changes} changes): preview (its new start) in the page {med(sliders['preview'])} "
          f"({spread(sliders['preview'])}), server {med(sliders['server preview'])}; full run in the page "
          f"{med(sliders['full'])} ({spread(sliders['full'])}), server {med(sliders['server full'])}")
    print("server RSS with its children after each change (MB): "
          + ", ".join(f"{x:.0f}" for x in sliders["rss"]))
    print(f"pile recording: written in {recs['write'][0]:.2f} s after a run of {recs['run'][0]:.2f} s "
          f"({recs['size MB'][0]:.1f} MB); opened -> page shows it: {med(recs['open'])} ({spread(recs['open'])})")


def bench_lod(n: int, seconds: float = 1.0, fps: float = 30.0) -> None:
    """A synthetic pile of n spheres (`seconds` of frames at `fps`) shown in headless Chromium:
    how it is drawn (level of detail: points above scene3d.POINT_BODIES), the time from
    show_frames to the page showing it, the server's resident and peak memory (this process:
    the frames, their view and the scene sent), and a frame moved by the player."""
    import resource
    import tempfile

    from playwright.sync_api import sync_playwright

    t0 = time.perf_counter()
    run = settling_pile(n, duration=seconds, fps=fps)
    made = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        app = ViewerApp("demo-1d", port=0, recordings_dir=Path(tmp))
        app.start()
        try:
            with sync_playwright() as p:
                browser = launch(p)
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url + "/?fixedDpr=0.5")
                session = app.wait_for_session(1, timeout=120)[0]
                shown(page, "demo-1d · ", "simulated in")
                t0 = time.perf_counter()
                session.show_frames(run)
                shown(page, f"{n} bodies, {len(run.times)} frames", timeout=900)
                opened = time.perf_counter() - t0
                t0 = time.perf_counter()
                session.seek(0.5 * (run.t0 + run.t1))
                page.evaluate(FRAME_JS)
                moved = time.perf_counter() - t0
                drawn = "points" if session.drawer.points else "spheres"
                page.screenshot(path=str(screenshot_dir() / f"bench-lod-{n}.png"))
                browser.close()
        finally:
            app.stop()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
    load = "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\nSynthetic pile of {n} spheres, {len(run.times)} frames ({made:.1f} s to make), headless Chromium "
          f"(software GL, fixedDpr=0.5); {load}")
    print(f"drawn as {drawn}; shown in the page {opened:.2f} s after show_frames; a seek drawn in {moved:.2f} s; "
          f"server RSS now {rss_mb():.0f} MB, peak {peak:.0f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--no-browser", action="store_true")
    parser.add_argument("--replay", type=Path, default=None,
                        help=f"a recording to replay (default: {DEFAULT_REPLAY} if it exists)")
    parser.add_argument("--synthetic", type=int, default=None, metavar="N",
                        help="replay a synthetic pile of N spheres instead of a recording")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--only", choices=("latency", "replay", "many", "lod"), default=None)
    parser.add_argument("--changes", type=int, default=10, help="slider changes on the pile (--only many)")
    args = parser.parse_args()
    if args.only == "lod":
        if not CHROMIUM.exists():
            parser.error(f"--only lod needs {CHROMIUM}")
        bench_lod(args.synthetic or 100_000)
        return
    if args.only == "many":
        if not CHROMIUM.exists():
            parser.error(f"--only many needs {CHROMIUM}")
        bench_many(max(args.repeats, 1), args.changes)
        return
    replay_path = args.replay
    if replay_path is None and args.synthetic is None:
        replay_path = DEFAULT_REPLAY if DEFAULT_REPLAY.exists() else None
    if replay_path is not None and not replay_path.exists():
        parser.error(f"{replay_path}: no such recording (collide run gas-box writes recordings/gas-box.rrd)")
    spheres = args.synthetic or 1000
    # Slider scenes: every built-in a user would drag a slider on (1 000-sphere runs take seconds).
    names = [n for n in builtin_names(heavy=False) if len(load_scene(n).bodies) <= 200] if args.only != "replay" else []
    do_replay = args.only != "latency"
    use_browser = not args.no_browser and CHROMIUM.exists()
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        use_browser = False

    app = ViewerApp("demo-bonus", port=0, recordings_dir=Path("recordings"))
    app.start()
    results, replay, opened = {}, [], (0, 0.0, 0.0)
    try:
        if use_browser:
            with sync_playwright() as p:
                browser = launch(p)
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.goto(app.url + "/?fixedDpr=0.5")
                session = app.wait_for_session(1, timeout=60)[0]
                page.wait_for_function("() => document.body.innerText.includes('simulated in')", timeout=60_000)
                for name in names:
                    results[name] = bench_scene(session, page, name, args.repeats)
                if do_replay:
                    opened = open_replay(session, spheres, replay_path)
                    replay = bench_replay(session, args.seconds)
                browser.close()
        else:
            from viewer.session import Session

            session = Session(app.session_config(), ServerClient(app.server))  # type: ignore[arg-type]
            session.fit_camera = lambda *a, **k: None  # no camera without a browser
            for name in names:
                results[name] = bench_scene(session, None, name, args.repeats)
            if do_replay:
                opened = open_replay(session, spheres, replay_path)
                replay = bench_replay(session, args.seconds)
            session.close()
    finally:
        app.stop()

    mode = "headless Chromium (software GL, fixedDpr=0.5)" if use_browser else "no browser"
    load = "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())
    if results:
        print(f"\nViewer latency, slider change -> new run drawn; median of {args.repeats} changes of "
              f"contact.k (ms), {mode}; {load}")
        print(f"{'scene':<20} {'first':>8} {'final':>8} {'browser':>8} {'preview':>8} {'sim':>8} {'prepare':>8} "
              f"{'draw':>8}")
        for name, r in results.items():
            print(f"{name:<20} {median_ms(r['first'])} {median_ms(r['final'])} {median_ms(r['browser'])} "
                  f"{int(sum(r['preview'])):>4d}/{len(r['first']):<3d} {median_ms(r['sim'])} "
                  f"{median_ms(r['prepare'])} {median_ms(r['draw'])}")
    if not do_replay:
        return
    bodies, read_s, prepare_s = opened
    what = "synthetic pile (frames, not physics)" if replay_path is None else str(replay_path)
    print(f"\nReplay of {what} ({bodies} spheres; force chains, colour by contacts, floor "
          f"shadows), {args.seconds:g} s per row, {mode}; {load}")
    if replay_path is not None:
        print(f"opened in {read_s + prepare_s:.2f} s: read (child process) {read_s:.2f} s, "
              f"view prepared {prepare_s:.2f} s")
    print(f"{'asked fps':>10} {'sent fps':>10} {'work/frame (ms) median':>24} {'p95':>8} {'allows (fps)':>14}")
    for fps, rate, median, p95 in replay:
        print(f"{fps:10.0f} {rate:10.1f} {median * 1e3:24.1f} {p95 * 1e3:8.1f} {1 / median:14.0f}")


if __name__ == "__main__":
    main()
