"""A video of the run for a lecture: matplotlib draws each frame (spheres, walls, the time), and
ffmpeg encodes them as H.264 in an MP4 that browsers and players play.

ffmpeg comes from the `imageio-ffmpeg` wheel (a dependency), which carries a
static binary for the platform, or else from an `ffmpeg` on PATH. Frames are shown in order, one
per video frame: the recording's frames are denser across contacts, so contacts play in slow
motion; the label gives the simulated time. 2D spheres carry a line that turns with their spin.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np

from collide.export.frames import Frames

VIDEO_FPS = 30  # video frames per second of playback
WIDTH, HEIGHT, DPI = 960, 720, 120


class VideoError(ValueError):
    """No ffmpeg to encode with, or ffmpeg failed: one line saying which."""


def ffmpeg_path() -> str:
    """The ffmpeg binary: imageio-ffmpeg's, else one on PATH; else `VideoError` saying how to get one."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        found = shutil.which("ffmpeg")
        if found:
            return found
    raise VideoError("an MP4 needs ffmpeg: pip install imageio-ffmpeg (a dependency of collide, which carries it), "
                     "or put an ffmpeg on PATH")


def _extent(frames: Frames) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (3,), (3,) of every sphere over the run, with a margin."""
    r = frames.radius.max() if len(frames.radius) else 0.0
    lo = frames.s.min(axis=(0, 1)) - r
    hi = frames.s.max(axis=(0, 1)) + r
    span = max(float((hi - lo).max()), 1e-9)
    centre = 0.5 * (lo + hi)
    return centre - 0.55 * span, centre + 0.55 * span


def _wall_outline(point: np.ndarray, normal: np.ndarray, centre: np.ndarray, half: float, dim: int) -> np.ndarray:
    """A wall as a segment (1D, 2D) or a square (3D) across the region the spheres sweep."""
    foot = centre - np.dot(centre - point, normal) * normal
    if dim < 3:
        t = np.array([-normal[1], normal[0], 0.0])
        return np.stack((foot - half * t, foot + half * t))
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    return np.stack([foot + half * (i * a + j * b) for i, j in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


class _Painter:
    """One matplotlib figure, its artists updated frame by frame (drawing anew is slower)."""

    def __init__(self, frames: Frames, title: str) -> None:
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # no pyplot: no global backend
        from matplotlib.figure import Figure

        self.frames = frames
        self.fig = Figure(figsize=(WIDTH / DPI, HEIGHT / DPI), dpi=DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        lo, hi = _extent(frames)
        self.three = frames.dim == 3
        colours = matplotlib.colormaps["tab10" if len(frames.names) <= 10 else "viridis"]
        n = len(frames.names)
        self.colours = colours(np.arange(n) % 10) if n <= 10 else colours(np.linspace(0, 1, max(n, 1)))
        centre, half = 0.5 * (lo + hi), 0.5 * float((hi - lo).max())
        if self.three:
            self.ax = self.fig.add_subplot(projection="3d")
            self.ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]), xlabel="x (m)",
                        ylabel="y (m)", zlabel="z (m)")
            self.ax.set_box_aspect((1, 1, 1))
            self._walls_3d(centre, half)
            # Marker area in points^2: a sphere's radius over the box's width, at the axes' size.
            points_per_m = 0.5 * WIDTH / DPI * 72 / (hi[0] - lo[0])
            size = (frames.radius * points_per_m) ** 2 * np.pi
            self.bodies = self.ax.scatter(*frames.s[0].T, s=size, c=self.colours, depthshade=True)
        else:
            from matplotlib.patches import Circle

            self.ax = self.fig.add_subplot()
            self.ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), xlabel="x (m)", ylabel="y (m)")
            self.ax.set_aspect("equal")
            for p, nrm in zip(frames.wall_point, frames.wall_normal):
                seg = _wall_outline(p, nrm, centre, half, frames.dim)
                self.ax.plot(seg[:, 0], seg[:, 1], color="0.3", lw=2)
            self.circles = [self.ax.add_patch(Circle(frames.s[0, b, :2], frames.radius[b], color=self.colours[b]))
                            for b in range(n)]
            self.markers = None
            if frames.angle is not None:  # centre-to-rim lines that turn with each sphere's spin
                from matplotlib.collections import LineCollection

                self.markers = self.ax.add_collection(LineCollection(self._spokes(0), colors="white", linewidths=1.5))
        self.ax.set_title(title)
        self.label = self.fig.text(0.02, 0.02, "", family="monospace")

    def _walls_3d(self, centre: np.ndarray, half: float) -> None:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        for p, nrm in zip(self.frames.wall_point, self.frames.wall_normal):
            square = _wall_outline(p, nrm, centre, half, 3)
            self.ax.add_collection3d(Poly3DCollection([square], facecolor=(0.5, 0.5, 0.5, 0.25),
                                                      edgecolor="0.3"))

    def _spokes(self, k: int) -> np.ndarray:
        """(N, 2, 2) lines from each centre to its rim, at its orientation."""
        s, angle, r = self.frames.s[k, :, :2], self.frames.angle[k], self.frames.radius
        rim = s + r[:, None] * np.stack((np.cos(angle), np.sin(angle)), axis=1)
        return np.stack((s, rim), axis=1)

    def draw(self, k: int) -> bytes:
        s = self.frames.s[k]
        if self.three:
            self.bodies._offsets3d = (s[:, 0], s[:, 1], s[:, 2])
        else:
            for circle, centre in zip(self.circles, s):
                circle.center = (centre[0], centre[1])
            if self.markers is not None:
                self.markers.set_segments(self._spokes(k))
        self.label.set_text(f"t = {self.frames.times[k]:.6f} s")
        self.canvas.draw()
        rgba = np.asarray(self.canvas.buffer_rgba())
        return np.ascontiguousarray(rgba[:, :, :3]).tobytes()


def write_video(frames: Frames, path: Path, title: str, fps: int = VIDEO_FPS) -> None:
    """Encode every frame into an MP4 at `path` (H.264, yuv420p: plays in browsers)."""
    exe = ffmpeg_path()
    painter = _Painter(frames, title)
    cmd = [exe, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{WIDTH}x{HEIGHT}",
           "-r", str(fps), "-i", "-", "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-movflags", "+faststart",
           "-f", "mp4", str(path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        for k in range(len(frames.times)):
            proc.stdin.write(painter.draw(k))
        proc.stdin.close()
    except BrokenPipeError:
        pass
    err = proc.stderr.read().decode(errors="replace")
    if proc.wait() != 0:
        raise VideoError(f"ffmpeg could not encode the video: {' '.join(err.split())[:300] or 'no message'}")
