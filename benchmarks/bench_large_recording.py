"""Benchmark: where a large recording's memory and time go, writing it and opening it in the viewer.

    python benchmarks/bench_large_recording.py write SCENE [--set KEY=VALUE ...] --out FILE.rrd
    python benchmarks/bench_large_recording.py view FILE.rrd [--shot PNG]
    python benchmarks/bench_large_recording.py open FILE.rrd [--repeats R] [--shot PNG]

`write`: one fresh process loads the scene, runs it once tiny (the compiled kernels loaded: the
baseline), then runs it recorded and writes the recording; a thread samples the process's
resident memory every 10 ms and prints the peak above the baseline in each phase (the run, the
writer's frames, each entity, the trajectory's tables, the seal, the check). A 100 000-sphere
bed pressed from the first step (every frame full of contacts), the pour's spheres on a lattice:

    python benchmarks/bench_large_recording.py write benchmarks/data/pour-bed.toml --set duration=0.025 --out bed.rrd

`open`: `collide view FILE` as a user runs it, a fresh process each time, repeated: seconds from
the command to the server listening (its banner), to headless Chromium (already running, as a
user's browser is) showing the recording's first frame (its start, the status saying the rest is
still loading) and to its run shown; the CPU seconds of the server, of its reader process and
of every reader (a replacement included) by then, and each one's peak resident memory (the
kernel's VmHWM); medians and ranges, and the load average before and after. The pile's recording:

    collide run pile --out /tmp/pile.rrd
    python benchmarks/bench_large_recording.py open /tmp/pile.rrd --repeats 5

`view`: a viewer server in this process and headless Chromium open the recording (what the
recordings list calls): seconds to the server's prepared run and to the page showing it, the
server's peak memory above its baseline and the reader process's. Prints figures; asserts nothing.
"""

from __future__ import annotations

import os
import resource
import threading
import time
from pathlib import Path

os.environ.setdefault("COLLIDE_JIT", "1")
os.environ.setdefault("COLLIDE_THREADS", "2")
PAGE = os.sysconf("SC_PAGE_SIZE")


def _rss() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 1e6


def bench_write(name: str, sets: list[str], out: Path) -> None:
    from collide import recording as rec
    from collide.recording import writer as rec_writer
    from collide.run import run_scene
    from collide.scene import load_scene

    phase, peaks, order, stop = ["import"], {}, [], []

    def sample() -> None:
        while not stop:
            p, r = phase[0], _rss()
            if p not in peaks:
                order.append(p)
                peaks[p] = r
            peaks[p] = max(peaks[p], r)
            time.sleep(0.01)

    def label(owner, attr: str, text: str) -> None:  # noqa: ANN001 - a class or module
        f = getattr(owner, attr)

        def labelled(*a, **k):  # noqa: ANN002, ANN003, ANN202
            before = phase[0]
            phase[0] = text
            try:
                return f(*a, **k)
            finally:
                phase[0] = before
        setattr(owner, attr, labelled)

    for attr in ("_prepare", "_write_static", "_write_bodies", "_write_contacts", "_write_conserved", "_write_steps",
                 "_write_meta", "check"):
        label(rec_writer._Writer, attr, attr.strip("_"))
    label(rec_writer, "_seal", "seal")
    threading.Thread(target=sample, daemon=True).start()
    phase[0] = "warm-up"
    run_scene(load_scene(name, sets + ["fill.0.count=8", "duration=0.0002"]), record=True)
    phase[0] = "baseline"
    time.sleep(0.05)
    base = _rss()
    phase[0] = "run"
    wall, cpu = time.perf_counter(), time.process_time()
    run = run_scene(load_scene(name, sets), record=True)
    t_run, c_run = time.perf_counter() - wall, time.process_time() - cpu
    phase[0] = "after the run"
    time.sleep(0.05)
    traj = run.result.trajectory
    phase[0] = "write: encoding, the file"
    wall, cpu = time.perf_counter(), time.process_time()
    rec.write_recording(run, out)
    t_w, c_w = time.perf_counter() - wall, time.process_time() - cpu
    phase[0] = "end"
    time.sleep(0.05)
    stop.append(1)
    print(f"{run.scene.name}: {run.result.model.n_bodies} bodies, {int(run.result.steps[0])} steps, "
          f"{len(traj.knot_times)} frames, {len(traj.knots)} knots, {len(traj.records)} records, "
          f"{len(traj.intervals)} intervals; {out.stat().st_size / 1e6:.1f} MB; load {os.getloadavg()[0]:.1f}")
    print(f"run {t_run:.1f} s wall, {c_run:.1f} s CPU; write {t_w:.1f} s wall, {c_w:.1f} s CPU")
    print(f"baseline {base:.0f} MB; peak resident memory above it by phase (MB):")
    for p in order[order.index("run"):]:
        print(f"  {p:28s} {peaks[p] - base:8.0f}")
    print(f"  process peak (ru_maxrss) {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - base:.0f} above it")


def bench_view(path: Path, shot: str | None) -> None:
    import psutil
    from playwright.sync_api import sync_playwright

    from viewer.app import ViewerApp
    from viewer.testing import launch, open_page, settle

    me = psutil.Process()
    peak, stop = {"server": 0.0, "reader": 0.0}, []

    def children() -> float:
        total = 0.0
        for child in me.children(recursive=True):
            try:
                if child.exe() == me.exe():
                    total += child.memory_info().rss / 1e6
            except psutil.Error:
                pass
        return total

    def sample() -> None:
        while not stop:
            peak["server"] = max(peak["server"], me.memory_info().rss / 1e6)
            peak["reader"] = max(peak["reader"], children())
            time.sleep(0.02)

    app = ViewerApp("demo-1d", host="127.0.0.1", port=0, recordings_dir=path.parent)
    app.start()
    with sync_playwright() as p:
        browser = launch(p)
        page = open_page(browser, app, width=1280, height=800, query="fixedDpr=0.6")
        session = page.session
        time.sleep(2)
        base, base_reader = me.memory_info().rss / 1e6, children()
        threading.Thread(target=sample, daemon=True).start()
        wall, cpu = time.perf_counter(), time.process_time()
        ok = session.open_recording(path)
        t_server = time.perf_counter() - wall
        print(f"{path.name}: opened {ok} in {t_server:.1f} s (load {os.getloadavg()[0]:.1f}); "
              f"server peak {peak['server'] - base:.0f} MB above its {base:.0f} MB", flush=True)
        if not ok:
            stop.append(1)
            print("  " + session.panel.status.content.replace("\n", " ")[:300])
            browser.close()
            app.stop()
            return
        page.wait_for_function("(t) => document.body.innerText.includes(t)", arg=f"recording {path.name}",
                               timeout=900_000, polling=100)
        page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame("
                      "() => setTimeout(() => r(1), 0))))")
        t_page, cpu = time.perf_counter() - wall, time.process_time() - cpu
        stop.append(1)
        print(f"{path.name}: opened {ok}, {session.view.n_bodies} bodies, drawn as points: {session.drawer.points}; "
              f"load {os.getloadavg()[0]:.1f}")
        print(f"  server prepared it in {t_server:.1f} s, the page shows it at {t_page:.1f} s "
              f"(server CPU {cpu:.1f} s)")
        print(f"  server RSS {base:.0f} MB before, peak {peak['server'] - base:.0f} MB above; reader process "
              f"{base_reader:.0f} MB before, peak {peak['reader']:.0f} MB")
        if shot:
            settle(page)
            page.screenshot(path=shot)
        browser.close()
    app.stop()


BODIES_JS = ("() => { const s = window.__viserSceneTree?.getState(); "
             "return !!(s && (s['/bodies/spheres'] || s['/bodies/points'])); }")


def _status_kb(pid: int, key: str) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return float(line.split()[1])
    except OSError:
        pass
    return float("nan")


def _watch(pid: int, seen: dict[int, tuple[float, float]], stop: list) -> None:
    """CPU seconds and peak RSS (MB) of the server's reader processes, by pid, while they live (a
    reader grown by a large file is replaced by a fresh one once it has answered)."""
    import psutil

    server = psutil.Process(pid)
    while not stop:
        try:
            for child in server.children(recursive=True):
                if "_serve_reads" in " ".join(child.cmdline()):
                    times = child.cpu_times()
                    seen[child.pid] = (times.user + times.system, _status_kb(child.pid, "VmHWM") / 1024)
        except psutil.Error:
            pass
        time.sleep(0.05)


def _open_once(browser, path: Path, command: list[str], cwd: Path) -> dict[str, float]:  # noqa: ANN001 - a Playwright browser
    """One `collide view FILE`: its figures (s, CPU s, MB). The first frame is the recording's
    start while the rest loads, or its run where the viewer shows nothing before it."""
    import subprocess

    import psutil

    from viewer.testing import _FRAME_JS

    start = time.perf_counter()
    proc = subprocess.Popen([*command, "view", str(path.resolve()), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=cwd)
    out: dict[str, float] = {}
    seen: dict[int, tuple[float, float]] = {}
    stop: list = []
    threading.Thread(target=_watch, args=(proc.pid, seen, stop), daemon=True).start()
    try:
        line = proc.stdout.readline()
        out["listening"] = time.perf_counter() - start
        url = line.split(" at ")[-1].split()[0]
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(url + "/?fixedDpr=0.6")
        page.wait_for_function("(t) => ['bodies at the start', t].some(x => document.body.innerText.includes(x))",
                               arg=f"Replaying {path.name}", timeout=600_000, polling=50)
        page.wait_for_function(BODIES_JS, timeout=600_000, polling=50)  # the bodies in the page's scene
        page.evaluate(_FRAME_JS)
        page.evaluate(_FRAME_JS)  # a frame with them drawn (their mesh is built at the first)
        out["first frame"] = time.perf_counter() - start
        page.wait_for_function("(t) => document.body.innerText.includes(t)", arg=f"Replaying {path.name}",
                               timeout=900_000, polling=50)
        page.evaluate(_FRAME_JS)
        out["run shown"] = time.perf_counter() - start
        server = psutil.Process(proc.pid)
        times = server.cpu_times()
        out["server CPU"] = times.user + times.system
        out["server peak MB"] = _status_kb(proc.pid, "VmHWM") / 1024
        stop.append(1)
        time.sleep(0.1)
        out["reader CPU"] = max((cpu for cpu, _ in seen.values()), default=float("nan"))
        out["all readers CPU"] = sum(cpu for cpu, _ in seen.values())  # a replacement reader's too
        out["reader peak MB"] = max((mb for _, mb in seen.values()), default=float("nan"))
        page.close()
    finally:
        stop.append(1)
        proc.terminate()
        proc.wait(60)
    return out


def bench_open(path: Path, repeats: int, shot: str | None, vs: Path | None) -> None:
    import statistics
    import sys

    from playwright.sync_api import sync_playwright

    from viewer.testing import launch

    here = Path(__file__).resolve().parents[1]
    checkouts = [here] + ([vs.resolve()] if vs else [])
    print(f"collide view {path} ({path.stat().st_size / 1e6:.1f} MB), {repeats} fresh processes"
          f"{' each, alternated: ' + ' against '.join(map(str, checkouts)) if vs else ''}; {os.cpu_count()} cores; "
          f"load before {os.getloadavg()[0]:.1f}", flush=True)
    rows: dict[Path, list[dict[str, float]]] = {c: [] for c in checkouts}
    with sync_playwright() as p:
        browser = launch(p)
        for k in range(repeats):
            for checkout in checkouts:
                python = checkout / ".venv" / "bin" / "python"
                command = [str(python) if python.exists() else sys.executable, "-m", "cli.main"]
                rows[checkout].append(_open_once(browser, path, command, checkout))
                print(f"  {checkout.name} {k + 1}: " + ", ".join(f"{key} {value:.2f}"
                                                              for key, value in rows[checkout][-1].items()), flush=True)
        if shot:
            _shots(browser, path, [sys.executable, "-m", "cli.main"], shot)
        browser.close()
    print(f"medians of {repeats} (range); load after {os.getloadavg()[0]:.1f}")
    for checkout, got in rows.items():
        print(f"  {checkout}:")
        for key in got[0]:
            values = [r[key] for r in got]
            unit = "MB" if "MB" in key else "s"
            print(f"    {key:16s} {statistics.median(values):8.2f} {unit} ({min(values):.2f}-{max(values):.2f})")


def _shots(browser, path: Path, command: list[str], shot: str) -> None:  # noqa: ANN001 - a Playwright browser
    """Screenshots of the page while the recording loads and once its run is shown."""
    import subprocess

    proc = subprocess.Popen([*command, "view", str(path), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().split(" at ")[-1].split()[0]
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(url + "/?fixedDpr=0.6")
        page.wait_for_function("() => document.body.innerText.includes('bodies at the start')", timeout=600_000)
        page.screenshot(path=shot.replace(".png", "-loading.png"))
        page.wait_for_function("(t) => document.body.innerText.includes(t)", arg=f"Replaying {path.name}",
                               timeout=900_000)
        page.evaluate("() => new Promise(r => setTimeout(r, 1500))")
        page.screenshot(path=shot.replace(".png", "-loaded.png"))
        page.close()
    finally:
        proc.terminate()
        proc.wait(60)


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    write = sub.add_parser("write")
    write.add_argument("scene")
    write.add_argument("--set", action="append", default=[])
    write.add_argument("--out", type=Path, required=True)
    view = sub.add_parser("view")
    view.add_argument("recording", type=Path)
    view.add_argument("--shot")
    opening = sub.add_parser("open")
    opening.add_argument("recording", type=Path)
    opening.add_argument("--repeats", type=int, default=5)
    opening.add_argument("--shot", help="also save FILE-loading.png and FILE-loaded.png")
    opening.add_argument("--vs", type=Path, help="another checkout (its .venv) to alternate with, run by run")
    args = parser.parse_args()
    if args.what == "write":
        bench_write(args.scene, args.set, args.out)
    elif args.what == "open":
        bench_open(args.recording, args.repeats, args.shot, args.vs)
    else:
        bench_view(args.recording, args.shot)


if __name__ == "__main__":
    main()
