"""`collide view` on the command line: bad input is one line and a non-zero exit, quickly."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CRASH = ROOT / "tests" / "data" / "viewer-reader-crash.rrd"


def collide(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cli.main", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize("host, reason", [("10.255.255.1", "not an address of this machine"),
                                          ("999.1.1.1", "not a valid IP address"),
                                          ("no-such-host.invalid", "cannot resolve")])
def test_a_host_it_cannot_listen_on_fails_in_one_line(host, reason):
    """Issue 14, item 6: these hung forever (viser retried 1 000 ports, then waited)."""
    started = time.monotonic()
    proc = collide("view", "demo-bonus", "--host", host, "--port", "0", timeout=30)
    assert time.monotonic() - started < 30
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: --host {host}:") and reason in lines[0], proc.stderr
    assert proc.stdout == ""


def test_a_recording_that_crashes_the_reader_is_one_line(tmp_path):
    """Issue 14, item 3: this file makes rerun's reader abort the process (SIGABRT); read in a
    child process, it is one line and exit code 2."""
    proc = collide("view", str(CRASH), "--port", "0")
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "damaged recording" in lines[0] and str(CRASH) in lines[0]


def test_the_crash_sample_still_crashes_the_reader():
    """Keeps the test above honest: reading this file in-process really aborts."""
    code = f"from collide.recording import read_recording; read_recording({str(CRASH)!r}, trusted=True)"
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, timeout=60)
    if proc.returncode >= 0:
        pytest.skip(f"this rerun version no longer aborts on the sample (exit {proc.returncode})")
    assert proc.returncode == -6


def test_banner_names_the_recording(tmp_path):
    """Issue 12, item 8: `collide view recordings/demo-bonus.rrd` printed 'demo-1d'."""
    from collide.recording import write_recording
    from collide.run import run_scene
    from collide.scene import load_scene

    path = write_recording(run_scene(load_scene("demo-bonus")), tmp_path / "demo-bonus.rrd")
    proc = subprocess.Popen([sys.executable, "-m", "cli.main", "view", str(path), "--port", "0",
                             "--recordings", str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
    finally:
        proc.terminate()
        proc.wait(20)
    assert line.startswith(f"collide view: recording {path} at http://127.0.0.1:"), line
    assert "demo-1d" not in line


def test_help_reads_well():
    """Issue 12, item 8: options ended with ' .' (rich ate '[default: ...]') and the command
    list cut the view command's sentence."""
    text = collide("view", "--help").stdout
    assert not re.search(r" \.(\s|$)", text) and "[default: ./scenes" not in text
    assert "by default ./scenes when it" in re.sub(r"\s+", " ", re.sub(r"[│╭╮╰╯─]", " ", text))
    listing = collide("--help").stdout
    line = next(ln for ln in listing.splitlines() if re.search(r"│ view\s", ln))
    assert "Serve the live viewer in the browser, or replay a recording." in line
