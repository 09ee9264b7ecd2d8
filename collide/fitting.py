"""The report's section I: the stress ball's spring constant from force probe + motion detector runs.

Each run is a plain CSV as a Vernier LabQuest / Logger Pro exports it: columns time, force and
position (named in a header such as "Time (s),Force (N),Position (m)"; comma, tab or semicolon
separated). For each run:

1. count the readings outside the force probe's valid range (6-50 N, found in the report by
   testing it against known weights). They are kept by default: cutting on the *measured*
   force selects on the noise (near the cut only readings with upward noise survive), which
   biases the slope low; on the sample data a 6-50 N cut gives 1460 instead of 1500 N/m.
   `force_range` cuts anyway, e.g. for readings far outside the range;
2. compression x = |position - position at the smallest force| with the sign chosen so that x
   grows with the force (the detector may look at the hand from either side). The smallest
   valid force marks the "uncompressed" ball: the probe reads > 0 N before any squeeze, so the
   fit's intercept b absorbs that reading (the report drops it for the same reason);
3. least-squares line F = k x + b: slope k and intercept b with their standard errors
   (classical OLS: s^2 = SSR/(n-2)), and R^2.

The runs' slopes are then averaged (`fit_runs`). The uncertainty of the mean is the larger of
(a) the standard error of the mean from the run-to-run scatter, s/sqrt(N), and (b) the per-run
fit errors propagated into the mean, sqrt(sum se_i^2)/N. (a) already contains the fit noise, so
adding the two in quadrature would count it twice; taking the larger keeps a run-to-run
stiffness variation (a) and a too-small sample's luck (b) both covered. The sample standard
deviation of the slopes (the typical single run's distance from the mean, which is what the
report's "1500 +- 30" is) is reported as the spread.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

import numpy as np

PROBE_RANGE = (6.0, 50.0)  # N: where the report found the force probe accurate
SAMPLE_PACKAGE = "collide.data"
SAMPLE_DIR = "spring_runs"

_COLUMNS = {"time": ("time",), "force": ("force",), "position": ("position", "distance")}


@dataclass
class ProbeRun:
    """One run's raw columns (SI units as exported); `source` names the file in messages."""

    name: str
    source: str
    time: np.ndarray
    force: np.ndarray
    position: np.ndarray


@dataclass
class LineFit:
    """y = slope x + intercept by least squares, with standard errors and R^2."""

    slope: float
    slope_se: float
    intercept: float
    intercept_se: float
    r2: float
    n: int


@dataclass
class RunFit:
    """A run's fit of F = k x + b. `outside`: readings outside the probe's valid range 6-50 N;
    `dropped`: points cut by `force_range` (0 by default)."""

    name: str
    fit: LineFit
    uncompressed_position: float
    outside: int
    dropped: int


@dataclass
class SpringFit:
    """All runs and their average spring constant (see the module docstring for the rule)."""

    runs: list[RunFit]
    k_mean: float
    k_uncertainty: float
    k_sem: float
    k_fit_error: float
    k_spread: float

    def rows(self) -> list[tuple[str, str]]:
        """Fig 2 of the report: (index, 'k +- u') per run, then the average."""
        out = [(str(i + 1), format_pm(r.fit.slope, r.fit.slope_se)) for i, r in enumerate(self.runs)]
        out.append(("AVERAGE", format_pm(self.k_mean, self.k_uncertainty)))
        return out

    def to_dict(self) -> dict:
        return {"runs": [{"name": r.name, "k": r.fit.slope, "k_se": r.fit.slope_se,
                          "intercept": r.fit.intercept, "intercept_se": r.fit.intercept_se,
                          "r2": r.fit.r2, "n": r.fit.n, "outside": r.outside, "dropped": r.dropped,
                          "uncompressed_position": r.uncompressed_position} for r in self.runs],
                "k_mean": self.k_mean, "k_uncertainty": self.k_uncertainty, "k_sem": self.k_sem,
                "k_fit_error": self.k_fit_error, "k_spread": self.k_spread}


# ---------------------------------------------------------------------------------------------
# Reading


def _name(source: str | Path | Traversable) -> str:
    return str(source)


def read_probe_csv(source: str | Path | Traversable) -> ProbeRun:
    """Read a Vernier export. Raises ValueError naming the file and the problem."""
    where = _name(source)
    try:
        text = source.read_text() if not isinstance(source, (str, Path)) else Path(source).read_text()
    except FileNotFoundError:
        raise ValueError(f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{where}: cannot read: {exc}") from None
    lines = [(i + 1, line.strip()) for i, line in enumerate(text.splitlines()) if line.strip()]
    if not lines:
        raise ValueError(f"{where}: the file is empty")
    sep = "\t" if any("\t" in line for _, line in lines) else (
        ";" if not any("," in line for _, line in lines) and any(";" in line for _, line in lines) else ",")

    def cells(line: str) -> list[str]:
        return [c.strip().strip('"').strip() for c in line.split(sep)]

    # The header is the first line naming a force column (Logger Pro may put a "Run 1" line
    # above it and a units line below it); a file without any header has the default order.
    header_at = next((k for k, (_, line) in enumerate(lines) if "force" in line.lower()), None)
    if header_at is None and not all(_is_number(c) for c in cells(lines[0][1])):
        header_at = 0  # a header without a force column: reported as missing below
    if header_at is None:
        header, body = ["time", "force", "position"], lines
    else:
        header, body = cells(lines[header_at][1]), lines[header_at + 1:]
        while body and not any(ch.isdigit() for ch in body[0][1]):
            body = body[1:]  # a units line
    index = {}
    for key, words in _COLUMNS.items():
        found = [j for j, h in enumerate(header) if any(w in h.lower() for w in words)]
        if not found:
            raise ValueError(f"{where}: missing column '{key}' (header: {', '.join(header)})")
        index[key] = found[0]
    data = []
    for number, line in body:
        row = cells(line)
        if len(row) < len(header):
            raise ValueError(f"{where}, line {number}: {len(row)} values, the header has {len(header)}")
        values = []
        for key in ("time", "force", "position"):
            cell = row[index[key]]
            try:
                value = float(cell)
            except ValueError:
                raise ValueError(f"{where}, line {number}: {key} '{cell}' is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"{where}, line {number}: {key} '{cell}' is not finite")
            values.append(value)
        data.append(values)
    if len(data) < 3:
        raise ValueError(f"{where}: {len(data)} data point(s); a line fit needs at least 3")
    arr = np.array(data)
    name = Path(where).stem if isinstance(source, (str, Path)) else Path(source.name).stem
    return ProbeRun(name, where, arr[:, 0], arr[:, 1], arr[:, 2])


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _is_number(cell: str) -> bool:
    return bool(_NUMBER.match(cell))


# ---------------------------------------------------------------------------------------------
# Fitting


def fit_line(x: np.ndarray, y: np.ndarray) -> LineFit:
    """Ordinary least squares y = a x + b with standard errors from the residual scatter."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    n = len(x)
    if n < 3:
        raise ValueError(f"a line fit with errors needs at least 3 points, got {n}")
    xm, ym = x.mean(), y.mean()
    sxx = float(np.sum((x - xm) ** 2))
    if sxx == 0.0:
        raise ValueError("x does not vary: no slope can be fitted")
    slope = float(np.sum((x - xm) * (y - ym)) / sxx)
    intercept = float(ym - slope * xm)
    resid = y - (slope * x + intercept)
    ssr = float(resid @ resid)
    sst = float(np.sum((y - ym) ** 2))
    s2 = ssr / (n - 2)  # unbiased residual variance: two parameters fitted
    return LineFit(slope, math.sqrt(s2 / sxx), intercept, math.sqrt(s2 * (1.0 / n + xm * xm / sxx)),
                   1.0 - ssr / sst if sst > 0 else 1.0, n)


def compression(position: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, float]:
    """Compression from position: relative to the position at the smallest force, signed so
    that it grows with the force. Returns (x, uncompressed position)."""
    p0 = float(position[int(np.argmin(force))])
    # Which way the detector sees the squeeze: the sign of cov(position, force).
    cov = float(np.mean((position - position.mean()) * (force - force.mean())))
    sign = 1.0 if cov >= 0 else -1.0
    return sign * (position - p0), p0


def fit_run(run: ProbeRun, force_range: tuple[float, float] | None = None) -> RunFit:
    """Fit F = k x + b to one run (points outside `force_range` dropped; None keeps all)."""
    keep = np.ones(len(run.force), bool)
    if force_range is not None:
        keep = (run.force >= force_range[0]) & (run.force <= force_range[1])
    if keep.sum() < 3:
        raise ValueError(f"{run.source}: {int(keep.sum())} point(s) inside the probe's valid range "
                         f"{force_range[0]:g}-{force_range[1]:g} N; a line fit needs at least 3")
    force, position = run.force[keep], run.position[keep]
    x, p0 = compression(position, force)
    try:
        fit = fit_line(x, force)
    except ValueError as exc:
        raise ValueError(f"{run.source}: {exc} (the position column does not change)") from None
    outside = int(np.sum((run.force < PROBE_RANGE[0]) | (run.force > PROBE_RANGE[1])))
    return RunFit(run.name, fit, p0, outside, int((~keep).sum()))


def fit_runs(sources: list[str | Path | Traversable] | None = None,
             force_range: tuple[float, float] | None = None) -> SpringFit:
    """Fit every run and average the slopes (default: the shipped SYNTHETIC sample data)."""
    sources = sample_files() if not sources else list(sources)
    runs = [fit_run(read_probe_csv(s), force_range) for s in sources]
    slopes = np.array([r.fit.slope for r in runs])
    errors = np.array([r.fit.slope_se for r in runs])
    n = len(runs)
    spread = float(slopes.std(ddof=1)) if n > 1 else 0.0
    sem = spread / math.sqrt(n) if n > 1 else 0.0
    fit_error = float(math.sqrt(np.sum(errors**2)) / n)
    return SpringFit(runs, float(slopes.mean()), max(sem, fit_error), sem, fit_error, spread)


def sample_files() -> list[Traversable]:
    """The shipped sample runs (SYNTHETIC, see `collide.data`), in order."""
    folder = resources.files(SAMPLE_PACKAGE) / SAMPLE_DIR
    return sorted((p for p in folder.iterdir() if p.name.endswith(".csv")), key=lambda p: p.name)


def format_pm(value: float, error: float) -> str:
    """'1580 ± 30': the error to one significant figure, the value to the same place."""
    if not (error > 0 and math.isfinite(error)):
        return f"{value:g} ± {error:g}"
    place = math.floor(math.log10(error))
    err = round(error, -place)
    if err >= 10 ** (place + 1):  # 0.96 rounds to 1.0: one place up
        place += 1
    decimals = max(-place, 0)
    return f"{round(value, -place):.{decimals}f} ± {round(error, -place):.{decimals}f}"
