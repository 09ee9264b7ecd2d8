"""Write the built-in scenes beyond the report's (fixed seeds, so the files never change unless
this script does): `python scripts/make_scenes.py` writes them into collide/scenes/.

- billiards-break: a cue ball into a tight 15-ball rack on a table seen from above (2D), with
  friction between the balls (mu = 0.1).
- newtons-cradle: five steel balls in a row, 1 mm apart; the first swings in at 1 m/s.
- gas-box: 1 000 spheres in a closed box (3D), random speeds, elastic.
- break-3d: a cue ball rolling into three balls on a table (3D, gravity, friction with the
  cloth and between the balls).
"""

from __future__ import annotations

import math
import random
from pathlib import Path

OUT = Path(__file__).resolve().parent.parent / "collide" / "scenes"

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
             'description = "A cue ball rolling at 2 m/s into three balls on a table (3D, gravity, friction '
             'mu = 0.2 with the cloth and between the balls)."',
             "dim = 3", 'dt = "auto"', 'integrator = "kahan6"', "tol = 1e-4", "duration = 0.6",
             "gravity = [0.0, 0.0, -9.81]", "", "[contact]", "k = 1e6", "mu = 0.2", ""]
    lines += _body("cue", m, r, [0.0, 0.0, r], [2.0, 0.0, 0.0], [0.0, 2.0 / r, 0.0])
    apex = 0.4
    for n, (x, y) in enumerate([(apex, 0.0), (apex + math.sqrt(3) * r, -r), (apex + math.sqrt(3) * r, r)]):
        lines += _body(f"b{n + 1}", m, r, [x, y, r], [0.0, 0.0, 0.0])
    lines += ["[[wall]]", "point = [0.0, 0.0, 0.0]", "normal = [0.0, 0.0, 1.0]", ""]
    return "\n".join(lines)


def main() -> None:
    for name, text in (("billiards-break", billiards_break()), ("newtons-cradle", newtons_cradle()),
                       ("gas-box", gas_box()), ("break-3d", break_3d())):
        (OUT / f"{name}.toml").write_text(text)
        print(f"wrote {OUT / f'{name}.toml'}")


if __name__ == "__main__":
    main()
