"""What a client sends cannot flood the viewer's log.

viser 1.1 reads each websocket message with `Message.deserialize` in its connection's reader
(`viser.infra._infra._message_consumer`); a message that does not read (random bytes, a text
frame, an unknown type, a field of the wrong shape) raised out of the connection handler, and
the websockets library logged a 15-line traceback for it; any local client could repeat that
at will. `guard_connections` replaces that reader with one that reads the same way, but closes
a connection at its first unreadable message with one line on stderr naming the client; a
message that reads but makes one of viser's handlers fail is one line too (each distinct
failure once); the websockets library's own errors (bytes that are not HTTP) are one line each
too. The pinned viser version keeps the replaced reader stable.

It also silences viser's warning for messages queued on a closed connection: a tab that closes
while it is being set up or drawn gets some, by design (its session is closed right after).
"""

from __future__ import annotations

import asyncio
import logging
import sys
import threading
import warnings
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, Union, get_args, get_origin

import msgspec
import viser
from viser.infra import _infra
from viser.infra import _messages as _wire

MAX_FAILURE_LINES = 100  # distinct handler failures reported; later ones are counted only


class UnreadableMessage(ValueError):
    """A websocket message that is not one of viser's."""


def read_message(raw: Any, message_class: Any) -> Any:
    """The viser message in `raw` (bytes from a websocket), or UnreadableMessage saying why not."""
    if not isinstance(raw, bytes):
        raise UnreadableMessage("a text frame")
    try:
        mapping = msgspec.msgpack.decode(raw)
    except msgspec.DecodeError as exc:
        raise UnreadableMessage(f"bytes that are not MessagePack ({exc})") from None
    if not isinstance(mapping, dict) or not isinstance(mapping.get("type"), str):
        raise UnreadableMessage("a message without a type")
    kind = message_class._subclass_from_type_string().get(mapping["type"])
    if kind is None:
        raise UnreadableMessage(f"a message of unknown type '{mapping['type'][:40]}'")
    hints = _wire.get_type_hints_cached(kind)
    for key, value in mapping.items():
        if key != "type" and key in hints and not _shape_fits(value, hints[key]):
            raise UnreadableMessage(f"a {mapping['type']} whose '{key[:40]}' has the wrong shape")
    try:
        return message_class.deserialize(raw)
    except Exception as exc:  # noqa: BLE001 - whatever viser's reader trips on, the client sent it
        raise UnreadableMessage(f"a {mapping['type']} that does not read ({type(exc).__name__}: "
                                f"{_first_line(exc)})") from None


def _shape_fits(value: Any, annotation: Any) -> bool:
    """False where viser's reader would warn about a tuple of the wrong length (it keeps such a
    value as it is, for the handlers to trip on)."""
    origin = get_origin(annotation)
    if origin is Union:
        if value is None:
            return True
        for arg in get_args(annotation):
            if get_origin(arg) is tuple and isinstance(value, (list, tuple)):
                return _shape_fits(value, arg)
        return True
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            return False
        args = get_args(annotation)
        if len(args) >= 2 and args[1] is Ellipsis:
            args = (args[0],) * len(value)
        elif len(value) != len(args):
            return False
        return all(_shape_fits(v, a) for v, a in zip(value, args))
    return True


async def _guarded_consumer(websocket: Any, handle_message: Callable[[Any], None], message_class: Any) -> None:
    """viser's reader loop, closing the connection at its first unreadable message."""
    while True:
        raw = await websocket.recv()
        try:
            message = read_message(raw, message_class)
        except UnreadableMessage as exc:
            report(f"closed the connection from {_peer(websocket)}: it sent {exc}")
            await websocket.close(1003, "unreadable message")
            # Drop what had already arrived; recv() then raises ConnectionClosed, which viser's
            # handler takes as a disconnect (the tab's teardown runs as for any closed tab).
            while True:
                await websocket.recv()
        handle_message(message)


def _peer(websocket: Any) -> str:
    address = getattr(websocket, "remote_address", None)
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return "a client"


class _Failures:
    """One line per distinct failure of a handler or callback that a client's message set off
    (viser's event loop, its thread pool): a client repeating a message that fails cannot
    repeat the line."""

    def __init__(self) -> None:
        self.seen: set[str] = set()
        self.dropped = 0
        self.lock = threading.Lock()

    def report(self, exc: BaseException | None, what: str = "a message from a browser tab",
               message: str = "unknown error") -> None:
        """One line: `what` failed, and why (unless the same line was written before)."""
        text = f"{type(exc).__name__}: {_first_line(exc)}" if exc is not None else message
        line = f"{what} failed: {text}"
        with self.lock:
            if line in self.seen or len(self.seen) >= MAX_FAILURE_LINES:
                self.dropped += 1
                return
            self.seen.add(line)
        report(line)

    def on_loop(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """The event loop's exception handler."""
        self.report(context.get("exception"), message=str(context.get("message", "unknown error")))

    def on_future(self, future: Future) -> None:
        """Stands in for viser's `print_threadpool_errors` (a traceback per failure)."""
        if not future.cancelled() and future.exception() is not None:
            self.report(future.exception())


FAILURES = _Failures()


class _OneLine(logging.Filter):
    """The websockets library's errors (a handshake that fails on bytes that are not HTTP, a
    handler that fails) as one line naming the client, without the traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if exc is not None:
            peer = _peer(getattr(record, "websocket", None))
            record.msg = f"collide view: {record.getMessage()} for {peer} ({type(exc).__name__}: {_first_line(exc)})"
            record.args, record.exc_info, record.exc_text = (), None, None
        return True


def report(line: str) -> None:
    """One line on stderr."""
    print(f"collide view: {line}", file=sys.stderr, flush=True)


_installed = threading.Lock()


def guard_connections(server: viser.ViserServer) -> None:
    """Read `server`'s incoming messages with the guarded reader and report handler and
    callback failures in one line each (process-wide for the reader and the callbacks' report:
    they are module functions of viser's)."""
    with _installed:
        if _infra._message_consumer is not _guarded_consumer:
            _infra._message_consumer = _guarded_consumer
        logger = logging.getLogger("websockets.server")
        if not any(isinstance(f, _OneLine) for f in logger.filters):
            logger.addFilter(_OneLine())
        for name, module in list(sys.modules.items()):
            if name.startswith("viser") and callable(getattr(module, "print_threadpool_errors", None)):
                module.print_threadpool_errors = FAILURES.on_future
    warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection", category=UserWarning)
    loop = server._event_loop
    loop.call_soon_threadsafe(loop.set_exception_handler, FAILURES.on_loop)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else ""
