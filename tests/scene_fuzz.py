"""Random physical scenes and the invariants every run that exits 0 keeps (issue 53, item 7).

`random_raw(rng)` draws a scene as a TOML table: 1D, 2D or 3D; 1-30 spheres of random radii,
masses over several decades and speeds over several decades; a contact stiffness drawn so that a
collision lasts from a thousandth to a fifth of the time the spheres take to meet (now and then
any stiffness at all, to reach the refusals); friction, dead band, walls, gravity onto a floor,
and now and then restitution, Hertz, the tangential spring or rolling friction. Starts never
overlap (a pair may touch). `rng` is a `random.Random` or hypothesis's `randoms()`, which
shrinks a failing scene.

`check_run(raw, summary)` judges an exit-0 run from its scene and its JSON summary alone (not
from `collide/invariant.py`, which it checks): every number finite; in 1D the starting order
kept; no pair (nor sphere and wall) overlapping deeper than the contact law can be pressed by
all of the scene's energy; and, where nothing dissipates, the energy balance within ENERGY_TOL,
recomputed from the final positions, velocities and spins.

Used by tests/test_scene_fuzz.py (hypothesis, a few dozen scenes) and scripts/fuzz.py
(`--count N --seed S`, thousands).
"""

from __future__ import annotations

import math
import signal
import time
import tomllib
import warnings
from dataclasses import dataclass
from typing import Any

from collide.scene import dump_toml

ENERGY_TOL = 1e-3  # the bar for a scene where nothing dissipates
TIME_LIMIT_S = 60.0  # no run may take longer
# A final overlap this many times the deepest the law can store from all the energy is a pass-through.
DEPTH_SLACK = 1.5


def _log_uniform(rng: Any, lo: float, hi: float) -> float:
    return 10.0 ** rng.uniform(math.log10(lo), math.log10(hi))


def _unit(rng: Any, dim: int) -> list[float]:
    while True:
        u = [rng.gauss(0.0, 1.0) for _ in range(dim)]
        n = math.sqrt(sum(c * c for c in u))
        if n > 1e-6:
            return [c / n for c in u]


def _place(rng: Any, dim: int, radii: list[float], box: float, floor: bool, touching: bool) -> list[list[float]]:
    """Non-overlapping centres in a cube of side `box` (above a floor at 0 along the last axis).
    `touching`: the second body starts exactly touching the first along x."""
    placed: list[list[float]] = []
    for r in radii:
        for _ in range(100):
            p = [rng.uniform(-box / 2, box / 2) for _ in range(dim)]
            if floor:
                p[-1] = abs(p[-1]) + r * (1.0 + rng.choice([0.0, 0.01, 0.5, 3.0]))
            if touching and len(placed) == 1:
                p = list(placed[0])
                p[0] += radii[0] + r
            if all(math.dist(p, q) - (s + r) >= -1e-13 * (s + r) for q, s in zip(placed, radii)) and \
                    (not floor or p[-1] >= r):
                placed.append(p)
                break
        else:
            break  # the box is full: fewer bodies
    return placed


def random_raw(rng: Any, max_bodies: int = 30, quick: bool = False) -> dict:
    """A random scene's TOML table (see the module's docstring). `quick`: collisions no shorter
    than a hundredth of the crossing time and at most 100 of them in the duration (a few seconds
    with the kernels interpreted, as the test suite may run them)."""
    dim = rng.choice([1, 2, 2, 3, 3])
    n = min(max_bodies, max(1, int(_log_uniform(rng, 1, 31))))
    r0 = _log_uniform(rng, 1e-3, 1.0)
    spread_r = rng.choice([0.0, 0.0, 0.3, 0.7])
    radii = [r0 * 10 ** rng.uniform(-spread_r, spread_r) for _ in range(n)]
    m0 = _log_uniform(rng, 1e-3, 1e2)
    spread_m = rng.choice([0.0, 0.0, 1.0, 2.0])
    masses = [m0 * 10 ** rng.uniform(-spread_m, spread_m) for _ in range(n)]
    v0 = _log_uniform(rng, 1e-2, 30.0)
    gravity = rng.random() < 0.25
    floor = gravity or rng.random() < 0.15
    box = max(radii) * 2.0 * (n ** (1.0 / dim)) * rng.choice([1.5, 3.0, 6.0])
    positions = _place(rng, dim, radii, box, floor, rng.random() < 0.15)
    n = len(positions)
    aim = rng.random() < 0.5  # every body heads for the middle: many meetings
    centre = [sum(p[a] for p in positions) / n for a in range(dim)]
    bodies = []
    for i in range(n):
        speed = v0 * 10 ** rng.uniform(-1.0, 0.3) * (rng.random() > 0.1)
        toward = [c - p for c, p in zip(centre, positions[i])]
        norm = math.sqrt(sum(c * c for c in toward))
        u = [c / norm for c in toward] if aim and norm > 0 else _unit(rng, dim)
        body: dict[str, Any] = {"name": f"b{i}", "mass": masses[i], "radius": radii[i],
                                "position": positions[i][0] if dim == 1 else positions[i],
                                "velocity": speed * u[0] if dim == 1 else [speed * c for c in u]}
        if dim > 1 and rng.random() < 0.3:
            spin = [rng.gauss(0.0, 1.0) * v0 / radii[i] for _ in range(1 if dim == 2 else 3)]
            body["spin"] = spin[0] if dim == 2 else spin
        bodies.append(body)
    meet = box / v0  # the time to cross the box at the typical speed
    t_c = meet * _log_uniform(rng, 1e-2 if quick else 1e-3, 0.05)  # a collision's duration
    m_eff = 0.5 * min(masses)
    k = m_eff * (math.pi / t_c) ** 2 if rng.random() > 0.1 else _log_uniform(rng, 1.0, 1e10)
    contact: dict[str, Any] = {"k": k}
    if rng.random() < 0.5:
        contact["mu"] = rng.uniform(0.0, 1.0)
    if rng.random() < 0.3:
        contact["eps"] = _log_uniform(rng, 1e-9, 1e-3)
    law = rng.random()
    if law < 0.12:
        contact["model"] = "hertz"
        depth = v0 * t_c / math.pi  # the overlap a linear spring of stiffness k reaches
        contact["youngs_modulus"] = k / math.sqrt(r0 * max(depth, 1e-12))
    if rng.random() < 0.12:
        contact["restitution"] = rng.uniform(0.2, 1.0)
    if rng.random() < 0.08:
        contact["tangential"] = "spring"
    if rng.random() < 0.06:
        contact["rolling_friction"] = rng.uniform(0.0, 0.1)
    raw: dict[str, Any] = {"name": "fuzz", "dim": dim, "contact": contact, "body": bodies}
    dem = contact.get("model") == "hertz" or contact.get("tangential") == "spring" or \
        contact.get("restitution", 1.0) < 1.0 or contact.get("rolling_friction", 0.0) > 0.0
    if not dem and rng.random() < 0.4:
        raw["integrator"] = rng.choice(["seed", "verlet", "yoshida4", "kahan6"])
    if raw.get("integrator") == "seed" and rng.random() < 0.85:  # first order: 1e-6 needs 1e6 steps a contact
        raw["tol"] = _log_uniform(rng, 3e-5, 3e-4)
    elif dem and rng.random() < 0.85:  # the DEM kernel's first order reaches about 6e-5
        raw["tol"] = _log_uniform(rng, 6e-5, 3e-4)
    elif rng.random() < 0.5:
        raw["tol"] = _log_uniform(rng, 1e-9, 1e-5)
    if rng.random() < 0.1:
        raw["dt"] = t_c / _log_uniform(rng, 20, 2000)
    walls = []
    if floor:
        up = [0.0] * dim
        up[-1] = 1.0
        walls.append({"point": [0.0] * dim, "normal": up})
        if gravity:
            g = _log_uniform(rng, 0.1, 30.0)
            raw["gravity"] = [-g * c for c in up]
    if (rng.random() < 0.15 and dim > 1) or (n == 1 and not walls):  # a side wall at the box's edge
        normal = [0.0] * dim
        normal[0] = 1.0
        walls.append({"point": [-box / 2 - 2 * max(radii)] + [0.0] * (dim - 1), "normal": normal})
    if walls:
        raw["wall"] = walls
    if walls or quick or rng.random() < 0.3:
        # Bounded: a resting pile costs steps every collision time.
        raw["duration"] = min(meet * rng.uniform(0.5, 4.0), (100 if quick else 3000) * t_c)
    return raw


def replayable(raw: dict) -> dict:
    """The table as `collide run FILE` reads it back from `dump_toml`."""
    return tomllib.loads(dump_toml(raw))


# ---------------------------------------------------------------------------------------------
# The judge


@dataclass
class Verdict:
    outcome: str  # "ran", "refused", "violation"
    kind: str = ""  # the refusal's cause or the violation's kind
    message: str = ""
    seconds: float = 0.0
    energy_residual: float | None = None  # where nothing dissipates (the judge's own)


def _vec(value: Any) -> list[float]:
    return [float(value)] if not isinstance(value, list) else [float(c) for c in value]


def dissipative(raw: dict) -> bool:
    """Whether anything in the scene can take energy out: friction (2D/3D), damping, rolling."""
    c = raw.get("contact", {})
    friction = raw["dim"] > 1 and c.get("mu", 0.0) > 0.0
    return friction or c.get("restitution", 1.0) < 1.0 or c.get("rolling_friction", 0.0) > 0.0


def _laws(raw: dict) -> tuple[float, float, float, float]:
    """(pair k, wall k, pair E*, wall E*) of the scene's single contact law."""
    c = raw.get("contact", {})
    k = float(c.get("k", 1500.0))
    young = c.get("youngs_modulus")
    if young is None:
        return 0.5 * k, k, math.nan, math.nan
    nu = float(c.get("poisson_ratio", 0.3))
    return 0.5 * k, k, young / (2 * (1 - nu * nu)), young / (1 - nu * nu)


def _deepest(raw: dict, energy: float, k: float, estar: float, rstar: float) -> float:
    if raw.get("contact", {}).get("model", "linear") == "hertz":
        return (15.0 * energy / (8.0 * estar * math.sqrt(rstar))) ** 0.4
    return math.sqrt(2.0 * energy / k)


def _floor_height(p: list[float], wall: dict) -> float:
    n = _vec(wall["normal"])
    norm = math.sqrt(sum(c * c for c in n))
    return sum((a - b) * c for a, b, c in zip(p, _vec(wall["point"]), n)) / norm


def energy_of(raw: dict, bodies: list[dict]) -> float:
    """Mechanical energy: kinetic, rotational (solid spheres), gravity's potential (zero at the
    origin) and the normal springs' energy at these positions."""
    k_pair, k_wall, e_pair, e_wall = _laws(raw)
    hertz = raw.get("contact", {}).get("model", "linear") == "hertz"
    g = _vec(raw.get("gravity", [0.0] * raw["dim"]))
    spec = raw["body"]
    total = 0.0
    for b, state in zip(spec, bodies):
        m, r = float(b["mass"]), float(b["radius"])
        total += 0.5 * m * sum(c * c for c in _vec(state["velocity"]))
        if "spin" in state or "spin" in b:
            w = _vec(state.get("spin", b.get("spin", 0.0)))
            total += 0.5 * 0.4 * m * r * r * sum(c * c for c in w)
        total -= m * sum(a * c for a, c in zip(g, _vec(state["position"])))
    for i in range(len(spec)):
        ri, pi = float(spec[i]["radius"]), _vec(bodies[i]["position"])
        for j in range(i + 1, len(spec)):
            rj = float(spec[j]["radius"])
            d = ri + rj - math.dist(pi, _vec(bodies[j]["position"]))
            if d > 0:
                total += 8 / 15 * e_pair * math.sqrt(ri * rj / (ri + rj)) * d ** 2.5 if hertz else 0.5 * k_pair * d * d
        for wall in raw.get("wall", []):
            d = ri - _floor_height(pi, wall)
            if d > 0:
                total += 8 / 15 * e_wall * math.sqrt(ri) * d ** 2.5 if hertz else 0.5 * k_wall * d * d
    return total


def _all_energy(raw: dict) -> float:
    """All the energy that can reach one contact: the start's kinetic and rotational energy,
    plus each body's fall to the lowest wall under gravity (no centre-of-mass share is taken
    out: a looser bound than the engine's)."""
    spec = raw["body"]
    start = [{"position": b["position"], "velocity": b["velocity"], **({"spin": b["spin"]} if "spin" in b else {})}
             for b in spec]
    raw_free = dict(raw)
    raw_free.pop("gravity", None)
    energy = energy_of(raw_free, start)
    g = _vec(raw.get("gravity", [0.0] * raw["dim"]))
    gn = math.sqrt(sum(c * c for c in g))
    if gn > 0 and raw.get("wall"):
        for b in spec:
            drop = max(max(_floor_height(_vec(b["position"]), w) for w in raw["wall"]), 0.0)
            energy += float(b["mass"]) * gn * drop
    return energy


def _non_finite(value: Any, where: str = "") -> str | None:
    if isinstance(value, float) and not math.isfinite(value):
        return where or "value"
    if isinstance(value, dict):
        return next((w for k, v in value.items() if (w := _non_finite(v, f"{where}.{k}"))), None)
    if isinstance(value, list):
        return next((w for i, v in enumerate(value) if (w := _non_finite(v, f"{where}[{i}]"))), None)
    return None


def check_run(raw: dict, summary: dict) -> tuple[str, str] | None:
    """(kind, message) of the first invariant an exit-0 run broke, else None."""
    where = _non_finite(summary)
    if where:
        return "non-finite", f"a non-finite number at {where}"
    spec, final = raw["body"], summary["bodies"]
    energy = _all_energy(raw)
    k_pair, k_wall, e_pair, e_wall = _laws(raw)
    pos = [_vec(b["position"]) for b in final]
    if raw["dim"] == 1:
        order = sorted(range(len(spec)), key=lambda i: float(_vec(spec[i]["position"])[0]))
        for a, b in zip(order, order[1:]):
            if pos[b][0] < pos[a][0]:
                return "pass-through", f"1D order lost: {spec[a]['name']} ended beyond {spec[b]['name']}"
    for i in range(len(spec)):
        ri = float(spec[i]["radius"])
        for j in range(i + 1, len(spec)):
            rj = float(spec[j]["radius"])
            overlap = ri + rj - math.dist(pos[i], pos[j])
            bound = _deepest(raw, energy, k_pair, e_pair, ri * rj / (ri + rj))
            if overlap > DEPTH_SLACK * bound:
                return "pass-through", (f"{spec[i]['name']} and {spec[j]['name']} overlap by {overlap:.3g} m at the "
                                        f"end; all the energy presses at most {bound:.3g} m")
        for w, wall in enumerate(raw.get("wall", [])):
            overlap = ri - _floor_height(pos[i], wall)
            bound = _deepest(raw, energy, k_wall, e_wall, ri)
            if overlap > DEPTH_SLACK * bound:
                return "through-wall", (f"{spec[i]['name']} overlaps wall {w} by {overlap:.3g} m at the end; all the "
                                        f"energy presses at most {bound:.3g} m")
    residual = energy_residual(raw, summary)
    if residual is not None and residual > ENERGY_TOL:
        return "energy", (f"energy residual {residual:.3g} > {ENERGY_TOL:g} with nothing that dissipates "
                          f"(the engine's: {summary['residuals']['energy']})")
    return None


def energy_residual(raw: dict, summary: dict) -> float | None:
    """|E_end - E_start| / E_start where nothing dissipates and the step was chosen for the
    tolerance (a given dt is the user's accuracy), else None."""
    if dissipative(raw) or raw.get("dt", "auto") != "auto":
        return None
    e0 = energy_of(raw, [{"position": b["position"], "velocity": b["velocity"],
                          **({"spin": b["spin"]} if "spin" in b else {})} for b in raw["body"]])
    e1 = energy_of(raw, summary["bodies"])
    scale = _energy_scale(raw, e0)
    return abs(e1 - e0) / scale if scale > 0 else None


def _energy_scale(raw: dict, e0: float) -> float:
    """What the residual is relative to: the start's energy with gravity's potential measured
    from the floor (a height's zero is arbitrary; the floor's is the one the motion sees)."""
    if "gravity" not in raw or not raw.get("wall"):
        return abs(e0)
    free = dict(raw)
    free.pop("gravity")
    start = [{"position": b["position"], "velocity": b["velocity"], **({"spin": b["spin"]} if "spin" in b else {})}
             for b in raw["body"]]
    g = _vec(raw["gravity"])
    gn = math.sqrt(sum(c * c for c in g))
    fall = sum(float(b["mass"]) * gn * max(_floor_height(_vec(b["position"]), raw["wall"][0]), 0.0)
               for b in raw["body"])
    return energy_of(free, start) + fall


# ---------------------------------------------------------------------------------------------
# Running a scene in this process, as `collide run FILE --json --no-record` does


class _TooLong(BaseException):
    """Raised by the alarm: the run went far past TIME_LIMIT_S."""


REFUSAL_CAUSES = [
    ("overlaps", "start overlap"), ("too soft", "too soft"), ("stability limit", "dt beyond the stability limit"),
    ("passed through", "pass-through caught"),
    ("through wall", "pass-through caught"),
    ("beyond the", "pass-through caught"), ("stiff", "too stiff"), ("round-off", "too stiff"),
    ("tol", "tolerance unreachable"), ("steps", "too many steps"), ("not finite", "non-finite"),
    ("overflow", "non-finite"), ("duration", "needs a duration"), ("no contact", "nothing to step"),
]


def refusal_cause(message: str) -> str:
    low = message.lower()
    return next((cause for word, cause in REFUSAL_CAUSES if word in low), "other: " + " ".join(message.split()[:6]))


def run_in_process(raw: dict, hard_limit_s: int = 180) -> tuple[Verdict, dict | None]:
    """Run the scene and judge it: (verdict, JSON summary or None)."""
    from collide.errors import RunError
    from collide.run import run_scene
    from collide.scene import SceneError, parse_scene
    from collide.summary import run_summary

    def alarm(signum: int, frame: object) -> None:
        raise _TooLong

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(hard_limit_s)
    began = time.perf_counter()
    summary = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # as the CLI: a warning is no result
            scene = parse_scene(replayable(raw), "fuzz")
            summary = run_summary(run_scene(scene, record=False))
    except _TooLong:
        return Verdict("violation", "too slow", f"still running after {hard_limit_s} s",
                       time.perf_counter() - began), None
    except (SceneError, RunError, ValueError) as exc:
        took = time.perf_counter() - began
        text = str(exc)
        if "\n" in text.strip():
            return Verdict("violation", "refusal not one line", text[:300], took), None
        if took > TIME_LIMIT_S:
            return Verdict("violation", "too slow", f"refused after {took:.0f} s: {text}", took), None
        return Verdict("refused", refusal_cause(text), text, took), None
    except RuntimeWarning as exc:
        return Verdict("violation", "overflow net", f"a RuntimeWarning escaped the engine: {exc}",
                       time.perf_counter() - began), None
    except Exception as exc:  # noqa: BLE001 - anything else is an internal error
        return Verdict("violation", "internal error", f"{type(exc).__name__}: {exc}",
                       time.perf_counter() - began), None
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    took = time.perf_counter() - began
    problem = check_run(raw, summary)
    if problem:
        return Verdict("violation", problem[0], problem[1], took), summary
    if took > TIME_LIMIT_S:
        return Verdict("violation", "too slow", f"took {took:.0f} s", took), summary
    return Verdict("ran", "", "", took, energy_residual(raw, summary)), summary


def run_cli(path: str, timeout_s: float = TIME_LIMIT_S) -> Verdict:
    """`collide run PATH --json --no-record` in a child process, held to the CLI's contract:
    exit 0 with a JSON summary and a quiet stderr, or exit 2 with one line `error: ...`."""
    import json
    import subprocess
    import sys

    began = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-c", "from cli.main import main; main()", "run", path, "--json",
                               "--no-record"], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return Verdict("violation", "too slow", f"the CLI ran past {timeout_s:.0f} s", timeout_s)
    took = time.perf_counter() - began
    err = done.stderr.splitlines()
    if "Traceback" in done.stderr:
        return Verdict("violation", "traceback", done.stderr[-300:], took)
    if done.returncode == 0:
        if err:
            return Verdict("violation", "stderr on exit 0", done.stderr[:300], took)
        try:
            json.loads(done.stdout, parse_constant=lambda text: (_ for _ in ()).throw(ValueError(text)))
        except ValueError as exc:
            return Verdict("violation", "bad JSON", str(exc)[:300], took)
        return Verdict("ran", "", "", took)
    if done.returncode != 2:
        return Verdict("violation", f"exit {done.returncode}", done.stderr[:300], took)
    if len(err) != 1 or not err[0].startswith("error: "):
        return Verdict("violation", "refusal not one line", done.stderr[:300], took)
    return Verdict("refused", refusal_cause(err[0]), err[0], took)
