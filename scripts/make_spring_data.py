"""Generate the SYNTHETIC sample runs in collide/data/spring_runs/ (run01.csv ... run10.csv).

THESE DATA ARE SYNTHETIC. The report's raw Vernier files were not published; these files are
made up to have the report's statistics (section I, Figs 1-2), so that `collide fit-spring`
has something realistic to chew on. They are not measurements.

Model of one run (a stress ball squeezed against a wall, detector behind the hand):

* the ball's true spring constant in run i is 1500 N/m plus the report's Fig 2 deviation of
  run i from its own mean (so the true runs average exactly 1500 N/m and scatter 1450-1580 N/m
  like the report's: the squeeze differs from run to run);
* the force rises from about 6 N to about 49 N and back (sin^2 in time) over 2.5 s, sampled at
  20 Hz (LabQuest's default), inside the probe's valid range 6-50 N;
* the force probe reads F = k x + offset plus Gaussian noise whose size is set so that the
  run's slope standard error is about the report's (Fig 2: 20-50 N/m), which gives R^2 ~ 0.98;
* the motion detector reads 0.4500 m + x, quantised to its 1 mm resolution.

Run: python scripts/make_spring_data.py [--out DIR] [--seed N]   (defaults reproduce the files)
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SEED = 2019
K_TRUE = 1500.0  # N/m
FIG2_K = np.array([1580, 1520, 1510, 1520, 1490, 1480, 1500, 1490, 1450, 1500], float)
FIG2_SE = np.array([30, 20, 40, 20, 50, 30, 20, 20, 40, 30], float)
F_LOW, F_HIGH = 6.0, 49.0  # N: the squeeze stays inside the probe's 6-50 N range
DURATION, RATE = 2.5, 20.0  # s, samples per second
DETECTOR_DISTANCE = 0.45  # m to the hand at the lightest squeeze
RESOLUTION = 0.001  # m: the motion detector's resolution
OUT = Path(__file__).resolve().parent.parent / "collide" / "data" / "spring_runs"


def make_run(rng: np.random.Generator, k: float, slope_se: float) -> np.ndarray:
    """Columns time, force, position of one synthetic run."""
    t = np.arange(0.0, DURATION + 1e-9, 1.0 / RATE)
    force_true = F_LOW + (F_HIGH - F_LOW) * np.sin(np.pi * t / DURATION) ** 2
    x = (force_true - F_LOW) / k  # compression beyond the lightest squeeze
    # Force noise giving the wanted slope standard error: se = sigma / sqrt(sum (x - mean)^2).
    sigma = slope_se * np.sqrt(np.sum((x - x.mean()) ** 2))
    force = force_true + rng.normal(0.0, sigma, t.size)
    position = np.round((DETECTOR_DISTANCE + x) / RESOLUTION) * RESOLUTION
    return np.column_stack((t, force, position))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    k_runs = K_TRUE + (FIG2_K - FIG2_K.mean())
    for i, (k, se) in enumerate(zip(k_runs, FIG2_SE, strict=True), start=1):
        data = make_run(rng, k, se)
        # Runs 9 and 10 as LabQuest's tab-separated text export; the rest as CSV.
        sep = "\t" if i >= 9 else ","
        lines = [sep.join(("Time (s)", "Force (N)", "Position (m)"))]
        lines += [sep.join((f"{t:.2f}", f"{f:.3f}", f"{p:.3f}")) for t, f, p in data]
        (args.out / f"run{i:02d}.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {len(k_runs)} SYNTHETIC runs to {args.out}")


if __name__ == "__main__":
    main()
