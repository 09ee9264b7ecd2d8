"""One browser tab: its controls, its 3D scene, its plots, its simulation worker and player.

Every tab gets a `Session` of its own (client-scoped GUI and scene), so tabs do not fight over
the timeline or the parameters, and a tab that closes takes only its own threads with it. A
session is made of parts, each with one job:

- `Panel` (viewer.panel): the fixed controls, built once; `Messages`: the lines of text in it;
- `ParamControls` (viewer.param_controls): the Parameters folder and the values set in it;
- `Player` (viewer.playback): the time shown, the Timeline folder and the player thread;
- `CameraFit` (viewer.camera): the camera, fitted to the run;
- `LiveRuns` (viewer.live): runs with the changed parameters (previews, background runs);
- `EnsembleView` (viewer.ensemble_view), `FileActions` (viewer.file_actions): those folders.

The session joins them: it shows a scene, a recording or frames in all of them at once. What it
needs from the app comes in a `SessionConfig`. Threads: viser runs GUI callbacks on its pool; the
live runs' worker re-simulates; the player advances the timeline; typed values apply after a
short pause in typing. `self._lock` serialises everything that draws.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import viser

from collide.run import SceneRun
from collide.scene import Scene, SceneError, load_scene
from viewer.camera import CameraFit
from viewer.config import SessionConfig
from viewer.drag import DragSetup
from viewer.ensemble_view import EnsembleView
from viewer.file_actions import FileActions
from viewer.frames import FramesRun
from viewer.inside import Inspector
from viewer.lesson_view import LessonView
from viewer.live import LiveRuns, Preview, Request
from viewer.messages import Messages, one_line
from viewer.opening import OpeningRecording, start_of_recording
from viewer.panel import Panel, Typing
from viewer.param_controls import ParamControls
from viewer.params import AUTO, Controls, add_ball, build_scene, remove_ball, scene_controls, values_of
from viewer.playback import Player
from viewer.scene3d import SceneDrawer
from viewer.state import ViewRun


class _Via:
    """An attribute of one of the session's parts, read and set through the session (tests and
    benchmarks reach the controls and the playback state as `session.x`)."""

    def __init__(self, part: str, name: str | None = None) -> None:
        self._part = part
        self._name = name

    def __set_name__(self, owner: type, name: str) -> None:
        self._name = self._name or name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return getattr(getattr(obj, self._part), self._name)

    def __set__(self, obj: Any, value: Any) -> None:
        setattr(getattr(obj, self._part), self._name, value)


class Session:
    """The viewer for one client."""

    # The run and time shown, and playback
    view = _Via("player")
    t = _Via("player")
    playing = _Via("player")
    fps = _Via("player")  # frames a second the player sends while playing
    frame_times = _Via("player")
    frame_costs = _Via("player")
    _player = _Via("player", "thread")
    _speed = _Via("player", "speed")
    # Parameters and live runs
    controls = _Via("params")
    values = _Via("params")  # every parameter's value (display units)
    _param_handles = _Via("params", "sliders")  # ident -> slider
    _param_boxes = _Via("params", "boxes")  # ident -> text box
    worker = _Via("live")
    runner = _Via("live")
    timings = _Via("live")  # per drawn run, for benchmarks
    _full_cost = _Via("live", "full_cost")
    _ensemble_paths = _Via("ensemble", "paths")
    downloads = _Via("files")  # (file name, bytes) sent to the browser
    # Controls of the panel
    progress = _Via("panel")
    stop_button = _Via("panel")
    play_button = _Via("panel")
    frame_buttons = _Via("panel")
    step_buttons = _Via("panel")
    time_box = _Via("panel")
    time_slider = _Via("panel")
    contact_slider = _Via("panel")
    speed = _Via("panel")
    loop = _Via("panel")
    slowmo = _Via("panel")
    show_forces = _Via("panel")
    show_velocity = _Via("panel")
    show_momentum = _Via("panel")
    show_com = _Via("panel")
    show_trails = _Via("panel")
    colour_by = _Via("panel")
    show_chains = _Via("panel")
    show_shadows = _Via("panel")
    draw_as = _Via("panel")
    picker = _Via("panel")
    balls = _Via("panel")
    integrator = _Via("panel")
    dt = _Via("panel")
    tol = _Via("panel")
    recording = _Via("panel")
    upload = _Via("panel")
    export_buttons = _Via("panel")
    plots = _Via("panel")

    def __init__(self, config: SessionConfig, client: viser.ClientHandle) -> None:
        self.config = config
        self.client = client
        self._lock = threading.RLock()
        self._closed = threading.Event()
        self.error: str | None = None
        self.notes: list[str] = []
        self.runs_drawn = 0
        self.last_latency: float | None = None
        self._plot_window = "whole run"
        self.drawer = SceneDrawer(client.scene, config.point_bodies)
        self.panel = panel = Panel(client.gui, config, self.drawer.options)
        self.messages = Messages(panel.status, panel.progress, panel.notice, panel.file_message, self._closed)
        self._typing = Typing()
        self.params = ParamControls(client.gui, panel.param_parent, self._lock, self._typing, self.messages,
                                    self.request_run)
        self.player = Player(client, panel, self.drawer, self._lock, self._closed, self._typing, self.messages,
                             self.show_error)
        self.camera = CameraFit(client, self.drawer, lambda: self.player.view, self.player.redraw_soon)
        self.files = FileActions(client, config, panel, self.messages, self._closed, self.show_recording,
                                 self._shown)
        self.live = LiveRuns(self, self.messages, panel.stop_button, self._closed, config.initial_cost,
                             name=f"collide-sim-{client.client_id}")
        self.ensemble = EnsembleView(panel, self.drawer, self._lock, self.request_run)
        self.inside = Inspector(client, panel.plot_panel, self.drawer, self._lock)  # clip, pick, histograms
        self.drag = DragSetup(self)  # drag to set up (viewer.drag)
        self.lesson = LessonView(self)  # momentum diagram, energy bars, lesson switches
        self.player.values_hooks += [self.lesson.at_time, self.drag.at_time]
        self._wire()
        self.player.start()

    def _wire(self) -> None:
        """The callbacks of the controls that act on more than one part."""
        panel = self.panel
        panel.stop_button.on_click(lambda _e: self.stop_run())
        for handle in panel.show_handles().values():
            handle.on_update(self._on_show)
        panel.picker.on_update(self._on_pick)
        panel.balls.on_click(lambda e: self._on_balls(e))
        for handle in (panel.integrator, panel.dt, panel.tol):
            handle.on_update(self._on_settings)
        panel.reset_button.on_click(lambda _e: self._reset_params())
        panel.fit_buttons.on_click(lambda _e: self.fit_camera(panel.fit_buttons.value))
        panel.window_buttons.on_click(lambda _e: self.set_plot_window(panel.window_buttons.value))

    # ==========================================================================================
    # Callbacks (viser's thread pool). Server-side assignments arrive with client None: ignored.

    def _on_settings(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.panel.tol.visible = self.panel.dt.value == AUTO
        self.request_run()

    def _on_show(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.set_show(**{key: handle.value for key, handle in self.panel.show_handles().items()})

    def _on_pick(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        choice = next((c for c in self.config.scene_choices if c.label == self.panel.picker.value), None)
        if choice is not None:
            self.load_scene(choice.source)

    def _on_balls(self, event: viser.GuiEvent) -> None:
        self.change_balls(+1 if self.panel.balls.value == "more balls" else -1)

    # ==========================================================================================
    # Actions (also called by tests and benchmarks)

    def load_scene(self, source: str | Scene, *, run: SceneRun | None = None, label: str | None = None,
                   keep_settings: bool = False) -> None:
        """Show a scene (a name or .toml path, or a Scene) with its default parameters; `run`, if
        given, is that scene's run already computed."""
        try:
            scene = source if isinstance(source, Scene) else load_scene(source)
        except SceneError as exc:
            self.show_error(str(exc))
            return
        controls = scene_controls(scene)
        with self._lock:
            self._show_controls(controls)
            self.ensemble.clear()
            if label is not None and label in self.panel.picker.options:
                self.panel.picker.value = label
        # What the scene's runs cost is known from its own run only (chooses previews and
        # background runs): this one, or the scene's last in this tab.
        self.live.full_cost = run.result.wall_time_s if run is not None else self.live.costs.get(scene.name)
        if run is not None:
            self._show_view(ViewRun(run, origin="live run"), refit=True)
        else:
            self.request_run(refit=True)

    def open_recording(self, path: Path, name: str | None = None) -> bool:
        """Replay a recording (read in a child process: a damaged file cannot take the server
        down); a file that cannot be read leaves a message and changes nothing."""
        return self.files.open_recording(path, name)

    def show_recording(self, view: ViewRun, name: str) -> None:
        """Show a run read from a recording, with its scene's parameters in the controls."""
        scene = view.scene
        controls = scene_controls(scene)
        with self._lock:
            self._show_controls(controls, values_of(scene, controls))
            self.panel.integrator.value = view.result.integrator
            self.ensemble.clear()
            self.panel.pick(f"rec: {name}")
        self.live.full_cost = view.result.wall_time_s
        self._show_view(view, refit=True)
        self.seek(view.t0)
        self.messages.clear_notice()
        self.messages.file_message(f"Replaying **{name}** ({scene.name}). Move a parameter to re-simulate "
                                   "from its scene.")

    def follow_opening(self, opening: OpeningRecording) -> None:
        """Show the recording given at start as it is read: "reading", then its scene's start
        (the status saying the run is still loading), then its run, or why it cannot be read."""
        shown: list[str] = []
        order = threading.Lock()

        def update(o: OpeningRecording) -> None:
            stage = ("run" if o.view is not None else "error" if o.error else
                     "start" if o.scene is not None else "reading")
            with order:
                if self._closed.is_set() or stage in shown or {"run", "error"} & set(shown):
                    return
                shown.append(stage)
                if stage == "run":
                    self.show_recording(o.view, o.name)
                    self.messages.show_progress("")
                elif stage == "error":
                    self.messages.show_progress("")
                    self.messages.show_notice(f"Cannot open {o.name}: {o.error}", error=True)
                    self.show_error(o.error)
                elif stage == "start":
                    with self._lock:
                        self.panel.pick(f"rec: {o.name}")
                    self._show_view(start_of_recording(o.scene, o.name), refit=True)
                    self.messages.show_progress(f"*Reading {o.name}: its start is shown, the run follows...*")
                else:
                    self.messages.show_progress(f"*Reading {o.name}...*")

        opening.follow(update)

    def show_frames(self, run: FramesRun) -> None:
        """Replay a run given as frames (many bodies; no parameters to change)."""
        with self._lock:
            self.params.show_note(f"*{run.origin}: {run.n_bodies} bodies replayed, no parameters to change*")
            self.panel.pick(f"frames: {run.name}")
            self.panel.balls.visible = False
            self.ensemble.clear()
        self._show_view(run, refit=True)
        self.messages.clear_notice()

    def set_show(self, **options: Any) -> None:
        """What the 3D view shows (the Show folder): forces, velocity, momentum, com, trails,
        colour_by, chains, shadows, bodies (drawn as "auto", "spheres" or "points"). Keeps the
        folder's controls in step."""
        handles = self.panel.show_handles()
        with self._lock:
            # Paths and the way bodies are drawn are built with the run's fixed parts.
            rebuild = any(key in options and options[key] != getattr(self.drawer.options, key)
                          for key in ("trails", "bodies"))
            for key, value in options.items():
                if handles[key].value != value:
                    handles[key].value = value
            with self.client.atomic():
                self.drawer.set_options(**options)
                if rebuild and self.player.view is not None:
                    self.drawer.show_run(self.player.view)
                    self.player.draw_frame(cursor=False)
                    self.panel.show_chains.visible = self.drawer.many and not self.drawer.points
                self.panel.legend.content = self.drawer.legend()
                self.panel.colour_legend.content = self.drawer.colour_legend()

    def change_balls(self, delta: int) -> None:
        """Add (delta > 0) or take away a ball, keeping every other parameter as it is."""
        with self._lock:
            controls = self.params.controls
            if controls is None:
                return
            values = dict(self.params.values)
        try:
            scene = build_scene(controls, values, self.panel.settings())
            scene = add_ball(scene) if delta > 0 else remove_ball(scene)
        except (SceneError, ValueError) as exc:
            self.messages.show_notice(one_line(exc), error=True)
            return
        self.messages.clear_notice()
        self.load_scene(scene, keep_settings=True)

    def apply_typed(self, ident: str, text: str) -> bool:
        """A typed parameter value (see `ParamControls.apply_typed`)."""
        return self.params.apply_typed(ident, text)

    def request_run(self, refit: bool = False) -> None:
        """Re-simulate with the controls' current values (the worker drops stale requests)."""
        with self._lock:
            controls = self.params.controls
            if controls is None:
                return
            values = dict(self.params.values)
            try:
                settings = self.panel.settings()
            except (SceneError, ValueError) as exc:
                self.show_error(one_line(exc))
                return
        self.live.submit(Request(controls, values, settings, refit, time.perf_counter()))

    def stop_run(self) -> None:
        """Stop the run going in the background (the Stop button)."""
        self.live.stop_run()

    def toggle_play(self, playing: bool | None = None) -> None:
        self.player.toggle_play(playing)

    def seek(self, t: float, *, from_box: bool = False) -> None:
        """Show time t (clamped to the run): bodies, forces, the plots' cursor, the values."""
        self.player.seek(t, from_box=from_box)

    def step(self, what: str, direction: int) -> None:
        """One frame ("frame") or one contact step ("step"), forward (+1) or back (-1)."""
        self.player.step(what, direction)

    def type_time(self, text: str) -> bool:
        """Go to a typed time (ms), or refuse it with the reason."""
        return self.player.type_time(text)

    def fit_camera(self, target: str = "whole run") -> None:
        """Point this client's camera at the run's paths or at its contact (waits for the
        browser's camera)."""
        self.camera.fit(target)

    def set_plot_window(self, which: str) -> None:
        """The plots' time axis: the whole run, or the first contact (padded by a third)."""
        with self._lock:
            self._plot_window = which
            if self.player.view is not None:
                self.panel.plots.set_window(self._window(self.player.view))

    def close(self) -> None:
        """Stop this tab's threads (the tab closed) and drop its unfinished uploads."""
        self._closed.set()
        self.player.playing = False
        self._typing.cancel()
        self.live.close()
        self.player.join(timeout=2.0)
        self.files.close()

    # ==========================================================================================
    # What the live runs need (`viewer.live.LiveTab`)

    def show_live(self, view: ViewRun, *, refit: bool, stamp: float) -> None:
        self._show_view(view, refit=refit, stamp=stamp)

    def show_error(self, message: str) -> None:
        with self._lock:
            self.error = message
            self._show_status()

    def after_run(self, scene: Scene, preview: Preview | None) -> None:
        if self.ensemble.wanted:
            self.ensemble.run(scene, preview)

    # ==========================================================================================
    # Drawing

    def _show_controls(self, controls: Controls, values: dict[str, float] | None = None) -> None:
        self.params.rebuild(controls, values)
        self.panel.show_settings(controls)

    def _reset_params(self) -> None:
        with self._lock:
            if self.params.controls is None:
                return
            self._show_controls(scene_controls(self.params.controls.scene))
        self.messages.clear_notice()
        self.request_run()

    def _show_view(self, view: ViewRun, *, refit: bool = False, stamp: float | None = None) -> None:
        panel, player = self.panel, self.player
        with self._lock:
            first = player.view is None
            self.error = None
            player.set_view(view, refit)
            with self.client.atomic():
                self.drawer.show_run(view)
                panel.plots.show_run(view, player.t, self._window(view))
                player.set_sliders(view)
                panel.show_chains.visible = self.drawer.many and not self.drawer.points
                panel.draw_as.visible = self.drawer.many
                panel.show_shadows.visible = self.drawer._floor is not None
                player.draw_frame(cursor=False)
                self._show_status()
                self.lesson.show(view)
                player.show_values()
                panel.legend.content = self.drawer.legend()
                panel.colour_legend.content = self.drawer.colour_legend()
                self.drag.show(view)
            self.client.flush()
            self.runs_drawn += 1
            if stamp:
                self.last_latency = time.perf_counter() - stamp
        if self.params.controls is not None:
            self.live.warm_for(view)  # the next run will go to the background: its process is ready
        if refit or first:
            self.fit_camera()

    def _window(self, view: ViewRun) -> tuple[float, float]:
        if self._plot_window == "contact" and view.contact_windows:
            a, b = view.contact_windows[0]
            pad = 0.35 * (b - a)
            return max(view.t0, a - pad), min(view.t1, b + pad)
        return view.t0, view.t1

    def _show_status(self) -> None:
        self.messages.show_status(self.player.view, self.notes, self.error)

    def _shown(self) -> tuple[ViewRun | None, float]:
        with self._lock:
            return self.player.view, self.player.t
