"""Inside the pile (issue 54, item 5): the panel's "Inside the pile" folder (a clip plane, the
picked sphere's values and contacts) and the Histograms tab, for one tab.

A click on the 3D view arrives as a ray (viser's scene `on_click`); the sphere it hits first,
among those shown, is picked (`viewer.picking`): it turns magenta, its neighbours in contact
orange and the rest grey (`viewer.clip.BodyLook`, which the drawing applies each frame). The
picked sphere's values and the histograms follow the time shown, at most every UPDATE_PERIOD s
while playing (the last frame is always shown).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import viser

from viewer.clip import AXES, KEEP
from viewer.histograms import Histograms, frame_histograms
from viewer.picking import frame_report, pick_sphere, report_markdown, sphere_report
from viewer.scene3d import SceneDrawer
from viewer.state import Frame, ViewRun

UPDATE_PERIOD = 0.3  # s between updates of the values and histograms while the frames change
HINT = "*Click a sphere in the 3D view to read its values and contacts.*"


class Inspector:
    """The clip plane, the picked sphere and the histograms of one tab."""

    def __init__(self, client: viser.ClientHandle, plot_panel: Any, drawer: SceneDrawer,
                 lock: threading.RLock) -> None:
        self._client = client
        self._drawer = drawer
        self._lock = lock
        self.look = drawer.look
        self.look.listener = self._frame_shown
        self._view: ViewRun | None = None
        self._last = 0.0
        self._pending = False
        self._latest: Frame | None = None
        gui = client.gui
        with gui.add_folder("Inside the pile", order=2.5):
            self._controls(gui)
        self.histograms = Histograms(gui, plot_panel.add_tab("Histograms", viser.Icon.CHART_BAR))
        client.scene.on_click()(self._on_click)

    def _controls(self, gui: viser.GuiApi) -> None:
        self.clip_on = gui.add_checkbox("clip plane", initial_value=False,
                                        hint="hide the spheres on one side of a plane (by their centres)")
        self.clip_axis = gui.add_dropdown("plane across", list(AXES), initial_value="x")
        self.clip_keep = gui.add_dropdown("keep", list(KEEP), initial_value="below",
                                          hint="the side of the plane whose spheres stay shown")
        self.clip_offset = gui.add_slider("plane at (mm)", min=0.0, max=1.0, step=0.1, initial_value=0.5)
        self.clear_button = gui.add_button("Clear the pick", icon=viser.Icon.X, visible=False)
        self.picked = gui.add_markdown(HINT)
        for handle in (self.clip_on, self.clip_axis, self.clip_keep, self.clip_offset):
            handle.on_update(self._on_clip)
        self.clear_button.on_click(lambda _e: self.pick(None))

    # -- callbacks (viser's thread pool) ----------------------------------------------------------

    def _on_clip(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        with self._lock:
            axis = AXES.index(self.clip_axis.value) if self.clip_axis.value in AXES else 0
            if axis != self.look.clip.axis:
                self.look.clip.axis = axis
                self._fit_slider(self._drawer.view, centre=True)
            clip = self.look.clip
            clip.on = bool(self.clip_on.value)
            clip.keep = self.clip_keep.value if self.clip_keep.value in KEEP else "below"
            clip.offset = float(self.clip_offset.value) * 1e-3
            self._redraw()

    def _on_click(self, event: Any) -> None:
        """A click in the 3D view: pick the sphere under it (a click beside every sphere changes
        nothing)."""
        with self._lock:
            view, frame = self._drawer.view, self._drawer.frame
            if view is None or frame is None:
                return
            k = pick_sphere(event.ray_origin, event.ray_direction, frame.positions, view.radius,
                            self.look.hidden(frame.positions))
        if k is not None:
            self.pick(k)

    # -- actions (tests call them too) ------------------------------------------------------------

    def pick(self, k: int | None) -> None:
        """Pick body k (None: nobody): highlight it and its neighbours, show its values."""
        with self._lock:
            self.look.picked = k
            self.clear_button.visible = k is not None
            self._redraw()

    def set_clip(self, on: bool, axis: str = "x", offset_mm: float | None = None, keep: str = "below") -> None:
        """The clip plane as the panel sets it (offset None: the middle of the run's extent)."""
        with self._lock:
            self.look.clip.axis = AXES.index(axis)
            self._fit_slider(self._drawer.view, centre=offset_mm is None)
            if offset_mm is not None:
                self.clip_offset.value = offset_mm
            self.clip_axis.value, self.clip_keep.value, self.clip_on.value = axis, keep, on
            clip = self.look.clip
            clip.on, clip.keep, clip.offset = on, keep, float(self.clip_offset.value) * 1e-3
            self._redraw()

    # -- drawing ----------------------------------------------------------------------------------

    def _redraw(self) -> None:
        """Draw the frame shown again with the clip and pick as they are now, and update the
        values and histograms at once. Called under the lock."""
        frame = self._drawer.frame
        if frame is None:
            return
        self._last = 0.0
        with self._client.atomic():
            self._drawer.show_frame(frame)

    def _fit_slider(self, view: ViewRun | None, centre: bool) -> None:
        """The plane's slider over the run's extent along the plane's axis (mm)."""
        if view is None:
            return
        lo, hi = view.bounds()
        a, b = float(lo[self.look.clip.axis]) * 1e3, float(hi[self.look.clip.axis]) * 1e3
        step = 10.0 ** math.floor(math.log10(max(b - a, 1e-9) / 200))
        slider = self.clip_offset
        slider.min, slider.max, slider.step = math.floor(a / step) * step, math.ceil(b / step) * step, step
        if centre or not slider.min <= slider.value <= slider.max:
            slider.value = round(0.5 * (a + b) / step) * step
        self.look.clip.offset = float(slider.value) * 1e-3

    def _frame_shown(self, frame: Frame) -> None:
        """Every frame drawn (under the lock): the values and histograms now, or shortly."""
        self._latest = frame
        now = time.monotonic()
        if now - self._last >= UPDATE_PERIOD:
            self._update(frame)
        elif not self._pending:
            self._pending = True
            timer = threading.Timer(UPDATE_PERIOD - (now - self._last), self._late)
            timer.daemon = True
            timer.start()

    def _late(self) -> None:
        with self._lock:
            self._pending = False
            if self._latest is None:
                return
            with self._client.atomic():
                self._update(self._latest)

    def _update(self, frame: Frame) -> None:
        self._last = time.monotonic()
        view = self._drawer.view
        if view is None:
            return
        if view is not self._view:
            self._new_view(view)
        hidden = self.look.hidden(frame.positions)
        shown = int((~hidden).sum())
        note = f"at {frame.t * 1e3:.4g} ms: {shown} of {view.n_bodies} spheres" + (
            " (the clip plane hides the rest)" if shown < view.n_bodies else "")
        self.histograms.show(frame_histograms(frame, hidden), note)
        k = self.look.picked
        if k is None:
            self.picked.content = HINT
            return
        # A run given as frames has no engine records behind it: the frame's own values.
        report = sphere_report(view, frame.t, k) if isinstance(view, ViewRun) else frame_report(view, frame, k)
        self.picked.content = report_markdown(report)

    def _new_view(self, view: ViewRun) -> None:
        """A new run: the pick kept if it names a body of it, the plane's slider over it."""
        same = self._view is not None and self._view.n_bodies == view.n_bodies
        self._view = view
        if not same and self.look.picked is not None:
            self.look.picked = None
            self.clear_button.visible = False
        self._fit_slider(view, centre=not same)
