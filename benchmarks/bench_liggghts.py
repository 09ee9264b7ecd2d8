"""Outside check: the same impacts and the same granular box in LIGGGHTS and in collide, side by side.

Not a test and not in CI: it needs LIGGGHTS, a DEM code, installed from Debian (or Ubuntu):

    apt-get install liggghts          # LIGGGHTS-PUBLIC 3.8.0, binary /usr/bin/liggghts

then, from the repository root:

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_liggghts.py [--repeat 3] [--steps 20000]
        [--only impacts|box] [--liggghts-only] [--keep DIR]

For each case it writes a LIGGGHTS input (with a data file holding the spheres) and our scene TOML
with the same physics, runs LIGGGHTS on one core (`-echo none -log none`) and `collide run FILE.toml
--json --no-record` in subprocesses, and prints Markdown tables:

(a) single impacts in the manner of Chung & Ooi (2011): two identical glass spheres head-on (Hertz,
    elastic), a sphere on a rigid plane with restitution 0.5, and oblique impacts on the plane with
    friction (one in gross sliding, one near sticking where the tangential spring matters), each with
    its closed form where one exists and the relative difference collide vs LIGGGHTS;
(b) a granular box: 1000 spheres dropped from a loose lattice into a box of five walls under gravity,
    the same fixed dt (1/50 of the Hertz contact time) and number of steps on both sides: particle-steps
    per second of wall clock (LIGGGHTS: its "Loop time"; collide: `wall_time_s`) and of CPU time (the run
    less a one-step run: LIGGGHTS's processes; collide's simulation, both runs in one process that ran
    the one-step scene before, so that its start-up, as long as the box's steps and as variable, is not
    part of either), medians of runs taken alternately, their ratio, and the final kinetic energy and
    mean height as a sanity check.

One contact law on both sides: Hertz F = 4/3 E* sqrt(R*) delta^1.5; damping
gamma = -2 sqrt(5/6) beta sqrt(S_n m*), S_n = 2 E* sqrt(R* delta), beta = ln e / sqrt(ln^2 e + pi^2),
no clipping of the (attractive) total normal force (LIGGGHTS `limitForce` off, its default); the
tangential history spring k_t = 8 G* sqrt(R* delta) (Mindlin), which for equal Poisson ratios is
2(1 - nu)/(2 - nu) of dF_n/d delta, our default ratio, with a tangential dashpot of the same form
(gamma_t from S_t = k_t; LIGGGHTS `tangential_damping on`, its default, and ours); Coulomb cap
mu F_n. LIGGGHTS walls are `fix wall/gran ... primitive` planes of a second atom type with
E = 1e30 Pa: a rigid wall, as ours (E* = E/(1 - nu^2), R* = r).

Known differences that remain (they show in the table): the lever arm of a wall contact's friction
is r - delta/2 in LIGGGHTS (as for two spheres) and r - delta in collide (the rigid plane's
surface), so spins after an oblique impact differ by about delta/(2 r) ~ 1e-3; LIGGGHTS turns the
tangential spring into the new tangent plane by projection (its length shrinks), collide keeps its
length; contact times count the steps in contact, so they agree to a step, not better.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from collide.chung_ooi import Material

ROOT = Path(__file__).resolve().parents[1]
LIGGGHTS = shutil.which("liggghts") or "/usr/bin/liggghts"
RIGID_E = 1e30  # Pa: LIGGGHTS's wall material; (1 - nu^2)/E of the wall vanishes next to the sphere's
TIMEOUT_S = 1800.0


GLASS = Material("glass", 4.8e10, 0.20, 2800.0)  # Chung & Ooi test 1's glass
# Soft "glass" for the box: at glass's own E, t_c/50 is 0.15 us and 20 000 steps are 3 ms, in which a
# dropped lattice falls 0.05 mm and never touches anything; DEM users soften E for the same reason.
SOFT_GLASS = Material("soft-glass", 5.0e6, 0.20, 2500.0)


@dataclass
class Sphere:
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]


@dataclass
class Case:
    """One run, written for both codes: spheres of one radius and material, optional walls."""

    name: str
    material: Material
    radius: float  # m
    spheres: list[Sphere]
    dt: float  # s
    steps: int
    restitution: float = 1.0
    mu: float = 0.0
    walls: list[tuple[str, float]] = field(default_factory=list)  # ("zplane", 0.0): LIGGGHTS primitive, at
    gravity: float = 0.0  # m/s^2, along -z
    dump_every: int = 1  # 0: only the final state
    box: tuple[float, float, float, float, float, float] = (-0.05, 0.05, -0.05, 0.05, -0.05, 0.05)
    skin: float = 1e-3  # m, LIGGGHTS neighbour skin

    @property
    def mass(self) -> float:
        return 4.0 / 3.0 * math.pi * self.radius**3 * self.material.density


# ------------------------------------------------------------------ closed forms


def e_star(m: Material, wall: bool) -> float:
    """Effective modulus: two identical spheres, or one sphere on a rigid wall."""
    e = m.youngs_modulus / (1.0 - m.poisson_ratio**2)
    return e if wall else e / 2.0


def hertz_closed_form(m_eff: float, r_eff: float, estar: float, v: float) -> dict[str, float]:
    """Elastic Hertz impact at normal closing speed v: peak overlap, peak force, contact time."""
    delta = (15.0 * m_eff * v**2 / (16.0 * estar * math.sqrt(r_eff))) ** 0.4
    return {
        "delta_max": delta,
        "f_max": 4.0 / 3.0 * estar * math.sqrt(r_eff) * delta**1.5,
        "t_contact": 2.868 * (m_eff**2 / (r_eff * estar**2 * v)) ** 0.2,
    }


# ------------------------------------------------------------------ LIGGGHTS side


def liggghts_input(case: Case, workdir: Path) -> Path:
    """Write the data file and the input script of a case; return the input's path."""
    n = len(case.spheres)
    x0, x1, y0, y1, z0, z1 = case.box
    d, rho = 2.0 * case.radius, case.material.density
    data = [f"LIGGGHTS data: {case.name}", "", f"{n} atoms", "2 atom types", "",
            f"{x0!r} {x1!r} xlo xhi", f"{y0!r} {y1!r} ylo yhi", f"{z0!r} {z1!r} zlo zhi", "", "Atoms", ""]
    data += [f"{i + 1} 1 {d!r} {rho!r} {s.position[0]!r} {s.position[1]!r} {s.position[2]!r}"
             for i, s in enumerate(case.spheres)]
    data += ["", "Velocities", ""]
    data += [f"{i + 1} {s.velocity[0]!r} {s.velocity[1]!r} {s.velocity[2]!r} 0 0 0"
             for i, s in enumerate(case.spheres)]
    (workdir / "spheres.data").write_text("\n".join(data) + "\n")
    m, e, mu = case.material, case.restitution, case.mu
    model = "model hertz tangential history"
    # Stated although it is LIGGGHTS's default: collide's spring has the same dashpot. pair_style
    # takes such settings after the model, wall/gran at the end of the line.
    settings = "tangential_damping on"
    lines = [
        "atom_style granular", "atom_modify map array", "boundary f f f", "newton off",
        "communicate single vel yes", "units si",
        "hard_particles yes",  # LIGGGHTS refuses E > 1e9 Pa in SI units without it
        "read_data spheres.data",
        f"neighbor {case.skin!r} bin", "neigh_modify delay 0",
        f"fix m1 all property/global youngsModulus peratomtype {m.youngs_modulus!r} {RIGID_E!r}",
        f"fix m2 all property/global poissonsRatio peratomtype {m.poisson_ratio!r} {m.poisson_ratio!r}",
        f"fix m3 all property/global coefficientRestitution peratomtypepair 2 {e!r} {e!r} {e!r} {e!r}",
        f"fix m4 all property/global coefficientFriction peratomtypepair 2 {mu!r} {mu!r} {mu!r} {mu!r}",
        f"pair_style gran {model} {settings}", "pair_coeff * *",
        f"timestep {case.dt!r}",
    ]
    for i, (plane, at) in enumerate(case.walls):
        lines.append(f"fix w{i} all wall/gran {model} primitive type 2 {plane} {at!r} {settings}")
    if case.gravity:
        lines.append(f"fix grav all gravity {case.gravity!r} vector 0.0 0.0 -1.0")
    lines += ["fix integr all nve/sphere", f"thermo {max(case.steps, 1)}"]
    every = case.dump_every or case.steps
    lines += [f"dump d all custom {every} out.dump id x y z vx vy vz omegax omegay omegaz fx fy fz",
              # full precision: the default %g keeps 6 digits, too few for an overlap of 1e-4 r
              "dump_modify d sort id format \"%d" + " %.17g" * 12 + "\"", f"run {case.steps}"]
    path = workdir / "in.liggghts"
    path.write_text("\n".join(lines) + "\n")
    return path


@dataclass
class LiggghtsRun:
    loop_time_s: float  # LIGGGHTS's own "Loop time" (the run command, setup excluded)
    wall_s: float  # the whole process
    cpu_s: float  # the process's user + system time: what it cost on a machine shared with other work
    frames: np.ndarray  # (T, N, 12): x y z vx vy vz wx wy wz fx fy fz, every dump_every steps


# LIGGGHTS's processes (`--np`: under mpirun, its domain split among them).
PROCESSES = [1]


def run_liggghts(case: Case, workdir: Path) -> LiggghtsRun:
    workdir.mkdir(parents=True, exist_ok=True)
    inp = liggghts_input(case, workdir)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-np", str(PROCESSES[0])] if PROCESSES[0] > 1 else []
    proc = subprocess.run([*mpi, LIGGGHTS, "-echo", "none", "-log", "none", "-in", inp.name], cwd=workdir,
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    out = proc.stdout + proc.stderr
    loop = re.search(r"Loop time of ([0-9.eE+-]+) on", out)
    if proc.returncode != 0 or loop is None or "ERROR" in out:
        raise RuntimeError(f"LIGGGHTS failed on {case.name} (exit {proc.returncode}):\n{out[-2000:]}")
    lost = re.search(r"Lost atoms", out)
    if lost:
        raise RuntimeError(f"LIGGGHTS lost atoms on {case.name}")
    return LiggghtsRun(float(loop.group(1)), wall, cpu, read_dump(workdir / "out.dump", len(case.spheres)))


def read_dump(path: Path, n: int) -> np.ndarray:
    """The frames of a LIGGGHTS custom dump (sorted by id) as an array (T, N, 12)."""
    lines = path.read_text().splitlines()
    per = 9 + n  # ITEM headers: TIMESTEP, step, NUMBER, n, BOX, 3 bounds, ATOMS columns
    frames = [np.loadtxt(lines[k + 9:k + per], ndmin=2)[:, 1:] for k in range(0, len(lines), per)]
    return np.stack(frames)


# ------------------------------------------------------------------ collide side


def scene_toml(case: Case) -> str:
    m = case.material
    out = [f'name = "{case.name}"', "dim = 3", 'integrator = "dem"', f"dt = {case.dt!r}",
           f"duration = {case.steps * case.dt!r}", f"gravity = [0.0, 0.0, {(-case.gravity or 0.0)!r}]", "",
           "[contact]", 'model = "hertz"', f"restitution = {case.restitution!r}", 'tangential = "spring"',
           f"mu = {case.mu!r}", "", "[[material]]", f'name = "{m.name}"', f"density = {m.density!r}",
           f"youngs_modulus = {m.youngs_modulus!r}", f"poisson_ratio = {m.poisson_ratio!r}", ""]
    for i, s in enumerate(case.spheres):
        out += ["[[body]]", f'name = "s{i + 1}"', f'material = "{m.name}"', f"radius = {case.radius!r}",
                f"position = [{', '.join(repr(x) for x in s.position)}]",
                f"velocity = [{', '.join(repr(x) for x in s.velocity)}]", ""]
    for plane, at in case.walls:
        axis = "xyz".index(plane[0])
        # LIGGGHTS's primitive plane pushes from whichever side the sphere is on: the normal points
        # towards the spheres' side (the box's inside).
        lo = at <= (case.box[2 * axis] + case.box[2 * axis + 1]) / 2
        point = [0.0, 0.0, 0.0]
        point[axis] = at
        normal = [0.0, 0.0, 0.0]
        normal[axis] = 1.0 if lo else -1.0
        out += ["[[wall]]", f"point = [{', '.join(repr(x) for x in point)}]",
                f"normal = [{', '.join(repr(x) for x in normal)}]", ""]
    return "\n".join(out)


# `collide run FILE --json --no-record` three times in one process: the one-step copy of the scene
# (which pays the imports and the loading of the compiled kernels: about as long as the box's
# 20 000 steps, and too variable to subtract), again, then the case; the CPU time of the
# simulation (collide.dem.simulate_dem: the kernel and its set-up) is taken in each, and the
# case's less the second one-step run's is that of the steps after the first. (Reading a scene
# of 1000 spheres alone takes 0.7 s of CPU: in both runs, but not alike to a few percent.)
WARMED_RUN = """
import contextlib, io, json, resource, sys
import collide.dem
from cli.main import main

spent = []
simulate_dem = collide.dem.simulate_dem

def timed(*args, **kwargs):
    before = resource.getrusage(resource.RUSAGE_SELF)
    try:
        return simulate_dem(*args, **kwargs)
    finally:
        after = resource.getrusage(resource.RUSAGE_SELF)
        spent.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)

collide.dem.simulate_dem = timed

def run(path):
    sys.argv = ["collide", "run", path, "--json", "--no-record"]
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            main()
    except SystemExit as exc:  # main() ends with one, 0 when all went well
        if exc.code:
            raise
    return out.getvalue()

case, warm_up = sys.argv[1], sys.argv[2]
run(warm_up)
run(warm_up)
summary = json.loads(run(case))
summary["bench_cpu_s"] = spent[-1] - spent[-2]
print(json.dumps(summary))
"""


def run_collide(case: Case, workdir: Path, warm_up: Case | None = None) -> dict:
    """`collide run` on the case's scene: its JSON summary. With `warm_up` (the case for one step),
    as WARMED_RUN, and the summary gets `bench_cpu_s`: the CPU time (user + system, s) of the
    case's steps after the first."""
    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / f"{case.name}.toml"
    path.write_text(scene_toml(case))
    # COLLIDE_JIT=1: compiled kernels, waiting for numba if the cache is cold (the default runs a
    # first run interpreted while it compiles: the box then takes more than half an hour).
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLLIDE_JIT="1")
    if warm_up is None:
        code = "import sys; from cli.main import main; sys.argv[0] = 'collide'; main()"
        argv = ["run", str(path), "--json", "--no-record"]
    else:
        first = workdir / f"{warm_up.name}-warm-up.toml"
        first.write_text(scene_toml(warm_up))
        code, argv = WARMED_RUN, [str(path), str(first)]
    proc = subprocess.run([sys.executable, "-c", code, *argv], cwd=workdir, env=env, capture_output=True, text=True,
                          timeout=TIMEOUT_S, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"collide failed on {case.name} (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout)


# ------------------------------------------------------------------ (a) impacts


def impact_cases() -> list[Case]:
    r = 0.01
    m = GLASS
    cases = []
    # Two identical spheres head-on, 5 m/s each (closing speed 10 m/s), a 0.1 um gap at the start.
    v, gap = 5.0, 1e-7
    cases.append(Case("head-on", m, r, [Sphere((-r - gap, 0.0, 0.0), (v, 0.0, 0.0)),
                                        Sphere((r + gap, 0.0, 0.0), (-v, 0.0, 0.0))],
                      dt=2e-8, steps=4000))
    # A sphere onto the rigid plane z = 0 at 1 m/s, e = 0.5.
    cases.append(Case("wall-e0.5", m, r, [Sphere((0.0, 0.0, r + 1e-7), (0.0, 0.0, -1.0))],
                      dt=5e-8, steps=2400, restitution=0.5, walls=[("zplane", 0.0)]))
    # Oblique impacts at 3.9 m/s (Chung & Ooi test 4's speed), mu = 0.1, elastic: 60 degrees from the
    # normal slides throughout (tan 60 = 1.73 > 7/2 mu (1 + e) = 0.7); 20 degrees (0.36) sticks, and
    # once more with e = 0.5, where both codes damp the tangential spring too.
    for angle, e in ((60.0, 1.0), (20.0, 1.0), (20.0, 0.5)):
        a = math.radians(angle)
        vel = (3.9 * math.sin(a), 0.0, -3.9 * math.cos(a))
        name = f"oblique-{angle:.0f}deg" + ("" if e == 1.0 else f"-e{e:g}")
        cases.append(Case(name, m, r, [Sphere((0.0, 0.0, r + 1e-7), vel)], dt=5e-8, steps=2400, restitution=e,
                          mu=0.1, walls=[("zplane", 0.0)]))
    return cases


def impact_outcome_liggghts(case: Case, run: LiggghtsRun) -> dict[str, float]:
    """Peak overlap and normal force, contact time (steps in contact x dt), rebound of sphere 1."""
    f = run.frames
    if case.walls:
        delta = case.radius - f[:, 0, 2]
        fn = f[:, 0, 11]
    else:
        dist = np.linalg.norm(f[:, 1, 0:3] - f[:, 0, 0:3], axis=1)
        delta = 2.0 * case.radius - dist
        n = (f[:, 1, 0:3] - f[:, 0, 0:3]) / dist[:, None]
        fn = -np.einsum("ij,ij->i", f[:, 0, 9:12], n)
    touching = delta > 0
    if touching[-1]:
        raise RuntimeError(f"{case.name}: LIGGGHTS run ended in contact; give it more steps")
    last = f[-1, 0]
    return {"delta_max": float(delta.max()), "f_max": float(fn[touching].max()),
            "t_contact": float(touching.sum() * case.dt * case.dump_every),
            "vx": float(last[3]), "vz": float(last[5]), "wy": float(last[7])}


def impact_outcome_collide(case: Case, summary: dict) -> dict[str, float]:
    body = summary["bodies"][0]
    # max_overlap: the overlap of the pair (max_compression is each sphere's share, the report's)
    return {"delta_max": summary["contact"]["max_overlap"], "f_max": summary["contact"]["max_normal_force"],
            "t_contact": summary["contact"]["duration"], "vx": body["velocity"][0], "vz": body["velocity"][2],
            "wy": body["spin"][1]}


def impact_rows(case: Case, lig: dict[str, float], ours: dict[str, float] | None) -> list[list[str]]:
    """Rows: case, quantity, closed form, LIGGGHTS, collide, relative difference."""
    s = case.spheres[0]
    wall = bool(case.walls)
    m_eff = case.mass if wall else case.mass / 2
    r_eff = case.radius if wall else case.radius / 2
    vn = -s.velocity[2] if wall else 2 * s.velocity[0]
    closed = hertz_closed_form(m_eff, r_eff, e_star(case.material, wall), vn)
    e = case.restitution
    quantities: list[tuple[str, str, float | None]] = []
    if case.restitution == 1.0:
        quantities += [("delta_max", "delta_max (m)", closed["delta_max"]), ("f_max", "F_max (N)", closed["f_max"]),
                       ("t_contact", "contact time (s)", closed["t_contact"])]
    if not wall:
        quantities.append(("vx", "rebound velocity of sphere 1 (m/s)", -s.velocity[0]))
    elif case.mu == 0.0:
        quantities += [("t_contact", "contact time (s)", None), ("vz", "rebound ratio v_out/v_in", e)]
    else:
        vt = s.velocity[0]
        sliding = vt / vn > 3.5 * case.mu * (1 + e)
        # Rigid-body gross sliding: the friction impulse mu (1 + e) m vn takes vt down and spins the sphere.
        quantities += [("vz", "rebound normal speed (m/s)", e * vn),
                       ("vx", "rebound tangential speed (m/s)", vt - case.mu * (1 + e) * vn if sliding else None),
                       ("wy", "rebound spin (rad/s)",
                        2.5 * case.mu * (1 + e) * vn / case.radius if sliding else None)]
    rows = []
    for key, label, exact in quantities:
        a = lig[key] / vn if label.startswith("rebound ratio") else lig[key]
        b = None if ours is None else (ours[key] / vn if label.startswith("rebound ratio") else ours[key])
        rel = "" if b is None else f"{(b - a) / abs(a):+.2e}" if a else f"{b - a:+.2e} (abs)"
        rows.append([case.name, label, "" if exact is None else f"{exact:.6g}", f"{a:.6g}",
                     "" if b is None else f"{b:.6g}", rel])
    return rows


def emulate_wall_impact(case: Case, lever: str, cap: str) -> tuple[float, float]:
    """A sphere on the plane z = 0, stepped as both codes step it (velocity Verlet, Hertz with
    damping, history spring with dashpot), with one code's convention for each of the two things
    in which they differ. Returns the rebound (v_x, w_y).

    lever: "half" (LIGGGHTS: friction acts at r - delta/2) or "full" (collide: at r - delta, the
    plane's surface). cap: "spring" (LIGGGHTS 3.8: the spring force alone is compared with mu F_n;
    when it slides, the dashpot is dropped and the stretch set to F/k_t) or "total" (collide, as
    LAMMPS `pair granular`: spring plus dashpot is capped, the stretch set to the capped force less
    the dashpot's part)."""
    m, r, mat = case.mass, case.radius, case.material
    inertia = 0.4 * m * r * r
    estar = e_star(mat, wall=True)
    kt_ratio = 2 * (1 - mat.poisson_ratio) / (2 - mat.poisson_ratio)
    le = math.log(case.restitution)
    zeta = -le / math.sqrt(le * le + math.pi**2) * math.sqrt(5.0 / 6.0)
    s = case.spheres[0]
    z, vz, vx, wy = s.position[2], s.velocity[2], s.velocity[0], 0.0

    def force(z: float, vz: float, vx: float, wy: float, xi: float, h: float) -> tuple[float, ...]:
        delta = r - z
        if delta <= 0:
            return 0.0, 0.0, 0.0, 0.0
        sn = 2 * estar * math.sqrt(r * delta)
        kt = kt_ratio * sn
        fn = 4 / 3 * estar * math.sqrt(r) * delta**1.5 - 2 * zeta * math.sqrt(m * sn) * vz
        arm = r - (0.5 * delta if lever == "half" else delta)
        slip = vx - arm * wy
        xi += slip * h
        gt = 2 * zeta * math.sqrt(m * kt)
        if cap == "spring":
            ft = -kt * xi
            if abs(ft) > case.mu * abs(fn):
                ft = math.copysign(case.mu * abs(fn), ft)
                xi = -ft / kt
            else:
                ft -= gt * slip
        else:
            ft = -kt * xi - gt * slip
            if abs(ft) > case.mu * max(fn, 0.0):
                ft = math.copysign(case.mu * max(fn, 0.0), ft)
                xi = -(ft + gt * slip) / kt
        return fn, ft, -arm * ft, xi

    fn, ft, ty, xi = force(z, vz, vx, wy, 0.0, 0.0)
    h = case.dt
    for _ in range(case.steps):
        vz, vx, wy = vz + 0.5 * h * fn / m, vx + 0.5 * h * ft / m, wy + 0.5 * h * ty / inertia
        z += h * vz
        fn, ft, ty, xi = force(z, vz, vx, wy, xi, h)
        vz, vx, wy = vz + 0.5 * h * fn / m, vx + 0.5 * h * ft / m, wy + 0.5 * h * ty / inertia
    return vx, wy


def explain_oblique(results: list[tuple[Case, dict[str, float], dict[str, float] | None]]) -> None:
    print("\nWhere the oblique impacts differ, and why: a 40-line stepper (`emulate_wall_impact`) with "
          "each code's convention for the friction's lever arm and for capping the damped spring "
          "reproduces each code:\n")
    print("| case | lever arm, cap | rebound v_x (m/s) | rebound w_y (rad/s) | matches |")
    print("|---|---|---|---|---|")
    for case, lig, ours in results:
        for lever, cap in (("half", "spring"), ("full", "spring"), ("half", "total"), ("full", "total")):
            vx, wy = emulate_wall_impact(case, lever, cap)
            match = []
            for name, out in (("LIGGGHTS", lig), ("collide", ours)):
                if out is not None and abs(vx - out["vx"]) <= 1e-6 * abs(out["vx"]) + 1e-9 \
                        and abs(wy - out["wy"]) <= 1e-6 * abs(out["wy"]):
                    match.append(name)
            arm = "r - delta/2" if lever == "half" else "r - delta"
            print(f"| {case.name} | {arm}, {'spring alone' if cap == 'spring' else 'spring + dashpot'} | "
                  f"{vx:.6g} | {wy:.6g} | {', '.join(match) or '-'} |")


def run_impacts(workdir: Path, liggghts_only: bool) -> None:
    print("\n### (a) Single impacts (Hertz, tangential history spring)\n")
    print("| case | quantity | closed form | LIGGGHTS | collide | collide vs LIGGGHTS |")
    print("|---|---|---|---|---|---|")
    oblique = []
    for case in impact_cases():
        lig = impact_outcome_liggghts(case, run_liggghts(case, workdir / case.name / "liggghts"))
        ours = None if liggghts_only else impact_outcome_collide(case, run_collide(case, workdir / case.name))
        for row in impact_rows(case, lig, ours):
            print("| " + " | ".join(row) + " |", flush=True)
        if case.walls and case.mu > 0:
            oblique.append((case, lig, ours))
    print("\nOblique cases: sphere moving +x and down onto z = 0; spin is about y (rad/s). Closed forms: "
          "Hertz for e = 1; v_out/v_in = e; rigid-body gross sliding (none near sticking).")
    explain_oblique(oblique)


# ------------------------------------------------------------------ (b) granular box


def box_case(steps: int, seed: int = 1, spheres: int = 1000) -> Case:
    """`spheres` spheres (r = 1 mm; 1000: a 10 x 10 x 10 lattice) on a lattice of 2.5 mm pitch with
    small random velocities, dropped into a box (floor and four side walls, 40 mm wide for 1000,
    15 mm wider than the lattice) under gravity."""
    per = max(1, round(spheres ** (1 / 3)))
    layers = -(-spheres // (per * per))
    r, pitch = 1e-3, 2.5e-3
    side = per * pitch + 0.015
    rng = np.random.default_rng(seed)
    spheres_at = []
    offset = side / 2 - (per - 1) / 2 * pitch
    for i in range(per):
        for j in range(per):
            for k in range(layers):
                pos = (offset + i * pitch, offset + j * pitch, 2 * r + k * pitch)
                vel = tuple(float(x) for x in rng.uniform(-0.05, 0.05, 3))
                spheres_at.append(Sphere(pos, vel))
    spheres_at = spheres_at[:spheres]
    top = max(0.2, 2 * r + layers * pitch + 0.01)
    mat = SOFT_GLASS
    case = Case("granular-box", mat, r, spheres_at, dt=0.0, steps=steps, restitution=0.5, mu=0.5,
                walls=[("zplane", 0.0), ("xplane", 0.0), ("xplane", side), ("yplane", 0.0), ("yplane", side)],
                gravity=9.81, dump_every=0, box=(-0.001, side + 0.001, -0.001, side + 0.001, -0.001, top),
                skin=0.5 * r)
    # dt: 1/50 of the Hertz contact time of two spheres meeting at 1 m/s (the lattice's top falls 25 mm:
    # 0.7 m/s).
    t_c = hertz_closed_form(case.mass / 2, r / 2, e_star(mat, wall=False), 1.0)["t_contact"]
    case.dt = float(f"{t_c / 50:.2g}")
    return case


def box_state(x: np.ndarray, v: np.ndarray, m: float) -> tuple[float, float]:
    return 0.5 * m * float((v**2).sum()), float(x[:, 2].mean())


def run_box(workdir: Path, steps: int, repeat: int, liggghts_only: bool, spheres: int = 1000) -> None:
    case = box_case(steps, spheres=spheres)
    one = box_case(1, spheres=spheres)  # the same set-up for one step: the cost of all but the steps, to subtract
    n = len(case.spheres)
    print(f"\n### (b) Granular box: {n} spheres, r = {case.radius * 1e3:g} mm, "
          f"E = {case.material.youngs_modulus:.2g} Pa, e = {case.restitution}, mu = {case.mu}, "
          f"dt = {case.dt:.3g} s, {case.steps} steps ({case.steps * case.dt:.3g} s simulated)\n", flush=True)
    t: dict[str, list[float]] = {k: [] for k in ("lig", "lig_cpu", "lig_cpu1", "lig_cpu_steps", "ours",
                                                 "ours_cpu_steps")}
    lig = ours = None
    if not liggghts_only:
        run_collide(case, workdir / "box-warm")  # loads (or compiles) the kernels before any timing
    load = [os.getloadavg()[0]]
    for i in range(repeat):  # alternate, so that load from other work on the machine hits both alike
        lig = run_liggghts(case, workdir / f"box-{i}" / "liggghts")
        t["lig"].append(lig.loop_time_s)
        t["lig_cpu"].append(lig.cpu_s)
        t["lig_cpu1"].append(run_liggghts(one, workdir / f"one-{i}" / "liggghts").cpu_s)
        t["lig_cpu_steps"].append(t["lig_cpu"][-1] - t["lig_cpu1"][-1])
        if not liggghts_only:
            ours = run_collide(case, workdir / f"box-{i}", warm_up=one)
            # collide skips contact-free stretches in closed form ("jumps"), so its step count is
            # lower; throughput is counted in LIGGGHTS's steps for the same simulated time.
            if not math.isclose(ours["sim_time"], case.steps * case.dt, rel_tol=1e-9):
                raise RuntimeError(f"collide simulated {ours['sim_time']} s, LIGGGHTS {case.steps * case.dt} s")
            t["ours"].append(ours["wall_time_s"])
            t["ours_cpu_steps"].append(ours["bench_cpu_s"])
        load.append(os.getloadavg()[0])
    assert lig is not None
    # CPU seconds of the steps after the first, which unlike wall time do not grow while other
    # work waits for the cores: LIGGGHTS's process less its one-step process; collide's (WARMED_RUN)
    # simulation less a one-step simulation.
    med = {k: statistics.median(v) for k, v in t.items() if v}
    work = n * (case.steps - 1)

    def rate(key: str, count: int) -> str:
        return f"{count / med[key]:.3g}" if key in med else ""

    def ratio(ours_key: str, lig_key: str) -> str:
        return f"{med[lig_key] / med[ours_key]:.2f}" if ours_key in med else ""

    def runs(key: str) -> str:
        return ", ".join(f"{x:.3g}" for x in t[key])

    rows = [("particle-steps per second, wall clock (median; LIGGGHTS loop time, collide `wall_time_s`)",
             rate("lig", n * case.steps), rate("ours", n * case.steps), ratio("ours", "lig")),
            ("particle-steps per CPU second (median CPU of the run less a one-step run's; collide: of its "
             "simulation, both runs in one process)",
             rate("lig_cpu_steps", work), rate("ours_cpu_steps", work), ratio("ours_cpu_steps", "lig_cpu_steps")),
            ("simulation wall time, s (runs)", runs("lig"), runs("ours"), ""),
            ("CPU time of the steps, s (runs)", runs("lig_cpu_steps"), runs("ours_cpu_steps"), ""),
            ("LIGGGHTS: process CPU time, full and one-step runs, s", f"{runs('lig_cpu')}; {runs('lig_cpu1')}", "", ""),
            ("steps taken (collide: + free-flight jumps)", str(case.steps),
             "" if ours is None else f"{ours['steps']} + {ours.get('jumps', 0)}", "")]
    ke_l, z_l = box_state(lig.frames[-1, :, 0:3], lig.frames[-1, :, 3:6], case.mass)
    if ours is not None:
        x = np.array([b["position"] for b in ours["bodies"]])
        v = np.array([b["velocity"] for b in ours["bodies"]])
        ke_o, z_o = box_state(x, v, case.mass)
        rows += [("final kinetic energy (J, translational)", f"{ke_l:.4g}", f"{ke_o:.4g}", f"{ke_o / ke_l:.3f}"),
                 ("final mean height (m)", f"{z_l:.5g}", f"{z_o:.5g}", f"{z_o / z_l:.4f}")]
    else:
        rows += [("final kinetic energy (J, translational)", f"{ke_l:.4g}", "", ""),
                 ("final mean height (m)", f"{z_l:.5g}", "", "")]
    print(f"| | LIGGGHTS ({PROCESSES[0]} process(es)) | collide ({os.environ.get('COLLIDE_THREADS', 'default')} "
          "threads) | collide / LIGGGHTS (speed; heights, energies) |")
    print("|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(f"\nLoad average (1 min) during the runs: {', '.join(f'{x:.1f}' for x in load)} "
          f"on {os.cpu_count()} cores.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="box runs per code (median)")
    parser.add_argument("--steps", type=int, default=20000, help="box steps")
    parser.add_argument("--only", choices=["impacts", "box"], help="run one part")
    parser.add_argument("--liggghts-only", action="store_true", help="skip collide (check LIGGGHTS alone)")
    parser.add_argument("--keep", type=Path, help="write inputs and outputs here and keep them")
    parser.add_argument("--spheres", type=int, default=1000, help="box spheres")
    parser.add_argument("--np", type=int, default=1, help="LIGGGHTS processes (mpirun -np)")
    parser.add_argument("--threads", type=int, help="collide's threads (COLLIDE_THREADS)")
    args = parser.parse_args()
    PROCESSES[0] = args.np
    if args.threads is not None:
        os.environ["COLLIDE_THREADS"] = str(args.threads)
    if not Path(LIGGGHTS).exists():
        sys.exit("LIGGGHTS not found: apt-get install liggghts (Debian/Ubuntu)")
    workdir = args.keep or Path(tempfile.mkdtemp(prefix="bench_liggghts_"))
    try:
        if args.only != "box":
            run_impacts(workdir, args.liggghts_only)
        if args.only != "impacts":
            run_box(workdir, args.steps, args.repeat, args.liggghts_only, args.spheres)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        sys.exit(f"error: {exc}")
    finally:
        if args.keep is None:
            shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
