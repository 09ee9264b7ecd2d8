"""The 3D view: spheres with spin markers, trails, walls, contact forces and compression.

`SceneDrawer` owns the scene nodes of one client. `show_run` draws what stays fixed for a run
(grid, walls, full paths, the bodies' meshes) and `show_frame` moves what changes with time
(body poses, the compressed shape and dimmed undeformed outline, the contact point, normal
and friction force arrows, the trail so far). 1D and 2D scenes lie in the z = 0 plane; their
force arrows are drawn just above the spheres so the bodies never hide them.
"""

from __future__ import annotations

import numpy as np
import viser

from viewer.geometry import compressed_sphere, embed3, nice_cell, torus, unit_sphere, wall_box
from viewer.state import Frame, ViewRun

BODY_COLOURS = [(66, 133, 244), (244, 132, 36), (52, 168, 83), (171, 71, 188), (219, 68, 55), (96, 125, 139)]
NORMAL_COLOUR = (170, 0, 20)
FRICTION_COLOUR = (0, 120, 40)
POINT_COLOUR = (250, 204, 21)
GHOST_COLOUR_MIX = 0.55
SUBDIVISIONS = 3


def body_colour(i: int) -> tuple[int, int, int]:
    return BODY_COLOURS[i % len(BODY_COLOURS)]


def _darker(c: tuple[int, int, int], f: float = 0.45) -> tuple[int, int, int]:
    return tuple(int(x * f) for x in c)  # type: ignore[return-value]


def _lighter(c: tuple[int, int, int], f: float) -> tuple[int, int, int]:
    return tuple(int(x + (255 - x) * f) for x in c)  # type: ignore[return-value]


def _segments(path: np.ndarray) -> np.ndarray:
    """A polyline (T, 3) as line segments (T-1, 2, 3)."""
    if len(path) < 2:
        path = np.repeat(path[:1], 2, axis=0)
    return np.stack((path[:-1], path[1:]), axis=1)


class SceneDrawer:
    """Draws runs into one client's (or the server's) scene."""

    def __init__(self, scene: viser.SceneApi) -> None:
        self.scene = scene
        self.view: ViewRun | None = None
        self._bodies: list[dict] = []
        self._force_scale = 1.0
        self._friction_scale = 1.0
        self._lift = 0.0
        self._compressed: set[int] = set()
        self._arrows: dict[str, viser.SceneNodeHandle | None] = {"normal": None, "friction": None}
        self._point = None
        self._past: list = []
        self._shape: tuple | None = None
        self._ghosts: list = []

    # ------------------------------------------------------------------------------------------

    def show_run(self, view: ViewRun) -> None:
        """Draw a run's fixed parts; rebuilds the bodies when their number or size changed."""
        self.view = view
        scene = self.scene
        r_max = float(view.radius.max())
        planar = view.dim < 3
        lo, hi = view.bounds()
        extent = float(max(hi[0] - lo[0], hi[1] - lo[1], 4 * r_max))
        shape = (view.dim, view.n_bodies, tuple(np.round(view.radius, 12)), len(view.scene.walls))
        # Ground under the spheres (1D, 2D) or under the whole scene (3D): a table top with grid
        # lines. (viser's own grid shader costs most of a frame under software rendering.)
        cell = nice_cell(extent, 12)
        half = cell * np.ceil(0.75 * extent / cell)
        centre = np.round(0.5 * (lo + hi) / cell) * cell
        ground = -1.02 * r_max if planar else float(lo[2]) - 0.02 * extent
        self._show_ground(centre, half, cell, ground)
        for k, wall in enumerate(view.scene.walls):
            c, wxyz, dims = wall_box(np.array(wall.point), np.array(wall.normal), 1.6 * extent,
                                     0.04 * r_max + 0.01 * extent, planar, 2.4 * r_max)
            scene.add_box(f"/world/walls/{k}", color=(150, 158, 170), dimensions=dims, position=c, wxyz=wxyz,
                          opacity=0.85, cast_shadow=False)
        # Paths: the whole run faint, the part already travelled in the body's colour.
        self._past = []
        for i in range(view.n_bodies):
            colour = body_colour(i)
            scene.add_line_segments(f"/paths/{i}/all", _segments(view.paths[i]), _lighter(colour, 0.6),
                                    thickness=1.5, thickness_units="screen")
            self._past.append(scene.add_line_segments(f"/paths/{i}/past", _segments(view.paths[i][:2]), colour,
                                                      thickness=3.0, thickness_units="screen"))
        if shape != self._shape:
            self._build_bodies(view)
            self._shape = shape
        # Arrows: the run's largest normal force is drawn two radii long, its largest friction
        # force 1.5 radii (friction is often far smaller, so it gets a scale of its own).
        self._force_scale = 2.0 * r_max / max(view.max_normal_force, 1e-12)
        self._friction_scale = 1.5 * r_max / max(view.max_friction_force, 1e-12)
        self._lift = 1.08 * r_max if planar else 0.0
        self._remove_contact_nodes()

    def _show_ground(self, centre: np.ndarray, half: float, cell: float, z: float) -> None:
        scene = self.scene
        size = 2 * half
        # Lines only: a plane filling the view (viser's grid shader, or any lit surface) costs
        # most of a frame under software WebGL.
        ticks = np.arange(-half, half + 0.5 * cell, cell)
        major = np.isclose(np.round(ticks / cell) % 5, 0)
        segs, colours = [], []
        for tick, is_major in zip(ticks, major):
            colour = (160, 166, 178) if is_major else (208, 212, 220)
            segs += [((tick, -half, 0), (tick, half, 0)), ((-half, tick, 0), (half, tick, 0))]
            colours += [(colour, colour)] * 2
        points = np.array(segs, dtype=np.float32) + np.array([centre[0], centre[1], z + 1e-4 * size], np.float32)
        scene.add_line_segments("/world/grid", points, np.array(colours, dtype=np.uint8), thickness=1.0,
                                thickness_units="screen")

    def legend(self) -> str:
        """What the colours and arrow lengths mean, for the GUI."""
        view = self.view
        if view is None:
            return ""
        r_mm = float(view.radius.max()) * 1e3
        text = (f"<span style='color:#aa0014'>&#9632;</span> normal force: {view.max_normal_force:.3g} N peak "
                f"= {2 * r_mm:.3g} mm arrow")
        if view.max_friction_force > 0:
            text += (f"  \n<span style='color:#007828'>&#9632;</span> friction: {view.max_friction_force:.3g} N "
                     f"peak = {1.5 * r_mm:.3g} mm arrow")
        if view.dim > 1:
            text += "  \nstripe and dot turn with each sphere (spin)"
        text += ("  \nin contact: the sphere flattens; " +
                 ("the ring is its undeformed outline" if view.dim < 3 else "the pale shell is the undeformed sphere"))
        return text

    def _build_bodies(self, view: ViewRun) -> None:
        scene = self.scene
        for body in self._bodies:
            body["frame"].remove()
        self._bodies = []
        self._compressed = set()
        _, faces = unit_sphere(SUBDIVISIONS)
        for i in range(view.n_bodies):
            r = float(view.radius[i])
            colour = body_colour(i)
            base = f"/bodies/{i}"
            frame = scene.add_frame(base, show_axes=False)
            sphere = scene.add_mesh_simple(f"{base}/sphere", compressed_sphere(r, [], SUBDIVISIONS), faces,
                                           color=colour, flat_shading=False, cast_shadow=False)
            if view.dim < 3:
                # In the plane: the undeformed circle, drawn at the spheres' top so nothing hides it
                # (seen from above it is the outline the report's figures show).
                a = np.linspace(0, 2 * np.pi, 97)
                circle = np.stack((r * np.cos(a), r * np.sin(a), np.full_like(a, 1.001 * r)), -1)
                outline = scene.add_line_segments(f"{base}/outline", _segments(circle), _darker(colour, 0.6),
                                                  thickness=2.0, thickness_units="screen", visible=False)
            else:
                outline = scene.add_mesh_simple(f"{base}/outline", unit_sphere(SUBDIVISIONS)[0] * r, faces,
                                                color=_lighter(colour, 0.2), opacity=0.35, cast_shadow=False,
                                                visible=False)
            spin = scene.add_frame(f"{base}/spin", show_axes=False)
            if view.dim > 1:
                ring_v, ring_f = torus(1.004 * r, 0.075 * r)
                scene.add_mesh_simple(f"{base}/spin/stripe", ring_v, ring_f, color=_darker(colour, 0.35),
                                      cast_shadow=False)
                dot = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4)]) * r
                scene.add_icosphere(f"{base}/spin/dot", radius=0.16 * r, color=(255, 255, 255),
                                    position=tuple(dot), subdivisions=2, cast_shadow=False)
            self._bodies.append({"frame": frame, "sphere": sphere, "outline": outline, "spin": spin, "r": r})

    def _remove_contact_nodes(self) -> None:
        for key, handle in self._arrows.items():
            if handle is not None:
                handle.remove()
            self._arrows[key] = None
        if self._point is not None:
            self._point.remove()
            self._point = None

    # ------------------------------------------------------------------------------------------

    def show_frame(self, frame: Frame) -> None:
        """Move everything that changes with time to `frame`."""
        view = self.view
        if view is None:
            return
        cuts: dict[int, list[tuple[np.ndarray, float]]] = {}
        for c in frame.contacts:
            cuts.setdefault(c.i, []).append((c.normal, c.compression[0]))
            if c.j is not None:
                cuts.setdefault(c.j, []).append((-c.normal, c.compression[1]))
        for i, body in enumerate(self._bodies):
            body["frame"].position = tuple(frame.positions[i])
            body["spin"].wxyz = tuple(frame.wxyz[i])
            if i in cuts:
                body["sphere"].vertices = compressed_sphere(body["r"], cuts[i], SUBDIVISIONS).astype(np.float32)
                body["outline"].visible = True
                self._compressed.add(i)
            elif i in self._compressed:
                body["sphere"].vertices = compressed_sphere(body["r"], [], SUBDIVISIONS).astype(np.float32)
                body["outline"].visible = False
                self._compressed.discard(i)
        self._show_forces(frame)
        k = int(np.searchsorted(view.path_times, frame.t, side="right"))
        for i, past in enumerate(self._past):
            path = np.concatenate((view.paths[i][:k], frame.positions[i][None]), axis=0)
            past.points = _segments(path).astype(np.float32)

    def _show_forces(self, frame: Frame) -> None:
        lift = np.array([0.0, 0.0, self._lift])
        normal, friction, points = [], [], []
        for c in frame.contacts:
            p = c.point + lift
            points.append(p)
            # Action and reaction: the force on body i, and its opposite on the other side.
            fn = c.normal_force * self._force_scale
            normal += [(p, p + fn)] + ([(p, p - fn)] if c.j is not None else [])
            if c.friction_force is not None and np.linalg.norm(c.friction_force) > 0:
                ft = c.friction_force * self._friction_scale
                friction += [(p, p + ft)] + ([(p, p - ft)] if c.j is not None else [])
        r = float(self.view.radius.max()) if self.view is not None else 1.0
        self._set_arrows("normal", normal, NORMAL_COLOUR, r)
        self._set_arrows("friction", friction, FRICTION_COLOUR, r)
        if points:
            pts = np.array(points, dtype=np.float32)
            if self._point is None:
                self._point = self.scene.add_icosphere("/contact/point", radius=0.09 * r, color=POINT_COLOUR,
                                                       subdivisions=2, position=tuple(pts[0]), cast_shadow=False)
            else:
                self._point.position = tuple(pts[0])
        elif self._point is not None:
            self._point.remove()
            self._point = None

    def _set_arrows(self, key: str, arrows: list, colour: tuple[int, int, int], r: float) -> None:
        handle = self._arrows[key]
        if not arrows:
            if handle is not None:
                handle.remove()
                self._arrows[key] = None
            return
        pts = np.array([[a, b] for a, b in arrows], dtype=np.float32)
        if handle is not None and len(handle.points) == len(pts):
            handle.points = pts
            return
        if handle is not None:
            handle.remove()
        self._arrows[key] = self.scene.add_arrows(f"/contact/{key}", pts, colour, shaft_radius=0.045 * r,
                                                  head_radius=0.11 * r, head_length=0.3 * r)

    # ------------------------------------------------------------------------------------------

    def show_ghosts(self, paths: list[np.ndarray] | None) -> None:
        """Faint trajectories of an ensemble: paths[m] is (N, T, 3) for member m; None clears."""
        for handle in self._ghosts:
            handle.remove()
        self._ghosts = []
        if not paths:
            return
        n = paths[0].shape[0]
        for i in range(n):
            segs = np.concatenate([_segments(embed3(p[i])) for p in paths], axis=0).astype(np.float32)
            self._ghosts.append(self.scene.add_line_segments(
                f"/ensemble/{i}", segs, _lighter(body_colour(i), GHOST_COLOUR_MIX), thickness=1.2,
                thickness_units="screen"))
