"""What the page exports: the run's CSV (the `collide run --csv` columns) and PNG images.

Pure Python (no viser): the session sends the bytes as a download.
"""

from __future__ import annotations

import io
import math

import numpy as np

from collide.run import SceneRun
from collide.summary import report_csv

MIN_CSV_ROWS = 200


def csv_every(run: SceneRun) -> float:
    """Row spacing (s): the CLI's default, 100 steps, unless that gives fewer than MIN_CSV_ROWS
    rows over the run; then a round spacing giving at least that many."""
    dt = float(run.result.dt[0])
    end = float(run.result.final.t[0])
    every = 100 * dt
    if end / every >= MIN_CSV_ROWS:
        return every
    raw = end / MIN_CSV_ROWS
    exp = math.floor(math.log10(raw))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**exp <= raw:
            return m * 10.0**exp
    return 10.0 ** (exp - 1)


def run_csv(run: SceneRun) -> tuple[bytes, float]:
    """The run's CSV in the `--csv` layout (collide.summary.report_csv, aligned columns) and
    the spacing used."""
    every = csv_every(run)
    return report_csv(run, every, "aligned").encode(), every


def png_bytes(pixels: np.ndarray) -> bytes:
    """An (H, W, 3) or (H, W, 4) uint8 image as PNG."""
    from PIL import Image

    array = np.asarray(pixels)
    if array.dtype != np.uint8:
        array = np.clip(array, 0, 255).astype(np.uint8)
    image = Image.fromarray(array)
    if image.mode == "RGBA":
        # viser renders with a transparent background: put it on white, as the page shows it.
        white = Image.new("RGBA", image.size, (255, 255, 255, 255))
        image = Image.alpha_composite(white, image).convert("RGB")
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()
