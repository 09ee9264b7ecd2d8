"""A sphere alone on a floor through a whole run (collide/alone.py), as `collide run` gives it: for
ten bounces of the built-in bounce's ball (Hertz at E = 1e9 Pa, or a linear spring of 1e6 N/m,
thrown at 0.3 m/s along the floor from 1 m), the JSON's wall_time_s (every run the measurement
took, and the first run alone), the error method and estimate, the most steps a contact took,
and the rebound speeds' largest error against the same run at a 100 times finer tolerance; then
the built-in bounce at --tol 1e-9 against a run at 1e-11. Prints Markdown tables. With
--variants, ten bounces at --tol 1e-9 over the restitution, the stiffness and the speed
(thrown down onto the floor): wall_time_s and the rebound speeds' largest error against DOP853's
chain of the same law at rtol 1e-13 (tests/test_event_laws.py's `reference_contact`).

    .venv/bin/python benchmarks/bench_bounce_run.py [--repeat 11] [--variants]
"""

from __future__ import annotations

import os

os.environ.setdefault("COLLIDE_JIT", "1")  # time the compiled kernels

import argparse
import math
import statistics
import sys
from pathlib import Path

import numpy as np

from collide.dem import damping_ratio
from collide.engine import layout
from collide.engine.event import impact as im
from collide.measure import outcome_distance
from collide.run import run_scene
from collide.scene import load_scene, parse_scene

G = 9.81


def ten_bounces(hertz: bool, e: float) -> dict:
    contact = {"model": "hertz", "youngs_modulus": 1e9, "poisson_ratio": 0.45} if hertz else {"k": 1e6}
    contact["restitution"] = e
    # Ten contacts: the first fall, the contacts and the nine flights between, and half the tenth's
    # flight after it (the contacts' times from the kernel at a tight tolerance).
    mass = 4.0 / 3.0 * math.pi * 0.03**3 * 1100.0
    zeta = float(damping_ratio(np.array(e), hertz))
    params = im.impact_params(hertz=hertz, mstar=mass, k=1e6, estar=1e9 / (1 - 0.45**2), rstar=0.03, zeta=zeta,
                              accel=G)
    v = math.sqrt(2 * G)
    duration = v / G
    for bounce in range(10):
        out = im.normal_impact(params, v, 1e-12)
        v = out[im.O_VOUT]
        duration += out[im.O_TIME] + (2 * v / G if bounce < 9 else 0.5 * v / G)
    return {"dim": 2, "duration": duration, "gravity": [0.0, -G], "contact": contact,
            "body": [{"name": "ball", "radius": 0.03, "mass": 4.0 / 3.0 * math.pi * 0.03**3 * 1100.0,
                      "position": [0.0, 1.03],
                      "velocity": [0.3, 0.0]}],
            "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}


def rebounds(run) -> np.ndarray:
    traj = run.result.trajectory
    k = traj.knots
    rows = [np.flatnonzero((k[:, layout.K_T] == end) & (k[:, layout.K_FREE] == 1.0))[0]
            for end in traj.intervals[:, layout.V_END]]
    return k[rows, layout.K_V + 1]


def steps_per_contact(run) -> float:
    traj = run.result.trajectory
    times = traj.knots[:, layout.K_T]
    return max(((times > a) & (times <= b)).sum() for a, b in traj.intervals[:, 2:4])


def thrown(hertz: bool, e: float, stiffness: float, speed: float) -> tuple[dict | None, list[float]]:
    """Up to ten bounces of the bounce's ball (r = 0.03 m, 1100 kg/m^3) thrown down at `speed`
    from 0.05 speed^2 / g above the floor (it lands at 1.05 times that), Hertz at E = stiffness
    or a linear spring of k = stiffness, under gravity, until gravity holds it on the floor: the
    scene, to half the last bounce's flight (None for fewer than two bounces), and DOP853's
    rebound speeds."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.test_event_laws import reference_contact

    r, nu = 0.03, 0.45
    mass = 4.0 / 3.0 * math.pi * r**3 * 1100.0
    zeta = float(damping_ratio(np.array(e), hertz))
    params = im.impact_params(hertz=hertz, mstar=mass, k=stiffness, estar=stiffness / (1 - nu * nu), rstar=r,
                              zeta=zeta, accel=G)
    drop = 0.05 * speed**2 / G
    v = math.sqrt(speed**2 + 2 * G * drop)
    expected, flights = [], [(v - speed) / G]
    for _ in range(10):
        out = im.normal_impact(params, v, 1e-12)
        if out[im.O_OK] != 1.0 or out[im.O_VOUT] < 1e-3 * speed:
            break  # held on the floor, or (below 1e-3 of the speed) about to be
        try:
            v, contact_time = reference_contact(params, v)
        except AssertionError:  # DOP853's contact did not separate within its span
            break
        expected.append(v)
        flights.append(contact_time + 2 * v / G)
    if len(expected) < 2:
        return None, expected
    duration = sum(flights) - 1.5 * expected[-1] / G  # half the last flight
    contact = {"model": "hertz", "youngs_modulus": stiffness, "poisson_ratio": nu} if hertz else {"k": stiffness}
    return {"dim": 2, "duration": duration, "gravity": [0.0, -G], "contact": {**contact, "restitution": e},
            "body": [{"name": "ball", "radius": r, "mass": mass, "position": [0.0, r + drop],
                      "velocity": [0.0, -speed]}],
            "wall": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}]}, expected


def variants(repeat: int) -> None:
    print("| law | e | E or k | speed (m/s) | bounces | wall_time_s (median) | steps per contact (most) | "
          "error estimate | largest error of the rebound speeds against DOP853 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for hertz, stiffnesses in ((True, (1e6, 1e9, 1e12)), (False, (1e3, 1e6, 1e9))):
        for e in (0.05, 0.3, 0.8, 0.95):
            for stiffness in stiffnesses:
                for speed in (1e-3, 1.0, 100.0):
                    raw, expected = thrown(hertz, e, stiffness, speed)
                    head = f"| {'hertz' if hertz else 'linear'} | {e} | {stiffness:.0e} | {speed:g} |"
                    if raw is None:
                        print(f"{head} {len(expected)} | (held on the floor: fewer than two bounces) | | | |")
                        continue
                    scene = parse_scene(raw)
                    runs = [run_scene(scene, tol=1e-9) for _ in range(repeat)]
                    run = runs[0]
                    got = rebounds(run)
                    error = float(np.max(np.abs(got[:len(expected)] / np.array(expected)[:len(got)] - 1)))
                    wall = statistics.median(r.result.wall_time_s for r in runs)
                    print(f"{head} {int(run.result.contacts.count[0])} | {wall * 1e3:.3f} ms | "
                          f"{steps_per_contact(run)} | {float(run.error_estimate[0]):.1e} "
                          f"({run.error_method[0]}) | {error:.1e} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=11)
    parser.add_argument("--variants", action="store_true", help="ten bounces over e, the stiffness and the speed")
    args = parser.parse_args()
    if args.variants:
        run_scene(parse_scene(ten_bounces(True, 0.8)), tol=1e-6)  # load the kernels before timing
        variants(args.repeat)
        return
    run_scene(parse_scene(ten_bounces(True, 0.8)), tol=1e-6)  # load the kernels before timing
    print("| law | e | tol | contacts | wall_time_s (median, measured) | of it the run itself | error method, estimate "
          "| steps per contact (most) | largest error of the rebound speeds |")
    print("|---|---|---|---|---|---|---|---|---|")
    for hertz, e in ((True, 0.8), (False, 0.6)):
        scene = parse_scene(ten_bounces(hertz, e))
        for tol in (1e-6, 1e-8, 1e-9):
            runs = [run_scene(scene, tol=tol) for _ in range(args.repeat)]
            alone = [run_scene(scene, tol=tol, measure=False).result.wall_time_s for _ in range(args.repeat)]
            run = runs[0]
            finer = run_scene(scene, tol=tol / 100, measure=False)
            error = float(np.max(np.abs(rebounds(run) / rebounds(finer) - 1)))
            wall = statistics.median(r.result.wall_time_s for r in runs)
            print(f"| {'hertz' if hertz else 'linear'} | {e} | {tol:.0e} | {int(run.result.contacts.count[0])} | "
                  f"{wall * 1e3:.3f} ms | {statistics.median(alone) * 1e3:.3f} ms | {run.error_method[0]}, "
                  f"{float(run.error_estimate[0]):.1e} | {steps_per_contact(run)} | {error:.1e} |", flush=True)
    scene = load_scene("bounce")
    coarse, fine = run_scene(scene, tol=1e-9, record=False), run_scene(scene, tol=1e-11, record=False)
    print()
    print("| built-in bounce | wall_time_s | error estimate | against --tol 1e-11 |")
    print("|---|---|---|---|")
    print(f"| --tol 1e-9 | {coarse.result.wall_time_s * 1e3:.3f} ms | {float(coarse.error_estimate[0]):.2g} "
          f"({coarse.error_method[0]}) | {outcome_distance(coarse.result, fine.result, scene):.2g} |")


if __name__ == "__main__":
    main()
