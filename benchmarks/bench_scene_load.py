"""Scene set-up time against the number of bodies (docs/design.md section 10).

For each N: a 3D scene of N spheres written as N `[[body]]` tables (a cubic lattice, neighbours
0.1 radius apart), and one declared as a `[[fill]]` of N spheres (random, packing fraction 0.2),
each loaded by `collide.scene.load_scene` in a fresh process: CPU seconds of the load alone
(imports excluded), per body, and the process's peak memory. The bar (issue 52): at most 3 s of
CPU at N = 1e5 for each, and per-body time within 1.5x from decade to decade.

    .venv/bin/python benchmarks/bench_scene_load.py              # N = 1e4, 1e5
    .venv/bin/python benchmarks/bench_scene_load.py 1e4 1e5 1e6  # 1e6: about 2 GB, a minute
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

RADIUS = 0.001
FRACTION = 0.2

LOAD = """
import json, resource, sys, time
from collide.scene import load_scene
started = time.process_time()
scene = load_scene(sys.argv[1])
cpu = time.process_time() - started
print(json.dumps({"cpu": cpu, "bodies": len(scene.bodies),
                  "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def lattice_toml(n: int, path: Path) -> None:
    side = round(n ** (1 / 3)) + 1
    pitch = 2.1 * RADIUS
    head = ['name = "lattice"', "dim = 3", 'integrator = "dem"', "dt = 1e-6",
            "[contact]", 'model = "hertz"', "youngs_modulus = 1e7", "restitution = 0.5", ""]
    with path.open("w") as out:
        out.write("\n".join(head))
        for i in range(n):
            x, y, z = i % side, i // side % side, i // side // side
            out.write(f'[[body]]\nname = "b{i}"\nradius = {RADIUS!r}\nmass = 1e-5\n'
                      f"position = [{x * pitch!r}, {y * pitch!r}, {z * pitch!r}]\n")


def fill_toml(n: int, path: Path) -> None:
    side = (n * 4 / 3 * 3.141592653589793 * RADIUS**3 / FRACTION) ** (1 / 3)
    path.write_text(f"""name = "fill"
dim = 3
integrator = "dem"
dt = 1e-6
[contact]
model = "hertz"
youngs_modulus = 1e7
restitution = 0.5
[[fill]]
name = "grain"
lower = [0.0, 0.0, 0.0]
upper = [{side!r}, {side!r}, {side!r}]
count = {n}
radius = {RADIUS!r}
mass_density = 2500.0
seed = 1
""")


def load(path: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", LOAD, str(path)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def main(sizes: list[int]) -> None:
    print(f"{'N':>9} {'TOML load CPU s':>16} {'us/body':>8} {'RSS MB':>7} {'fill load CPU s':>16} "
          f"{'us/body':>8} {'RSS MB':>7}")
    with tempfile.TemporaryDirectory() as folder:
        for n in sizes:
            toml, fill = Path(folder) / f"lattice{n}.toml", Path(folder) / f"fill{n}.toml"
            lattice_toml(n, toml)
            fill_toml(n, fill)
            a, b = load(toml), load(fill)
            assert a["bodies"] == b["bodies"] == n
            toml.unlink()
            print(f"{n:>9} {a['cpu']:>16.2f} {1e6 * a['cpu'] / n:>8.1f} {a['rss_mb']:>7.0f} {b['cpu']:>16.2f} "
                  f"{1e6 * b['cpu'] / n:>8.1f} {b['rss_mb']:>7.0f}", flush=True)


if __name__ == "__main__":
    main([int(float(x)) for x in sys.argv[1:]] or [10_000, 100_000])
