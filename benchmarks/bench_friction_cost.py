"""What friction costs the event engine (issue 9: the billiards break with mu = 0.1 against the
frictionless one; issue 10: a ball set down sliding on a floor against demo-bonus, the break
turned into a tilted plane against the 2D one, and a stiff oblique wall impact with spin about a
skew axis, whose slip turns as it slides, against the same impact in a 2D scene). Each run is
timed twice: the kernel alone (`wall_time_s` of a run whose error is not measured) and as
`collide run` does it (error measured where the model does not cover it). Runs of the scenes
alternate within one process, the compiled kernels loaded first; prints medians and ratios,
never asserts.

    python benchmarks/bench_friction_cost.py [--repeat 7] [--tol 1e-6] [--variants] [--cli 9] [--scan 40 [--eps]]

--variants adds other breaks, each against its frictionless twin: at mu = 0.1 the rack turned
30 degrees in its plane, balls 1.3 times larger (same density) and the cue at 3 m/s; and breaks
with more friction mode changes: the cue ball 0.5, 1 and 2 cm off the rack's line (every mode
changes at its own time), mu = 0.2 and 0.4; and a true 3D break, the cue 5 mm above the rack's
plane (its contacts leave the plane: the 3D kicks' cost, not the bar's planar break).

--cli N also times the breaks that `--set` can make as a user runs them: `collide run
billiards-break --json --no-record` in a fresh process each, N rounds alternating, `wall_time_s`
(its error measured as always) medians and ratios; a process's one run finds colder caches than
runs repeated in one process.

--scan N times N random breaks at mu = 0.1 against their twins (the cue up to 3 cm off the
rack's line, the rack turned by any angle, balls 0.7 to 1.4 times the size, the cue at half to
twice its speed, and with `--eps` the friction band's half-width drawn from 1e-7 to 1e-4 m/s,
log-uniform, where the scene's is 1e-6; `--seed`), 5 alternating rounds each, and prints every
ratio and the worst.
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time compiled kernels (waited for), not a fresh install's interpreted

import argparse
import json
import math
import random
import statistics
import subprocess
import sys
import time

from collide.run import run_scene
from collide.scene import load_scene, parse_scene, turned_source

# The --variants breaks: `--set` overrides, and in_plane changes (turned, scaled, slower).
VARIANTS = {"rack turned 30 deg": ([], {"angle": math.pi / 6}), "balls 1.3x larger": ([], {"size": 1.3}),
            "cue at 3 m/s": ([], {"speed": 0.5}), "cue 0.5 cm off-centre": (["body.cue.position.y=0.005"], {}),
            "cue 1 cm off-centre": (["body.cue.position.y=0.01"], {}),
            "cue 2 cm off-centre": (["body.cue.position.y=0.02"], {}),
            "mu = 0.2": (["contact.mu=0.2"], {}), "mu = 0.4": (["contact.mu=0.4"], {}),
            "cue 5 mm above the rack's plane (3D)": ([], {"lift": 0.005})}


def rolling_ball(tol: float):
    """A ball (m 0.1 kg, r 0.05 m, k 1e7 N/m, mu 0.3) set down touching a floor, sliding at 1 m/s."""
    return parse_scene({
        "name": "rolling-ball", "dim": 3, "dt": "auto", "integrator": "kahan6", "tol": tol, "duration": 0.5,
        "gravity": [0.0, 0.0, -9.81], "contact": {"k": 1e7, "mu": 0.3},
        "wall": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
        "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [0.0, 0.0, 0.05],
                  "velocity": [1.0, 0.0, 0.0]}],
    })


def wall_impact(dim: int):
    """A ball (m 0.1 kg, r 0.05 m) hitting a wall at k = 1e12 N/m, mu 0.3, tol 1e-8: 1.2 m/s into
    it and 0.9 m/s along it, spinning at 20 rad/s; in 3D the wall is tilted and the spin's axis
    skew (the slip turns as it slides), in 2D the spin is about z."""
    if dim == 3:
        normal = [0.36, -0.48, 0.8]
        along, spin = [0.0, 0.8575, 0.5145], [14.0, 9.0, -11.0]
    else:
        normal, along, spin = [0.6, 0.8], [-0.8, 0.6], 20.0
    return parse_scene({
        "name": f"wall-impact-{dim}d", "dim": dim, "tol": 1e-8, "contact": {"k": 1e12, "mu": 0.3},
        "wall": [{"point": [0.0] * dim, "normal": normal}],
        "body": [{"name": "ball", "mass": 0.1, "radius": 0.05, "position": [0.06 * x for x in normal],
                  "velocity": [-1.2 * a + 0.9 * b for a, b in zip(normal, along)], "spin": spin}],
    })


def tilted(scene):
    """The scene turned as a whole by 0.7 rad about (1, 2, 0.5): its plane is no longer z = 0."""
    return parse_scene(turned_source(scene.source))


def in_plane(source: dict, angle: float = 0.0, size: float = 1.0, speed: float = 1.0, lift: float = 0.0) -> dict:
    """A 2D scene's source turned by `angle` (rad) about the origin, its lengths times `size` (masses
    times size^3: the same density) and its velocities times `speed`; with `lift` (m), a 3D scene
    whose first body (the cue) is that far above the others' plane: its contacts leave the plane."""
    c, s = math.cos(angle), math.sin(angle)

    def turned(vector: list, factor: float) -> list[float]:
        return [factor * (c * vector[0] - s * vector[1]), factor * (s * vector[0] + c * vector[1])]

    bodies = [dict(b, position=turned(b["position"], size), velocity=turned(b["velocity"], speed),
                   radius=b["radius"] * size, mass=b["mass"] * size ** 3) for b in source["body"]]
    if lift:
        bodies = [dict(b, position=[*b["position"], lift if k == 0 else 0.0], velocity=[*b["velocity"], 0.0])
                  for k, b in enumerate(bodies)]
        return dict(source, dim=3, body=bodies)
    return dict(source, body=bodies)


def timed(scene, measure: bool) -> tuple[float, float, int, int]:
    """(kernel seconds, whole call seconds, steps, whole steps tried) of one run."""
    start = time.perf_counter()
    run = run_scene(scene, record=False, measure=measure)
    whole = time.perf_counter() - start
    return run.result.wall_time_s, whole, int(run.result.steps[0]), int(run.result.attempts[0])


def cli_wall_time(sets: list[str], tol: float) -> float:
    """`wall_time_s` of one `collide run billiards-break --json --no-record` in a fresh process."""
    overrides = [arg for item in sets for arg in ("--set", item)]
    out = subprocess.run([sys.executable, "-m", "cli.main", "run", "billiards-break", "--tol", str(tol), "--json",
                          "--no-record", *overrides], capture_output=True, text=True, check=True).stdout
    return float(json.loads(out)["wall_time_s"])


def cli_ratios(rounds: int, tol: float) -> None:
    """The breaks `--set` makes, each against its frictionless twin, one process a run."""
    variants = {"built-in": [], **{label: sets for label, (sets, change) in VARIANTS.items() if not change}}
    times: dict[tuple[str, bool], list[float]] = {}
    for _ in range(rounds):
        for label, sets in variants.items():
            for friction in (True, False):
                twin = [] if friction else ["contact.mu=0"]
                times.setdefault((label, friction), []).append(cli_wall_time(sets + twin, tol))
    print(f"\n`collide run billiards-break --tol {tol:g} --json --no-record`, a fresh process each, "
          f"medians of {rounds} alternating rounds, ms of wall_time_s (error measured)")
    print("| break | with friction | frictionless twin | ratio |")
    print("|---|---|---|---|")
    for label in variants:
        a, b = statistics.median(times[label, True]), statistics.median(times[label, False])
        print(f"| {label} | {a * 1e3:.2f} | {b * 1e3:.2f} | {a / b:.1f} |")


def scan(count: int, seed: int, tol: float, vary_eps: bool) -> None:
    """`--scan`: random breaks at mu = 0.1, each against its frictionless twin."""
    rng = random.Random(seed)
    print(f"\n{count} random breaks (seed {seed}), tol {tol:g}, mu 0.1 against 0: medians of 5 alternating rounds")
    print("| cue off the line (cm) | rack turned (deg) | size | cue speed | eps (m/s) | kernel ratio | as run ratio |")
    print("|---|---|---|---|---|---|---|")
    kernel, as_run = [], []
    for _ in range(count):
        offset = rng.uniform(-0.03, 0.03)
        change = {"angle": rng.uniform(0.0, math.pi), "size": rng.choice([0.7, 1.0, 1.4]),
                  "speed": rng.choice([0.5, 1.0, 2.0])}
        eps = 10.0 ** rng.uniform(-7.0, -4.0) if vary_eps else 1e-6
        sets = [f"tol={tol}", f"body.cue.position.y={offset}", f"contact.eps={eps}"]
        scenes = [parse_scene(in_plane(load_scene("billiards-break", [*sets, f"contact.mu={mu}"]).source, **change))
                  for mu in (0.1, 0.0)]
        for scene in scenes:
            timed(scene, True)
        times: dict[tuple[int, bool], list[float]] = {}
        for _ in range(5):
            for measure in (False, True):
                for which, scene in enumerate(scenes):
                    times.setdefault((which, measure), []).append(timed(scene, measure)[0])
        med = {key: statistics.median(value) for key, value in times.items()}
        kernel.append(med[0, False] / med[1, False])
        as_run.append(med[0, True] / med[1, True])
        print(f"| {100 * offset:+.2f} | {math.degrees(change['angle']):.0f} | {change['size']} | {change['speed']} "
              f"| {eps:.2g} | {kernel[-1]:.2f} | {as_run[-1]:.2f} |")
    print(f"kernel ratio: median {statistics.median(kernel):.2f}, worst {max(kernel):.2f}; "
          f"as run: median {statistics.median(as_run):.2f}, worst {max(as_run):.2f} (bar 5x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--variants", action="store_true", help="also breaks with more mode changes")
    parser.add_argument("--cli", type=int, default=0, metavar="N",
                        help="also N rounds of the breaks as `collide run` in fresh processes")
    parser.add_argument("--scan", type=int, default=0, metavar="N", help="also N random breaks against their twins")
    parser.add_argument("--seed", type=int, default=1, help="the --scan breaks' random seed")
    parser.add_argument("--eps", action="store_true", help="--scan also draws the friction band's half-width")
    args = parser.parse_args()
    cases = {
        "billiards-break mu = 0.1": load_scene("billiards-break", [f"tol={args.tol}"]),
        "billiards-break mu = 0": load_scene("billiards-break", [f"tol={args.tol}", "contact.mu=0"]),
        "billiards-break mu = 0.1, tilted plane (3D)": tilted(load_scene("billiards-break", [f"tol={args.tol}"])),
        "rolling ball, 0.5 s": rolling_ball(args.tol),
        "demo-bonus": load_scene("demo-bonus"),
        "wall impact, skew spin (3D)": wall_impact(3),
        "wall impact (2D)": wall_impact(2),
    }
    pairs = [("billiards-break mu = 0.1", "billiards-break mu = 0", "bar 5x"),
             ("rolling ball, 0.5 s", "demo-bonus", "bar 50x"),
             ("billiards-break mu = 0.1, tilted plane (3D)", "billiards-break mu = 0.1", "about 1x"),
             ("wall impact, skew spin (3D)", "wall impact (2D)", "comparable")]
    variants = VARIANTS if args.variants else {}
    for label, (sets, change) in variants.items():
        with_friction, twin = f"billiards-break, {label}", f"billiards-break, {label}: its frictionless twin"
        for name, mu in ((with_friction, []), (twin, ["contact.mu=0"])):
            scene = load_scene("billiards-break", [f"tol={args.tol}", *sets, *mu])
            cases[name] = parse_scene(in_plane(scene.source, **change)) if change else scene
        bar = "mu above the bar's 0.1" if "mu" in label else ("out of the plane: not the bar's break" if "3D" in label
                                                             else "bar 5x")
        pairs.append((with_friction, twin, bar))
    for scene in cases.values():
        timed(scene, True)  # load the compiled kernels, outside the clock
    figures: dict[str, dict[bool, list]] = {name: {False: [], True: []} for name in cases}
    for _ in range(args.repeat):
        # Every run follows another scene's, in both columns: a run timed right after itself
        # found its data in the caches (demo-bonus 0.08 ms against 0.12 ms).
        for measure in (False, True):
            for name, scene in cases.items():
                figures[name][measure].append(timed(scene, measure))
    med = {name: {m: statistics.median(x[0] for x in runs[m]) for m in runs} for name, runs in figures.items()}
    print(f"tol {args.tol:g} (demo-bonus at its own), medians of {args.repeat}, ms of wall_time_s")
    print("| run | steps | whole steps tried | kernel, error not measured | as `collide run` (error measured) |")
    print("|---|---|---|---|---|")
    for name, runs in figures.items():
        print(f"| {name} | {runs[False][0][2]} | {runs[False][0][3]} | {med[name][False] * 1e3:.2f} "
              f"| {med[name][True] * 1e3:.2f} |")
    for a, b, bar in pairs:
        print(f"{a} / {b}: {med[a][False] / med[b][False]:.1f}x unmeasured, "
              f"{med[a][True] / med[b][True]:.1f}x as run ({bar})")
    if args.cli:
        cli_ratios(args.cli, args.tol)
    if args.scan:
        scan(args.scan, args.seed, args.tol, args.eps)


if __name__ == "__main__":
    main()
