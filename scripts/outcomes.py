"""Every built-in and every scene file of the tests run with the compiled kernels; their steps and
final states saved, or compared with a saved set (a restructuring of the engine must change
neither: the steps equal, the final velocities, spins and positions within 1e-12 of the fastest
speed).

    python scripts/outcomes.py --save before.json
    python scripts/outcomes.py --compare before.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RANDOM_SCENES = 120
EXTRA_TOLS = {"demo-bonus": [1e-4, 1e-9], "billiards-break": [1e-6], "textbook-glancing": [1e-8]}


def cases() -> list[tuple[str, str | dict, dict]]:
    """(label, source, run options): the built-ins (but the heavy ones) at their own settings and a few tolerances, the
    report's seed runs, and the tests' scene files."""
    from collide.scene import builtin_names

    out = []
    for name in builtin_names(heavy=False):
        out.append((name, name, {}))
        for tol in EXTRA_TOLS.get(name, []):
            out.append((f"{name}@tol={tol:g}", name, {"tol": tol}))
    out.append(("demo-bonus@seed", "demo-bonus", {"integrator": "seed", "dt": 1e-5}))
    out.append(("demo-1d@seed", "demo-1d", {"integrator": "seed", "dt": 2e-5}))
    for path in sorted((ROOT / "tests" / "data").rglob("*.toml")):
        if "slow" not in path.parts:
            out.append((str(path.relative_to(ROOT)), str(path), {}))
    # Random scenes of every kind (1-3D, walls, gravity, friction, spin, materials, DEM laws).
    import random

    sys.path.insert(0, str(ROOT))
    from tests.scene_fuzz import random_raw

    rng = random.Random(2026)
    for k in range(RANDOM_SCENES):
        out.append((f"random-{k}", random_raw(rng, max_bodies=12, quick=True), {}))
    return out


def outcome(source: str | dict, options: dict) -> dict:
    from collide.errors import RunError
    from collide.run import run_scene
    from collide.scene import SceneError, load_scene, parse_scene

    try:
        scene = parse_scene(source) if isinstance(source, dict) else load_scene(source)
        run = run_scene(scene, record=False, **options)
    except (RunError, SceneError) as exc:
        return {"refused": str(exc)}
    final = run.result.final
    return {"steps": int(run.result.steps[0]), "t": float(final.t[0]), "s": final.s[0].tolist(),
            "v": final.v[0].tolist(), "w": final.w[0].tolist(), "error": float(run.error_estimate[0]),
            "speed": float(np.abs(run.result.initial.v[0]).max(initial=0.0))}


def differs(a: dict, b: dict) -> str | None:
    if "refused" in a or "refused" in b:
        return None if a.get("refused") == b.get("refused") else f"refusal {a.get('refused')} / {b.get('refused')}"
    if a["steps"] != b["steps"]:
        return f"steps {a['steps']} / {b['steps']}"
    scale = max(a["speed"], 1e-300)
    for key in ("v", "w", "s"):
        gap = float(np.abs(np.array(a[key]) - np.array(b[key])).max(initial=0.0))
        if gap > 1e-12 * scale * (1.0 if key != "s" else max(1.0, a["t"])):
            return f"{key} differs by {gap:.3g}"
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--save", type=Path)
    group.add_argument("--compare", type=Path)
    args = parser.parse_args()
    from collide.engine import tier

    if not tier.COMPILED:
        print("the compiled kernels are not in use here (collide engine --compile first)", file=sys.stderr)
        return 2
    results = {label: outcome(source, options) for label, source, options in cases()}
    if args.save:
        args.save.write_text(json.dumps(results))
        print(f"{len(results)} outcomes saved to {args.save}")
        return 0
    saved = json.loads(args.compare.read_text())
    bad = 0
    for label, now in results.items():
        if label not in saved:
            print(f"new: {label}")
            continue
        why = differs(saved[label], now)
        if why:
            bad += 1
            print(f"DIFFERS {label}: {why}")
    print(f"{len(results) - bad} of {len(results)} outcomes the same")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
