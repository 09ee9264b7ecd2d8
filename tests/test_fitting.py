"""Spring constant fits (report section I): reading, fitting, averaging, sample data, CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from typer.testing import CliRunner

from cli.main import app as collide_app
from collide import fitting

ROOT = Path(__file__).resolve().parent.parent


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def synthetic(k: float = 1200.0, n: int = 40, sigma: float = 1.0, seed: int = 0,
              flip: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 0.03, n)
    force = 7.0 + k * x + rng.normal(0, sigma, n)
    position = 0.5 - x if flip else 0.5 + x
    return np.arange(n) * 0.05, force, position


def as_csv(t: np.ndarray, f: np.ndarray, p: np.ndarray, header: str = "Time (s),Force (N),Position (m)",
           sep: str = ",") -> str:
    lines = [header] if header else []
    lines += [sep.join(f"{c:.6f}" for c in row) for row in zip(t, f, p, strict=True)]
    return "\n".join(lines) + "\n"


def test_fit_line_matches_scipy_linregress() -> None:
    t, f, p = synthetic(sigma=2.0)
    x = p - p[0]
    ours = fitting.fit_line(x, f)
    ref = stats.linregress(x, f)
    assert ours.slope == pytest.approx(ref.slope) and ours.intercept == pytest.approx(ref.intercept)
    assert ours.slope_se == pytest.approx(ref.stderr) and ours.intercept_se == pytest.approx(ref.intercept_stderr)
    assert ours.r2 == pytest.approx(ref.rvalue**2)


def test_compression_is_relative_to_smallest_force_and_grows_with_force() -> None:
    t, f, p = synthetic(sigma=0.0)
    for pos in (p, 1.0 - p):  # the detector on either side of the hand
        x, p0 = fitting.compression(pos, f)
        assert p0 == pos[np.argmin(f)] and x[np.argmin(f)] == 0.0
        assert np.all(np.diff(x) > 0)


@pytest.mark.parametrize("header, sep", [("Time (s),Force (N),Position (m)", ","),
                                         ("Time (s)\tForce (N)\tPosition (m)", "\t"),
                                         ('"Latest: Time (s)";"Latest: Force (N)";"Latest: Position (m)"', ";"),
                                         ("", ",")])
def test_reads_vernier_variants(tmp_path: Path, header: str, sep: str) -> None:
    t, f, p = synthetic(k=1300.0, sigma=0.0, flip=True)
    run = fitting.fit_run(fitting.read_probe_csv(write(tmp_path / "r.csv", as_csv(t, f, p, header, sep))))
    assert run.fit.slope == pytest.approx(1300.0, rel=1e-4) and run.fit.r2 == pytest.approx(1.0)


def test_reads_columns_by_name_with_a_run_line_and_a_units_line(tmp_path: Path) -> None:
    t, f, p = synthetic(k=900.0, sigma=0.0)
    rows = "\n".join(f"{pi:.6f},{ti:.2f},{fi:.6f}" for ti, fi, pi in zip(t, f, p, strict=True))
    path = write(tmp_path / "r.csv", f"Run 1\nPosition,Time,Force\nm,s,N\n{rows}\n")
    run = fitting.read_probe_csv(path)
    assert run.force == pytest.approx(f, abs=1e-6) and run.position == pytest.approx(p, abs=1e-6)
    assert fitting.fit_run(run).fit.slope == pytest.approx(900.0, rel=1e-4)


@pytest.mark.parametrize("text, problem", [
    ("Time (s),Position (m)\n0,0.5\n1,0.6\n2,0.7\n", "missing column 'force'"),
    ("Time (s),Force (N),Position (m)\n0,6,0.5\n1,7,0.51\n", "at least 3"),
    ("Time (s),Force (N),Position (m)\n0,6,0.5\n1,seven,0.51\n2,8,0.52\n", "line 3: force 'seven' is not a number"),
    ("Time (s),Force (N),Position (m)\n0,6,0.5\n1,7\n2,8,0.52\n", "line 3"),
    ("", "empty"),
    ("Time (s),Force (N),Position (m)\n0,6,0.5\n1,7,0.5\n2,8,0.5\n", "position column does not change"),
])
def test_bad_files_raise_a_clear_error_naming_the_file(tmp_path: Path, text: str, problem: str) -> None:
    path = write(tmp_path / "bad.csv", text)
    with pytest.raises(ValueError) as info:
        fitting.fit_runs([path])
    assert str(path) in str(info.value) and problem in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such file"):
        fitting.fit_runs([tmp_path / "nope.csv"])


def test_sample_data_recovers_k_1500_within_its_uncertainty() -> None:
    files = fitting.sample_files()
    assert [f.name for f in files] == [f"run{i:02d}.csv" for i in range(1, 11)]
    fit = fitting.fit_runs()
    assert len(fit.runs) == 10
    assert abs(fit.k_mean - 1500.0) <= fit.k_uncertainty
    assert fit.k_uncertainty == max(fit.k_sem, fit.k_fit_error)
    # The report's statistics: slopes 1400-1600 N/m, R^2 around 0.98, intercept a few newtons.
    slopes = [r.fit.slope for r in fit.runs]
    assert 1400 < min(slopes) and max(slopes) < 1600
    assert 0.97 < float(np.median([r.fit.r2 for r in fit.runs])) < 0.99
    assert all(4.0 < r.fit.intercept < 10.0 for r in fit.runs)
    rows = fit.rows()
    assert rows[0] == ("1", fitting.format_pm(slopes[0], fit.runs[0].fit.slope_se)) and rows[-1][0] == "AVERAGE"


def test_cutting_on_measured_force_biases_the_slope_low() -> None:
    cut = fitting.fit_runs(force_range=fitting.PROBE_RANGE)
    assert cut.k_mean < fitting.fit_runs().k_mean - 20
    assert sum(r.dropped for r in cut.runs) > 0


def test_generator_reproduces_the_shipped_files(tmp_path: Path) -> None:
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_spring_data.py"), "--out", str(tmp_path)],
                   check=True, capture_output=True)
    for shipped in fitting.sample_files():
        assert (tmp_path / shipped.name).read_text() == shipped.read_text(), shipped.name
    assert "SYNTHETIC" in (ROOT / "scripts" / "make_spring_data.py").read_text()[:200]


@pytest.mark.parametrize("value, error, text", [(1576.3, 28.0, "1580 ± 30"), (1499.9, 12.4, "1500 ± 10"),
                                                (5.67, 0.58, "5.7 ± 0.6"), (2.0, 0.96, "2 ± 1")])
def test_format_pm(value: float, error: float, text: str) -> None:
    assert fitting.format_pm(value, error) == text


def test_cli_fit_spring(tmp_path: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(collide_app, ["fit-spring"])
    assert result.exit_code == 0 and "AVERAGE" in result.stdout and "1500 ± 10" in result.stdout
    as_json = runner.invoke(collide_app, ["fit-spring", "--json"])
    assert as_json.exit_code == 0
    import json

    data = json.loads(as_json.stdout)
    assert len(data["runs"]) == 10 and abs(data["k_mean"] - 1500) < data["k_uncertainty"]
    bad = write(tmp_path / "bad.csv", "Time (s),Force (N)\n0,1\n")
    failed = runner.invoke(collide_app, ["fit-spring", str(bad)])
    assert failed.exit_code == 2 and failed.stderr.startswith("error: ") and failed.stderr.count("\n") == 1
    assert "Traceback" not in failed.output
    assert runner.invoke(collide_app, ["fit-spring", "--range", "50:6"]).exit_code == 2
    assert "Example" in runner.invoke(collide_app, ["fit-spring", "--help"]).stdout
