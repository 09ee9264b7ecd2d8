"""Playback of the run a tab shows: its time `t`, the Timeline folder (play, frame and contact
steps, the typed time, the time and contact sliders, speed, loop, slow motion), seeking, and the
player thread that advances the time while playing. Each frame draws the bodies, moves the
sliders, and (every CURSOR_PERIOD s) the plots' cursor and the values table.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable

import viser

from viewer.guard import FAILURES
from viewer.messages import Messages, one_line
from viewer.panel import SPEEDS, Panel, Typing
from viewer.params import TypedValueError, read_typed
from viewer.scene3d import SceneDrawer
from viewer.state import ViewRun
from viewer.table import values_markdown

FPS = 30.0
CURSOR_PERIOD = 0.25  # s between plot-cursor and values-table updates while playing
SLOW_MOTION = 0.1  # playback rate inside contacts, relative to the chosen speed
PLAYBACK_SECONDS = 5.0  # 'auto' speed plays a run in about this long


def first_contact_time(view: ViewRun) -> float:
    """Where a new scene starts: just before its first contact, where something happens."""
    if not view.contact_windows:
        return view.t0
    start = view.contact_windows[0][0]
    return view.t0 + max(0.0, start - view.t0 - 0.02 * view.duration)


def slider_step(duration: float) -> float:
    step = duration / 2000
    if not step > 0:
        return 1e-6
    exp = math.floor(math.log10(step))
    return 10.0**exp


class Player:
    """The time shown and its controls; `lock` serialises drawing with the rest of the tab."""

    def __init__(self, client: viser.ClientHandle, panel: Panel, drawer: SceneDrawer, lock: threading.RLock,
                 closed: threading.Event, typing: Typing, messages: Messages,
                 failed: Callable[[str], None]) -> None:
        self._client = client
        self._panel = panel
        self._drawer = drawer
        self._lock = lock
        self._closed = closed
        self._typing = typing
        self._messages = messages
        self._failed = failed  # shows a playback error in the status
        self.view: ViewRun | None = None
        self.values_hooks: list[Callable[[ViewRun, float], None]] = []  # also shown with the values
        self.t = 0.0
        self.playing = False
        self.fps = FPS  # frames a second the player sends while playing
        self.frame_times: deque[float] = deque(maxlen=600)  # when each played frame was sent
        self.frame_costs: deque[float] = deque(maxlen=600)  # s of server work per played frame
        self._sent_times: deque[float] = deque(maxlen=60)
        self._cursor_time = 0.0
        self._redraw_pending = threading.Event()
        self.thread = threading.Thread(target=self._play_loop, name=f"collide-play-{client.client_id}", daemon=True)
        panel.play_button.on_click(lambda _e: self.toggle_play())
        panel.frame_buttons.on_click(lambda e: self._on_step("frame", panel.frame_buttons.value))
        panel.step_buttons.on_click(lambda e: self._on_step("step", panel.step_buttons.value))
        panel.time_slider.on_update(self._on_time)
        panel.time_box.on_update(self._on_time_box)
        panel.contact_slider.on_update(self._on_contact_slider)

    def start(self) -> None:
        self.thread.start()

    # -- a new run ------------------------------------------------------------------------------

    def set_view(self, view: ViewRun, refit: bool) -> None:
        """Play `view` from the time shown (clamped), or from just before its first contact."""
        self.view = view
        self.t = view.clamp_time(first_contact_time(view) if refit else self.t)
        if refit:
            self.toggle_play(False)

    def set_sliders(self, view: ViewRun) -> None:
        """The time slider over the run, the contact slider over its first contact."""
        slider = self._panel.time_slider
        step = slider_step(view.duration * 1e3)
        slider.max = max(math.ceil(view.t1 * 1e3 / step) * step, step)
        slider.min = view.t0 * 1e3
        slider.step = step
        slider.precision = max(0, -math.floor(math.log10(step)))
        contact = self._panel.contact_slider
        if not view.contact_windows:
            contact.visible = False
            return
        a, b = view.contact_windows[0]
        span = max(b - a, 1e-12) * 1e3
        step = slider_step(span * 2)  # about 4000 positions over the contact
        contact.visible = True
        contact.min = math.floor(a * 1e3 / step) * step
        contact.max = math.ceil(b * 1e3 / step) * step
        contact.step = step
        contact.precision = max(0, -math.floor(math.log10(step)))
        unit_label = "in contact (ms)"
        if contact.label != unit_label:
            contact.label = unit_label

    # -- actions ----------------------------------------------------------------------------------

    def toggle_play(self, playing: bool | None = None) -> None:
        with self._lock:
            want = (not self.playing) if playing is None else playing
            if want == self.playing and playing is not None:
                return
            self.playing = want
            if self.playing and self.view is not None and self.t >= self.view.t1:
                self.t = self.view.t0
            button = self._panel.play_button
            button.label = "Pause" if self.playing else "Play"
            button.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY
            if not self.playing:
                self.show_values()

    def seek(self, t: float, *, from_box: bool = False) -> None:
        """Show time t (clamped to the run): bodies, forces, the plots' cursor, the values."""
        with self._lock:
            if self.view is None:
                return
            self.t = self.view.clamp_time(t)
            with self._client.atomic():
                self.draw_frame(cursor=True, box=not from_box)
                self.show_values()

    def step(self, what: str, direction: int) -> None:
        """A step button: one frame ("frame") or one contact step ("step"), forward (+1) or
        back (-1)."""
        view = self.view
        if view is None:
            return
        if what == "frame":
            rate = self.speed(view)
            if self._panel.slowmo.value and view.in_contact(self.t):
                rate *= SLOW_MOTION
            self.seek(self.t + direction * rate / self.fps)
        else:
            self.seek(view.next_step(self.t, direction))

    def type_time(self, text: str) -> bool:
        """Go to a typed time (ms), or refuse it with the reason."""
        view = self.view
        if view is None or text.strip() == self.time_text():
            return False
        try:
            t_ms = read_typed(text, "time (ms)")
        except TypedValueError as exc:
            self._messages.show_notice(str(exc), error=True)
            return False
        lo, hi = view.t0 * 1e3, view.t1 * 1e3
        # The box shows times rounded to its digits: the run's ends as shown are typed back
        # within half a last digit of the exact ends, and taken as those ends.
        digits = int(self._panel.time_slider.precision)
        half = 0.5 * 10.0 ** -digits * (1 + 1e-9)  # and float round-off of the rounding
        if not lo - half <= t_ms <= hi + half:
            self._messages.show_notice(f"time (ms) = '{text.strip()}' is outside the run ({lo:.{digits}f} to "
                                       f"{hi:.{digits}f} ms); not applied", error=True)
            return False
        self._messages.clear_notice()
        self.seek(min(max(t_ms, lo), hi) / 1e3, from_box=True)
        return True

    def speed(self, view: ViewRun) -> float:
        """Simulated seconds per second of playback (outside contacts)."""
        choice = self._panel.speed.value
        if choice == "auto" or choice not in SPEEDS:  # a value no menu offers: from a forged message
            contact = sum(b - a for a, b in view.contact_windows)
            slow = (1 / SLOW_MOTION - 1) * contact if self._panel.slowmo.value else 0.0
            return max(view.duration + slow, 1e-9) / PLAYBACK_SECONDS
        return float(choice.rstrip("x"))

    # -- callbacks (viser's thread pool; server-side assignments arrive with client None) --------

    def _on_time(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        slider = self._panel.time_slider
        value = float(slider.value)
        # A browser may send back a value the player just sent: seeking to it would pull the
        # playback back.
        if any(abs(value - sent) <= 0.5 * slider.step for sent in self._sent_times):
            return
        self.seek(value / 1e3)

    def _on_time_box(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.toggle_play(False)
        self._typing.after("time", lambda: self.type_time(self._panel.time_box.value))

    def _on_contact_slider(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.seek(float(self._panel.contact_slider.value) / 1e3)

    def _on_step(self, what: str, arrow: str) -> None:
        self.toggle_play(False)
        self.step(what, 1 if arrow == "▶" else -1)

    # -- drawing ----------------------------------------------------------------------------------

    def time_text(self) -> str:
        return f"{self.t * 1e3:.{int(self._panel.time_slider.precision)}f}"

    def draw_frame(self, cursor: bool, box: bool = True) -> None:
        """The bodies at time t, the sliders and time box on it; the plots' cursor and values
        now (`cursor`) or at most every CURSOR_PERIOD s. Called under the lock."""
        view = self.view
        if view is None:
            return
        panel = self._panel
        self._drawer.show_frame(view.frame(self.t))
        shown = round(self.t * 1e3, int(panel.time_slider.precision))
        self._sent_times.append(shown)
        panel.time_slider.value = shown
        if box:
            panel.time_box.value = self.time_text()
        if view.contact_windows and panel.contact_slider.visible:
            lo, hi = panel.contact_slider.min, panel.contact_slider.max
            panel.contact_slider.value = min(max(self.t * 1e3, lo), hi)
        now = time.monotonic()
        if cursor or now - self._cursor_time > CURSOR_PERIOD:
            panel.plots.show_cursor(self.t)
            if self.playing:
                self.show_values()
            self._cursor_time = now

    def show_values(self) -> None:
        view = self.view
        if view is not None:
            self._panel.values_table.content = values_markdown(view, self.t)
            for hook in self.values_hooks:
                hook(view, self.t)

    def redraw_soon(self) -> None:
        """Redraw the frame shortly (the camera moved: the overlays follow it); the player does
        this anyway while playing."""
        if self._redraw_pending.is_set() or self.playing:
            return
        self._redraw_pending.set()

        def redraw() -> None:
            self._redraw_pending.clear()
            with self._lock:
                if self.view is None or self.playing or self._closed.is_set():
                    return
                with self._client.atomic():
                    self._drawer.show_frame(self.view.frame(self.t))

        timer = threading.Timer(0.05, redraw)
        timer.daemon = True
        timer.start()

    # -- the player thread ------------------------------------------------------------------------

    def _play_loop(self) -> None:
        period = 1.0 / self.fps
        last = time.perf_counter()
        deadline = last + period
        # Frames on a fixed schedule: the wait shrinks by the time the last frame took, and a
        # frame that took longer than its period is made up by the next ones (up to a quarter
        # of a second behind; beyond that the schedule starts afresh).
        while not self._closed.wait(max(0.0, deadline - time.perf_counter())):
            now = time.perf_counter()
            period = 1.0 / self.fps
            deadline = deadline + period if now - deadline < 0.25 else now + period
            elapsed, last = now - last, now
            if not self.playing:
                continue
            try:
                self._advance(now, elapsed)
            except Exception as exc:  # noqa: BLE001 - a closed tab must not kill the thread noisily
                if self._closed.is_set():
                    return
                FAILURES.report(exc, "a tab's playback")
                self._failed(f"playback: {one_line(exc)}")
                self.toggle_play(False)

    def _advance(self, now: float, elapsed: float) -> None:
        """One played frame, `elapsed` s of wall time after the last."""
        with self._lock:
            view = self.view
            if view is None or not self.playing:
                return
            rate = self.speed(view)
            if self._panel.slowmo.value and view.in_contact(self.t):
                rate *= SLOW_MOTION
            t = self.t + min(elapsed, 0.25) * rate
            if t > view.t1:
                if self._panel.loop.value:
                    t = view.t0
                else:
                    t = view.t1
                    self.toggle_play(False)
            self.t = t
            with self._client.atomic():
                self.draw_frame(cursor=False)
            done = time.perf_counter()
            self.frame_times.append(done)
            self.frame_costs.append(done - now)

    def join(self, timeout: float) -> None:
        self.playing = False
        self.thread.join(timeout=timeout)

