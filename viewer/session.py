"""One browser tab: its controls, its 3D scene, its plots, its simulation worker and player.

Every tab gets a `Session` of its own (client-scoped GUI and scene), so tabs do not fight over
the timeline or the parameters, and a tab that closes takes only its own threads with it.
Threads: viser runs GUI callbacks on its pool; the `LatestWorker` re-simulates; the player
advances the timeline; typed values apply after a short pause in typing. `self._lock`
serialises everything that draws.

Every parameter has a slider (drag) and a text box (type): the box reads exactly what is typed,
`1e-7` included, or refuses it with a message at the top of the panel; the slider's own number
box, which drops an "e" (1e-7 became -17), is hidden.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import viser
from viser import _messages

from collide import dem as cdem
from collide.model import compile_scenes
from collide.recording import RecordingError
from collide.run import SceneRun, auto_dt, run_scene
from collide.scene import INTEGRATORS, Scene, SceneError, load_scene
from collide.stepper import RunError
from viewer import ensemble as ens
from viewer import files
from viewer.background import BackgroundRunner, RunStopped
from viewer.exports import png_bytes, run_csv
from viewer.frames import FramesRun
from viewer.geometry import fit_camera
from viewer.guard import FAILURES
from viewer.params import (
    AUTO,
    Controls,
    Param,
    Settings,
    TypedValueError,
    add_ball,
    build_scene,
    check_settings,
    dt_choice,
    for_viewing,
    format_value,
    parse_dt_choice,
    read_typed,
    remove_ball,
    scene_controls,
    values_of,
)
from viewer.plots import Plots
from viewer.reading import read_untrusted
from viewer.scene3d import COLOUR_MODES, SceneDrawer
from viewer.state import ViewRun
from viewer.table import values_markdown
from viewer.uploads import UploadSink
from viewer.worker import LatestWorker

if TYPE_CHECKING:
    from viewer.app import ViewerApp

FPS = 30.0
CURSOR_PERIOD = 0.25  # s between plot-cursor and values-table updates while playing
# s: when a full run takes longer, a coarse preview is drawn first; the run's share of a 100 ms
# answer (preparing and drawing a run take 10-40 ms more)
PREVIEW_BUDGET = 0.05
PREVIEW_TOL = 1e-3  # the preview's accuracy (auto dt)
# A run expected to take longer than this (its last run did), or of more bodies than MANY_BODIES,
# goes to a child process with a progress line and a Stop button (viewer.background), and starts
# once the slider rests: a drag does not start a minute-long run for every value it passes.
LONG_RUN_S = 1.0
MANY_BODIES = 200
STAGES = {"seed": 1, "verlet": 1, "yoshida4": 3, "kahan6": 9, "dem": 1}  # force evaluations per step
DEM_PREVIEW_STEPS = 8  # a DEM preview's steps per contact time (a full run takes at least 50)
DEM_PREVIEW_MARGIN = 0.7  # of the DEM step's stability limit, at most
SLOW_MOTION = 0.1  # playback rate inside contacts, relative to the chosen speed
PLAYBACK_SECONDS = 5.0  # 'auto' speed plays a run in about this long
SPEEDS = ["auto", "0.001x", "0.003x", "0.01x", "0.03x", "0.1x", "0.3x", "1x"]
TYPING_SETTLE = 0.5  # s without a keystroke before a typed value is read
# s after an upload's outcome when viser's own "uploaded successfully" is removed again: a
# loaded browser may show it seconds late.
UPLOAD_TOAST_REMOVALS = (0.4, 1.5, 4.0, 10.0)
EXPANDED_BODIES = 4  # up to this many bodies: one open folder each
FOLDED_BODIES = 12  # up to this many: one closed folder each; beyond: a body picker
# viser's slider carries a number box that drops an "e" as it is typed (issue 12, item 2): hide
# it; the text box above each slider reads typed values exactly.
STYLE = ("<style>.mantine-Slider-root + .mantine-NumberInput-root{display:none !important}"
         ".collide-notice{font-size:0.9em}</style>")
RED = "#c5221f"


@dataclass
class Request:
    """Parameters to simulate: control values (display units) and run settings."""

    controls: Controls
    values: dict[str, float]
    settings: Settings
    refit: bool = False
    stamp: float = 0.0


class Preview(NamedTuple):
    """A cheaper run drawn while the user drags: integrator, step (AUTO or seconds), tolerance."""

    integrator: str
    dt: float | str
    tol: float


def preview_settings(scene: Scene) -> Preview | None:
    """A cheaper run for a first, coarse answer while the user drags, or None when none costs
    less than half the scene's own run (force evaluations per contact: stages / dt). A preview
    that costs more than the real run (issue 12, item 3) is never used."""
    if scene.integrator == "dem":
        return _dem_preview(scene)

    def cost(integrator: str, tol: float) -> float:
        if scene.dt != AUTO and integrator == scene.integrator and tol == scene.tol:
            return STAGES[integrator] / float(scene.dt)
        dt, _ = auto_dt([scene], integrator, np.array([tol]))
        return STAGES[integrator] / float(dt[0])

    try:
        full = cost(scene.integrator, scene.tol)
        candidates = [("verlet", max(PREVIEW_TOL, scene.tol)), (scene.integrator, max(PREVIEW_TOL, scene.tol))]
        best = min(candidates, key=lambda c: cost(*c))
        return Preview(best[0], AUTO, best[1]) if cost(*best) < 0.5 * full else None
    except (RunError, SceneError, ValueError, ZeroDivisionError):
        return None


def _dem_preview(scene: Scene) -> Preview | None:
    """DEM_PREVIEW_STEPS steps per contact time, where the scene's own run takes at least 50
    (the kernel's floor): the DEM step's error is first order, so the preview's outcome is off
    by some per cent. The step keeps a margin to the kernel's stability limit, or no preview."""
    if scene.dt != AUTO:
        return None
    try:
        model, state = compile_scenes([scene])
        t_c = float(cdem.contact_time(model, state)[0][0])
        full = float(cdem.auto_dt(model, state, np.array([scene.tol]))[0])
        for steps in (DEM_PREVIEW_STEPS, 2 * DEM_PREVIEW_STEPS):
            dt = t_c / steps
            if dt < 2 * full:
                return None
            try:
                cdem.check_dem(model, state, np.array([dt / DEM_PREVIEW_MARGIN]), 2**62, np.array([np.inf]))
            except RunError:
                continue
            return Preview("dem", float(dt), scene.tol)
    except (RunError, SceneError, ValueError, ZeroDivisionError):
        return None
    return None


class Session:
    """The viewer for one client."""

    def __init__(self, app: ViewerApp, client: viser.ClientHandle) -> None:
        self.app = app
        self.client = client
        self._lock = threading.RLock()
        self._closed = threading.Event()
        self.view: ViewRun | None = None
        self.controls: Controls | None = None
        self.values: dict[str, float] = {}  # every parameter's value (display units)
        self.t = 0.0
        self.playing = False
        self.error: str | None = None
        self.notes: list[str] = []
        self.runs_drawn = 0
        self.last_latency: float | None = None
        self.downloads: list[tuple[str, int]] = []  # (file name, bytes) sent to the browser
        self._full_cost: float | None = app.initial_cost
        self._param_handles: dict[str, Any] = {}  # ident -> slider
        self._param_boxes: dict[str, Any] = {}  # ident -> text box
        self._param_folder: Any = None
        self._body_picker: Any = None
        self._typing: dict[str, threading.Timer] = {}
        self._camera_ready = threading.Event()
        self._redraw_pending = threading.Event()
        self._cursor_time = 0.0
        self._ensemble_paths: list[np.ndarray] | None = None
        self._plot_window = "whole run"
        self._auto_fit: tuple[float, np.ndarray, float, float] | None = None
        self._fit_target = "whole run"
        self._sent_times: deque[float] = deque(maxlen=60)
        self.timings: deque[dict[str, float]] = deque(maxlen=200)  # per drawn run, for benchmarks
        self.frame_times: deque[float] = deque(maxlen=600)  # when each played frame was sent
        self.frame_costs: deque[float] = deque(maxlen=600)  # s of server work per played frame
        client.camera.on_update(self._on_camera)
        if _camera_known(client):
            # viser reports a tab once its first camera message has arrived: the first fit
            # need not wait for another (a set-up thread would wait 5 s for a quiet tab).
            self._camera_ready.set()
        self.drawer = SceneDrawer(client.scene)
        self._build_gui()
        self.uploads = UploadSink(client, self.upload._impl.uuid, app.recordings_dir, app.max_upload_bytes,
                                  self._upload_started, self._upload_done) if hasattr(client, "_websock_connection") \
            else None
        self._upload_ids: dict[str, str] = {}
        self.worker: LatestWorker[Request] = LatestWorker(self._job, on_error=self._job_failed,
                                                          name=f"collide-sim-{client.client_id}")
        self.fps = FPS  # frames a second the player sends while playing
        self.runner = BackgroundRunner()  # long runs (many bodies) in a child process
        self._stop_run = threading.Event()
        self._player = threading.Thread(target=self._play_loop, name=f"collide-play-{client.client_id}",
                                        daemon=True)
        self._player.start()

    # ==========================================================================================
    # GUI

    def _build_gui(self) -> None:
        gui = self.client.gui
        app = self.app
        gui.main_panel.dock_right()
        gui.main_panel.set_width(340)
        gui.add_html(STYLE, order=-1)
        self.status = gui.add_markdown("Loading...", order=0)
        self.progress = gui.add_markdown("", order=0.3)
        self.stop_button = gui.add_button("Stop this run", icon=viser.Icon.PLAYER_STOP, order=0.4, visible=False,
                                          hint="stop the run going in the background; the last run stays shown")
        self.notice = gui.add_markdown("", order=0.5)
        with gui.add_folder("Timeline", order=1):
            self.play_button = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
            self.frame_buttons = gui.add_button_group("frame", ["◀", "▶"],
                                                      hint="back or forward one frame of playback at the chosen speed")
            self.step_buttons = gui.add_button_group("contact step", ["◀", "▶"],
                                                     hint="back or forward one step of the integrator inside a "
                                                          "contact (outside one: to the next contact)")
            self.time_box = gui.add_text("time (ms)", "0", hint="type a time in ms (read exactly, e.g. 12.5 or 1e1)")
            self.time_slider = gui.add_slider("", min=0.0, max=1.0, step=0.001, initial_value=0.0)
            self.contact_slider = gui.add_slider("in contact (ms)", min=0.0, max=1.0, step=0.001, initial_value=0.0,
                                                 hint="the first contact, stretched over the whole slider")
            self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="auto",
                                          hint="simulated seconds per second; auto plays the run in ~5 s")
            self.loop = gui.add_checkbox("loop", initial_value=True)
            self.slowmo = gui.add_checkbox("slow motion in contact", initial_value=True,
                                           hint="play contacts 10x slower so the compression can be seen")
        with gui.add_folder("Show", order=2):
            opts = self.drawer.options
            self.show_forces = gui.add_checkbox("contact forces", initial_value=opts.forces)
            self.show_velocity = gui.add_checkbox("velocity vectors", initial_value=opts.velocity)
            self.show_momentum = gui.add_checkbox("momentum vectors", initial_value=opts.momentum)
            self.show_com = gui.add_checkbox("centre of mass", initial_value=opts.com)
            self.show_trails = gui.add_checkbox("paths", initial_value=opts.trails)
            self.colour_by = gui.add_dropdown("colour by", list(COLOUR_MODES), initial_value=opts.colour_by)
            self.show_chains = gui.add_checkbox("force chains", initial_value=opts.chains, visible=False,
                                                hint="normal forces as links between centres (many bodies)")
            self.show_shadows = gui.add_checkbox("shadows", initial_value=opts.shadows, visible=False,
                                                 hint="each sphere's shadow on the floor")
            self.legend = gui.add_markdown("")
            self.colour_legend = gui.add_html("")
        with gui.add_folder("Scene", order=3):
            self.picker = gui.add_dropdown("scene", [c.label for c in app.scene_choices],
                                           initial_value=app.scene_choices[0].label)
            self.balls = gui.add_button_group("balls", ["fewer balls", "more balls"], visible=False,
                                              hint="take away the last ball, or add one like it (2D scenes)")
            self.integrator = gui.add_dropdown("integrator", list(INTEGRATORS), initial_value="verlet")
            self.dt = gui.add_dropdown("dt", [AUTO], initial_value=AUTO)
            self.tol = gui.add_dropdown("tol (auto dt)", ["1e-06"], initial_value="1e-06")
            self.reset_button = gui.add_button("Reset parameters", icon=viser.Icon.REFRESH)
            self.fit_buttons = gui.add_button_group("fit view", ["whole run", "contact"],
                                                    hint="point the camera at the whole run or at the contact")
        self._param_parent = gui.add_folder("Parameters", order=4)
        with gui.add_folder("Files and export", order=5, expand_by_default=True):
            self.recording = gui.add_dropdown("open .rrd", self._recording_options(), initial_value="(choose)")
            self.refresh_button = gui.add_button("Refresh list", icon=viser.Icon.REFRESH)
            self.upload = gui.add_upload_button("Upload .rrd", icon=viser.Icon.UPLOAD, mime_type=".rrd",
                                                hint=f"at most {app.max_upload_bytes // 2**20} MB")
            self.save_button = gui.add_button("Save this run (.rrd)", icon=viser.Icon.DEVICE_FLOPPY)
            self.export_buttons = gui.add_button_group(
                "download", ["CSV", "PNG"],
                hint="CSV: the run in the columns of `collide run --csv`; PNG: the 3D view as it is now")
            self.file_message = gui.add_markdown("")
        with gui.add_folder("Ensemble", order=6, expand_by_default=False):
            self.ens_on = gui.add_checkbox("show ensemble", initial_value=False,
                                           hint="run a small batch around the current parameters (run_scenes)")
            self.ens_kind = gui.add_dropdown("vary", list(ens.KINDS), initial_value="k")
            kind = ens.KINDS["k"]
            self.ens_spread = gui.add_slider("spread (+-, %)", min=kind.lo, max=kind.hi, step=kind.step,
                                             initial_value=kind.default)
            self.ens_members = gui.add_slider("members", min=3, max=15, step=1, initial_value=7)
            self.ens_message = gui.add_markdown("")
        self.plot_panel = gui.add_panel()
        plots_tab = self.plot_panel.add_tab("Plots", viser.Icon.CHART_LINE)
        with plots_tab:
            self.window_buttons = gui.add_button_group("time axis", ["whole run", "contact"], order=-1,
                                                       hint="plot the whole run or zoom on the first contact")
        with self.plot_panel.add_tab("Values", viser.Icon.TABLE):
            self.values_table = gui.add_markdown("")
        self.plots = Plots(gui, plots_tab)
        # Below the controls, in one column on the right: the 3D view keeps the rest of the width.
        self.plot_panel.dock_below(gui.main_panel)

        self.play_button.on_click(lambda _e: self.toggle_play())
        self.stop_button.on_click(lambda _e: self.stop_run())
        self.frame_buttons.on_click(lambda e: self._on_step("frame", self.frame_buttons.value))
        self.step_buttons.on_click(lambda e: self._on_step("step", self.step_buttons.value))
        self.time_slider.on_update(self._on_time)
        self.time_box.on_update(self._on_time_box)
        self.contact_slider.on_update(self._on_contact_slider)
        for handle in (self.show_forces, self.show_velocity, self.show_momentum, self.show_com, self.show_trails,
                       self.colour_by, self.show_chains, self.show_shadows):
            handle.on_update(self._on_show)
        self.picker.on_update(self._on_pick)
        self.balls.on_click(lambda e: self._on_balls(e))
        for handle in (self.integrator, self.dt, self.tol):
            handle.on_update(self._on_settings)
        self.reset_button.on_click(lambda _e: self._reset_params())
        self.fit_buttons.on_click(lambda _e: self.fit_camera(self.fit_buttons.value))
        self.window_buttons.on_click(lambda _e: self.set_plot_window(self.window_buttons.value))
        self.recording.on_update(self._on_recording)
        self.refresh_button.on_click(lambda _e: self.refresh_recordings())
        self.upload.on_upload(self._on_upload)
        self.save_button.on_click(lambda _e: self.save_run())
        self.export_buttons.on_click(lambda e: self._on_export(e))
        for handle in (self.ens_on, self.ens_spread, self.ens_members):
            handle.on_update(self._on_ensemble)
        self.ens_kind.on_update(self._on_ensemble_kind)

    def _recording_options(self) -> list[str]:
        return ["(choose)"] + files.list_recordings(self.app.recordings_dir)

    def refresh_recordings(self, select: str | None = None) -> None:
        options = self._recording_options()
        if select is not None and select not in options:
            options.append(select)
        self.recording.options = options
        self.recording.value = select if select is not None else "(choose)"

    def _rebuild_params(self, controls: Controls, values: dict[str, float] | None = None) -> None:
        """A text box and a slider for every parameter the scene uses, grouped per body (open
        folders for a few bodies, closed ones for more, a body picker for many) and for the
        contact."""
        gui = self.client.gui
        self.controls = controls
        self.values = dict(values or controls.defaults())
        if self._param_folder is not None:
            self._param_folder.remove()
        self._param_handles, self._param_boxes, self._body_picker = {}, {}, None
        bodies = [g for g in controls.groups() if g != "contact"]
        with self._param_parent:
            self._param_folder = gui.add_folder(None)
            with self._param_folder:
                if len(bodies) > FOLDED_BODIES:
                    self._body_picker = gui.add_dropdown(f"body (of {len(bodies)})", bodies, initial_value=bodies[0])
                    self._body_picker.on_update(self._on_body_picked)
                    self._body_folder = gui.add_folder(bodies[0])
                    self._fill_group(bodies[0], self._body_folder)
                else:
                    for group in bodies:
                        folder = gui.add_folder(group, expand_by_default=len(bodies) <= EXPANDED_BODIES)
                        self._fill_group(group, folder)
                if "contact" in controls.groups():
                    self._fill_group("contact", gui.add_folder("contact"))
        s = controls.settings
        self.integrator.value = s.integrator
        self.dt.options = controls.dt_choices
        self.dt.value = dt_choice(s.dt)
        self.tol.options = controls.tol_choices
        self.tol.value = f"{s.tol:.0e}"
        self.tol.visible = s.dt == AUTO
        self.balls.visible = controls.scene.dim == 2

    def _fill_group(self, group: str, folder: Any) -> None:
        gui = self.client.gui
        assert self.controls is not None
        with folder:
            for p in self.controls.params:
                if p.group == group:
                    self._param_widgets(gui, p)

    def _param_widgets(self, gui: viser.GuiApi, p: Param) -> None:
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
        self._param_boxes[p.ident] = box
        self._param_handles[p.ident] = slider

    def _on_body_picked(self, event: viser.GuiEvent) -> None:
        if event.client is None or self._body_picker is None:
            return
        with self._lock:
            name = self._body_picker.value
            for ident in [i for i, _ in self._param_handles.items() if i.startswith("body.")]:
                self._param_handles.pop(ident)
                self._param_boxes.pop(ident)
            self._body_folder.remove()
            with self._param_folder:
                self._body_folder = self.client.gui.add_folder(name, order=self._body_picker.order + 0.5)
            self._fill_group(name, self._body_folder)

    # ==========================================================================================
    # Callbacks (viser's thread pool). Server-side assignments arrive with client None: ignored.

    def _on_slider(self, event: viser.GuiEvent, ident: str) -> None:
        if event.client is None:
            return
        with self._lock:
            handle = self._param_handles.get(ident)
            if handle is None:
                return
            value = float(handle.value)
            self.values[ident] = value
            self._param_boxes[ident].value = format_value(value)
        self._clear_notice()
        self.request_run()

    def _on_box(self, event: viser.GuiEvent, ident: str) -> None:
        if event.client is None:
            return
        self._after_typing(ident, lambda: self.apply_typed(ident, self._param_boxes[ident].value))

    def _after_typing(self, key: str, action) -> None:
        """Run `action` once the user has stopped typing in this box for TYPING_SETTLE s."""
        timer = self._typing.pop(key, None)
        if timer is not None:
            timer.cancel()
        timer = threading.Timer(TYPING_SETTLE, action)
        timer.daemon = True
        self._typing[key] = timer
        timer.start()

    def apply_typed(self, ident: str, text: str) -> bool:
        """Use a typed parameter value if it reads exactly and the scene can take it; otherwise
        say why at the top and change nothing. A valid value beyond the slider widens it."""
        with self._lock:
            controls = self.controls
            param = controls.by_ident().get(ident) if controls is not None else None
            if param is None or ident not in self._param_boxes:
                return False
            if text.strip() == format_value(self.values.get(ident, param.value)):
                return False
            try:
                x = read_typed(text, param.title)
            except TypedValueError as exc:
                self._show_notice(str(exc), error=True)
                return False
            problem = param.problem(x)
            if problem:
                self._show_notice(f"{param.title} = '{text.strip()}': {problem}; not applied", error=True)
                return False
            wider = param.widened(x)
            slider = self._param_handles[ident]
            if wider is not param:
                controls.replace_param(wider)
                slider.min, slider.max, slider.step = wider.lo, wider.hi, wider.step
            slider.value = x
            self.values[ident] = x
        self._clear_notice()
        self.request_run()
        return True

    def _on_settings(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.tol.visible = self.dt.value == AUTO
        self.request_run()

    def _on_time(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        value = float(self.time_slider.value)
        # A browser may send back a value the player just sent: seeking to it would pull the
        # playback back.
        if any(abs(value - sent) <= 0.5 * self.time_slider.step for sent in self._sent_times):
            return
        self.seek(value / 1e3)

    def _on_time_box(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.toggle_play(False)
        self._after_typing("time", lambda: self.type_time(self.time_box.value))

    def type_time(self, text: str) -> bool:
        """Go to a typed time (ms), or refuse it with the reason."""
        view = self.view
        if view is None or text.strip() == self._time_text():
            return False
        try:
            t_ms = read_typed(text, "time (ms)")
        except TypedValueError as exc:
            self._show_notice(str(exc), error=True)
            return False
        lo, hi = view.t0 * 1e3, view.t1 * 1e3
        if not lo <= t_ms <= hi:
            self._show_notice(f"time (ms) = '{text.strip()}' is outside the run ({lo:.4g} to {hi:.4g} ms); "
                              "not applied", error=True)
            return False
        self._clear_notice()
        self.seek(t_ms / 1e3, from_box=True)
        return True

    def _on_contact_slider(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.seek(float(self.contact_slider.value) / 1e3)

    def _on_step(self, what: str, arrow: str) -> None:
        self.toggle_play(False)
        self.step(what, 1 if arrow == "▶" else -1)

    def step(self, what: str, direction: int) -> None:
        """A step button: one frame ("frame") or one contact step ("step"), forward (+1) or
        back (-1)."""
        view = self.view
        if view is None:
            return
        if what == "frame":
            rate = self._speed(view)
            if self.slowmo.value and view.in_contact(self.t):
                rate *= SLOW_MOTION
            self.seek(self.t + direction * rate / self.fps)
        else:
            self.seek(view.next_step(self.t, direction))

    def _on_show(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.set_show(forces=self.show_forces.value, velocity=self.show_velocity.value,
                      momentum=self.show_momentum.value, com=self.show_com.value, trails=self.show_trails.value,
                      colour_by=self.colour_by.value, chains=self.show_chains.value, shadows=self.show_shadows.value)

    def set_show(self, **options: Any) -> None:
        """What the 3D view shows (the Show folder): forces, velocity, momentum, com, trails,
        colour_by, chains, shadows. Keeps the folder's controls in step."""
        handles = {"forces": self.show_forces, "velocity": self.show_velocity, "momentum": self.show_momentum,
                   "com": self.show_com, "trails": self.show_trails, "colour_by": self.colour_by,
                   "chains": self.show_chains, "shadows": self.show_shadows}
        with self._lock:
            trails = "trails" in options and options["trails"] != self.drawer.options.trails
            for key, value in options.items():
                if handles[key].value != value:
                    handles[key].value = value
            with self.client.atomic():
                self.drawer.set_options(**options)
                if trails and self.view is not None:
                    self.drawer.show_run(self.view)
                    self._draw_frame(cursor=False)
                self.legend.content = self.drawer.legend()
                self.colour_legend.content = self.drawer.colour_legend()

    def _on_pick(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        choice = next((c for c in self.app.scene_choices if c.label == self.picker.value), None)
        if choice is not None:
            self.load_scene(choice.source)

    def _on_balls(self, event: viser.GuiEvent) -> None:
        self.change_balls(+1 if self.balls.value == "more balls" else -1)

    def change_balls(self, delta: int) -> None:
        """Add (delta > 0) or take away a ball, keeping every other parameter as it is."""
        with self._lock:
            controls = self.controls
            if controls is None:
                return
            values = dict(self.values)
        try:
            scene = build_scene(controls, values, self._settings())
            scene = add_ball(scene) if delta > 0 else remove_ball(scene)
        except (SceneError, ValueError) as exc:
            self._show_notice(_one_line(exc), error=True)
            return
        self._clear_notice()
        self.load_scene(scene, keep_settings=True)

    def _on_recording(self, event: viser.GuiEvent) -> None:
        if event.client is None or self.recording.value == "(choose)":
            return
        try:
            path = files.recording_path(self.app.recordings_dir, self.recording.value)
        except files.UploadError as exc:
            self._file_message(str(exc), error=True)
            return
        self.open_recording(path)

    def _on_upload(self, event: viser.GuiEvent) -> None:
        # Only reached when uploads are not streamed (no client connection to hook).
        uploaded = self.upload.value
        self.receive_upload(uploaded.name, uploaded.content)

    def _on_export(self, event: viser.GuiEvent) -> None:
        if self.export_buttons.value == "CSV":
            self.export_csv()
        else:
            self.export_png()

    def _on_ensemble(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        if not self.ens_on.value:
            with self._lock:
                self._ensemble_paths = None
                self.drawer.show_ghosts(None)
                self.ens_message.content = ""
            return
        self.request_run()

    def _on_ensemble_kind(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        kind = ens.KINDS[self.ens_kind.value]
        self.ens_spread.min, self.ens_spread.max, self.ens_spread.step = kind.lo, kind.hi, kind.step
        self.ens_spread.label = f"spread (+-, {kind.unit})"
        self.ens_spread.value = kind.default
        if self.ens_on.value:
            self.request_run()

    # ==========================================================================================
    # Actions (also called by tests and benchmarks)

    def load_scene(self, source: str | Scene, *, run: SceneRun | None = None, label: str | None = None,
                   keep_settings: bool = False) -> None:
        """Show a scene (a name or .toml path, or a Scene) with its default parameters; `run`, if
        given, is that scene's run already computed."""
        try:
            scene = source if isinstance(source, Scene) else load_scene(source)
        except SceneError as exc:
            self._show_error(str(exc))
            return
        controls = scene_controls(scene)
        with self._lock:
            self._rebuild_params(controls)
            self._ensemble_paths = None
            self.drawer.show_ghosts(None)
            if label is not None and label in self.picker.options:
                self.picker.value = label
        # What the scene's runs cost is known from its own run only (chooses previews and
        # background runs).
        self._full_cost = run.result.wall_time_s if run is not None else None
        if run is not None:
            self._show_view(ViewRun(run, origin="live run"), refit=True)
        else:
            self.request_run(refit=True)

    def open_recording(self, path: Path, name: str | None = None) -> bool:
        """Replay a recording (read in a child process: a damaged file cannot take the server
        down); a file that cannot be read leaves a message and changes nothing."""
        shown = name or path.name
        self._file_message(f"Reading {shown}...")
        try:
            run = read_untrusted(path, name=shown)
            view = ViewRun(run, origin=f"recording {shown}")
        except (RecordingError, ValueError, OSError) as exc:
            self._file_message(f"Cannot open {shown}: {_strip_name(_one_line(exc), shown)}", error=True)
            self._show_notice(f"Cannot open {shown}: {_strip_name(_one_line(exc), shown)}", error=True)
            return False
        self.show_recording(view, shown)
        return True

    def show_recording(self, view: ViewRun, name: str) -> None:
        """Show a run read from a recording, with its scene's parameters in the controls."""
        scene = view.scene
        controls = scene_controls(scene)
        with self._lock:
            self._rebuild_params(controls, values_of(scene, controls))
            self.integrator.value = view.result.integrator
            self._ensemble_paths = None
            self.drawer.show_ghosts(None)
            label = f"rec: {name}"
            if label not in self.picker.options:
                self.picker.options = list(self.picker.options) + [label]
            self.picker.value = label
        self._full_cost = view.result.wall_time_s
        self._show_view(view, refit=True)
        self.seek(view.t0)
        self._clear_notice()
        self._file_message(f"Replaying **{name}** ({scene.name}). Move a parameter to re-simulate "
                           "from its scene.")

    def show_frames(self, run: FramesRun) -> None:
        """Replay a run given as frames (many bodies; no parameters to change)."""
        gui = self.client.gui
        with self._lock:
            self.controls = None
            self.values = {}
            if self._param_folder is not None:
                self._param_folder.remove()
            self._param_handles, self._param_boxes, self._body_picker = {}, {}, None
            with self._param_parent:
                self._param_folder = gui.add_folder(None)
                with self._param_folder:
                    gui.add_markdown(f"*{run.origin}: {run.n_bodies} bodies replayed, no parameters to change*")
            label = f"frames: {run.name}"
            if label not in self.picker.options:
                self.picker.options = list(self.picker.options) + [label]
            self.picker.value = label
            self.balls.visible = False
            self._ensemble_paths = None
            self.drawer.show_ghosts(None)
        self._show_view(run, refit=True)
        self._clear_notice()

    # -- uploads ---------------------------------------------------------------------------------

    def _upload_started(self, name: str, transfer_uuid: str) -> None:
        self._upload_ids[name] = transfer_uuid
        self._file_message(f"Receiving {Path(name).name}...")

    def _upload_done(self, name: str, staged: Path | None, error: str | None) -> None:
        transfer = self._upload_ids.pop(name, None)
        if error is not None:
            message = f"Upload refused: {error}"
            self._file_message(message, error=True)
            self._show_notice(message, error=True)
            self._upload_toast(transfer, "Upload refused", error, ok=False)
            return
        assert staged is not None
        self._open_staged(name, staged, transfer)

    def receive_upload(self, name: str, content: bytes) -> bool:
        """Check, stage and open an uploaded recording given as bytes (tests; the page streams
        uploads through `UploadSink`). Keeps it in recordings/ if it reads."""
        folder = self.app.recordings_dir
        try:
            files.check_upload(name, len(content), self.app.max_upload_bytes)
            staged = files.write_staged(folder, content)
        except (files.UploadError, OSError) as exc:
            self._file_message(f"Upload refused: {_one_line(exc)}", error=True)
            self._show_notice(f"Upload refused: {_one_line(exc)}", error=True)
            return False
        return self._open_staged(name, staged, None)

    def _open_staged(self, name: str, staged: Path, transfer: str | None) -> bool:
        folder = self.app.recordings_dir
        shown = f"{files.safe_stem(name)}.rrd"
        self._file_message(f"Checking {shown}...")
        try:
            run = read_untrusted(staged, name=shown)
            view = ViewRun(run, origin=f"recording {shown}")
        except (RecordingError, ValueError, OSError) as exc:
            staged.unlink(missing_ok=True)
            reason = _strip_name(_one_line(exc), shown)
            self._file_message(f"Cannot open {shown}: {reason}", error=True)
            self._show_notice(f"Cannot open {shown}: {reason}", error=True)
            self._upload_toast(transfer, f"Cannot open {shown}", reason, ok=False)
            return False
        final = files.unique_path(folder, name)
        staged.rename(final)
        self.refresh_recordings(select=final.name)
        view.origin = f"recording {final.name}"
        self.show_recording(view, final.name)
        self._upload_toast(transfer, f"Opened {final.name}", f"kept in {folder.name}/", ok=True)
        return True

    def _upload_toast(self, transfer: str | None, title: str, body: str, ok: bool) -> None:
        """Replace viser's own upload notification ("File uploaded successfully", shown for any
        file once its bytes arrive, even one that cannot be opened) with what became of the file.
        The removal is sent twice: the browser may show its notification after the first."""
        if not self._closed.is_set():
            self.client.add_notification(title, body, with_close_button=True,
                                         auto_close_seconds=8.0 if ok else 20.0, color="green" if ok else "red")
        if transfer is None:
            return
        message = _messages.RemoveNotificationMessage(uuid=f"upload-{transfer}")

        def send() -> None:
            if not self._closed.is_set():
                self.client._websock_connection.queue_message(message)

        send()
        for delay in UPLOAD_TOAST_REMOVALS:
            timer = threading.Timer(delay, send)
            timer.daemon = True
            timer.start()

    # -- saving and exports ----------------------------------------------------------------------

    def save_run(self) -> Path | None:
        """Write the current run (at full quality) to recordings/ under a safe, new name."""
        from collide.recording import write_recording

        with self._lock:
            view = self.view
        if view is None or getattr(view, "run", None) is None:
            self._file_message("Nothing to save yet.", error=True)
            return None
        run = view.run
        try:
            if view.preview:
                run = run_scene(view.scene, record=True)
            folder = self.app.recordings_dir
            folder.mkdir(parents=True, exist_ok=True)
            path = files.unique_path(folder, files.save_name(view.scene.name))
            write_recording(run, path)
        except (SceneError, RunError, OSError, ValueError) as exc:
            self._file_message(f"Not saved: {_one_line(exc)}", error=True)
            return None
        self.refresh_recordings()
        self._file_message(f"Saved **{path.name}** in {self.app.recordings_dir.name}/.")
        return path

    def export_csv(self) -> str | None:
        """Send the run's CSV (the `collide run --csv` columns) to the browser as a download."""
        view = self.view
        if view is None or getattr(view, "run", None) is None:
            self._file_message("No run to export.", error=True)
            return None
        try:
            content, every = run_csv(view.run)
        except (ValueError, RunError) as exc:
            self._file_message(f"CSV not made: {_one_line(exc)}", error=True)
            return None
        name = f"{files.safe_stem(view.scene.name)}.csv"
        self.client.send_file_download(name, content, save_immediately=True)
        self.downloads.append((name, len(content)))
        rows = content.count(b"\n") - 1
        self._file_message(f"Downloaded **{name}**: {rows} rows, every {every * 1e3:.3g} ms.")
        return name

    def export_png(self) -> str | None:
        """Render the 3D view in the browser and send it back as a PNG download."""
        view = self.view
        cam = self.client.camera
        try:
            width, height = int(cam.image_width), int(cam.image_height)
        except (AttributeError, AssertionError):
            width = height = 0
        if view is None or width <= 0 or height <= 0:
            self._file_message("No view to capture yet.", error=True)
            return None
        try:
            pixels = self.client.get_render(height, width, transport_format="png", timeout=30.0)
        except (TimeoutError, RuntimeError) as exc:
            self._file_message(f"Screenshot failed: {_one_line(exc)}", error=True)
            return None
        content = png_bytes(pixels)
        name = f"{files.safe_stem(view.scene.name if view.scene is not None else 'view')}-{self.t * 1e3:.4g}ms.png"
        self.client.send_file_download(name, content, save_immediately=True)
        self.downloads.append((name, len(content)))
        self._file_message(f"Downloaded **{name}** ({width}x{height}).")
        return name

    # -- timeline ---------------------------------------------------------------------------------

    def toggle_play(self, playing: bool | None = None) -> None:
        with self._lock:
            want = (not self.playing) if playing is None else playing
            if want == self.playing and playing is not None:
                return
            self.playing = want
            if self.playing and self.view is not None and self.t >= self.view.t1:
                self.t = self.view.t0
            self.play_button.label = "Pause" if self.playing else "Play"
            self.play_button.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY
            if not self.playing:
                self._show_values()

    def seek(self, t: float, *, from_box: bool = False) -> None:
        """Show time t (clamped to the run): bodies, forces, the plots' cursor, the values."""
        with self._lock:
            if self.view is None:
                return
            self.t = self.view.clamp_time(t)
            with self.client.atomic():
                self._draw_frame(cursor=True, box=not from_box)
                self._show_values()

    def set_plot_window(self, which: str) -> None:
        """The plots' time axis: the whole run, or the first contact (padded by a third)."""
        with self._lock:
            self._plot_window = which
            if self.view is not None:
                self.plots.set_window(self._window(self.view))

    def _window(self, view: ViewRun) -> tuple[float, float]:
        if self._plot_window == "contact" and view.contact_windows:
            a, b = view.contact_windows[0]
            pad = 0.35 * (b - a)
            return max(view.t0, a - pad), min(view.t1, b + pad)
        return view.t0, view.t1

    def _settings(self) -> Settings:
        return check_settings(self.integrator.value, parse_dt_choice(self.dt.value), float(self.tol.value))

    def request_run(self, refit: bool = False) -> None:
        """Re-simulate with the controls' current values (the worker drops stale requests)."""
        with self._lock:
            controls = self.controls
            if controls is None:
                return
            values = dict(self.values)
            try:
                settings = self._settings()
            except (SceneError, ValueError) as exc:
                self._show_error(_one_line(exc))
                return
        self.worker.submit(Request(controls, values, settings, refit, time.perf_counter()))

    def _reset_params(self) -> None:
        with self._lock:
            if self.controls is None:
                return
            self._rebuild_params(scene_controls(self.controls.scene))
        self._clear_notice()
        self.request_run()

    # ==========================================================================================
    # Simulation (worker thread)

    def _job(self, req: Request, final: bool) -> bool:
        if req.controls is not self.controls or self._closed.is_set():
            return False
        clock = [time.perf_counter()]

        def lap() -> float:
            now = time.perf_counter()
            clock.append(now)
            return now - clock[-2]

        try:
            scene = build_scene(req.controls, req.values, req.settings)
            long = self._expect_long(scene)
            preview = None
            if (not final and self._full_cost is not None and self._full_cost > PREVIEW_BUDGET
                    and len(scene.bodies) <= MANY_BODIES):
                preview = preview_settings(scene)
            if long and preview is None and not final and not req.refit:
                # Seconds to a minute of run and no quick preview: only once the slider rests
                # (the worker calls back with final=True after its settle time, unless a newer
                # value came).
                self._show_progress(f"*{scene.name}: the run starts when the slider rests...*")
                return True
            t_build = lap()
            if preview is not None:
                # A preview is a coarse first answer, redrawn by the real run once the slider rests:
                # its error is not measured (that runs the scene again at a tenth of the
                # tolerance: 23 -> 8 ms for the billiards break's preview).
                run = run_scene(scene, integrator=preview.integrator, dt=preview.dt, tol=preview.tol, record=True,
                                measure=False)
            elif long:
                run = self._run_in_background(scene)
                if run is None:
                    return False
            else:
                run = run_scene(scene, record=True)
            t_run = lap()
            if preview is None:
                self._full_cost = t_run
            view = ViewRun(run, origin="live run", preview=preview is not None)
            t_view = lap()
        except (SceneError, RunError) as exc:
            self._show_progress("")
            self._show_error(_one_line(exc))
            return False
        if req.controls is not self.controls:
            return False
        self._show_view(view, refit=req.refit, stamp=req.stamp)
        if long:
            self._show_progress("")
        self.timings.append({"stamp": req.stamp, "preview": preview is not None, "queued": clock[0] - req.stamp,
                             "build": t_build, "simulate": t_run, "core_wall": run.result.wall_time_s,
                             "prepare": t_view, "draw": lap(), "total": time.perf_counter() - req.stamp})
        if self.ens_on.value and not self.worker.pending():
            self._run_ensemble(scene, preview)
        return preview is not None

    def _expect_long(self, scene: Scene) -> bool:
        return len(scene.bodies) > MANY_BODIES or (self._full_cost is not None and self._full_cost > LONG_RUN_S)

    def _run_in_background(self, scene: Scene) -> SceneRun | None:
        """Run in the child process with a progress line; None when stopped (the Stop button,
        a newer value, the tab closing)."""
        self._stop_run.clear()
        self.stop_button.visible = True
        name = scene.name

        at_rest = " (or sooner, at rest)" if scene.rest is not None else ""

        def progress(t: float, t_end: float, steps: int, seconds: float) -> None:
            done = f" ({100 * t / t_end:.0f} %)" if math.isfinite(t_end) and t_end > 0 and not at_rest else ""
            self._show_progress(f"**Running {name}** in the background: {t:.4g} of {t_end:.4g} s{at_rest} "
                                f"simulated{done}, {steps:,} steps, {seconds:.1f} s. The last run stays shown; "
                                "moving a slider restarts it.")

        self._show_progress(f"**Running {name}** in the background: starting...")
        try:
            run = self.runner.run(scene, progress=progress, record=True, stop=self._run_should_stop)
        except RunStopped:
            if self._stop_run.is_set():
                self._show_progress(f"*{name}: run stopped; the last run is shown.*")
            return None
        finally:
            self.stop_button.visible = False
        self._full_cost = run.result.wall_time_s
        self._show_progress(f"*{name}: run done in {run.result.wall_time_s:.1f} s; preparing the view...*")
        return run

    def _run_should_stop(self) -> bool:
        return self._stop_run.is_set() or self.worker.pending() or self._closed.is_set()

    def stop_run(self) -> None:
        """Stop the run going in the background (the Stop button)."""
        self._stop_run.set()

    def _show_progress(self, text: str) -> None:
        if not self._closed.is_set() and self.progress.content != text:
            self.progress.content = text

    def _run_ensemble(self, scene: Scene, preview: Preview | None) -> None:
        kind = self.ens_kind.value
        try:
            if kind not in ens.kinds_for(scene):
                raise SceneError(f"'{kind}' needs a 2D or 3D scene")
            scenes = ens.ensemble_scenes(scene, kind, float(self.ens_spread.value), int(self.ens_members.value))
            if preview is not None:
                scenes = [replace(s, integrator=preview.integrator, dt=preview.dt, tol=preview.tol) for s in scenes]
            paths, wall = ens.ensemble_paths(scenes)
        except (SceneError, RunError) as exc:
            self.ens_message.content = f"**Ensemble not run:** {_one_line(exc)}"
            return
        with self._lock:
            self._ensemble_paths = paths
            self.drawer.show_ghosts(paths)
            self.ens_message.content = (f"{len(scenes)} runs ({ens.KINDS[kind].label}, "
                                        f"+-{self.ens_spread.value:g} {ens.KINDS[kind].unit}) in {wall * 1e3:.0f} ms")

    def _job_failed(self, exc: BaseException) -> None:
        FAILURES.report(exc, "a tab's run")  # one line, each distinct one once: values can repeat it
        self._show_error(f"internal error: {_one_line(exc)}")

    # ==========================================================================================
    # Drawing

    def _show_view(self, view: ViewRun, *, refit: bool = False, stamp: float | None = None) -> None:
        with self._lock:
            first = self.view is None
            self.view = view
            self.error = None
            self.t = view.clamp_time(self.t if not refit else view.t0 + _first_contact_fraction(view))
            if refit:
                self.toggle_play(False)
            with self.client.atomic():
                self.drawer.show_run(view)
                self.plots.show_run(view, self.t, self._window(view))
                step = _slider_step(view.duration * 1e3)
                self.time_slider.max = max(math.ceil(view.t1 * 1e3 / step) * step, step)
                self.time_slider.min = view.t0 * 1e3
                self.time_slider.step = step
                self.time_slider.precision = max(0, -math.floor(math.log10(step)))
                self._set_contact_slider(view)
                many = self.drawer.many
                self.show_chains.visible = many
                self.show_shadows.visible = self.drawer._floor is not None
                self._draw_frame(cursor=False)
                self._show_status()
                self._show_values()
                self.legend.content = self.drawer.legend()
                self.colour_legend.content = self.drawer.colour_legend()
            self.client.flush()
            self.runs_drawn += 1
            if stamp:
                self.last_latency = time.perf_counter() - stamp
        if self.controls is not None and (view.n_bodies > MANY_BODIES or (self._full_cost or 0.0) > LONG_RUN_S):
            self.runner.warm()  # the next run will go to the background: its process is ready
        if refit or first:
            self.fit_camera()

    def _set_contact_slider(self, view: ViewRun) -> None:
        if not view.contact_windows:
            self.contact_slider.visible = False
            return
        a, b = view.contact_windows[0]
        span = max(b - a, 1e-12) * 1e3
        step = _slider_step(span * 2)  # about 4000 positions over the contact
        self.contact_slider.visible = True
        self.contact_slider.min = math.floor(a * 1e3 / step) * step
        self.contact_slider.max = math.ceil(b * 1e3 / step) * step
        self.contact_slider.step = step
        self.contact_slider.precision = max(0, -math.floor(math.log10(step)))
        unit_label = "in contact (ms)"
        if self.contact_slider.label != unit_label:
            self.contact_slider.label = unit_label

    def fit_camera(self, target: str = "whole run") -> None:
        """Point this client's camera at the run's paths or at its contact (waits for the
        browser's camera)."""
        view = self.view
        if view is None or not self._camera_ready.wait(5.0):
            return
        self._fit_target = target
        lo, hi = view.contact_bounds() if target == "contact" else view.bounds()
        cam = self.client.camera
        try:
            aspect = min(cam.aspect, 1.6) if cam.image_height > 0 else 1.0
        except AssertionError:
            aspect = 1.0
        fit = fit_camera(lo, hi, planar=view.dim < 3, aspect=aspect)
        try:
            cam.up_direction = fit.up
            cam.fov = fit.fov
            cam.position = fit.position
            cam.look_at = fit.look_at
        except (AssertionError, ValueError):
            return
        dist = float(np.linalg.norm(np.subtract(fit.position, fit.look_at)))
        self._auto_fit = (aspect, np.array(fit.position), dist, time.monotonic())

    def _on_camera(self, cam: viser.CameraHandle) -> None:
        """Re-fit while the canvas settles (the panels dock after the page loads and change its
        aspect), until the user moves the camera. The overlays follow the eye."""
        self._camera_ready.set()
        try:
            eye = np.array(cam.position, dtype=float)
        except (AssertionError, TypeError, ValueError):
            eye = None
        if eye is not None:
            old = self.drawer.eye
            self.drawer.eye = eye
            if old is None or float(np.linalg.norm(eye - old)) > 1e-4 * (float(np.linalg.norm(eye)) + 1e-12):
                self._redraw_soon()
        fit = self._auto_fit
        if fit is None or self.view is None:
            return
        aspect, position, dist, when = fit
        try:
            # Messages within a moment of the fit may still carry the old pose.
            moved = (time.monotonic() - when > 2.0 and
                     float(np.linalg.norm(cam.position - position)) > 1e-3 * dist)
            new_aspect = min(cam.aspect, 1.6)
        except (AssertionError, ZeroDivisionError):
            return
        if moved:
            self._auto_fit = None
        elif abs(new_aspect / aspect - 1) > 0.03:
            self.fit_camera(self._fit_target)

    def _redraw_soon(self) -> None:
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
                with self.client.atomic():
                    self.drawer.show_frame(self.view.frame(self.t))

        timer = threading.Timer(0.05, redraw)
        timer.daemon = True
        timer.start()

    def _time_text(self) -> str:
        return f"{self.t * 1e3:.{int(self.time_slider.precision)}f}"

    def _draw_frame(self, cursor: bool, box: bool = True) -> None:
        view = self.view
        if view is None:
            return
        self.drawer.show_frame(view.frame(self.t))
        shown = round(self.t * 1e3, int(self.time_slider.precision))
        self._sent_times.append(shown)
        self.time_slider.value = shown
        if box:
            self.time_box.value = self._time_text()
        if view.contact_windows and self.contact_slider.visible:
            lo, hi = self.contact_slider.min, self.contact_slider.max
            self.contact_slider.value = min(max(self.t * 1e3, lo), hi)
        now = time.monotonic()
        if cursor or now - self._cursor_time > CURSOR_PERIOD:
            self.plots.show_cursor(self.t)
            if self.playing:
                self._show_values()
            self._cursor_time = now

    def _show_values(self) -> None:
        view = self.view
        if view is not None:
            self.values_table.content = values_markdown(view, self.t)

    def _show_status(self) -> None:
        view = self.view
        lines = []
        if view is not None:
            tag = " *(preview: coarse step while you drag)*" if view.preview else ""
            lines.append(f"**{view.name}** · {view.dim}D · {view.origin}{tag}")
            lines += view.status_lines()
        if self.notes:
            lines += [f"*{n}*" for n in self.notes]
        if self.error:
            lines.append(f"<span style='color:{RED}'>**Not run:** {self.error}</span>")
            if view is not None:
                lines.append("*(showing the last good run)*")
        self.status.content = "  \n".join(lines)

    def _show_error(self, message: str) -> None:
        with self._lock:
            self.error = message
            self._show_status()

    def _show_notice(self, message: str, error: bool = False) -> None:
        """A message at the top of the panel: what became of something the user did."""
        colour = RED if error else "#1e6b34"
        self.notice.content = f"<div class='collide-notice' style='color:{colour}'>{_escape(message)}</div>"

    def _clear_notice(self) -> None:
        if self.notice.content:
            self.notice.content = ""

    def _file_message(self, message: str, error: bool = False) -> None:
        self.file_message.content = (f"<span style='color:{RED}'>{_escape(message)}</span>" if error else message)

    # ==========================================================================================
    # Playback (player thread)

    def _speed(self, view: ViewRun) -> float:
        choice = self.speed.value
        if choice == "auto" or choice not in SPEEDS:  # a value no menu offers: from a forged message
            contact = sum(b - a for a, b in view.contact_windows)
            slow = (1 / SLOW_MOTION - 1) * contact if self.slowmo.value else 0.0
            return max(view.duration + slow, 1e-9) / PLAYBACK_SECONDS
        return float(choice.rstrip("x"))

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
                with self._lock:
                    view = self.view
                    if view is None or not self.playing:
                        continue
                    rate = self._speed(view)
                    if self.slowmo.value and view.in_contact(self.t):
                        rate *= SLOW_MOTION
                    t = self.t + min(elapsed, 0.25) * rate
                    if t > view.t1:
                        if self.loop.value:
                            t = view.t0
                        else:
                            t = view.t1
                            self.toggle_play(False)
                    self.t = t
                    with self.client.atomic():
                        self._draw_frame(cursor=False)
                    done = time.perf_counter()
                    self.frame_times.append(done)
                    self.frame_costs.append(done - now)
            except Exception as exc:  # noqa: BLE001 - a closed tab must not kill the thread noisily
                if self._closed.is_set():
                    return
                FAILURES.report(exc, "a tab's playback")
                self._show_error(f"playback: {_one_line(exc)}")
                self.toggle_play(False)

    def close(self) -> None:
        """Stop this tab's threads (the tab closed) and drop its unfinished uploads."""
        self._closed.set()
        self.playing = False
        for timer in list(self._typing.values()):
            timer.cancel()
        self.worker.close(timeout=2.0)
        self.runner.close()
        self._player.join(timeout=2.0)
        if self.uploads is not None:
            self.uploads.close()


def _camera_known(client: Any) -> bool:
    """True once the browser has reported its camera (never for a stand-in client)."""
    try:
        client.camera.wxyz  # noqa: B018 - asserts that the camera state has arrived
    except (AssertionError, AttributeError):
        return False
    return True


def _first_contact_fraction(view: ViewRun) -> float:
    """Start a new scene just before its first contact, where something happens."""
    if not view.contact_windows:
        return 0.0
    start = view.contact_windows[0][0]
    return max(0.0, start - view.t0 - 0.02 * view.duration)


def _slider_step(duration: float) -> float:
    step = duration / 2000
    if not step > 0:
        return 1e-6
    exp = math.floor(math.log10(step))
    return 10.0**exp


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _strip_name(text: str, name: str) -> str:
    """'name: reason' as 'reason' (the message already names the file)."""
    return text[len(name) + 2:] if text.startswith(f"{name}: ") else text


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def initial_view(scene: Scene) -> ViewRun:
    """The first run of a scene as the viewer shows it (its tail long enough to see the outcome)."""
    return ViewRun(run_scene(for_viewing(scene), record=True), origin="live run")
