"""A worker thread that always runs the latest request and drops stale ones.

A slider sends a value many times a second while it is dragged; re-simulating each one would
build a backlog. `LatestWorker` keeps one slot: `submit` overwrites it, and the thread takes
whatever is there when it is free. A job may first answer cheaply (a preview) and ask for a
final pass; that pass runs only once the requests have stopped for `settle` seconds.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")

_EMPTY = object()


class LatestWorker(Generic[T]):
    """Run `job(item, final)` on one thread for the newest submitted item.

    `job` returns True when it only produced a preview and wants `job(item, final=True)` once
    no newer item has arrived for `settle` seconds. Exceptions from `job` go to `on_error` and
    never stop the thread.
    """

    def __init__(self, job: Callable[[T, bool], bool], *, settle: float = 0.3,
                 on_error: Callable[[BaseException], None] | None = None, name: str = "latest-worker") -> None:
        self._job = job
        self._settle = settle
        self._on_error = on_error
        self._cond = threading.Condition()
        self._item: object = _EMPTY
        self._closed = False
        self._busy = False
        self._submitted = 0
        self._done = 0
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: T) -> None:
        """Replace whatever is waiting with `item`."""
        with self._cond:
            self._item = item
            self._submitted += 1
            self._cond.notify_all()

    def pending(self) -> bool:
        """True when a newer item is waiting (a running job may stop early)."""
        with self._cond:
            return self._item is not _EMPTY

    def idle(self) -> bool:
        with self._cond:
            return not self._busy and self._item is _EMPTY

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until nothing is running or waiting (tests and benchmarks)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._busy or self._item is not _EMPTY:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def close(self, timeout: float = 5.0) -> None:
        with self._cond:
            self._closed = True
            self._item = _EMPTY
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _take(self, timeout: float | None, stay_busy: bool = False) -> object:
        """The waiting item, or _EMPTY after `timeout` seconds (None: wait until one comes).
        `stay_busy` keeps the worker marked busy meanwhile (a final pass may follow)."""
        with self._cond:
            deadline = None if timeout is None else time.monotonic() + timeout
            while self._item is _EMPTY and not self._closed:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    break
                self._cond.wait(left)
            item, self._item = self._item, _EMPTY
            self._busy = stay_busy or item is not _EMPTY
            return item

    def _finish(self) -> None:
        with self._cond:
            self._busy = False
            self._done += 1
            self._cond.notify_all()

    def _run(self, item: object, final: bool) -> bool:
        try:
            return bool(self._job(item, final))  # type: ignore[arg-type]
        except BaseException as exc:  # noqa: BLE001 - the thread must survive any job
            if self._on_error is not None:
                try:
                    self._on_error(exc)
                except Exception:
                    traceback.print_exc()
            else:
                traceback.print_exc()
            return False

    def _loop(self) -> None:
        item: object = _EMPTY
        while not self._closed:
            if item is _EMPTY:
                item = self._take(None)
                if item is _EMPTY:
                    continue
            wants_final = self._run(item, False)
            if wants_final and not self._closed:
                newer = self._take(self._settle, stay_busy=True)
                if newer is _EMPTY and not self._closed:
                    self._run(item, True)
                    item = _EMPTY
                    self._finish()
                else:
                    item = newer
                    continue
            else:
                item = _EMPTY
                self._finish()
