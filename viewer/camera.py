"""A tab's camera: fitted to the run (or its contact) once the browser has reported it, fitted
again while the canvas settles, and followed by the 3D overlays (`SceneDrawer.eye`)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from viewer.geometry import fit_camera
from viewer.scene3d import SceneDrawer
from viewer.state import ViewRun


def camera_known(client: Any) -> bool:
    """True once the browser has reported its camera (never for a stand-in client)."""
    try:
        client.camera.wxyz  # noqa: B018 - asserts that the camera state has arrived
    except (AssertionError, AttributeError):
        return False
    return True


class CameraFit:
    """Points one client's camera at the run shown (`view()`); `moved()` is called when the
    camera has moved enough for the overlays to be drawn again."""

    def __init__(self, client: viser.ClientHandle, drawer: SceneDrawer, view: Callable[[], ViewRun | None],
                 moved: Callable[[], None]) -> None:
        self._client = client
        self._drawer = drawer
        self._view = view
        self._moved = moved
        self._ready = threading.Event()
        self._auto_fit: tuple[float, np.ndarray, float, float] | None = None
        self._target = "whole run"
        client.camera.on_update(self._on_camera)
        if camera_known(client):
            # viser reports a tab once its first camera message has arrived: the first fit
            # need not wait for another (a set-up thread would wait 5 s for a quiet tab).
            self._ready.set()

    def fit(self, target: str = "whole run") -> None:
        """Point the camera at the run's paths or at its contact (waits for the browser's
        camera)."""
        view = self._view()
        if view is None or not self._ready.wait(5.0):
            return
        self._target = target
        lo, hi = view.contact_bounds() if target == "contact" else view.bounds()
        cam = self._client.camera
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
        self._ready.set()
        try:
            eye = np.array(cam.position, dtype=float)
        except (AssertionError, TypeError, ValueError):
            eye = None
        if eye is not None:
            old = self._drawer.eye
            self._drawer.eye = eye
            if old is None or float(np.linalg.norm(eye - old)) > 1e-4 * (float(np.linalg.norm(eye)) + 1e-12):
                self._moved()
        fit = self._auto_fit
        if fit is None or self._view() is None:
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
            self.fit(self._target)
