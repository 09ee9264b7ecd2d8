"""Uploads straight to disk, checked for type and size before a byte is kept.

viser's upload button collects every part of a file in memory, joins them (a second copy) and
keeps the result on the button's handle: a refused 250 MB upload left the server 500 MB larger
(issue 14, item 7). `UploadSink` takes over the transfers of one upload button on one client
connection: the file's declared name and size are checked when the transfer starts; a refused
transfer is acknowledged at once and its parts dropped as they arrive; an accepted one is
written part by part to a hidden file in the recordings folder, and `on_done` gets its path.
Transfers of any other upload button go to viser's own handlers unchanged.

This hooks viser's message handlers (viser 1.1's `FileTransferStartUpload` and
`FileTransferPart`); the pinned viser version keeps that stable.
"""

from __future__ import annotations

import os
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import viser
from viser import _messages

from viewer import files


@dataclass
class _Transfer:
    name: str
    size: int
    parts: int
    path: Path | None = None
    fd: int | None = None
    written: int = 0
    next_part: int = 0
    waiting: dict[int, bytes] = field(default_factory=dict)
    refused: str | None = None


class UploadSink:
    """Receives the uploads of one button on one client. `on_done(name, path, error)` runs on a
    worker thread: `path` is the staged file (the caller owns it) or None with `error`."""

    def __init__(self, client: viser.ClientHandle, button_uuid: str, folder: Path, limit: int,
                 on_start: Callable[[str, str], None], on_done: Callable[[str, Path | None, str | None], None]) -> None:
        self.client = client
        self.button_uuid = button_uuid
        self.folder = folder
        self.limit = limit
        self.on_start = on_start
        self.on_done = on_done
        self._transfers: dict[str, _Transfer] = {}
        self._lock = threading.Lock()
        conn = client._websock_connection
        gui = client.gui
        self._conn = conn
        self._viser_start = gui._handle_file_transfer_start
        self._viser_part = gui._handle_file_transfer_part
        conn.unregister_handler(_messages.FileTransferStartUpload, self._viser_start)
        conn.unregister_handler(_messages.FileTransferPart, self._viser_part)
        conn.register_handler(_messages.FileTransferStartUpload, self._start)
        conn.register_handler(_messages.FileTransferPart, self._part)

    # Handlers run on viser's event loop: no blocking work beyond writing one 512 kB part.

    def _start(self, client_id: int, message: Any) -> None:
        if message.source_component_uuid != self.button_uuid:
            self._viser_start(client_id, message)
            return
        transfer = _Transfer(message.filename, int(message.size_bytes), int(message.part_count))
        try:
            files.check_upload(message.filename, transfer.size, self.limit)
            self.folder.mkdir(parents=True, exist_ok=True)
            transfer.path = files.staging_path(self.folder)
            transfer.fd = os.open(transfer.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except (files.UploadError, OSError) as exc:
            transfer.refused = str(exc) if isinstance(exc, files.UploadError) else \
                f"cannot store it in {self.folder.name}/: {exc.strerror or exc}"
        with self._lock:
            self._transfers[message.transfer_uuid] = transfer
        self.on_start(message.filename, message.transfer_uuid)
        if transfer.refused is not None:
            # Acknowledge everything now: the button comes back at once, and the parts that the
            # browser still sends are dropped on arrival.
            self._ack(message.transfer_uuid, transfer.size, transfer.size)
            self._finish(message.transfer_uuid, transfer)
        elif transfer.parts == 0:
            self._ack(message.transfer_uuid, 0, 0)
            self._finish(message.transfer_uuid, transfer)

    def _part(self, client_id: int, message: Any) -> None:
        if message.source_component_uuid != self.button_uuid:
            self._viser_part(client_id, message)
            return
        with self._lock:
            transfer = self._transfers.get(message.transfer_uuid)
        if transfer is None or transfer.refused is not None or transfer.fd is None:
            return
        index = int(message.part_index)
        if not (0 <= index < transfer.parts) or index < transfer.next_part or index in transfer.waiting:
            return
        transfer.waiting[index] = bytes(message.content)
        try:
            while transfer.next_part in transfer.waiting:
                chunk = transfer.waiting.pop(transfer.next_part)
                transfer.written += len(chunk)
                if transfer.written > transfer.size:
                    raise files.UploadError(f"'{Path(transfer.name).name}' sent more bytes than it declared")
                os.write(transfer.fd, chunk)
                transfer.next_part += 1
        except (OSError, files.UploadError) as exc:
            transfer.refused = str(exc) if isinstance(exc, files.UploadError) else \
                f"cannot store it: {exc.strerror or exc}"
            self._ack(message.transfer_uuid, transfer.size, transfer.size)
            self._finish(message.transfer_uuid, transfer)
            return
        self._ack(message.transfer_uuid, transfer.written, transfer.size)
        if transfer.next_part == transfer.parts:
            self._finish(message.transfer_uuid, transfer)

    def _ack(self, transfer_uuid: str, done: int, total: int) -> None:
        self._conn.queue_message(_messages.FileTransferPartAck(
            source_component_uuid=self.button_uuid, transfer_uuid=transfer_uuid, transferred_bytes=done,
            total_bytes=total))

    def _finish(self, transfer_uuid: str, transfer: _Transfer) -> None:
        if transfer.fd is not None:
            os.close(transfer.fd)
            transfer.fd = None
        error = transfer.refused
        if error is None and transfer.written != transfer.size:
            error = f"'{Path(transfer.name).name}' arrived incomplete"
        if error is not None and transfer.path is not None:
            transfer.path.unlink(missing_ok=True)
            transfer.path = None
        # Forget the transfer only once its late parts can no longer arrive in quantity: a
        # refused one stays known (its parts are dropped) until the connection closes.
        if error is None:
            with self._lock:
                self._transfers.pop(transfer_uuid, None)
        path = transfer.path
        threading.Thread(target=self._report, args=(transfer.name, path, error), daemon=True,
                         name="collide-upload").start()

    def _report(self, name: str, path: Path | None, error: str | None) -> None:
        try:
            self.on_done(name, path, error)
        except Exception as exc:  # noqa: BLE001 - an upload must never take a thread down silently
            if path is not None:
                path.unlink(missing_ok=True)
            traceback.print_exc()
            try:
                self.on_done(name, None, f"internal error: {exc}")
            except Exception:  # noqa: BLE001
                traceback.print_exc()

    def close(self) -> None:
        """Remove staged files of transfers that never finished (the tab closed mid-upload)."""
        with self._lock:
            transfers = list(self._transfers.values())
            self._transfers.clear()
        for transfer in transfers:
            if transfer.fd is not None:
                os.close(transfer.fd)
                transfer.fd = None
                if transfer.path is not None:
                    transfer.path.unlink(missing_ok=True)
