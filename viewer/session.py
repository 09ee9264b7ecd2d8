"""One browser tab: its controls, its 3D scene, its plots, its simulation worker and player.

Every tab gets a `Session` of its own (client-scoped GUI and scene), so tabs do not fight over
the timeline or the parameters, and a tab that closes takes only its own threads with it.
Threads: viser runs GUI callbacks on its pool; the `LatestWorker` re-simulates; the player
advances the timeline. `self._lock` serialises everything that draws.
"""

from __future__ import annotations

import math
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from collide.run import SceneRun, run_scene
from collide.scene import INTEGRATORS, Scene, SceneError, load_scene
from collide.stepper import RunError
from viewer import ensemble as ens
from viewer import files
from viewer.geometry import fit_camera
from viewer.params import (
    AUTO,
    Controls,
    Param,
    Settings,
    build_scene,
    check_settings,
    dt_choice,
    parse_dt_choice,
    scene_controls,
    values_of,
)
from viewer.plots import Plots
from viewer.scene3d import SceneDrawer
from viewer.state import ViewRun
from viewer.worker import LatestWorker

if TYPE_CHECKING:
    from viewer.app import ViewerApp

FPS = 30.0
CURSOR_PERIOD = 0.25  # s between plot-cursor updates while playing
PREVIEW_BUDGET = 0.08  # s: when a full run takes longer, a coarse preview is drawn first
PREVIEW = ("verlet", 1e-3)  # the preview's integrator and tol (auto dt: about ten steps a contact)
SLOW_MOTION = 0.1  # playback rate inside contacts, relative to the chosen speed
PLAYBACK_SECONDS = 5.0  # 'auto' speed plays a run in about this long
SPEEDS = ["auto", "0.001x", "0.003x", "0.01x", "0.03x", "0.1x", "0.3x", "1x"]


@dataclass
class Request:
    """Parameters to simulate: control values (display units) and run settings."""

    controls: Controls
    values: dict[str, float]
    settings: Settings
    refit: bool = False
    stamp: float = 0.0


class Session:
    """The viewer for one client."""

    def __init__(self, app: ViewerApp, client: viser.ClientHandle) -> None:
        self.app = app
        self.client = client
        self._lock = threading.RLock()
        self._closed = threading.Event()
        self.view: ViewRun | None = None
        self.controls: Controls | None = None
        self.t = 0.0
        self.playing = False
        self.error: str | None = None
        self.notes: list[str] = []
        self.runs_drawn = 0
        self.last_latency: float | None = None
        self._full_cost: float | None = app.initial_cost
        self._param_handles: dict[str, Any] = {}
        self._param_folder: Any = None
        self._camera_ready = threading.Event()
        self._cursor_time = 0.0
        self._ensemble_paths: list[np.ndarray] | None = None

        self._auto_fit: tuple[float, np.ndarray, float, float] | None = None
        self._fit_target = "whole run"
        self._sent_times: deque[float] = deque(maxlen=60)
        self.timings: deque[dict[str, float]] = deque(maxlen=200)  # per drawn run, for benchmarks
        client.camera.on_update(self._on_camera)
        self.drawer = SceneDrawer(client.scene)
        self._build_gui()
        self.worker: LatestWorker[Request] = LatestWorker(self._job, on_error=self._job_failed,
                                                          name=f"collide-sim-{client.client_id}")
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
        self.status = gui.add_markdown("Loading...", order=0)
        with gui.add_folder("Timeline", order=1):
            self.play_button = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
            self.time_slider = gui.add_slider("time (ms)", min=0.0, max=1.0, step=0.001, initial_value=0.0)
            self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="auto",
                                          hint="simulated seconds per second; auto plays the run in ~5 s")
            self.loop = gui.add_checkbox("loop", initial_value=True)
            self.slowmo = gui.add_checkbox("slow motion in contact", initial_value=True,
                                           hint="play contacts 10x slower so the compression can be seen")
        with gui.add_folder("Scene", order=2):
            self.picker = gui.add_dropdown("scene", [c.label for c in app.scene_choices],
                                           initial_value=app.scene_choices[0].label)
            self.integrator = gui.add_dropdown("integrator", list(INTEGRATORS), initial_value="verlet")
            self.dt = gui.add_dropdown("dt", [AUTO], initial_value=AUTO)
            self.tol = gui.add_dropdown("tol (auto dt)", ["1e-06"], initial_value="1e-06")
            self.reset_button = gui.add_button("Reset parameters", icon=viser.Icon.REFRESH)
            self.fit_buttons = gui.add_button_group("fit view", ["whole run", "contact"],
                                                    hint="point the camera at the whole run or at the contact")
            self.legend = gui.add_markdown("")
        self._param_parent = gui.add_folder("Parameters", order=3)
        with gui.add_folder("Recordings", order=4, expand_by_default=True):
            self.recording = gui.add_dropdown("open .rrd", self._recording_options(), initial_value="(choose)")
            self.refresh_button = gui.add_button("Refresh list", icon=viser.Icon.REFRESH)
            self.upload = gui.add_upload_button("Upload .rrd", icon=viser.Icon.UPLOAD, mime_type=".rrd",
                                                hint=f"at most {files.MAX_UPLOAD_BYTES // 2**20} MB")
            self.save_button = gui.add_button("Save this run", icon=viser.Icon.DEVICE_FLOPPY)
            self.file_message = gui.add_markdown("")
        with gui.add_folder("Ensemble", order=5, expand_by_default=False):
            self.ens_on = gui.add_checkbox("show ensemble", initial_value=False,
                                           hint="run a small batch around the current parameters (run_scenes)")
            self.ens_kind = gui.add_dropdown("vary", list(ens.KINDS), initial_value="k")
            kind = ens.KINDS["k"]
            self.ens_spread = gui.add_slider("spread (+-, %)", min=kind.lo, max=kind.hi, step=kind.step,
                                             initial_value=kind.default)
            self.ens_members = gui.add_slider("members", min=3, max=15, step=1, initial_value=7)
            self.ens_message = gui.add_markdown("")
        self.plot_panel = gui.add_panel()
        self.plots = Plots(gui, self.plot_panel.add_tab("Plots", viser.Icon.CHART_LINE))
        self.plot_panel.dock_left()
        self.plot_panel.set_width(380)

        self.play_button.on_click(lambda _e: self.toggle_play())
        self.time_slider.on_update(self._on_time)
        self.picker.on_update(self._on_pick)
        for handle in (self.integrator, self.dt, self.tol):
            handle.on_update(self._on_control)
        self.reset_button.on_click(lambda _e: self._reset_params())
        self.fit_buttons.on_click(lambda _e: self.fit_camera(self.fit_buttons.value))
        self.recording.on_update(self._on_recording)
        self.refresh_button.on_click(lambda _e: self.refresh_recordings())
        self.upload.on_upload(self._on_upload)
        self.save_button.on_click(lambda _e: self.save_run())
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
        """Sliders for every parameter the scene uses, grouped per body and for the contact."""
        gui = self.client.gui
        values = values or controls.defaults()
        if self._param_folder is not None:
            self._param_folder.remove()
        self._param_handles = {}
        with self._param_parent:
            self._param_folder = gui.add_folder(None)
            with self._param_folder:
                for group in controls.groups():
                    with gui.add_folder(group):
                        for p in controls.params:
                            if p.group != group:
                                continue
                            self._param_handles[p.ident] = self._param_widget(gui, p, values.get(p.ident, p.value))
        self.controls = controls
        s = controls.settings
        self.integrator.value = s.integrator
        self.dt.options = controls.dt_choices
        self.dt.value = dt_choice(s.dt)
        self.tol.options = controls.tol_choices
        self.tol.value = f"{s.tol:.0e}"
        self.tol.visible = s.dt == AUTO

    def _param_widget(self, gui: viser.GuiApi, p: Param, value: float) -> Any:
        label = f"{p.label} ({p.unit})" if p.unit else p.label
        value = min(max(value, p.lo), p.hi)
        if p.slider:
            handle = gui.add_slider(label, min=p.lo, max=p.hi, step=p.step, initial_value=float(value),
                                    hint=p.hint or f"{p.key} in {p.unit or 'units of 1'}")
        else:
            handle = gui.add_number(label, initial_value=float(value), min=p.lo, max=p.hi, step=p.step,
                                    hint=p.hint or p.key)
        handle.on_update(self._on_control)
        return handle

    # ==========================================================================================
    # Callbacks (viser's thread pool). Server-side assignments arrive with client None: ignored.

    def _on_control(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.tol.visible = self.dt.value == AUTO
        self.request_run()

    def _on_time(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        value = float(self.time_slider.value)
        # A browser may send back a value the player just sent (its number box re-rounds it):
        # seeking to that would pull the playback back.
        if any(abs(value - sent) <= 0.5 * self.time_slider.step for sent in self._sent_times):
            return
        self.seek(value / 1e3)

    def _on_pick(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        choice = next((c for c in self.app.scene_choices if c.label == self.picker.value), None)
        if choice is not None:
            self.load_scene(choice.source)

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
        uploaded = self.upload.value
        self.receive_upload(uploaded.name, uploaded.content)

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

    def load_scene(self, source: str | Scene, *, run: SceneRun | None = None, label: str | None = None) -> None:
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
        if run is not None:
            self._show_view(ViewRun(run, origin="live run"), refit=True)
        else:
            self.request_run(refit=True)

    def open_recording(self, path: Path) -> bool:
        """Replay a recording; a file that cannot be read leaves a message and changes nothing."""
        from collide.recording import RecordingError, read_recording

        try:
            run = read_recording(path)
            view = ViewRun(run, origin=f"recording {path.name}")
        except (RecordingError, ValueError, OSError) as exc:
            self._file_message(f"Cannot open {path.name}: {_one_line(exc)}", error=True)
            return False
        self.show_recording(view, path.name)
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
        self._show_view(view, refit=True)
        self.seek(view.t0)
        self._file_message(f"Replaying **{name}** ({scene.name}). Move a parameter to re-simulate "
                           "from its scene.")

    def receive_upload(self, name: str, content: bytes) -> bool:
        """Check, stage and open an uploaded recording; keep it in recordings/ if it reads."""
        folder = self.app.recordings_dir
        try:
            files.check_upload(name, len(content), self.app.max_upload_bytes)
            staged = files.write_staged(folder, content)
        except (files.UploadError, OSError) as exc:
            self._file_message(f"Upload refused: {_one_line(exc)}", error=True)
            return False
        from collide.recording import RecordingError, read_recording

        try:
            read_recording(staged)
        except (RecordingError, ValueError, OSError) as exc:
            staged.unlink(missing_ok=True)
            self._file_message(f"Cannot open {files.safe_stem(name)}.rrd: {_one_line(exc)}", error=True)
            return False
        final = files.unique_path(folder, name)
        staged.rename(final)
        self.refresh_recordings(select=final.name)
        return self.open_recording(final)

    def save_run(self) -> Path | None:
        """Write the current run (at full quality) to recordings/ under a safe, new name."""
        from collide.recording import write_recording

        with self._lock:
            view = self.view
        if view is None:
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
        self._file_message(f"Saved **{path.name}** in {self.app.recordings_dir}.")
        return path

    def toggle_play(self, playing: bool | None = None) -> None:
        with self._lock:
            self.playing = (not self.playing) if playing is None else playing
            if self.playing and self.view is not None and self.t >= self.view.t1:
                self.t = self.view.t0
            self.play_button.label = "Pause" if self.playing else "Play"
            self.play_button.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY

    def seek(self, t: float) -> None:
        """Show time t (clamped to the run): bodies, forces and the plots' cursor."""
        with self._lock:
            if self.view is None:
                return
            self.t = self.view.clamp_time(t)
            self._draw_frame(cursor=True)

    def request_run(self, refit: bool = False) -> None:
        """Re-simulate with the controls' current values (the worker drops stale requests)."""
        with self._lock:
            controls = self.controls
            if controls is None:
                return
            values = {ident: float(h.value) for ident, h in self._param_handles.items()}
            try:
                settings = check_settings(self.integrator.value, parse_dt_choice(self.dt.value),
                                          float(self.tol.value))
            except (SceneError, ValueError) as exc:
                self._show_error(_one_line(exc))
                return
        self.worker.submit(Request(controls, values, settings, refit, time.perf_counter()))

    def _reset_params(self) -> None:
        with self._lock:
            if self.controls is None:
                return
            self._rebuild_params(self.controls)
        self.request_run()

    # ==========================================================================================
    # Simulation (worker thread)

    def _wants_preview(self, scene: Scene) -> bool:
        """Whether to show a coarse run first: the last full run of this scene took longer than
        the budget, and a coarse verlet run would take fewer steps."""
        if self._full_cost is None or self._full_cost <= PREVIEW_BUDGET:
            return False
        return scene.integrator != PREVIEW[0] or scene.dt != AUTO or scene.tol < PREVIEW[1]

    def _job(self, req: Request, final: bool) -> bool:
        if req.controls is not self.controls or self._closed.is_set():
            return False
        clock = [time.perf_counter()]

        def lap() -> float:
            now = time.perf_counter()
            clock.append(now)
            return now - clock[-2]

        try:
            scene, notes = build_scene(req.controls, req.values, req.settings)
            preview = not final and self._wants_preview(scene)
            t_build = lap()
            if preview:
                run = run_scene(scene, integrator=PREVIEW[0], dt=AUTO, tol=PREVIEW[1], record=True)
            else:
                run = run_scene(scene, record=True)
            t_run = lap()
            if not preview:
                self._full_cost = t_run
            view = ViewRun(run, origin="live run", preview=preview)
            t_view = lap()
        except (SceneError, RunError) as exc:
            self._show_error(_one_line(exc))
            return False
        if req.controls is not self.controls:
            return False
        self.notes = notes
        self._write_back(req, notes)
        self._show_view(view, refit=req.refit, stamp=req.stamp)
        self.timings.append({"stamp": req.stamp, "preview": preview, "queued": clock[0] - req.stamp,
                             "build": t_build, "simulate": t_run, "core_wall": run.result.wall_time_s,
                             "prepare": t_view, "draw": lap(), "total": time.perf_counter() - req.stamp})
        if self.ens_on.value and not self.worker.pending():
            self._run_ensemble(scene, preview)
        return preview

    def _write_back(self, req: Request, notes: list[str]) -> None:
        """Put clamped values back into their sliders."""
        if not notes:
            return
        for p in req.controls.params:
            value, note = p.clamp(req.values.get(p.ident, p.value))
            handle = self._param_handles.get(p.ident)
            if note and handle is not None:
                handle.value = value

    def _run_ensemble(self, scene: Scene, preview: bool) -> None:
        kind = self.ens_kind.value
        try:
            if kind not in ens.kinds_for(scene):
                raise SceneError(f"'{kind}' needs a 2D or 3D scene")
            scenes = ens.ensemble_scenes(scene, kind, float(self.ens_spread.value), int(self.ens_members.value))
            if preview:
                scenes = [replace(s, integrator=PREVIEW[0], dt=AUTO, tol=PREVIEW[1]) for s in scenes]
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
        self._show_error(f"internal error: {_one_line(exc)}")

    # ==========================================================================================
    # Drawing

    def _show_view(self, view: ViewRun, *, refit: bool = False, stamp: float | None = None) -> None:
        with self._lock:
            first = self.view is None
            self.view = view
            self.error = None
            self.t = view.clamp_time(self.t if not refit else view.t0 + _first_contact_fraction(view))
            with self.client.atomic():
                self.drawer.show_run(view)
                self.plots.show_run(view, self.t)
                step = _slider_step(view.duration * 1e3)
                self.time_slider.max = max(math.ceil(view.t1 * 1e3 / step) * step, step)
                self.time_slider.min = view.t0 * 1e3
                self.time_slider.step = step
                self.time_slider.precision = max(0, -math.floor(math.log10(step)))
                self._draw_frame(cursor=False)
                self._show_status()
                self.legend.content = self.drawer.legend()
            self.client.flush()
            self.runs_drawn += 1
            if stamp:
                self.last_latency = time.perf_counter() - stamp
        if refit or first:
            self.fit_camera()

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
        aspect), until the user moves the camera."""
        self._camera_ready.set()
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

    def _draw_frame(self, cursor: bool) -> None:
        view = self.view
        if view is None:
            return
        self.drawer.show_frame(view.frame(self.t))
        shown = round(self.t * 1e3, int(self.time_slider.precision))
        self._sent_times.append(shown)
        self.time_slider.value = shown
        now = time.monotonic()
        if cursor or now - self._cursor_time > CURSOR_PERIOD:
            self.plots.show_cursor(self.t)
            self._cursor_time = now

    def _show_status(self) -> None:
        view = self.view
        lines = []
        if view is not None:
            tag = " *(preview: coarse step while you drag)*" if view.preview else ""
            lines.append(f"**{view.scene.name}** · {view.dim}D · {view.origin}{tag}")
            lines += view.status_lines()
        if self.notes:
            lines += [f"*{n}*" for n in self.notes]
        if self.error:
            lines.append(f"<span style='color:#c5221f'>**Not run:** {self.error}</span>")
            if view is not None:
                lines.append("*(showing the last good run)*")
        self.status.content = "  \n".join(lines)

    def _show_error(self, message: str) -> None:
        with self._lock:
            self.error = message
            self._show_status()

    def _file_message(self, message: str, error: bool = False) -> None:
        self.file_message.content = (f"<span style='color:#c5221f'>{message}</span>" if error else message)

    # ==========================================================================================
    # Playback (player thread)

    def _speed(self, view: ViewRun) -> float:
        choice = self.speed.value
        if choice == "auto":
            contact = sum(b - a for a, b in view.contact_windows)
            slow = (1 / SLOW_MOTION - 1) * contact if self.slowmo.value else 0.0
            return max(view.duration + slow, 1e-9) / PLAYBACK_SECONDS
        return float(choice.rstrip("x"))

    def _play_loop(self) -> None:
        period = 1.0 / FPS
        last = time.perf_counter()
        while not self._closed.wait(period):
            now = time.perf_counter()
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
            except Exception as exc:  # noqa: BLE001 - a closed tab must not kill the thread noisily
                if self._closed.is_set():
                    return
                traceback.print_exc()
                self._show_error(f"playback: {_one_line(exc)}")
                self.toggle_play(False)

    def close(self) -> None:
        """Stop this tab's threads (the tab closed)."""
        self._closed.set()
        self.playing = False
        self.worker.close(timeout=2.0)
        self._player.join(timeout=2.0)


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
