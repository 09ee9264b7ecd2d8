"""Drag to set up (PhET's Collision Lab): a handle on each ball moves its start position and a
handle on the tip of its start velocity arrow aims it. A drag sets the same parameters as the
sliders (`body.NAME.position`, `body.NAME.velocity`) and re-runs as a slider does.

The handles are viser transform controls (gizmos) at the start of the run, shown when the time
shown is the start ("Set up (go to t = 0)" goes there; a drag keeps them). They move along x only
in 1D, in the xy plane in 2D, and in the plane chosen in the folder in 3D. "snap to grid" rounds
positions to 1 mm (1 cm in scenes drawn in metres) and velocities to 0.01 m/s. A position where
the ball would overlap another (or anything else the scene cannot start from) is refused at once
with the reason, and the ball goes back to where it was.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import viser

from collide.scene import SceneError
from viewer.messages import one_line
from viewer.params import Controls, build_scene, format_value
from viewer.state import ViewRun

PLANES = {"xy": (True, True, False), "xz": (True, False, True), "yz": (False, True, True)}
VELOCITY_SNAP = 0.01  # m/s
ROOT = "/setup"
MAX_DRAG_BODIES = 12  # beyond this many (a pile, a gas) no handles: the Parameters folder sets them


def snapped(x: np.ndarray, step: float) -> np.ndarray:
    """x rounded to the grid step (and -0.0 made 0.0)."""
    return np.round(np.asarray(x, float) / step) * step + 0.0


def position_snap(controls: Controls) -> float:
    """The position grid: 1 mm in table-top scenes (drawn in mm), 1 cm in larger ones."""
    scale = next((p.scale for p in controls.params if p.key.endswith(".position")), 1.0)
    return 1e-3 if scale >= 1e3 else 1e-2


class _Ball:
    """One ball's handles: the position gizmo, the velocity tip gizmo (its child) and the arrow."""

    def __init__(self, name: str, ball: Any, tip: Any, arrow: Any) -> None:
        self.name = name
        self.ball = ball
        self.tip = tip
        self.arrow = arrow
        self.good_position = np.zeros(3)  # the last position accepted (m)
        self.good_tip = np.zeros(3)


class DragSetup:
    """The handles and the Drag to set up folder of one tab."""

    def __init__(self, session: Any) -> None:
        # `session`: the tab's viewer.session.Session (its parts: params, panel, player, messages)
        self._session = session
        gui = session.client.gui
        with gui.add_folder("Drag to set up", order=3.5):
            self.enabled = gui.add_checkbox("drag handles", initial_value=True,
                                            hint="a handle on each ball (its start position) and on the tip of "
                                                 "its start velocity arrow; grabbing one shows t = 0")
            self.plane = gui.add_dropdown("drag plane", list(PLANES), initial_value="xy", visible=False,
                                          hint="3D scenes: the plane the handles move in")
            self.snap = gui.add_checkbox("snap to grid", initial_value=False,
                                         hint="positions to 1 mm (1 cm in scenes in metres), velocities to "
                                              "0.01 m/s")
            self.start_button = gui.add_button("Set up (go to t = 0)", icon=viser.Icon.PLAYER_SKIP_BACK,
                                               hint="the handles show at the start of the run")
        self.start_button.on_click(lambda _e: self._start())
        self.enabled.on_update(self._on_option)
        self.plane.on_update(self._on_option)
        self._balls: dict[str, _Ball] = {}
        self._made_for: tuple[Controls | None, str] = (None, "")
        self._arrow_scale = 1.0  # s: the start velocity arrow's length per m/s (fixed per scene)
        self._dragging: str | None = None
        self._visible: bool | None = None  # the handles show at the run's start only (where the balls are)
        self._drag_lock = threading.Lock()  # one drag change applied at a time

    # -- the handles ------------------------------------------------------------------------------

    def show(self, view: Any) -> None:
        """Place the handles for the scene shown (called under the session's lock after a run is
        drawn): made anew for new controls or another plane, moved to the values otherwise."""
        controls = self._session.params.controls
        if (controls is None or not self.enabled.value or not isinstance(view, ViewRun)
                or len(controls.scene.bodies) > MAX_DRAG_BODIES):
            self._clear()
            return
        dim = controls.scene.dim
        self.plane.visible = dim == 3
        plane = self.plane.value if dim == 3 else ("x" if dim == 1 else "xy")
        if self._made_for != (controls, plane):
            self._build(controls, plane)
        for ball in self._balls.values():
            if ball.name != self._dragging:
                self._place(ball)
        self._visible = None  # new or moved handles: their visibility is sent again
        self.at_time(view, self._session.player.t)

    def at_time(self, view: Any, t: float) -> None:
        """Show the handles when the time shown is the run's start (or a drag is going on)."""
        if not isinstance(view, ViewRun):
            return
        visible = self._dragging is not None or t <= view.t0 + 1e-9 * max(view.duration, 1e-300)
        if visible != self._visible:
            for ball in self._balls.values():
                ball.ball.visible = visible
            self._visible = visible

    def _axes(self, plane: str) -> tuple[bool, bool, bool]:
        return (True, False, False) if plane == "x" else PLANES[plane]

    def _build(self, controls: Controls, plane: str) -> None:
        self._clear()
        scene = self._session.client.scene
        bodies = controls.scene.bodies
        r_max = max(b.radius for b in bodies)
        speeds = [float(np.linalg.norm(self._vector(b.name, "velocity"))) for b in bodies]
        self._arrow_scale = 5.0 * r_max / max(max(speeds), 0.1)
        axes = self._axes(plane)
        for b in bodies:
            name = b.name
            ball = scene.add_transform_controls(f"{ROOT}/{name}", scale=1.4 * b.radius, active_axes=axes,
                                                disable_rotations=True, disable_sliders=plane == "x",
                                                depth_test=False, line_width=3.0)
            tip = scene.add_transform_controls(f"{ROOT}/{name}/tip", scale=1.2 * b.radius, active_axes=axes,
                                               disable_rotations=True, disable_sliders=plane == "x",
                                               depth_test=False, line_width=2.0, opacity=0.8)
            arrow = scene.add_line_segments(f"{ROOT}/{name}/arrow", np.zeros((1, 2, 3)), colors=(230, 120, 0),
                                            thickness=3.0, thickness_units="screen")
            item = _Ball(name, ball, tip, arrow)
            ball.on_update(lambda e, item=item: self._on_drag(e, item, self.move_ball))
            tip.on_update(lambda e, item=item: self._on_drag(e, item, self.aim_ball))
            self._balls[name] = item
        self._made_for = (controls, plane)

    def _clear(self) -> None:
        for ball in self._balls.values():
            ball.ball.remove()  # its children (the tip, the arrow) go with it
        self._balls = {}
        self._made_for = (None, "")
        self._visible = None

    def _vector(self, name: str, what: str) -> np.ndarray:
        """A ball's start position or velocity (SI, 3D) from the parameters' values."""
        params = self._session.params
        out = np.zeros(3)
        by = params.controls.by_ident() if params.controls is not None else {}
        for c, a in enumerate("xyz"):
            p = by.get(f"body.{name}.{what}.{a}")
            if p is not None:
                out[c] = params.values.get(p.ident, p.value) / p.scale
        return out

    def _place(self, ball: _Ball) -> None:
        position = self._vector(ball.name, "position")
        tip = self._vector(ball.name, "velocity") * self._arrow_scale
        ball.ball.position = position
        ball.tip.position = tip
        ball.arrow.points = np.array([[[0.0, 0.0, 0.0], tip]])
        ball.good_position, ball.good_tip = position, tip

    # -- drags (viser's thread pool) --------------------------------------------------------------

    def _on_option(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        with self._session._lock:
            self.show(self._session.player.view)

    def _start(self) -> None:
        session = self._session
        view = session.player.view
        session.toggle_play(False)
        if view is not None and session.player.t != view.t0:
            session.seek(view.t0)

    def _on_drag(self, event: Any, ball: _Ball, apply: Any) -> None:
        """A handle's drag: its start pauses at t0; each move after it is `apply` (move_ball for
        the ball, aim_ball for its velocity tip)."""
        if event.phase == "start":
            self._dragging = ball.name
            self._start()
            return
        apply(ball.name, np.asarray(event.target.position, float), end=event.phase == "end")

    def move_ball(self, name: str, position: np.ndarray, *, end: bool = True) -> bool:
        """Set a ball's start position (m, 3D) as the drag left it: snapped if asked, refused at
        once (the ball back where it was) if the scene cannot start there. What the handle's
        drag calls; tests call it too."""
        ball = self._balls.get(name)
        if ball is None:
            return False
        controls = self._session.params.controls
        step = position_snap(controls) if self.snap.value and controls is not None else 0.0
        target = self._in_plane(position, ball.good_position)
        target = snapped(target, step) if step else target
        ok = self._apply(name, "position", target)
        if end:
            self._dragging = None
            ball.ball.position = target if ok else ball.good_position
        if ok:
            ball.good_position = target
        return ok

    def aim_ball(self, name: str, tip: np.ndarray, *, end: bool = True) -> bool:
        """Set a ball's start velocity from its arrow's tip (m from the ball's centre, 3D)."""
        ball = self._balls.get(name)
        if ball is None:
            return False
        velocity = self._in_plane(tip, ball.good_tip) / self._arrow_scale
        if self.snap.value:
            velocity = snapped(velocity, VELOCITY_SNAP)
        target = velocity * self._arrow_scale
        ok = self._apply(name, "velocity", velocity)
        ball.arrow.points = np.array([[[0.0, 0.0, 0.0], target if ok else ball.good_tip]])
        if end:
            self._dragging = None
            ball.tip.position = target if ok else ball.good_tip
        if ok:
            ball.good_tip = target
        return ok

    def _in_plane(self, moved: np.ndarray, before: np.ndarray) -> np.ndarray:
        """`moved` with the components off the drag plane kept as `before` (the handle's axes
        allow no other motion; a call from elsewhere gets the same rule)."""
        axes = np.array(self._axes(self._made_for[1]) if self._made_for[1] else (True, True, True))
        return np.where(axes, np.asarray(moved, float), before)

    def _apply(self, name: str, what: str, vector: np.ndarray) -> bool:
        """The parameters with a ball's position or velocity (SI) set, if the scene takes them;
        then a run, as a slider's move starts one."""
        session = self._session
        with self._drag_lock:
            with session._lock:
                params = session.params
                controls = params.controls
                if controls is None:
                    return False
                by = controls.by_ident()
                updates = {}
                for c, a in enumerate("xyz"):
                    p = by.get(f"body.{name}.{what}.{a}")
                    if p is not None:
                        updates[p.ident] = float(vector[c]) * p.scale
                values = {**params.values, **updates}
                try:
                    build_scene(controls, values, session.panel.settings())
                except (SceneError, ValueError) as exc:
                    session.messages.show_notice(f"{name} not moved there: {one_line(exc)}", error=True)
                    return False
                self._set_params(updates)
            session.messages.clear_notice()
            session.request_run()
            return True

    def _set_params(self, updates: dict[str, float]) -> None:
        """The values into the Parameters folder: its text boxes and sliders (a slider's range
        widened to take a value beyond it, as a typed value does)."""
        params = self._session.params
        controls = params.controls
        for ident, x in updates.items():
            param = controls.by_ident()[ident]
            params.values[ident] = x
            slider, box = params.sliders.get(ident), params.boxes.get(ident)
            wider = param.widened(x)
            if wider is not param:
                controls.replace_param(wider)
                if slider is not None:
                    slider.min, slider.max, slider.step = wider.lo, wider.hi, wider.step
            if slider is not None:
                slider.value = x
            if box is not None:
                box.value = format_value(x)
