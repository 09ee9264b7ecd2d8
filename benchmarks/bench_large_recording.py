"""Benchmark: where a large recording's memory and time go, writing it and opening it in the viewer.

    python benchmarks/bench_large_recording.py write SCENE [--set KEY=VALUE ...] --out FILE.rrd
    python benchmarks/bench_large_recording.py view FILE.rrd [--shot PNG]

`write`: one fresh process loads the scene, runs it once tiny (the compiled kernels loaded: the
baseline), then runs it recorded and writes the recording; a thread samples the process's
resident memory every 10 ms and prints the peak above the baseline in each phase (the run, the
writer's frames, each entity, the trajectory's tables, the seal, the check). A 100 000-sphere
bed pressed from the first step (every frame full of contacts), the pour's spheres on a lattice:

    python benchmarks/bench_large_recording.py write benchmarks/data/pour-bed.toml --set duration=0.025 --out bed.rrd

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
    args = parser.parse_args()
    if args.what == "write":
        bench_write(args.scene, args.set, args.out)
    else:
        bench_view(args.recording, args.shot)


if __name__ == "__main__":
    main()
