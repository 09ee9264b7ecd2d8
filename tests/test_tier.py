"""Which kernels a command runs: a small run stays interpreted (loading numba costs a process
more than such a run takes), every other run loads the compiled ones, and both give the same
numbers."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from collide.hint import quick
from collide.scene import load_scene

QUICK = ["demo-1d", "demo-2d-moving", "demo-2d-stationary", "demo-bonus", "textbook-1d", "textbook-glancing",
         "textbook-unequal", "newtons-cradle"]
SLOW = ["billiards-break", "bounce", "break-3d", "gas-box", "pile"]

# Runs `collide` in this process's interpreter and reports on stderr whether numba was loaded.
PROBE = ("import sys\n"
         "sys.argv = ['collide'] + sys.argv[1:]\n"
         "from cli.main import main\n"
         "try:\n    main()\nexcept SystemExit:\n    pass\n"
         "print('numba loaded' if 'numba' in sys.modules else 'numba not loaded', file=sys.stderr)\n")


def _probe(*args: str, jit: str | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("COLLIDE_JIT", "COLLIDE_JIT_HINT")}
    if jit is not None:
        env["COLLIDE_JIT"] = jit
    return subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env, timeout=600)


@pytest.mark.parametrize("name", QUICK)
def test_a_few_spheres_without_walls_or_gravity_are_quick(name: str) -> None:
    assert quick(load_scene(name))


@pytest.mark.parametrize("name", SLOW)
def test_many_bodies_walls_gravity_or_dem_are_not_quick(name: str) -> None:
    assert not quick(load_scene(name))


def test_settings_that_take_many_steps_are_not_quick() -> None:
    scene = load_scene("demo-bonus")
    assert not quick(scene, integrator="seed")  # the report's fixed step: 1e-5 s, thousands of steps
    assert not quick(scene, dt=1e-6)
    assert not quick(scene, tol=1e-12)
    assert not quick(scene, tol=1e-9)  # a convergence or timing check: wall_time_s is the compiled engine's
    assert quick(scene, tol=1e-8)
    assert not quick(load_scene("demo-bonus", ["gravity=[0,-9.81]"]))


def test_a_quick_run_does_not_load_numba_and_gives_the_compiled_numbers() -> None:
    interpreted = _probe("run", "demo-bonus", "--json", "--no-record")
    compiled = _probe("run", "demo-bonus", "--json", "--no-record", jit="1")
    assert interpreted.returncode == 0 and compiled.returncode == 0, interpreted.stderr + compiled.stderr
    assert interpreted.stderr.strip().endswith("numba not loaded")
    assert compiled.stderr.strip().endswith("numba loaded")
    a, b = json.loads(interpreted.stdout), json.loads(compiled.stdout)
    assert (a.pop("kernels"), b.pop("kernels")) == ("interpreted", "compiled")
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b  # the same code either way, operation for operation


def test_the_summary_says_why_a_run_was_interpreted() -> None:
    """Its wall time is the interpreted code's: the text summary says so, and why."""
    from collide.engine import tier

    if not tier.compiled_ready():
        pytest.skip("the compiled kernels are not built here (python -m collide.warmup)")
    quick_run = _probe("run", "demo-bonus", "--no-record")
    forced = _probe("run", "demo-bonus", "--no-record", jit="0")
    assert "(interpreted kernels: quicker for a run this small; COLLIDE_JIT=1 compiles)" in quick_run.stdout
    assert "(interpreted kernels: COLLIDE_JIT=0)" in forced.stdout
    assert "interpreted" not in _probe("run", "demo-bonus", "--no-record", jit="1").stdout


def test_a_run_that_is_not_quick_loads_the_compiled_kernels_when_ready() -> None:
    from collide.engine import tier

    if not tier.compiled_ready():
        pytest.skip("the compiled kernels are not built here (python -m collide.warmup)")
    out = _probe("run", "demo-bonus", "--json", "--no-record", "--tol", "1e-12")
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip().endswith("numba loaded")


def test_the_hint_is_not_inherited_by_child_processes() -> None:
    code = ("import os\nimport collide.engine.tier\n"
            "print(os.environ.get('COLLIDE_JIT_HINT', 'gone'))\n")
    env = dict(os.environ, COLLIDE_JIT_HINT="interpreted")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.stdout.strip() == "gone", out.stderr


def test_the_engine_sources_list_is_kept_until_any_collide_source_changes(tmp_path, monkeypatch) -> None:
    """The followed imports are kept beside the caches; a kept list is used only while no
    collide source changed (size or modification time), so it cannot hide a new import."""
    from collide.engine import tier

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    sources = tier.engine_sources()
    assert sources == tier._follow_imports()
    memo = tmp_path / "engine-sources.json"
    kept = json.loads(memo.read_text())
    kept["sources"] = kept["sources"][:1]  # as if it were stale
    memo.write_text(json.dumps(kept))
    assert tier.engine_sources() == sources[:1]
    edited = sources[-1]
    stat = edited.stat()
    os.utime(edited, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1000))
    try:
        assert tier.engine_sources() == sources
    finally:
        os.utime(edited, ns=(stat.st_atime_ns, stat.st_mtime_ns))


# A load that takes longer than the notice's threshold (a compile), then a quick one (a cache load).
SLOW_THEN_QUICK = ("import time\n"
                   "from collide.engine import tier\n"
                   "with tier.loading():\n    time.sleep(tier.SLOW_LOAD_NOTICE_S + 0.5)\n"
                   "with tier.loading():\n    pass\n"
                   "print('loaded', file=__import__('sys').stderr)\n")


def _stderr_at_a_terminal(code: str) -> str:
    """What `code` writes to stderr when stderr is a terminal (a pseudo-terminal here)."""
    import pty

    leader, follower = pty.openpty()
    done = subprocess.run([sys.executable, "-c", code], stderr=follower, stdout=subprocess.DEVNULL, timeout=60)
    os.close(follower)
    said = b""
    try:
        while chunk := os.read(leader, 4096):
            said += chunk
    except OSError:  # the terminal's other end closed: all is read
        pass
    os.close(leader)
    assert done.returncode == 0
    return said.decode()


def test_a_slow_kernel_load_is_announced_at_a_terminal_once() -> None:
    said = _stderr_at_a_terminal(SLOW_THEN_QUICK)
    assert said.count("compiling the kernels this scene needs") == 1, said
    assert "loaded" in said


def test_a_slow_kernel_load_says_nothing_into_a_pipe() -> None:
    done = subprocess.run([sys.executable, "-c", SLOW_THEN_QUICK], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stderr.strip() == "loaded", done.stderr
