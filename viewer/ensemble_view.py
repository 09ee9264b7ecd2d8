"""The Ensemble folder: a small batch around the current parameters (`viewer.ensemble`), drawn
as ghost paths after each live run while "show ensemble" is ticked."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import viser

from collide.scene import Scene, SceneError
from collide.stepper import RunError
from viewer import ensemble as ens
from viewer.live import Preview
from viewer.messages import one_line
from viewer.panel import Panel
from viewer.scene3d import SceneDrawer


class EnsembleView:
    """The ensemble's controls and its ghost paths; `changed` asks for a new run."""

    def __init__(self, panel: Panel, drawer: SceneDrawer, lock: threading.RLock, changed: Callable[[], None]) -> None:
        self._panel = panel
        self._drawer = drawer
        self._lock = lock
        self._changed = changed
        self.paths: list[np.ndarray] | None = None
        for handle in (panel.ens_on, panel.ens_spread, panel.ens_members):
            handle.on_update(self._on_change)
        panel.ens_kind.on_update(self._on_kind)

    @property
    def wanted(self) -> bool:
        return bool(self._panel.ens_on.value)

    def clear(self) -> None:
        """No ghosts (a new scene)."""
        self.paths = None
        self._drawer.show_ghosts(None)

    def run(self, scene: Scene, preview: Preview | None) -> None:
        """Run the ensemble around `scene` (with the preview's settings, if it was one) and draw
        its paths; say why not if it cannot run."""
        panel = self._panel
        kind = panel.ens_kind.value
        try:
            if kind not in ens.kinds_for(scene):
                raise SceneError(f"'{kind}' needs a 2D or 3D scene")
            scenes = ens.ensemble_scenes(scene, kind, float(panel.ens_spread.value), int(panel.ens_members.value))
            if preview is not None:
                scenes = [replace(s, integrator=preview.integrator, dt=preview.dt, tol=preview.tol) for s in scenes]
            paths, wall = ens.ensemble_paths(scenes)
        except (SceneError, RunError) as exc:
            panel.ens_message.content = f"**Ensemble not run:** {one_line(exc)}"
            return
        with self._lock:
            self.paths = paths
            self._drawer.show_ghosts(paths)
            panel.ens_message.content = (f"{len(scenes)} runs ({ens.KINDS[kind].label}, "
                                         f"+-{panel.ens_spread.value:g} {ens.KINDS[kind].unit}) in {wall * 1e3:.0f} ms")

    def _on_change(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        if not self.wanted:
            with self._lock:
                self.clear()
                self._panel.ens_message.content = ""
            return
        self._changed()

    def _on_kind(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        spread = self._panel.ens_spread
        kind = ens.KINDS[self._panel.ens_kind.value]
        spread.min, spread.max, spread.step = kind.lo, kind.hi, kind.step
        spread.label = f"spread (+-, {kind.unit})"
        spread.value = kind.default
        if self.wanted:
            self._changed()
