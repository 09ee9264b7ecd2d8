"""Write the built-in scenes beyond the report's (fixed seeds, so the files never change unless
this script does): `python scripts/make_scenes.py` writes them into collide/scenes/.

- billiards-break: a cue ball into a tight 15-ball rack on a table seen from above (2D), with
  friction between the balls (mu = 0.1).
- newtons-cradle: five steel balls in a row, 1 mm apart; the first swings in at 1 m/s.
- gas-box: 1 000 spheres in a closed box (3D), random speeds, elastic.
- break-3d: a cue ball rolling into three balls on a cloth-covered table (3D, gravity, DEM with
  materials: Hertz contacts, restitution, friction and rolling resistance on the cloth).
- bounce: a rubber ball dropped on a floor with restitution 0.8 (heights fall by e^2 a bounce), in the
  event engine (a sphere alone among walls).
- pile: 1 000 spheres poured into a box settle to rest (Hertz, damping, tangential springs).
- drop-pile (not a built-in, into tests/data/: the viewer's many-sphere screenshots and test):
  125 beads dropped in a 5x5x5 lattice into a bin (floor and four side walls) under gravity,
  friction mu = 0.3 and restitution 0.3 (DEM kernel); in 0.4 s they land and nearly settle.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

OUT = Path(__file__).resolve().parent.parent / "collide" / "scenes"
EXTRA = Path(__file__).resolve().parent.parent / "tests" / "data"

# Pool balls (World Pool-Billiard Association): 57.15 mm, 170 g.
R_POOL, M_POOL = 0.028575, 0.17


def _vec(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _body(name: str, mass: float, radius: float, position, velocity=None, spin=None) -> list[str]:
    lines = ["[[body]]", f'name = "{name}"', f"mass = {mass!r}", f"radius = {radius!r}",
             f"position = {_vec(position) if isinstance(position, (list, tuple)) else repr(position)}"]
    if velocity is not None:
        lines.append(f"velocity = {_vec(velocity) if isinstance(velocity, (list, tuple)) else repr(velocity)}")
    if spin is not None:
        lines.append(f"spin = {_vec(spin) if isinstance(spin, (list, tuple)) else repr(spin)}")
    return lines + [""]


def _rack(x0: float, r: float) -> list[tuple[float, float]]:
    """A tight triangle of 15 balls, apex at (x0, 0), pointing at the cue ball (-x)."""
    out = []
    for row in range(5):
        for k in range(row + 1):
            out.append((x0 + row * math.sqrt(3.0) * r, (k - row / 2.0) * 2.0 * r))
    return out


def billiards_break() -> str:
    lines = ['name = "billiards-break"',
             'description = "A cue ball at 6 m/s into a tight 15-ball rack (2D, seen from above), friction '
             'between the balls (mu = 0.1)."',
             "dim = 2", 'dt = "auto"', 'integrator = "kahan6"', "tol = 1e-7", "",
             "[contact]", "k = 1e7", "mu = 0.1", ""]
    lines += _body("cue", M_POOL, R_POOL, [0.0, 0.0], [6.0, 0.0])
    for n, (x, y) in enumerate(_rack(0.5, R_POOL)):
        lines += _body(f"b{n + 1}", M_POOL, R_POOL, [x, y], [0.0, 0.0])
    return "\n".join(lines)


def newtons_cradle() -> str:
    r, m, gap = 0.02, 0.26, 0.001  # steel, 40 mm
    lines = ['name = "newtons-cradle"',
             'description = "Five steel balls 1 mm apart (1D): the first comes in at 1 m/s and the last leaves '
             'with it; equal masses exchange velocities in each collision."',
             "dim = 1", 'dt = "auto"', 'integrator = "kahan6"', "tol = 1e-7", "", "[contact]", "k = 1e8", ""]
    lines += _body("ball1", m, r, 0.0, 1.0)
    for n in range(1, 5):
        lines += _body(f"ball{n + 1}", m, r, 0.1 + (n - 1) * (2 * r + gap), 0.0)
    return "\n".join(lines)


def gas_box(n: int = 1000, seed: int = 1) -> str:
    rng = random.Random(seed)
    r, m, side = 0.01, 0.01, 0.5
    per = math.ceil(n ** (1 / 3))
    spacing = side / per
    lines = ['name = "gas-box"',
             f'description = "{n} spheres in a closed box (3D), random velocities of 1 m/s scale; elastic, so the '
             'energy stays constant."',
             "dim = 3", 'dt = "auto"', 'integrator = "kahan6"', "tol = 1e-7", "duration = 0.5", "",
             "[contact]", "k = 1e5", ""]
    cells = [(i, j, k) for i in range(per) for j in range(per) for k in range(per)]
    for index, (i, j, k) in enumerate(cells[:n]):
        jitter = 0.2 * (spacing - 2 * r)
        pos = [(c + 0.5) * spacing + rng.uniform(-jitter, jitter) for c in (i, j, k)]
        vel = [rng.gauss(0.0, 1.0) for _ in range(3)]
        lines += _body(f"p{index + 1}", m, r, pos, vel)
    for axis in range(3):
        for side_value, sign in ((0.0, 1.0), (side, -1.0)):
            point = [0.0, 0.0, 0.0]
            normal = [0.0, 0.0, 0.0]
            point[axis] = side_value
            normal[axis] = sign
            lines += ["[[wall]]", f"point = {_vec(point)}", f"normal = {_vec(normal)}", ""]
    return "\n".join(lines)


def break_3d() -> str:
    r, m = R_POOL, M_POOL
    lines = ['name = "break-3d"',
             'description = "A cue ball rolling at 2 m/s into three balls on a cloth-covered table (3D, gravity, '
             'DEM with Hertz contacts: balls e = 0.95, mu = 0.05 between them; on the cloth e = 0.5, mu = 0.2, '
             'rolling resistance 0.01)."',
             "dim = 3", 'dt = "auto"', 'integrator = "dem"', "tol = 4e-2", "duration = 1.2",
             "gravity = [0.0, 0.0, -9.81]", "", "[contact]", 'model = "hertz"', "youngs_modulus = 5e9",
             "poisson_ratio = 0.35", "",
             "[[material]]", 'name = "phenolic"', "density = 1740.0", "youngs_modulus = 5e9", "poisson_ratio = 0.35",
             "mu = 0.2", "restitution = 0.5", "rolling_friction = 0.01", "",
             "[[pair]]", 'materials = ["phenolic", "phenolic"]', "mu = 0.05", "restitution = 0.95",
             "rolling_friction = 0.0", ""]
    bodies = _body("cue", m, r, [0.0, 0.0, r], [2.0, 0.0, 0.0], [0.0, 2.0 / r, 0.0])
    apex = 0.4
    for n, (x, y) in enumerate([(apex, 0.0), (apex + math.sqrt(3) * r, -r), (apex + math.sqrt(3) * r, r)]):
        bodies += _body(f"b{n + 1}", m, r, [x, y, r], [0.0, 0.0, 0.0])
    lines += [line for line in bodies if not line.startswith("mass")] + [""]
    lines = _with_material(lines, "phenolic")
    lines += ["[[wall]]", "point = [0.0, 0.0, 0.0]", "normal = [0.0, 0.0, 1.0]", ""]
    return "\n".join(lines)


def _with_material(lines: list[str], material: str) -> list[str]:
    """Every [[body]] names `material` (its density gives the mass)."""
    out = []
    for line in lines:
        out.append(line)
        if line == "[[body]]":
            out.append(f'material = "{material}"')
    return out


def bounce() -> str:
    r, height, e = 0.03, 1.0, 0.8
    lines = ['name = "bounce"',
             'description = "A rubber ball dropped from 1 m onto a rigid floor, restitution 0.8 (Hertz): each '
             'bounce peaks at e^2 = 0.64 of the last. A sphere alone among walls, so the event engine runs it at '
             'full order."',
             "dim = 2", 'dt = "auto"', "tol = 1e-2", "duration = 3.5",
             "gravity = [0.0, -9.81]", "", "[contact]", 'model = "hertz"', f"restitution = {e!r}", "",
             "[[material]]", 'name = "rubber"', "density = 1100.0", "youngs_modulus = 5e6", "poisson_ratio = 0.45", "",
             "[[body]]", 'name = "ball"', 'material = "rubber"', f"radius = {r!r}", f"position = [0.0, {height + r!r}]",
             "velocity = [0.3, 0.0]", "",
             "[[wall]]", "point = [0.0, 0.0]", "normal = [0.0, 1.0]", ""]
    return "\n".join(lines)


def pile(n: int = 1000, seed: int = 2) -> str:
    rng = random.Random(seed)
    r, side = 0.005, 0.1
    per = int(side / (2.2 * r))
    spacing = side / per
    layers = math.ceil(n / per**2)
    lines = ['name = "pile"',
             f'description = "{n} glass-like spheres (r = 5 mm, softened E = 5 MPa) poured from a loose lattice into a '
             f'{side * 100:.0f} cm box settle under gravity (Hertz, e = 0.3, tangential springs, mu = 0.5, rolling '
             'resistance 0.05). The run ends at rest: kinetic energy below 1e-6 of its peak."',
             "dim = 3", 'dt = "auto"', 'integrator = "dem"', "tol = 4e-2", "duration = 5.0", "rest = 1e-6",
             "gravity = [0.0, 0.0, -9.81]", "", "[contact]", 'model = "hertz"', "restitution = 0.3",
             'tangential = "spring"', "mu = 0.5", "rolling_friction = 0.05", "",
             "[[material]]", 'name = "glass"', "density = 2500.0", "youngs_modulus = 5e6", "poisson_ratio = 0.25", ""]
    count = 0
    for k in range(layers):
        for i in range(per):
            for j in range(per):
                if count == n:
                    break
                jitter = 0.1 * (spacing - 2 * r)
                pos = [(i + 0.5) * spacing + rng.uniform(-jitter, jitter),
                       (j + 0.5) * spacing + rng.uniform(-jitter, jitter), r + 0.002 + k * spacing]
                vel = [rng.gauss(0.0, 0.05), rng.gauss(0.0, 0.05), 0.0]
                count += 1
                lines += ["[[body]]", f'name = "g{count}"', 'material = "glass"', f"radius = {r!r}",
                          f"position = {_vec(pos)}", f"velocity = {_vec(vel)}", ""]
    for axis in range(3):
        for side_value, sign in ((0.0, 1.0), (side, -1.0)):
            if axis == 2 and sign < 0:
                continue  # open at the top
            point = [0.0, 0.0, 0.0]
            normal = [0.0, 0.0, 0.0]
            point[axis] = side_value
            normal[axis] = sign
            lines += ["[[wall]]", f"point = {_vec(point)}", f"normal = {_vec(normal)}", ""]
    return "\n".join(lines)


def drop_pile(per: int = 5, layers: int = 5, seed: int = 3) -> str:
    """Spheres in a jittered lattice just above a floor, falling into a bin that fits them."""
    rng = random.Random(seed)
    r, m, gap = 0.01, 0.01, 0.024  # 20 mm beads of 10 g, 4 mm apart
    half = per * gap / 2 + 0.002
    n = per * per * layers
    # k = 1e5 N/m: a bead under four layers presses about 0.005 mm; restitution 0.3 takes the
    # bounce out (DEM kernel, 50 steps a contact), so in 0.4 s the beads land and nearly settle.
    lines = ['name = "drop-pile"',
             f'description = "{n} beads (20 mm, 10 g) dropped into a bin under gravity, friction mu = 0.3, '
             'restitution 0.3 (3D, DEM); the first 0.4 s, as they land and settle."',
             "dim = 3", 'dt = "auto"', 'integrator = "dem"', "tol = 4e-2", "duration = 0.4",
             "gravity = [0.0, 0.0, -9.81]", "", "[contact]", "k = 1e5", "mu = 0.3", "restitution = 0.3", ""]
    for index in range(n):
        layer, rest = divmod(index, per * per)
        i, j = divmod(rest, per)
        pos = [(i - (per - 1) / 2) * gap + rng.uniform(-0.001, 0.001),
               (j - (per - 1) / 2) * gap + rng.uniform(-0.001, 0.001), r + 0.003 + layer * gap]
        lines += _body(f"s{index + 1}", m, r, pos, [rng.gauss(0.0, 0.1), rng.gauss(0.0, 0.1), -0.3])
    lines += ["[[wall]]", "point = [0.0, 0.0, 0.0]", "normal = [0.0, 0.0, 1.0]", ""]
    for axis in range(2):
        for sign in (1.0, -1.0):
            point = [0.0, 0.0, 0.0]
            normal = [0.0, 0.0, 0.0]
            point[axis] = -sign * half
            normal[axis] = sign
            lines += ["[[wall]]", f"point = {_vec(point)}", f"normal = {_vec(normal)}", ""]
    return "\n".join(lines)


def main() -> None:
    for name, text in (("billiards-break", billiards_break()), ("newtons-cradle", newtons_cradle()),
                       ("gas-box", gas_box()), ("break-3d", break_3d()), ("bounce", bounce()), ("pile", pile())):
        (OUT / f"{name}.toml").write_text(text)
        print(f"wrote {OUT / f'{name}.toml'}")
    (EXTRA / "drop-pile.toml").write_text(drop_pile())
    print(f"wrote {EXTRA / 'drop-pile.toml'}")


if __name__ == "__main__":
    main()
