"""The Parameters folder: a text box and a slider for every parameter the scene uses, grouped per
body (open folders for a few bodies, closed ones for more, a body picker for many bodies or many
parameters) and for the contact. The slider drags; the box reads exactly what is typed, `1e-7` included, or refuses it
with a notice at the top of the panel.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import viser

from viewer.messages import Messages
from viewer.panel import Typing
from viewer.params import Controls, Param, TypedValueError, format_value, read_typed

EXPANDED_BODIES = 4  # up to this many bodies: one open folder each
FOLDED_BODIES = 12  # up to this many: one closed folder each; beyond: a body picker
# Also a body picker beyond this many body parameters in all (break-3d's four balls have 44): each
# is a box and a slider the browser builds anew at every scene pick, half a second of the first
# frame for break-3d's 54 parameters under software rendering and load.
PICKED_PARAMS = 24


class ParamControls:
    """The parameters' controls and values of the scene shown; `changed` is called when the user
    has set a value."""

    def __init__(self, gui: viser.GuiApi, parent: Any, lock: threading.RLock, typing: Typing,
                 messages: Messages, changed: Callable[[], None]) -> None:
        self._gui = gui
        self._parent = parent
        self._lock = lock
        self._typing = typing
        self._messages = messages
        self._changed = changed
        self.controls: Controls | None = None
        self.values: dict[str, float] = {}  # every parameter's value (display units)
        self.sliders: dict[str, Any] = {}  # ident -> slider
        self.boxes: dict[str, Any] = {}  # ident -> text box
        self._folder: Any = None
        self._body_picker: Any = None
        self._body_folder: Any = None

    def _clear(self) -> None:
        if self._folder is not None:
            self._folder.remove()
        self.sliders, self.boxes, self._body_picker = {}, {}, None

    def rebuild(self, controls: Controls, values: dict[str, float] | None = None) -> None:
        """The folder's controls for `controls`, at `values` (their defaults if None)."""
        gui = self._gui
        self.controls = controls
        self.values = dict(values or controls.defaults())
        self._clear()
        groups = controls.groups()
        bodies = [g for g in groups if g != "contact"]
        with self._parent:
            self._folder = gui.add_folder(None)
            with self._folder:
                body_params = sum(p.group != "contact" for p in controls.params)
                if len(bodies) > FOLDED_BODIES or (len(bodies) > 1 and body_params > PICKED_PARAMS):
                    self._body_picker = gui.add_dropdown(f"body (of {len(bodies)})", bodies, initial_value=bodies[0])
                    self._body_picker.on_update(self._on_body_picked)
                    self._body_folder = gui.add_folder(bodies[0])
                    self._fill_group(bodies[0], self._body_folder)
                else:
                    for group in bodies:
                        folder = gui.add_folder(group, expand_by_default=len(bodies) <= EXPANDED_BODIES)
                        self._fill_group(group, folder)
                if "contact" in groups:
                    self._fill_group("contact", gui.add_folder("contact"))

    def show_note(self, text: str) -> None:
        """No parameters (a run replayed from frames): the folder shows `text` instead."""
        self.controls = None
        self.values = {}
        self._clear()
        with self._parent:
            self._folder = self._gui.add_folder(None)
            with self._folder:
                self._gui.add_markdown(text)

    def _fill_group(self, group: str, folder: Any) -> None:
        assert self.controls is not None
        with folder:
            for p in self.controls.params:
                if p.group == group:
                    self._param_widgets(p)

    def _param_widgets(self, p: Param) -> None:
        gui = self._gui
        value = self.values.get(p.ident, p.value)
        hint = p.hint or f"{p.key} in {p.unit or 'units of 1'}"
        if p.unused:
            # Disabled, saying why: moving it would change nothing (issue 12, item 5).
            box = gui.add_text(f"{p.title} (not used)", format_value(value), hint=p.unused, disabled=True)
            slider = gui.add_slider("", min=p.lo, max=p.hi, step=p.step,
                                    initial_value=float(min(max(value, p.lo), p.hi)), hint=p.unused, disabled=True)
            gui.add_markdown(f"<small>{p.unused}.</small>")
        else:
            box = gui.add_text(p.title, format_value(value), hint=hint + " (type any number, e.g. 1e-7)")
            slider = gui.add_slider("", min=p.lo, max=p.hi, step=p.step,
                                    initial_value=float(min(max(value, p.lo), p.hi)), hint=hint)
        box.on_update(lambda e, ident=p.ident: self._on_box(e, ident))
        slider.on_update(lambda e, ident=p.ident: self._on_slider(e, ident))
        self.boxes[p.ident] = box
        self.sliders[p.ident] = slider

    def _on_body_picked(self, event: viser.GuiEvent) -> None:
        if event.client is None or self._body_picker is None:
            return
        with self._lock:
            name = self._body_picker.value
            for ident in [i for i in self.sliders if i.startswith("body.")]:
                self.sliders.pop(ident)
                self.boxes.pop(ident)
            self._body_folder.remove()
            with self._folder:
                self._body_folder = self._gui.add_folder(name, order=self._body_picker.order + 0.5)
            self._fill_group(name, self._body_folder)

    # Server-side assignments arrive with client None: ignored.

    def _on_slider(self, event: viser.GuiEvent, ident: str) -> None:
        if event.client is None:
            return
        with self._lock:
            handle = self.sliders.get(ident)
            if handle is None:
                return
            value = float(handle.value)
            self.values[ident] = value
            self.boxes[ident].value = format_value(value)
        self._messages.clear_notice()
        self._changed()

    def _on_box(self, event: viser.GuiEvent, ident: str) -> None:
        if event.client is None:
            return
        self._typing.after(ident, lambda: self.apply_typed(ident, self.boxes[ident].value))

    def apply_typed(self, ident: str, text: str) -> bool:
        """Use a typed parameter value if it reads exactly and the scene can take it; otherwise
        say why at the top and change nothing. A valid value beyond the slider widens it."""
        with self._lock:
            controls = self.controls
            param = controls.by_ident().get(ident) if controls is not None else None
            if param is None or ident not in self.boxes:
                return False
            if text.strip() == format_value(self.values.get(ident, param.value)):
                return False
            try:
                x = read_typed(text, param.title)
            except TypedValueError as exc:
                self._messages.show_notice(str(exc), error=True)
                return False
            problem = param.problem(x)
            if problem:
                self._messages.show_notice(f"{param.title} = '{text.strip()}': {problem}; not applied", error=True)
                return False
            wider = param.widened(x)
            slider = self.sliders[ident]
            if wider is not param:
                controls.replace_param(wider)
                slider.min, slider.max, slider.step = wider.lo, wider.hi, wider.step
            slider.value = x
            self.values[ident] = x
        self._messages.clear_notice()
        self._changed()
        return True
