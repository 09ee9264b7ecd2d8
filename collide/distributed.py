"""`collide batch --scheduler`: a batch's chunks run on a Dask cluster (issue 13).

Nothing here is imported unless a scheduler is asked for: the in-process batch needs no Dask
(`pip install collide[dask]` adds it). Each chunk is one task, `collide.batch.run_chunk`, which
workers import by name (so every worker needs collide installed) and which writes its own
recordings (so the recordings folder must be one every worker can reach). Results come back as
they finish; `run_batch` appends their rows to the summary and rewrites it in run order at the
end, exactly as in process.

What can go wrong, and what the user sees (one line each, `BatchError`):

- the scheduler cannot be reached (a connect timeout, not a hang), or has no workers;
- the client, scheduler and workers run different Dask, Python or collide versions;
- the workers cannot import collide;
- the scheduler goes away mid-batch, or is left without workers for a minute (finished chunks
  are kept: `--resume` finishes the rest).

A worker killed mid-task has its task retried elsewhere by the scheduler; a task that fails
twice (an exception, or its worker dying twice) becomes rows carrying the error.
"""

from __future__ import annotations

import logging
import os
import re
import time
import uuid
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from collide.batch import BatchError, ChunkResult, ChunkSettings, RunSpec, failure_row, run_chunk
from collide.settings import THREADS_VARIABLE

CONNECT_TIMEOUT_S = 5.0  # an unreachable address fails within this, not after minutes
WORKER_WAIT_S = 30.0  # a scheduler without workers: how long to wait for the first one
# Mid-batch, a scheduler left without workers this long is given up (finished chunks are kept,
# `--resume` runs the rest): Dask itself would wait for workers without end, and a LocalCluster
# whose nannies failed to restart their workers (seen at load 13 on 2 cores) has none to come.
WORKERLESS_S = 60.0
POLL_S = 0.05  # how often a waiting batch looks for a finished chunk (chunks take seconds)
RETRIES = 1  # a task that raised is run once more; the second failure becomes error rows
# Versions that must agree between client, scheduler and workers (pickled tasks and results,
# the wire protocol; collide itself, since workers compute the rows).
MUST_MATCH = ("python", "dask", "distributed", "cloudpickle", "msgpack", "collide")


def local_shape(workers: int | None = None, threads: int | None = None) -> tuple[int, int]:
    """Workers x threads for a LocalCluster on this machine: one single-threaded worker process
    per core by default (the engine is compiled numpy code that holds the GIL much of the time,
    so processes, not threads, use the cores)."""
    cores = os.cpu_count() or 1
    if threads is None:
        threads = 1
    if workers is None:
        workers = max(1, cores // threads)
    if workers < 1 or threads < 1:
        raise BatchError(f"--workers and --threads must be at least 1, got {workers} and {threads}")
    return workers, threads


@dataclass
class Cluster:
    """A connected client (and the LocalCluster it started, if any); close it when done."""

    client: Any
    address: str  # what the user gave ("local" or tcp://host:port), for messages
    local: Any = None
    closed: bool = field(default=False, init=False)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for thing in (self.client, self.local):
            if thing is None:
                continue
            try:
                thing.close(timeout=5) if thing is self.client else thing.close()
            except Exception:  # noqa: BLE001 - closing a broken connection must not hide the real error
                pass

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _quiet() -> None:
    """Dask logs worker deaths, retries, reconnections and shutdowns with tracebacks; the batch
    reports what matters itself, in one line. (Dask's config gives some of its loggers their own
    level, so each is set, and the handler Dask installs too.)"""
    for name in ["distributed", "tornado", "asyncio",
                 *(n for n in logging.root.manager.loggerDict if n.startswith("distributed."))]:
        logger = logging.getLogger(name)
        logger.setLevel(logging.CRITICAL)
        for handler in logger.handlers:
            handler.setLevel(logging.CRITICAL)


def connect(address: str, *, workers: int | None = None, threads: int | None = None,
            timeout: float = CONNECT_TIMEOUT_S) -> Cluster:
    """Connect to the scheduler at `address`, or start a LocalCluster for `address == "local"`,
    and check that the cluster can run collide's chunks (workers present, same versions,
    collide importable)."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise BatchError("--scheduler needs Dask: pip install 'collide[dask]'") from None
    _quiet()
    local = None
    if address == "local":
        n_workers, n_threads = local_shape(workers, threads)
        # A task whose workers die twice fails (KilledWorker; Dask allows 3): DaskExecutor then runs
        # it alone once more before it becomes error rows, so a culprit costs 4 deaths, not 8.
        with dask.config.set({"distributed.scheduler.allowed-failures": RETRIES}):
            try:
                local = LocalCluster(n_workers=n_workers, threads_per_worker=n_threads, processes=True,
                                     host="127.0.0.1", dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL,
                                     preload=["collide.distributed"])  # dask_setup below
            except Exception as exc:  # noqa: BLE001 - any failure to start is one line
                raise BatchError(f"could not start a local Dask cluster: {_first_line(exc)}") from None
        target: Any = local
    else:
        if workers is not None or threads is not None:
            raise BatchError("--workers and --threads go with --scheduler local (a running scheduler "
                             "has the workers it was given)")
        if not re.fullmatch(r"([a-z]+://)?[^\s/:]+:\d+", address):
            raise BatchError(f"--scheduler '{address}': expected a scheduler address like tcp://HOST:8786, "
                             "or 'local'")
        _reach(address, timeout)
        target = address
    try:
        client = Client(target, timeout=timeout, set_as_default=False)
    except Exception as exc:  # noqa: BLE001 - unreachable, refused, bad address: one line
        if local is not None:
            local.close()
        raise BatchError(f"cannot reach the Dask scheduler at {address}: {_first_line(exc)}") from None
    cluster = Cluster(client, address, local)
    try:
        check(cluster)
    except BaseException:
        cluster.close()
        raise
    return cluster


def dask_setup(worker: Any) -> None:
    """Run by Dask in each worker process of `--scheduler local` (a preload): Ctrl-C in the
    terminal reaches the whole process group, but it is the client's to handle (it keeps the
    finished chunks and closes the cluster); a worker that took it too would print a traceback.
    Its batches step their members one after another: the local cluster is shaped to the cores
    already (workers x threads), and each of its tasks stepping on every core too would
    oversubscribe them."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ[THREADS_VARIABLE] = "1"


def _reach(address: str, timeout: float) -> None:
    """Shake hands with the scheduler before making a Client: a Client that fails to connect
    leaves a half-made object that blocks for seconds, with a traceback, when collected."""
    import asyncio

    from distributed.comm import connect as comm_connect

    async def handshake() -> None:
        comm = await comm_connect(address, timeout=timeout)
        await comm.close()

    try:
        asyncio.run(asyncio.wait_for(handshake(), timeout + 1))
    except BaseException as exc:  # noqa: BLE001 - refused, timed out, not a Dask scheduler: one line
        if isinstance(exc, KeyboardInterrupt):
            raise
        if isinstance(exc, (TimeoutError, asyncio.TimeoutError)):
            why = f"no answer within {timeout:g} s"
        elif isinstance(exc, OSError):
            why = _first_line(exc)
        else:  # something answered, but not in Dask's protocol
            why = f"what answers is not a Dask scheduler ({_first_line(exc)})"
        raise BatchError(f"cannot reach the Dask scheduler at {address}: {why}") from None


def check(cluster: Cluster) -> None:
    """Workers present, versions that agree, collide importable on every worker."""
    client, address = cluster.client, cluster.address
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        raise BatchError(f"the Dask scheduler at {address} has no workers after {WORKER_WAIT_S:g} s: "
                         f"start some with `dask worker {address}`") from None
    except Exception as exc:  # noqa: BLE001
        raise BatchError(f"lost the Dask scheduler at {address}: {_first_line(exc)}") from None
    try:
        versions = client.get_versions(packages=["collide"])
        # exec, a builtin, unpickles on any worker; a function of collide's would fail to unpickle
        # on a worker without collide before it could report anything.
        imports = client.run(exec, "import collide.batch", on_error="return")
    except Exception as exc:  # noqa: BLE001
        raise BatchError(f"lost the Dask scheduler at {address}: {_first_line(exc)}") from None
    broken = {w: r for w, r in imports.items() if isinstance(r, BaseException)}
    if broken:
        worker, why = next(iter(broken.items()))
        why = _first_line(why)
        raise BatchError(f"{len(broken)} worker(s) of the Dask scheduler at {address} cannot import collide "
                         f"(e.g. {worker}: {why}): install collide on every worker")
    mismatch = version_mismatch(versions)
    if mismatch:
        raise BatchError(f"the Dask cluster at {address} runs other versions than this client: {mismatch}; "
                         "install the same versions everywhere")


def version_mismatch(versions: dict) -> str:
    """The first package whose version differs between client, scheduler and workers ('' if none),
    from `Client.get_versions()` (its own check only warns)."""
    def packages(info: Any) -> dict:
        return info.get("packages", {}) if isinstance(info, dict) else {}

    def short(version: Any, package: str) -> str:
        if version is None:
            return "missing"
        # Python: major.minor is what pickles must agree on (patch releases mix fine).
        return ".".join(str(version).split(".")[:2]) if package == "python" else str(version)

    client = packages(versions.get("client"))
    scheduler = packages(versions.get("scheduler"))
    workers = {w: packages(v) for w, v in (versions.get("workers") or {}).items()}
    for package in MUST_MATCH:
        mine = short(client.get(package), package)
        seen = [("scheduler", short(scheduler.get(package), package))] if package != "collide" else []
        seen += [(w, short(v.get(package), package)) for w, v in workers.items()]
        other = next(((where, v) for where, v in seen if v != mine), None)
        if other is not None:
            return f"{package} {mine} here, {other[1]} on {other[0]}"
    return ""


def _finished(queue: Any, client: Any, address: str) -> Iterator[Any]:
    """The queue's futures as they finish; a cluster left without workers for WORKERLESS_S is a
    BatchError, not a wait without end."""
    workerless_since: float | None = None
    next_look = time.monotonic()
    while not queue.is_empty():
        if queue.has_ready():
            workerless_since = None
            yield next(queue)
            continue
        time.sleep(POLL_S)
        now = time.monotonic()
        if now < next_look:
            continue
        next_look = now + 1.0
        if _has_workers(client):
            workerless_since = None
        elif workerless_since is None:
            workerless_since = now
        elif now - workerless_since > WORKERLESS_S:
            raise BatchError(f"the Dask scheduler at {address} has had no workers for {WORKERLESS_S:g} s with "
                             f"{queue.count()} chunk(s) unfinished; finished chunks are kept: start workers "
                             "and run the batch again with --resume")


def _has_workers(client: Any) -> bool:
    try:
        return bool(client.scheduler_info().get("workers"))
    except Exception:  # noqa: BLE001 - a lost scheduler shows up on the futures
        return True


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


@dataclass
class DaskExecutor:
    """Runs a batch's chunks as Dask tasks (`run_batch(..., executor=DaskExecutor(cluster))`).

    At most `in_flight` chunks (default twice the cluster's threads) are queued at once, so a
    sweep of a million runs does not sit pickled in the scheduler's memory. `task` is the
    function each chunk runs (tests wrap `run_chunk` to kill their worker).
    """

    cluster: Cluster
    task: Any = run_chunk
    in_flight: int | None = None

    def _slots(self) -> int:
        if self.in_flight is not None:
            return max(1, self.in_flight)
        try:
            return max(2, 2 * sum(self.cluster.client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a lost scheduler shows up on the futures
            return 2

    def run(self, chunks: list[list[RunSpec]], settings: ChunkSettings) -> Iterator[tuple[int, ChunkResult]]:
        """Submit chunks as slots free up; yield each as it finishes.

        When workers die, Dask blames every task they held, the innocent ones queued beside the
        culprit too. So a chunk whose workers died (KilledWorker) is run again alone, once the
        cluster has drained: only if its workers die again then does it become error rows.
        """
        from distributed import KilledWorker, as_completed

        client, address = self.cluster.client, self.cluster.address
        batch = uuid.uuid4().hex[:8]
        waiting = deque(range(len(chunks)))
        suspects: deque[int] = deque()
        live: dict[Any, tuple[int, bool]] = {}  # future -> (chunk, running alone)
        queue = as_completed([], loop=client.loop)
        slots = self._slots()

        def submit(i: int, alone: bool) -> None:
            future = client.submit(self.task, chunks[i], settings, retries=RETRIES, pure=False,
                                   key=f"collide-chunk-{batch}-{i}" + ("-alone" if alone else ""))
            live[future] = (i, alone)
            queue.add(future)

        def fill() -> None:
            if suspects:
                if not live:  # drained: the suspect runs with nothing beside it
                    submit(suspects.popleft(), True)
                return
            while waiting and len(live) < slots:
                submit(waiting.popleft(), False)

        fill()
        try:
            for future in _finished(queue, client, address):
                i, alone = live.pop(future)
                if future.status == "lost":
                    # It finished, but its result was on a worker that died before it came back:
                    # Dask computes it again for the future still held.
                    live[future] = (i, alone)
                    queue.add(future)
                    continue
                if future.status == "error" and not alone and isinstance(_exception(future, address), KilledWorker):
                    suspects.append(i)
                else:
                    yield i, self._outcome(future, chunks[i], address)
                future.release()
                fill()
        finally:
            if live and client.status == "running":
                try:
                    client.cancel(list(live))
                except Exception:  # noqa: BLE001 - the scheduler may be gone already
                    pass

    @staticmethod
    def _outcome(future: Any, chunk: list[RunSpec], address: str) -> ChunkResult:
        from distributed import KilledWorker

        status = future.status
        if status == "finished":
            try:
                return future.result()
            except Exception as exc:  # noqa: BLE001 - fetching the result lost the scheduler
                raise BatchError(f"lost the Dask scheduler at {address}: {_first_line(exc)}") from None
        if status == "error":
            exc = _exception(future, address)
            if isinstance(exc, ImportError) and "collide" in str(exc):
                raise BatchError(f"workers of the Dask scheduler at {address} cannot import collide "
                                 f"({_first_line(exc)}): install collide on every worker")
            if isinstance(exc, KilledWorker):
                why = "its workers died running it, again when it ran alone"
            else:
                why = f"it failed twice on the cluster ({_first_line(exc)})"
            return ChunkResult([failure_row(spec, f"chunk not run: {why}") for spec in chunk], [])
        # Cancelled: the scheduler went away (or restarted) and took the task with it.
        raise BatchError(f"lost the Dask scheduler at {address} (the running chunks were {status})")


def _exception(future: Any, address: str) -> BaseException:
    try:
        return future.exception()
    except Exception as lost:  # noqa: BLE001
        raise BatchError(f"lost the Dask scheduler at {address}: {_first_line(lost)}") from None
