"""A tab's fixed controls, built once: the right-hand panel (messages, Timeline, Show, Scene, the
Parameters folder's frame, Files and export, Ensemble) and the Plots / Values panel below it.
The session attaches the callbacks; the Parameters folder's content is `viewer.param_controls`.

viser's slider carries a number box that drops an "e" as it is typed (issue 12, item 2): it is
hidden, and a text box above each slider reads typed values exactly.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import viser

from collide.scene import INTEGRATORS
from viewer import ensemble as ens
from viewer import files
from viewer.config import SessionConfig
from viewer.params import AUTO, Controls, Settings, check_settings, dt_choice, parse_dt_choice
from viewer.plots import Plots
from viewer.scene3d import BODY_DRAWINGS, COLOUR_MODES, POINT_BODIES, DrawOptions

SPEEDS = ["auto", "0.001x", "0.003x", "0.01x", "0.03x", "0.1x", "0.3x", "1x"]
TYPING_SETTLE = 0.5  # s without a keystroke before a typed value is read
STYLE = ("<style>.mantine-Slider-root + .mantine-NumberInput-root{display:none !important}"
         ".collide-notice{font-size:0.9em}</style>")
CHOOSE = "(choose)"


class Typing:
    """Runs an action once the user has stopped typing in a box for TYPING_SETTLE s."""

    def __init__(self) -> None:
        self._timers: dict[str, threading.Timer] = {}

    def after(self, key: str, action: Callable[[], Any]) -> None:
        timer = self._timers.pop(key, None)
        if timer is not None:
            timer.cancel()
        timer = threading.Timer(TYPING_SETTLE, action)
        timer.daemon = True
        self._timers[key] = timer
        timer.start()

    def cancel(self) -> None:
        for timer in list(self._timers.values()):
            timer.cancel()


class Panel:
    """The handles of a tab's fixed controls."""

    def __init__(self, gui: viser.GuiApi, config: SessionConfig, options: DrawOptions) -> None:
        self._recordings_dir = config.recordings_dir
        self._point_bodies = POINT_BODIES if config.point_bodies is None else config.point_bodies
        gui.main_panel.dock_right()
        gui.main_panel.set_width(340)
        gui.add_html(STYLE, order=-1)
        self.status = gui.add_markdown("Loading...", order=0)
        self.progress = gui.add_markdown("", order=0.3)
        self.stop_button = gui.add_button("Stop this run", icon=viser.Icon.PLAYER_STOP, order=0.4, visible=False,
                                          hint="stop the run going in the background; the last run stays shown")
        self.notice = gui.add_markdown("", order=0.5)
        with gui.add_folder("Timeline", order=1):
            self._timeline(gui)
        with gui.add_folder("Show", order=2):
            self._show(gui, options)
        with gui.add_folder("Scene", order=3):
            self._scene(gui, config)
        self.param_parent = gui.add_folder("Parameters", order=4)
        with gui.add_folder("Files and export", order=5, expand_by_default=True):
            self._files(gui, config)
        with gui.add_folder("Ensemble", order=6, expand_by_default=False):
            self._ensemble(gui)
        self._plot_panel(gui)

    def _timeline(self, gui: viser.GuiApi) -> None:
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

    def _show(self, gui: viser.GuiApi, opts: DrawOptions) -> None:
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
        self.draw_as = gui.add_dropdown("draw bodies as", list(BODY_DRAWINGS), initial_value=opts.bodies,
                                        visible=False, hint=f"auto: spheres up to {self._point_bodies:,} bodies, "
                                                            "points (one per body, sized by the radius) above")
        self.legend = gui.add_markdown("")
        self.colour_legend = gui.add_html("")

    def show_handles(self) -> dict[str, Any]:
        """The Show folder's controls by `DrawOptions` field."""
        return {"forces": self.show_forces, "velocity": self.show_velocity, "momentum": self.show_momentum,
                "com": self.show_com, "trails": self.show_trails, "colour_by": self.colour_by,
                "chains": self.show_chains, "shadows": self.show_shadows, "bodies": self.draw_as}

    def _scene(self, gui: viser.GuiApi, config: SessionConfig) -> None:
        self.picker = gui.add_dropdown("scene", [c.label for c in config.scene_choices],
                                       initial_value=config.scene_choices[0].label)
        self.balls = gui.add_button_group("balls", ["fewer balls", "more balls"], visible=False,
                                          hint="take away the last ball, or add one like it (2D scenes)")
        self.integrator = gui.add_dropdown("integrator", list(INTEGRATORS), initial_value="verlet")
        self.dt = gui.add_dropdown("dt", [AUTO], initial_value=AUTO)
        self.tol = gui.add_dropdown("tol (auto dt)", ["1e-06"], initial_value="1e-06")
        self.reset_button = gui.add_button("Reset parameters", icon=viser.Icon.REFRESH)
        self.fit_buttons = gui.add_button_group("fit view", ["whole run", "contact"],
                                                hint="point the camera at the whole run or at the contact")

    def _files(self, gui: viser.GuiApi, config: SessionConfig) -> None:
        self.recording = gui.add_dropdown("open .rrd", self.recording_options(), initial_value=CHOOSE)
        self.refresh_button = gui.add_button("Refresh list", icon=viser.Icon.REFRESH)
        self.upload = gui.add_upload_button("Upload .rrd", icon=viser.Icon.UPLOAD, mime_type=".rrd",
                                            hint=f"at most {config.max_upload_bytes // 2**20} MB")
        self.save_button = gui.add_button("Save this run (.rrd)", icon=viser.Icon.DEVICE_FLOPPY)
        self.export_buttons = gui.add_button_group(
            "download", ["CSV", "PNG", "VTK", "CSV long", "MP4", "TOML"],
            hint="CSV: the run in the columns of `collide run --csv`; PNG: the 3D view as it is now; "
            "VTK, CSV long, MP4, TOML: as `collide export` writes them (docs/export.md; VTK and CSV long as a zip)")
        self.file_message = gui.add_markdown("")

    def _ensemble(self, gui: viser.GuiApi) -> None:
        self.ens_on = gui.add_checkbox("show ensemble", initial_value=False,
                                       hint="run a small batch around the current parameters (run_scenes)")
        self.ens_kind = gui.add_dropdown("vary", list(ens.KINDS), initial_value="k")
        kind = ens.KINDS["k"]
        self.ens_spread = gui.add_slider("spread (+-, %)", min=kind.lo, max=kind.hi, step=kind.step,
                                         initial_value=kind.default)
        self.ens_members = gui.add_slider("members", min=3, max=15, step=1, initial_value=7)
        self.ens_message = gui.add_markdown("")

    def _plot_panel(self, gui: viser.GuiApi) -> None:
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

    # ------------------------------------------------------------------------------------------

    def recording_options(self) -> list[str]:
        return [CHOOSE] + files.list_recordings(self._recordings_dir)

    def refresh_recordings(self, select: str | None = None) -> None:
        options = self.recording_options()
        if select is not None and select not in options:
            options.append(select)
        self.recording.options = options
        self.recording.value = select if select is not None else CHOOSE

    def pick(self, label: str) -> None:
        """Show `label` as the scene picker's choice, adding it if the picker lacks it."""
        if label not in self.picker.options:
            self.picker.options = list(self.picker.options) + [label]
        self.picker.value = label

    def show_settings(self, controls: Controls) -> None:
        """The Scene folder's run settings and ball buttons for a scene's controls."""
        s = controls.settings
        self.integrator.value = s.integrator
        self.dt.options = controls.dt_choices
        self.dt.value = dt_choice(s.dt)
        self.tol.options = controls.tol_choices
        self.tol.value = f"{s.tol:.0e}"
        self.tol.visible = s.dt == AUTO
        self.balls.visible = controls.scene.dim == 2

    def settings(self) -> Settings:
        """The run settings chosen (raises SceneError or ValueError on a forged choice)."""
        return check_settings(self.integrator.value, parse_dt_choice(self.dt.value), float(self.tol.value))
