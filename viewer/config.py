"""What a tab's session needs from the viewer app, made by the app and handed to each `Session`
(so the session never imports the app)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from viewer.files import SceneChoice


@dataclass(frozen=True)
class SessionConfig:
    """The app's settings and first run, as a tab sees them."""

    recordings_dir: Path  # recordings listed, saved and uploaded here
    max_upload_bytes: int
    scene_choices: tuple[SceneChoice, ...]  # the scene picker's entries
    initial_cost: float | None  # s: wall time of the first scene's run (chooses previews)
    point_bodies: int | None = None  # bodies above which "auto" draws points (None: scene3d.POINT_BODIES)
