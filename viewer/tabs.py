"""Every browser tab's life cycle, whatever order viser reports it in.

viser runs `on_client_connect` and `on_client_disconnect` callbacks on its thread pool (32
threads), so a tab that closes while it is being set up may see its disconnect run before its
connect, or while the connect is still building the session: the session was then registered
after its teardown and never closed (two threads and its memory kept per such tab: 100 tabs took
the server from 9 to 99 threads). A burst of tabs also ran up to 32 set-ups at once on the pool
that every GUI callback shares, and a new tab waited behind all of them.

`Tabs` keeps one entry per client under one lock, and its callbacks are async (viser runs them
on its event loop, in the order it sees the tab open and close; each takes the lock briefly):
- connect registers the tab and queues its set-up on a small pool of its own (SETUP_WORKERS
  threads, first come first served);
- a set-up whose tab has closed meanwhile is skipped; one that finds its tab closed once built
  closes the session it built;
- disconnect marks the tab closed and has its session, if it has one, closed on a teardown
  thread (closing joins the session's threads and stops its child process); a disconnect seen
  before its connect leaves a mark that the late connect consumes (nothing is built).
Only these fixed pools hold threads: none is kept per tab once it has closed.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from viewer.session import Session

# Tabs set up at once: a set-up is CPU work under the GIL (about 0.1 s of building controls and
# drawing), so more threads would not finish a burst sooner.
SETUP_WORKERS = 2
TEARDOWN_WORKERS = 2

# (client, closed) -> the tab's session; `closed()` turns true once the tab has gone.
Build = Callable[[Any, Callable[[], bool]], "Session"]


@dataclass
class _Tab:
    client: Any
    session: Session | None = None
    closed: bool = False


class Tabs:
    """The live tabs of one viewer and their sessions."""

    def __init__(self, build: Build, workers: int = SETUP_WORKERS) -> None:
        self._build = build
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._tabs: dict[int, _Tab] = {}
        self._gone: set[int] = set()  # disconnected before their connect callback ran
        self._stopped = False
        self._setups = ThreadPoolExecutor(workers, thread_name_prefix="collide-setup")
        # Closing a session joins its threads (at most seconds, if a run is going): never on
        # viser's event loop, and never behind the set-ups.
        self._teardowns = ThreadPoolExecutor(TEARDOWN_WORKERS, thread_name_prefix="collide-teardown")
        self.skipped = 0  # set-ups not done (or undone) because the tab had closed

    def sessions(self) -> dict[int, Session]:
        """The tabs whose session is set up, by client id (a copy)."""
        with self._lock:
            return {cid: tab.session for cid, tab in self._tabs.items() if tab.session is not None}

    def pending(self) -> int:
        """Tabs connected and not set up yet."""
        with self._lock:
            return sum(tab.session is None for tab in self._tabs.values())

    async def connect(self, client: Any) -> None:
        """viser's connect callback (on its event loop: async, so no pool thread waits on it):
        register the tab and queue its set-up."""
        cid = client.client_id
        with self._lock:
            if cid in self._gone:
                self._gone.discard(cid)
                self.skipped += 1
                return
            if self._stopped or cid in self._tabs:
                return
            self._tabs[cid] = _Tab(client)
            self._submit(self._setups, self._set_up, cid)

    async def disconnect(self, client: Any) -> None:
        """viser's disconnect callback (on its event loop): mark the tab closed; its session, if
        it has one, is closed on a teardown thread."""
        cid = client.client_id
        with self._lock:
            tab = self._tabs.pop(cid, None)
            if tab is None:
                if not self._stopped:
                    self._gone.add(cid)
                return
            tab.closed = True
            self._changed.notify_all()
            if tab.session is not None:
                self._submit(self._teardowns, tab.session.close)

    def _submit(self, pool: ThreadPoolExecutor, job: Callable[..., Any], *args: Any) -> None:
        try:
            pool.submit(_logged, job, *args)
        except RuntimeError:  # the pool is shut down: the viewer is stopping
            pass

    def _set_up(self, cid: int) -> None:
        with self._lock:
            tab = self._tabs.get(cid)
            if tab is None or tab.closed:
                self.skipped += 1
                return
        try:
            session = self._build(tab.client, lambda: tab.closed)
        except Exception as exc:  # noqa: BLE001 - one line, and the other tabs go on
            if not tab.closed:
                print(f"collide view: tab {cid} could not be set up: {type(exc).__name__}: "
                      f"{_first_line(exc)}", file=sys.stderr)
            with self._lock:
                self._tabs.pop(cid, None)
            return
        with self._lock:
            if not tab.closed:
                tab.session = session
                self._changed.notify_all()
                return
            self.skipped += 1
        session.close()

    def wait(self, count: int, timeout: float) -> list[Session]:
        """Block until at least `count` tabs have their session (TimeoutError after `timeout`)."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                ready = [tab.session for tab in self._tabs.values() if tab.session is not None]
                if len(ready) >= count:
                    return ready
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"{len(ready)} of {count} browser tabs connected")
                self._changed.wait(left)

    def close(self) -> None:
        """Close every session and stop setting tabs up (the viewer stops)."""
        with self._lock:
            self._stopped = True
            tabs = list(self._tabs.values())
            self._tabs.clear()
            self._gone.clear()
            for tab in tabs:
                tab.closed = True
        self._setups.shutdown(wait=False, cancel_futures=True)
        self._teardowns.shutdown(wait=True)
        for tab in tabs:
            if tab.session is not None:
                tab.session.close()


def _logged(job: Callable[..., Any], *args: Any) -> None:
    """Run `job`; an error in it is one line on stderr (a pool would keep it silently)."""
    try:
        job(*args)
    except Exception as exc:  # noqa: BLE001 - one line, and the pool goes on
        print(f"collide view: {type(exc).__name__}: {_first_line(exc)}", file=sys.stderr)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else ""
