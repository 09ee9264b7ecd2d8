"""What a tab tells its user in words: the status lines at the top, a notice under them (what
became of something the user did), the background run's progress line and the Files folder's
message; and the one-line forms of errors that they show."""

from __future__ import annotations

import threading
from typing import Any

RED = "#c5221f"
GREEN = "#1e6b34"


def one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def strip_name(text: str, name: str) -> str:
    """'name: reason' as 'reason' (the message already names the file)."""
    return text[len(name) + 2:] if text.startswith(f"{name}: ") else text


def escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


class Messages:
    """Writes the panel's message lines (markdown handles built by `viewer.panel.Panel`)."""

    def __init__(self, status: Any, progress: Any, notice: Any, file_message: Any, closed: threading.Event) -> None:
        self._status = status
        self._progress = progress
        self._notice = notice
        self._file_message = file_message
        self._closed = closed

    def show_status(self, view: Any, notes: list[str], error: str | None) -> None:
        """The run shown (name, dimension, origin, its status lines), notes, and the error of
        the last run that failed."""
        lines = []
        if view is not None:
            note = getattr(view, "preview_note", "preview: coarse step while you drag")
            tag = f" *({note})*" if view.preview else ""
            lines.append(f"**{view.name}** · {view.dim}D · {view.origin}{tag}")
            lines += view.status_lines()
        if notes:
            lines += [f"*{n}*" for n in notes]
        if error:
            lines.append(f"<span style='color:{RED}'>**Not run:** {error}</span>")
            if view is not None:
                lines.append("*(showing the last good run)*")
        self._status.content = "  \n".join(lines)

    def show_notice(self, message: str, error: bool = False) -> None:
        """A message at the top of the panel: what became of something the user did."""
        colour = RED if error else GREEN
        self._notice.content = f"<div class='collide-notice' style='color:{colour}'>{escape(message)}</div>"

    def clear_notice(self) -> None:
        if self._notice.content:
            self._notice.content = ""

    def show_progress(self, text: str) -> None:
        if not self._closed.is_set() and self._progress.content != text:
            self._progress.content = text

    def file_message(self, message: str, error: bool = False) -> None:
        self._file_message.content = (f"<span style='color:{RED}'>{escape(message)}</span>" if error else message)
