"""The CLI as a user meets it: commands, JSON contract, one-line errors with exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def collide(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cli.main", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_run_json_contract():
    out = collide("run", "demo-bonus", "--json", "--no-record")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    for key in ("scene", "dim", "integrator", "dt", "steps", "sim_time", "wall_time_s", "bodies",
                "residuals", "contact"):
        assert key in summary
    assert summary["scene"] == "demo-bonus" and summary["dim"] == 2
    assert {b["name"] for b in summary["bodies"]} == {"ball1", "ball2"}
    assert isinstance(summary["bodies"][0]["spin"], float)
    assert summary["residuals"]["momentum"] < 1e-12
    assert summary["contact"]["max_compression"] > 0


def test_run_json_1d_has_no_spin_and_null_angular_momentum():
    out = collide("run", "demo-1d", "--json", "--no-record", "--integrator", "seed", "--dt", "2e-5")
    summary = json.loads(out.stdout)
    assert "spin" not in summary["bodies"][0]
    assert summary["residuals"]["angular_momentum"] is None
    assert summary["bodies"][0]["velocity"] == pytest.approx(-2.004682, abs=5e-7)


def test_csv_report_layout_reproduces_the_report(tmp_path):
    path = tmp_path / "demo1d.csv"
    out = collide("run", "demo-1d", "--integrator", "seed", "--dt", "2e-5", "--no-record", "--csv", str(path),
                  "--csv-every", "0.002", "--csv-layout", "report")
    assert out.returncode == 0, out.stderr
    lines = path.read_text().splitlines()
    assert lines[0] == "time,s1.x,s2.x,scom.x,v1.x,v2.x,vcom.x,p1.x,p2.x,p.x,E1,E2,E"
    row = next(line for line in lines if line.startswith("0.314000,"))
    assert row.split(",")[1:3] == ["0.314015", "0.371965"]  # Fig 8, row 2


@pytest.mark.parametrize("args, needle", [
    (["run", "demo-1d", "--set", "contact.k=-5"], "contact.k"),
    (["run", "nope"], "unknown scene"),
    (["run", "demo-1d", "--dt", "abc"], "--dt"),
    (["run", "demo-1d", "--dt", "1"], "stability limit"),
    (["run", "demo-1d", "--integrator", "euler"], "integrator"),
    (["run", "demo-1d", "--set", "nokey"], "key=value"),
    (["scenes", "--show", "nope"], "unknown scene"),
])
def test_bad_input_one_line_exit_2(args, needle):
    out = collide(*args, "--no-record") if args[0] == "run" else collide(*args)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and needle in lines[0], out.stderr


def test_scenes_lists_and_shows():
    out = collide("scenes")
    assert out.returncode == 0
    for name in ("demo-1d", "demo-2d-stationary", "demo-2d-moving", "demo-bonus", "textbook-1d",
                 "textbook-glancing", "textbook-unequal"):
        assert name in out.stdout
    show = collide("scenes", "--show", "demo-bonus")
    assert "mu = 0.5" in show.stdout and "[[body]]" in show.stdout


def test_wall_times_read_as_people_write_them():
    from cli.main import wall_text

    assert wall_text(0.00147) == "1.47 ms"
    assert wall_text(25.7) == "25.7 s"


COMMANDS = ("run", "scenes", "validate", "fit-spring", "batch", "accuracy", "stress", "view")


def test_every_help_reads_well():
    """Issue 12, item 8, for every command: no option's help ends in ' .' (rich took
    '[default: ...]' for markup and dropped it), and the command list gives each command's
    summary as one sentence, not broken where its docstring's lines break."""
    import os
    import re

    env = dict(os.environ, COLUMNS="400")
    for command in COMMANDS:
        text = subprocess.run([sys.executable, "-m", "cli.main", command, "--help"], capture_output=True,
                              text=True, env=env, timeout=300).stdout
        assert "Usage:" in text, command
        assert not re.search(r" \.(\s|│|$)", text), (command, re.findall(r".{30} \.", text))
    listing = subprocess.run([sys.executable, "-m", "cli.main", "--help"], capture_output=True, text=True,
                             env=env, timeout=300).stdout
    rows = {m.group(1): m.group(2).strip() for m in re.finditer(r"│ ([a-z-]+)\s{2,}(.*?)\s*│", listing)}
    assert set(COMMANDS) <= set(rows), rows
    assert rows["validate"].startswith("Check the simulator: the report's textbook tables (Figs 3-6) and every "
                                       "built-in scene but the heavy ones (or the scenes given")
    assert ") by the checks that fit it" in rows["validate"]
    assert rows["stress"].endswith("Exit 1 if any case fails.")
    assert rows["fit-spring"].endswith("per run, then the average.")
