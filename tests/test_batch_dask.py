"""`collide batch --scheduler`: a batch on a Dask cluster gives the in-process summary, whatever
happens to its workers or its client (issue 13). Clusters listen on 127.0.0.1 only."""

from __future__ import annotations

import functools
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install 'collide[dask]')")

import dask  # noqa: E402
from distributed import Client, LocalCluster  # noqa: E402

from collide import batch as lib  # noqa: E402
from collide.distributed import Cluster, DaskExecutor, check, version_mismatch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SWEEP = "contact.mu=0:1:12"
WALL = "wall_time_s"  # the one column that differs between two runs of the same batch


def _plan(sweep: str = SWEEP) -> lib.Plan:
    return lib.plan_batch(["demo-bonus"], sweeps=[lib.parse_sweep(sweep)])


def _without_wall_time(path: Path) -> list[dict[str, str]]:
    header, rows = lib.read_summary(path)
    assert WALL in header
    return [{k: v for k, v in row.items() if k != WALL} for row in rows]


@pytest.fixture(scope="module")
def in_process(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, str]]:
    summary = tmp_path_factory.mktemp("in_process") / "summary.csv"
    lib.run_batch(_plan(), summary=summary)
    return _without_wall_time(summary)


@pytest.fixture(scope="module")
def cluster() -> Cluster:
    """Two single-threaded worker processes; a worker dying twice under one task fails it."""
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        local = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                             dashboard_address="127.0.0.1:0")
    client = Client(local, set_as_default=False)
    cluster = Cluster(client, str(local.scheduler_address), local)
    check(cluster)
    yield cluster
    cluster.close()


def _die_in_chunk_of(specs: list[lib.RunSpec], settings: lib.ChunkSettings, run_id: str,
                     marker: str | None) -> lib.ChunkResult:
    """run_chunk, but the worker process running `run_id` dies: the first time only when a
    `marker` file is given (created then), always without one."""
    if any(s.run_id == run_id for s in specs):
        if marker is None:
            os._exit(1)
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL)  # exactly one worker dies, once
        except FileExistsError:
            pass
        else:
            os.close(fd)
            os._exit(1)
    return lib.run_chunk(specs, settings)


@pytest.mark.slow
def test_cluster_summary_and_recordings_equal_in_process(cluster: Cluster, in_process: list[dict[str, str]],
                                                          tmp_path: Path) -> None:
    summary, records = tmp_path / "cluster.csv", tmp_path / "rrd"
    plan = _plan()
    done: list[int] = []
    result = lib.run_batch(plan, summary=summary, record_dir=records, chunk_size=3,
                           progress=lambda n, total: done.append(n), executor=DaskExecutor(cluster))
    assert _without_wall_time(summary) == in_process
    assert result.ran == 12 and result.failed == 0
    assert done[0] == 0 and done[-1] == 12 and sorted(done) == done and len(done) == 1 + 4  # one per chunk
    # Recordings were written by the workers, one per run, under the in-process names.
    assert sorted(p.name for p in records.iterdir()) == sorted(lib.recording_name(s) for s in plan.specs)


def _collide(*args: str) -> list[str]:
    return [sys.executable, "-m", "cli.main", "batch", *args]


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="200")


@pytest.mark.slow
def test_cli_sigint_then_resume_on_a_local_cluster(cluster: Cluster, tmp_path: Path) -> None:
    """Ctrl-C while chunks are out on a cluster: exit 130, one message, the finished chunks
    kept; --resume, on a cluster of its own (--scheduler local), completes the in-process summary."""
    sweep = "contact.mu=0:1:300"
    args = ["demo-bonus", "--sweep", sweep, "--chunk", "3", "--summary", "s.csv"]
    # Ctrl-C as a terminal sends it: a test run started in the background (`cmd &` in a script)
    # ignores SIGINT, the child inherits that, and Python then keeps it ignored.
    proc = subprocess.Popen(_collide(*args, "--scheduler", cluster.address), cwd=tmp_path, env=_env(),
                            stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines = []
    for line in proc.stderr:  # "runs: n/300" after each chunk (no terminal: plain lines)
        lines.append(line)
        if line.startswith("runs: ") and not line.startswith("runs: 0/"):
            proc.send_signal(signal.SIGINT)
            break
    out, err = proc.communicate(timeout=120)
    err = "".join(lines) + err
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted: finished runs are kept in s.csv" in err
    _, kept = lib.read_summary(tmp_path / "s.csv")
    assert 3 <= len(kept) < 300  # interrupted mid-sweep, with the finished chunks on disk
    resumed = subprocess.run(_collide(*args, "--scheduler", "local", "--workers", "1", "--resume", "--no-progress"),
                             cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(kept)} already in the summary" in resumed.stdout
    expected = tmp_path / "expected.csv"
    lib.run_batch(_plan(sweep), summary=expected)
    assert _without_wall_time(tmp_path / "s.csv") == _without_wall_time(expected)


def test_unreachable_scheduler_is_one_line_within_the_connect_timeout() -> None:
    from collide.distributed import connect

    with pytest.raises(lib.BatchError, match=r"^cannot reach the Dask scheduler at tcp://127\.0\.0\.1:1: "):
        connect("tcp://127.0.0.1:1", timeout=1)


@pytest.mark.slow
def test_a_worker_killed_mid_sweep_loses_nothing(cluster: Cluster, in_process: list[dict[str, str]],
                                                 tmp_path: Path) -> None:
    marker = tmp_path / "died"
    task = functools.partial(_die_in_chunk_of, run_id="0004", marker=str(marker))
    summary = tmp_path / "cluster.csv"
    result = lib.run_batch(_plan(), summary=summary, chunk_size=3, executor=DaskExecutor(cluster, task=task))
    assert marker.exists(), "no worker died: the test tested nothing"
    assert result.failed == 0
    assert _without_wall_time(summary) == in_process


@pytest.mark.slow
def test_a_chunk_whose_workers_die_twice_becomes_error_rows(cluster: Cluster, in_process: list[dict[str, str]],
                                                            tmp_path: Path) -> None:
    task = functools.partial(_die_in_chunk_of, run_id="0004", marker=None)
    summary = tmp_path / "cluster.csv"
    result = lib.run_batch(_plan(), summary=summary, chunk_size=3, executor=DaskExecutor(cluster, task=task))
    rows = _without_wall_time(summary)
    failed = [r["run_id"] for r in rows if r["error"]]
    assert failed == ["0003", "0004", "0005"] and result.failed == 3  # the chunk of run 0004
    assert all("died running it, again when it ran alone" in r["error"] for r in rows if r["error"])
    assert [r for r in rows if not r["error"]] == [r for r in in_process if r["run_id"] not in failed]


@pytest.mark.parametrize(("address", "words"), [
    ("nonsense", "expected a scheduler address like tcp://HOST:8786"),
])
def test_cli_bad_scheduler_address(address: str, words: str, capsys: pytest.CaptureFixture[str],
                                   monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from cli.main import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["collide", "batch", "demo-bonus", "--scheduler", address])
    with pytest.raises(SystemExit) as exit_:
        main()
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "recordings").exists()


def test_workers_and_threads_need_a_local_scheduler(capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from cli.main import main

    monkeypatch.setattr(sys, "argv", ["collide", "batch", "demo-bonus", "--workers", "2"])
    with pytest.raises(SystemExit) as exit_:
        main()
    assert exit_.value.code == 2 and "--workers and --threads go with --scheduler local" in capsys.readouterr().err


def test_version_mismatch_names_the_package_and_where() -> None:
    def info(**packages: str | None) -> dict:
        base = {"python": "3.11.7.final.0", "dask": "2026.8.0", "distributed": "2026.8.0",
                "cloudpickle": "3.1.1", "msgpack": "1.1.0", "collide": "0.1.0"}
        return {"packages": {**base, **packages}}

    same = {"client": info(), "scheduler": info(collide=None), "workers": {"tcp://w1": info(), "tcp://w2": info()}}
    assert version_mismatch(same) == ""  # the scheduler needs no collide; patch releases of Python mix
    assert version_mismatch({**same, "workers": {"tcp://w1": info(python="3.11.9.final.0")}}) == ""
    other = {**same, "scheduler": info(distributed="2024.1.0")}
    assert version_mismatch(other) == "distributed 2026.8.0 here, 2024.1.0 on scheduler"
    missing = {**same, "workers": {"tcp://w1": info(), "tcp://w2": info(collide=None)}}
    assert version_mismatch(missing) == "collide 0.1.0 here, missing on tcp://w2"
    python = {**same, "workers": {"tcp://w1": info(python="3.12.1.final.0")}}
    assert version_mismatch(python) == "python 3.11 here, 3.12 on tcp://w1"


BLOCK_COLLIDE = """
import sys
class _NoCollide:
    def find_spec(self, name, path=None, target=None):
        if name == "collide" or name.startswith("collide."):
            raise ModuleNotFoundError(f"No module named {name!r}")
sys.meta_path.insert(0, _NoCollide())
"""


@pytest.mark.slow
def test_workers_without_collide_are_one_line(tmp_path: Path) -> None:
    preload = tmp_path / "no_collide.py"
    preload.write_text(BLOCK_COLLIDE)
    local = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address="127.0.0.1:0",
                         preload=[str(preload)])
    with Cluster(Client(local, set_as_default=False), "tcp://example:8786", local) as cluster:
        with pytest.raises(lib.BatchError, match=r"^1 worker\(s\) of the Dask scheduler at tcp://example:8786 "
                                                 r"cannot import collide \(e\.g\. .*ModuleNotFoundError"):
            check(cluster)


def test_the_in_process_batch_imports_no_dask(tmp_path: Path) -> None:
    code = ("import sys; from cli.main import main; sys.argv = ['collide', 'batch', 'demo-bonus', '--sweep', "
            "'contact.mu=0:1:3', '--no-progress']\ntry:\n    main()\nexcept SystemExit as e:\n"
            "    assert e.code == 0, e.code\nbad = [m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed')]\nassert not bad, bad\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr


class _StalledQueue:
    """A queue whose futures never finish."""

    def is_empty(self) -> bool:
        return False

    def has_ready(self) -> bool:
        return False

    def count(self) -> int:
        return 3


class _Workerless:
    def scheduler_info(self) -> dict:
        return {"workers": {}}


def test_a_cluster_left_without_workers_is_one_line_not_a_wait_without_end(monkeypatch) -> None:
    from collide import distributed as dist

    monkeypatch.setattr(dist, "WORKERLESS_S", 0.5)
    with pytest.raises(lib.BatchError, match=r"has had no workers for 0.5 s with 3 chunk\(s\) unfinished; finished "
                       r"chunks are kept: .* --resume$"):
        next(dist._finished(_StalledQueue(), _Workerless(), "tcp://127.0.0.1:8786"))
