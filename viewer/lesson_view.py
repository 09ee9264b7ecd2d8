"""The lesson's controls and pictures in a tab: the Lesson folder (motion on a line or in a plane,
perfectly inelastic, the values as CSV) and the Momentum & energy tab beside Plots and Values
(the momentum diagram before and now, the energy bars now: `viewer.lesson`).
"""

from __future__ import annotations

import copy
from typing import Any

import viser

from collide.scene import Scene, SceneError, parse_scene
from viewer import files
from viewer.lesson import energy_svg, lesson_csv, moment, momentum_svg, with_dimensions, with_restitution
from viewer.messages import one_line
from viewer.params import build_scene
from viewer.state import ViewRun

MOTION = {"line (1D)": 1, "plane (2D)": 2}
STICKY = "perfectly inelastic (e = 0)"


class LessonView:
    """The Lesson folder and the Momentum & energy tab of one tab."""

    def __init__(self, session: Any) -> None:
        # `session`: the tab's viewer.session.Session (its parts: params, panel, player, messages)
        self._session = session
        gui = session.client.gui
        with gui.add_folder("Lesson", order=3.6):
            self.motion = gui.add_dropdown("motion", list(MOTION), initial_value="plane (2D)",
                                           hint="the same scene with its motion on a line (x) or in a plane (xy)")
            self.sticky = gui.add_checkbox(STICKY, initial_value=False,
                                           hint="restitution 0: a critically damped contact; a head-on pair ends "
                                                "moving together at (m1 v1 + m2 v2) / (m1 + m2)")
            self.export_button = gui.add_button("Download momentum and energy (CSV)", icon=viser.Icon.DOWNLOAD)
            self.message = gui.add_markdown("")
        with session.panel.plot_panel.add_tab("Momentum & energy", viser.Icon.SCALE):
            self.momentum_html = gui.add_html("")
            self.energy_html = gui.add_html("")
        self.motion.on_update(self._on_motion)
        self.sticky.on_update(self._on_sticky)
        self.export_button.on_click(lambda _e: self.export_csv())
        self._before: tuple[Any, Any] = (None, None)  # (view, its start's Moment)
        self._settings: tuple[str, Any, float, Any] | None = None  # run settings, duration before e = 0

    # -- drawing (under the session's lock) ------------------------------------------------------

    def show(self, view: Any) -> None:
        """A run is drawn: the switches follow its scene."""
        if not isinstance(view, ViewRun):
            self.momentum_html.content = self.energy_html.content = ""
            return
        scene = view.scene
        label = next((k for k, d in MOTION.items() if d == scene.dim), None)
        self.motion.visible = label is not None
        if label is not None and self.motion.value != label:
            self.motion.value = label
        sticky = _restitutions(scene) == {0.0}
        if self.sticky.value != sticky:
            self.sticky.value = sticky

    def at_time(self, view: Any, t: float) -> None:
        """The pictures at time t (the player calls this where it shows the values table)."""
        if not isinstance(view, ViewRun):
            return
        if self._before[0] is not view:
            self._before = (view, moment(view, view.t0))
        now = moment(view, t)
        self.momentum_html.content = momentum_svg(view, self._before[1], now)
        self.energy_html.content = energy_svg(view, now)

    # -- the switches (viser's thread pool) --------------------------------------------------------

    def _current(self) -> Scene | None:
        """The scene with the parameters' values, as the user set it up (no viewing tail)."""
        session = self._session
        with session._lock:
            controls = session.params.controls
            if controls is None:
                return None
            scene = build_scene(controls, dict(session.params.values), session.panel.settings())
        if "tail" not in controls.scene.source and "tail" in scene.source:
            raw = copy.deepcopy(scene.source)
            raw.pop("tail")
            scene = parse_scene(raw, scene.name)
        return scene

    def _on_motion(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.set_motion(MOTION[self.motion.value])

    def _on_sticky(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        self.set_sticky(bool(self.sticky.value))

    def set_motion(self, dim: int) -> bool:
        """Re-build the scene shown with its motion on a line (1) or in a plane (2) and run it."""
        return self._switch(lambda scene: scene if scene.dim == dim else with_dimensions(scene, dim),
                            f"motion in {dim}D")

    def set_sticky(self, on: bool) -> bool:
        """Every restitution 0 (perfectly inelastic) or back to 1 (elastic, the run settings as
        before), and run."""
        def change(scene: Scene) -> Scene:
            if on:
                self._settings = (scene.integrator, scene.dt, scene.tol, scene.source.get("duration"))
                return with_restitution(scene, 0.0)
            raw = copy.deepcopy(with_restitution(scene, 1.0).source)
            if self._settings is not None:
                integrator, dt, tol, duration = self._settings
                if integrator != "dem":
                    raw["integrator"], raw["dt"], raw["tol"] = integrator, dt, tol
                if duration is None:
                    raw.pop("duration", None)  # the one e = 0 needed
            return parse_scene(raw, scene.name)

        return self._switch(change, STICKY if on else "elastic")

    def _switch(self, change: Any, what: str) -> bool:
        session = self._session
        try:
            scene = self._current()
            if scene is None:
                return False
            scene = change(scene)
        except (SceneError, ValueError) as exc:
            session.messages.show_notice(f"{what}: not made: {one_line(exc)}", error=True)
            with session._lock:
                self.show(session.player.view)  # the switches back as the scene shown
            return False
        session.messages.clear_notice()
        session.load_scene(scene, keep_settings=True)
        return True

    # -- the values export --------------------------------------------------------------------------

    def export_csv(self) -> str | None:
        """Send the diagram's and the bars' numbers (before, now, after) as a CSV download."""
        session = self._session
        view, t = session._shown()
        if not isinstance(view, ViewRun):
            self.message.content = "No run to export."
            return None
        content = lesson_csv(view, t)
        name = f"{files.safe_stem(view.scene.name)}-momentum-energy.csv"
        session.client.send_file_download(name, content, save_immediately=True)
        session.downloads.append((name, len(content)))
        self.message.content = f"Downloaded **{name}** (at {t * 1e3:.4g} ms)."
        return name


def _restitutions(scene: Scene) -> set[float]:
    values = {float(scene.contact.restitution)}
    values |= {float(m.restitution) for m in scene.materials if m.restitution is not None}
    values |= {float(p.restitution) for p in scene.pairs if p.restitution is not None}
    return values
