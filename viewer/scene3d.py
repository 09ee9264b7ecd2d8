"""The 3D view: spheres with spin markers, trails, walls, contact forces, vectors, many bodies.

`SceneDrawer` owns the scene nodes of one client. `show_run` draws what stays fixed for a run
(ground, walls, full paths, the bodies) and `show_frame` moves what changes with time.

Two ways to draw the bodies:

- a few (up to `FEW_BODIES`): one mesh each, flattened where it presses on something, with a
  stripe and a dot that turn with its spin;
- many: one instanced mesh for all spheres (viser's batched meshes: one draw call, one
  message per frame), coloured by body, speed, kinetic energy or contact count, contacts as a
  force-chain view (a cylinder between the centres of each touching pair, thicker and darker
  with the force), and blob shadows on the floor as a depth cue.

Overlays (the undeformed outline, force and velocity arrows, the contact point, the centre of
mass) belong in the plane of the centres, where the opaque spheres would hide them. They are
drawn there as seen from the camera: scaled about the eye (`eye`) onto a plane just in front of
the spheres. A scaling about the eye leaves every projection unchanged, so they show exactly
where they belong on screen, on top. (Drawn simply above the spheres, they floated half a
radius off under a tilted camera: issue 12, item 4.)

1D and 2D scenes lie in the z = 0 plane, seen from above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import viser
from viser import _messages

from collide.periodic import nearest_image
from viewer.clip import BodyLook, links_shown
from viewer.colours import as_linear, body_colours, colour_map, darker, faded, legend_html, lighter, mixed
from viewer.geometry import (
    compressed_sphere,
    cylinder,
    disc,
    embed3,
    nice_cell,
    quats_from_z,
    rotate,
    torus,
    unit_sphere,
    wall_box,
)
from viewer.state import Frame, ViewRun

NORMAL_COLOUR = (170, 0, 20)
FRICTION_COLOUR = (0, 120, 40)
VELOCITY_COLOUR = (25, 25, 25)
MOMENTUM_COLOUR = (0, 128, 128)
POINT_COLOUR = (250, 204, 21)
COM_COLOUR = (40, 40, 40)
CHAIN_COLOUR = (200, 30, 30)
GHOST_COLOUR_MIX = 0.55
SUBDIVISIONS = 3
FEW_BODIES = 12  # above this, instanced spheres
# Under software GL a frame of many spheres costs in proportion to their vertices (a thousand
# 320-face spheres: about a second a frame, so seconds for any change to show): above this many
# bodies each is an 80-face sphere (a quarter of the vertices; at a pile's size on screen still
# round), its spin dot an icosahedron and its shadow an 8-sided disc.
DETAILED_BODIES = 250
FILL_SKY, FILL_GROUND, FILL_INTENSITY = (255, 255, 255), (150, 150, 160), 1.6  # instead of an environment map
CHAIN_OPACITY = 0.3  # spheres while the force chains are shown
CHAIN_BLOCK = 256  # the force chains' batch grows in blocks of this many links
IMAGE_BLOCK = 64  # the periodic copies' batch grows in blocks of this many spheres
CHAIN_SEGMENTS = 3  # sides of a force chain's prism: thin, three read as round at a pile's size on screen (six cost
# a fifth of a pile's frame in software GL)
WALL_KEEP = 0.03  # of the scene's extent: walls that moved less are not sent again
MIN_ARROW = 0.08  # arrows shorter than this many radii are not drawn (no heads on round-off)
COLOUR_MODES = ("body", "speed", "kinetic energy", "contacts")
# Level of detail: above POINT_BODIES bodies ("auto") each is one point, sized by the median radius
# (viser's point clouds take one size): a hundred thousand 80-face spheres are eight million
# triangles a frame, which software GL draws in seconds; their chains and blob shadows as many.
POINT_BODIES = 20_000
BODY_DRAWINGS = ("auto", "spheres", "points")
SPIN_DOT = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4)])  # where the spin dot sits (unit sphere)
FEW_DOT, MANY_DOT = 0.16, 0.22  # the spin dot's radius in the sphere's
# Blob shadows: dark at the floor, fading as the sphere rises. The fade is in the colour (towards
# the floor's, under one opacity): per-instance opacities made viser's client build the batch's
# material and instanced mesh anew at every frame that sent them.
FLOOR_COLOUR, SHADOW_COLOUR, SHADOW_OPACITY = (222, 224, 228), (60, 60, 70), 0.45


@dataclass
class DrawOptions:
    """What the 3D view shows (the Show folder's toggles)."""

    forces: bool = True
    velocity: bool = False
    momentum: bool = False
    com: bool = False
    trails: bool = True
    colour_by: str = "body"
    chains: bool = True
    shadows: bool = True
    bodies: str = "auto"  # BODY_DRAWINGS: spheres or points (auto: points above POINT_BODIES)


def send_pose(scene: viser.SceneApi, node: viser.SceneNodeHandle) -> None:
    """Send a node's pose even where it is viser's default (no turn, at the origin), which viser
    leaves unsent: a browser that drew a node of the same name before (removed with its parent,
    then added again) keeps that node's pose (the pile's first side wall lay flat, as break-3d's
    floor of the same name had)."""
    scene._queue_scene_message(_messages.SetOrientationMessage(node.name, tuple(float(x) for x in node.wxyz)))
    scene._queue_scene_message(_messages.SetPositionMessage(node.name, tuple(float(x) for x in node.position)))


def _segments(path: np.ndarray) -> np.ndarray:
    """A polyline (T, 3) as line segments (T-1, 2, 3)."""
    if len(path) < 2:
        path = np.repeat(path[:1], 2, axis=0)
    return np.stack((path[:-1], path[1:]), axis=1)


def _periodic(view: object) -> bool:
    """Whether a view is a run in a periodic box (a preview of frames has no model: never)."""
    model = getattr(view, "model", None)
    return model is not None and model.periodic


@dataclass(frozen=True)
class Lift:
    """A scaling by s about the eye: x -> eye + s (x - eye). Projections are unchanged."""

    eye: np.ndarray
    s: float

    def point(self, x: np.ndarray) -> np.ndarray:
        return self.eye + self.s * (np.asarray(x, float) - self.eye)


class ArrowSet:
    """One arrows node whose heads shrink with its shortest arrow, and which drops arrows
    shorter than `MIN_ARROW` radii (a 1e-17 m overlap gets no arrowhead)."""

    def __init__(self, scene: viser.SceneApi, name: str, colour: tuple[int, int, int]) -> None:
        self.scene, self.name, self.colour = scene, name, colour
        self.handle: viser.SceneNodeHandle | None = None
        self.count = 0

    def show(self, tails: np.ndarray, vectors: np.ndarray, r: float, lift: Lift | None = None) -> None:
        """Arrows from tails (K, 3) along vectors (K, 3), for spheres of radius r, drawn through
        `lift` (see the module docstring)."""
        length = np.linalg.norm(vectors, axis=-1) if len(vectors) else np.zeros(0)
        keep = length > MIN_ARROW * r
        if not keep.any():
            self.clear()
            return
        tails, vectors, length = tails[keep], vectors[keep], length[keep]
        if lift is not None:
            tails, vectors, length, r = lift.point(tails), vectors * lift.s, length * lift.s, r * lift.s
        pts = np.stack((tails, tails + vectors), axis=1).astype(np.float32)
        shortest = float(length.min())
        head_length = min(0.3 * r, 0.4 * shortest)
        head_radius = min(0.11 * r, 0.16 * shortest)
        shaft = min(0.045 * r, 0.06 * shortest)
        h = self.handle
        if h is not None and len(pts) == self.count:
            h.points = pts
            if abs(h.head_length - head_length) > 1e-3 * r:
                h.head_length, h.head_radius, h.shaft_radius = head_length, head_radius, shaft
            return
        self.clear()
        self.handle = self.scene.add_arrows(self.name, pts, self.colour, shaft_radius=shaft,
                                            head_radius=head_radius, head_length=head_length)
        self.count = len(pts)

    def clear(self) -> None:
        if self.handle is not None:
            self.handle.remove()
        self.handle = None
        self.count = 0

    @property
    def visible_count(self) -> int:
        return self.count


class SceneDrawer:
    """Draws runs into one client's (or the server's) scene."""

    def __init__(self, scene: viser.SceneApi, point_bodies: int | None = None) -> None:
        self.scene = scene
        # Bodies above which "auto" draws points (the level of detail; tests lower it).
        self.point_bodies = POINT_BODIES if point_bodies is None else int(point_bodies)
        self.view: ViewRun | None = None
        self.options = DrawOptions()
        self.many = False
        self.points = False  # many bodies drawn as points (level of detail)
        self._bodies: list[dict] = []
        self._batch: dict[str, viser.SceneNodeHandle] = {}
        self._chain_capacity = 0
        self._image_capacity = 0
        self._force_scale = 1.0
        self._friction_scale = 1.0
        self._velocity_scale = 1.0
        self._momentum_scale = 1.0
        self._compressed: set[int] = set()
        self._shadow_colours: np.ndarray | None = None  # the blob shadows' colours sent
        self._arrows = {key: ArrowSet(scene, f"/contact/{key}", colour) for key, colour in
                        (("normal", NORMAL_COLOUR), ("friction", FRICTION_COLOUR))}
        self._vectors = {key: ArrowSet(scene, f"/vectors/{key}", colour) for key, colour in
                         (("velocity", VELOCITY_COLOUR), ("momentum", MOMENTUM_COLOUR))}
        self._point = None
        self._com = None
        self._com_path = None
        self._past: list = []  # one node: every body's path so far
        self._paths: list = []  # one node: every body's whole path
        self._past_counts: tuple | None = None  # segments per body in `_past` (its colours follow)
        self._shape: tuple | None = None
        self._ground_key: tuple | None = None
        self._walls_drawn: list | None = None  # the wall boxes sent: (centre, wxyz, dims), is floor
        self._ghosts: list = []
        self._colours = np.zeros((0, 3), np.uint8)
        self._colour_range = (0.0, 1.0)
        self._floor: tuple[np.ndarray, np.ndarray] | None = None  # (point, unit normal) of the floor
        self._opacity: dict[int, float] = {}
        self._rings: dict[int, viser.SceneNodeHandle] = {}
        self._fill_light: viser.SceneNodeHandle | None = None
        self.frame: Frame | None = None
        self.eye: np.ndarray | None = None  # the camera's position, for the overlays
        self.lift: Lift | None = None
        self.look = BodyLook()  # the clip plane and the picked sphere (viewer.clip)
        self._hidden = np.zeros(0, bool)
        self._clipped = False

    # ------------------------------------------------------------------------------------------
    # Fixed parts of a run

    def show_run(self, view: ViewRun) -> None:
        """Draw a run's fixed parts; rebuilds the bodies when their number or size changed."""
        self.view = view
        scene = self.scene
        r_max = float(view.radius.max())
        planar = view.dim < 3
        lo, hi = view.bounds()
        extent = float(max(hi[0] - lo[0], hi[1] - lo[1], 4 * r_max))
        walls = list(view.walls)
        self.many = view.n_bodies > FEW_BODIES
        self.points = self.many and (self.options.bodies == "points" or (
            self.options.bodies == "auto" and view.n_bodies > self.point_bodies))
        if self._fill_light is None:
            self._configure_lights()
        self._floor = None
        if not planar:
            up = np.array([0.0, 0.0, 1.0])
            floors = [(p, n) for p, n in walls if float(np.dot(n, up)) > 0.95]
            if floors:
                self._floor = max(floors, key=lambda w: float(w[0][2]))
        shape = (view.dim, view.n_bodies, tuple(np.round(view.radius, 12)), len(walls), self.many, self.points)
        # Ground: a table top with grid lines, under the spheres (1D, 2D), on the floor when the
        # scene has one, else under the whole scene. (viser's own grid shader costs most of a
        # frame under software rendering.)
        cell = nice_cell(extent, 12)
        half = cell * np.ceil(0.75 * extent / cell)
        centre = np.round(0.5 * (lo + hi) / cell) * cell
        if planar:
            ground = -1.02 * r_max
        elif self._floor is not None:
            ground = float(self._floor[0][2])
        else:
            ground = float(lo[2]) - 0.02 * extent
        # What did not change is not sent again (a slider drag redraws a run ten times a second).
        ground_key = (tuple(np.round(centre[:2] / cell).astype(int)), float(half), float(cell), float(ground))
        if ground_key != self._ground_key:
            self._show_ground(centre, half, cell, ground)
            self._ground_key = ground_key
        self._show_walls(view, walls, lo, hi, extent, r_max, planar)
        # Paths: the whole run faint, the part already travelled in the body's colour; all bodies'
        # in one node each (per-segment colours: two nodes for a dozen balls, not 24).
        trails = self.options.trails and view.paths is not None and not self.many
        if trails:
            colours = body_colours(view.n_bodies)
            pieces = [_segments(path) for path in view.paths]
            points = np.concatenate(pieces).astype(np.float32)
            faint = as_linear(mixed(colours, lighter, 0.6))
            lines = np.concatenate([np.broadcast_to(c, (len(piece), 2, 3)) for piece, c in zip(pieces, faint)])
            if self._paths:
                self._paths[0].colors, self._paths[0].points = lines, points
            else:
                self._paths = [scene.add_line_segments("/paths/all", points, lines, thickness=1.5,
                                                       thickness_units="screen")]
                self._past = [scene.add_line_segments("/paths/past", points[:1], lines[:1], thickness=3.0,
                                                      thickness_units="screen")]
            self._past_counts = None
        else:
            self._clear_paths()
        if shape != self._shape:
            self._build_bodies(view)
            self._shape = shape
        # Arrows: the run's largest normal force is drawn two radii long, its largest friction
        # force 1.5 radii (friction is often far smaller, so it gets a scale of its own); the
        # fastest body's velocity and the largest momentum three radii.
        self._force_scale = 2.0 * r_max / max(view.max_normal_force, 1e-300)
        self._friction_scale = 1.5 * r_max / max(view.max_friction_force, 1e-300)
        self._velocity_scale = 3.0 * r_max / max(view.max_speed, 1e-300)
        self._momentum_scale = 3.0 * r_max / max(view.max_momentum, 1e-300)
        self._colour_range = self._range_for(self.options.colour_by)
        # The force chains' batch stays for the next run of the same bodies (a slider change):
        # removed, it had to be built again in the page and every sphere's colour resent.
        self._remove_contact_nodes(keep_chains=self.many)
        self._remove_com()
        for arrows in self._vectors.values():
            arrows.clear()
        for ring in self._rings.values():
            ring.remove()
        self._rings = {}
        self._opacity = {}

    def _configure_lights(self) -> None:
        """Once per client: no shadow map and no environment map, a hemisphere light instead.
        The shadow map (viser's three cascades of 1024 x 1024, sampled at every lit pixel) was
        half of break-3d's frame under software GL, and the floor's blob shadows give the depth
        it gave; the environment map's lighting was 60 % of a pile's frame there. Set once:
        switching either recompiles every material's shaders (seconds under software GL)."""
        scene = self.scene
        scene.configure_default_lights(True, cast_shadow=False)
        scene.configure_environment_map(None)
        self._fill_light = scene.add_light_hemisphere("/lights/fill", sky_color=FILL_SKY, ground_color=FILL_GROUND,
                                                      intensity=FILL_INTENSITY)

    def _show_ground(self, centre: np.ndarray, half: float, cell: float, z: float) -> None:
        # Lines only: a plane filling the view (viser's grid shader, or any lit surface) costs
        # most of a frame under software WebGL.
        ticks = np.arange(-half, half + 0.5 * cell, cell)
        major = np.isclose(np.round(ticks / cell) % 5, 0)
        segs, colours = [], []
        for tick, is_major in zip(ticks, major):
            colour = (160, 166, 178) if is_major else (208, 212, 220)
            segs += [((tick, -half, 0), (tick, half, 0)), ((-half, tick, 0), (half, tick, 0))]
            colours += [(colour, colour)] * 2
        points = np.array(segs, dtype=np.float32) + np.array([centre[0], centre[1], z + 2e-4 * half], np.float32)
        self.scene.add_line_segments("/world/grid", points, np.array(colours, dtype=np.uint8), thickness=1.0,
                                     thickness_units="screen")

    def _show_walls(self, view: ViewRun, walls: list, lo: np.ndarray, hi: np.ndarray, extent: float,
                    r_max: float, planar: bool) -> None:
        boxes = []
        middle = 0.5 * (lo + hi)
        corners = np.array([[a[0], b[1], c[2]] for a in (lo, hi) for b in (lo, hi) for c in (lo, hi)])
        for point, normal in walls:
            # A wall's face lies exactly on its plane (a floor under resting spheres, not a slab
            # above them), centred under the bodies and wide enough for every path (drawn from
            # the wall's own point, a floor ended short of the later bounces).
            foot = middle - np.dot(middle - point, normal) * normal
            # The box's own axes across the wall (its x is the normal): as far as the bounds reach.
            wxyz = wall_box(foot, normal, 1.0, 1.0, planar, 1.0)[1]
            axes = rotate(np.tile(wxyz, (2, 1)), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
            reach = 2.0 * np.max(np.abs((corners - foot) @ axes.T), axis=0) + 2.0 * r_max
            if planar:
                c, wxyz, dims = wall_box(foot, normal, max(float(reach[0]), 1.6 * extent),
                                         0.04 * r_max + 0.01 * extent, True, 2.4 * r_max)
            else:
                c, wxyz, dims = wall_box(foot, normal, 1.0, 0.02 * extent, False, 1.0)
                dims = (dims[0], max(float(reach[0]), 1.3 * extent), max(float(reach[1]), 1.3 * extent))
            is_floor = self._floor is not None and np.allclose(point, self._floor[0]) and np.allclose(
                normal, self._floor[1])
            boxes.append((np.concatenate((c, wxyz, dims)), is_floor))
        # The next run of a slider drag has walls within a few per cent of these: kept, not sent.
        old = self._walls_drawn
        if old is not None and len(old) == len(boxes) and all(
                f == g and np.allclose(a, b, rtol=0, atol=WALL_KEEP * extent) for (a, f), (b, g) in zip(old, boxes)):
            return
        self._walls_drawn = boxes
        handle = self.scene.get_handle_by_name("/world/walls")
        if handle is not None:
            handle.remove()
        if not walls:
            return
        self.scene.add_frame("/world/walls", show_axes=False)
        for k, (spec, is_floor) in enumerate(boxes):
            c, wxyz, dims = spec[:3], spec[3:7], spec[7:]
            # Walls other than the floor are glass: the sides of a bin stand between the camera
            # and the pile (at 0.85 opaque they hid it and its force chains).
            box = self.scene.add_box(f"/world/walls/{k}", color=FLOOR_COLOUR if is_floor else (150, 158, 170),
                                     dimensions=tuple(dims), position=tuple(c), wxyz=tuple(wxyz),
                                     opacity=None if is_floor else (0.85 if planar else 0.2), cast_shadow=False,
                                     receive_shadow=True)
            send_pose(self.scene, box)

    def legend(self) -> str:
        """What the colours and arrow lengths mean, for the GUI."""
        view = self.view
        if view is None:
            return ""
        r_mm = float(view.radius.max()) * 1e3
        lines = []
        if self.points:
            lines.append(f"{view.n_bodies:,} bodies drawn as points, sized by the median radius (level of detail: "
                         f"'draw bodies as' switches to spheres; auto above {self.point_bodies:,} bodies); no force "
                         "chains or shadows")
        if self.options.forces and view.max_normal_force > 0 and (self.options.chains or not self.many) and \
                not self.points:
            # The peak is the run's (the JSON summary's max_normal_force): no arrow is longer.
            what = (f"force chains: normal force between centres, thicker = stronger, thickest "
                    f"{view.max_normal_force:.4g} N peak") if self.many else \
                f"normal force: {view.max_normal_force:.4g} N peak = {2 * r_mm:.3g} mm arrow"
            lines.append(f"<span style='color:#aa0014'>&#9632;</span> {what}")
            if view.max_friction_force > 0 and not self.many:
                lines.append(f"<span style='color:#007828'>&#9632;</span> friction: {view.max_friction_force:.3g} N "
                             f"peak = {1.5 * r_mm:.3g} mm arrow")
        if self.options.velocity:
            lines.append(f"<span style='color:#191919'>&#9632;</span> velocity: {view.max_speed:.3g} m/s "
                         f"= {3 * r_mm:.3g} mm arrow")
        if self.options.momentum:
            lines.append(f"<span style='color:#008080'>&#9632;</span> momentum: {view.max_momentum:.3g} kg m/s "
                         f"= {3 * r_mm:.3g} mm arrow")
        if self.options.com:
            lines.append("&#8853; centre of mass (and its path)")
        if view.dim > 1 and not self.many and view.spin_dim:
            lines.append("stripe and dot turn with each sphere (spin)")
        if not self.many:
            lines.append("in contact: the sphere flattens and turns see-through; " +
                         ("the ring is its undeformed outline" if view.dim < 3 else
                          "the pale shell is the undeformed sphere"))
        return "  \n".join(lines)

    def colour_legend(self) -> str:
        """The colour bar for the colour mode (HTML), or '' for body colours."""
        mode = self.options.colour_by
        if mode == "body" or self.view is None:
            return ""
        lo, hi = self._colour_range
        unit = {"speed": "m/s", "kinetic energy": "J", "contacts": "contacts"}[mode]
        return legend_html(f"colour: {mode}", lo, hi, unit, integer=mode == "contacts")

    def _range_for(self, mode: str) -> tuple[float, float]:
        view = self.view
        if view is None or mode == "body":
            return 0.0, 1.0
        if mode == "speed":
            return 0.0, float(view.max_speed) or 1.0
        if mode == "kinetic energy":
            return 0.0, float(view.max_body_energy) or 1.0
        return 0.0, float(max(view.max_contacts, 6))

    def body_colours(self) -> np.ndarray:
        """The colour each body is drawn in now (N, 3)."""
        return self._colours

    def set_options(self, **changes) -> None:
        """Change what is shown; redraws the current frame."""
        changed = {key for key, value in changes.items() if getattr(self.options, key) != value}
        for key, value in changes.items():
            setattr(self.options, key, value)
        if "colour_by" in changes:
            self._colour_range = self._range_for(self.options.colour_by)
        if changed <= {"colour_by"}:
            # A colour mode is the spheres' colours only: one message of N colours, nothing moved
            # (a thousand spheres' positions, shadows and chains sent again cost seconds).
            if changed and self.frame is not None and self.view is not None:
                self._recolour(self.frame)
            return
        if "shadows" in changes or "chains" in changes:
            self._opacity = {}
        if not self.options.forces:
            self._remove_contact_nodes()
        for key, arrows in self._vectors.items():
            if not getattr(self.options, key):
                arrows.clear()
        if not self.options.com:
            self._remove_com()
        if self.frame is not None:
            self.show_frame(self.frame)

    def _recolour(self, frame: Frame) -> None:
        """The spheres in the colours of the current mode at `frame`, and nothing else sent."""
        colours = self._frame_colours(frame)
        if np.array_equal(colours, self._colours):
            return
        self._colours = colours
        if self.points:
            shown = ~self._hidden if len(self._hidden) == len(colours) else np.ones(len(colours), bool)
            self._batch["points"].colors = colours[shown]
            return
        if self.many:
            spheres = self._batch.get("spheres")
            if spheres is not None:
                spheres.batched_colors = colours
            return
        for body, colour in zip(self._bodies, colours):
            body["sphere"].color = tuple(int(c) for c in colour)

    # ------------------------------------------------------------------------------------------
    # Bodies

    def _clear_paths(self) -> None:
        for handle in self._paths + self._past:
            handle.remove()
        self._paths, self._past = [], []

    def _build_bodies(self, view: ViewRun) -> None:
        for body in self._bodies:
            body["frame"].remove()
        for handle in self._batch.values():
            handle.remove()
        self._bodies, self._batch, self._chain_capacity = [], {}, 0
        self._compressed = set()
        colours = body_colours(view.n_bodies)
        self._colours = colours
        if self.many:
            self._build_batch(view, colours)
            return
        self._build_few(view, colours)
        self._add_shadows(view)

    def _build_few(self, view: ViewRun, colours: np.ndarray) -> None:
        """A mesh for each sphere (its own vertices: it flattens where it presses), its stripe, dot
        and undeformed shell: plain meshes, one material kind with the spheres' (an instanced
        mesh of them needed shaders of its own, compiled anew at each pick under software GL)."""
        scene = self.scene
        _, faces = unit_sphere(SUBDIVISIONS)
        for i in range(view.n_bodies):
            r = float(view.radius[i])
            colour = tuple(int(c) for c in colours[i])
            base = f"/bodies/{i}"
            frame = scene.add_frame(base, show_axes=False)
            sphere = scene.add_mesh_simple(f"{base}/sphere", compressed_sphere(r, [], SUBDIVISIONS), faces,
                                           color=colour, flat_shading=False, cast_shadow=False)
            # The undeformed sphere (3D; in 1D and 2D a ring overlay shows it: `_show_rings`).
            outline = None if view.dim < 3 else scene.add_mesh_simple(
                f"{base}/outline", unit_sphere(SUBDIVISIONS)[0] * r, faces, color=lighter(colour, 0.2), opacity=0.35,
                cast_shadow=False, visible=False)
            spin = scene.add_frame(f"{base}/spin", show_axes=False)
            if view.dim > 1:
                ring_v, ring_f = torus(1.004 * r, 0.075 * r)
                scene.add_mesh_simple(f"{base}/spin/stripe", ring_v, ring_f, color=darker(colour, 0.35),
                                      cast_shadow=False)
                scene.add_icosphere(f"{base}/spin/dot", radius=FEW_DOT * r, color=(255, 255, 255),
                                    position=tuple(SPIN_DOT * r), subdivisions=2, cast_shadow=False)
            self._bodies.append({"frame": frame, "sphere": sphere, "outline": outline, "spin": spin, "r": r})

    def _build_batch(self, view: ViewRun, colours: np.ndarray) -> None:
        scene = self.scene
        n = view.n_bodies
        if self.points:
            self._batch["points"] = scene.add_point_cloud(
                "/bodies/points", np.zeros((n, 3), np.float32), colours, point_size=float(2 * np.median(view.radius)),
                point_shape="circle", precision="float32")
            return
        coarse = n > DETAILED_BODIES
        verts, faces = unit_sphere(1 if coarse else 2)
        ident = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        zeros = np.zeros((n, 3))
        self._batch["spheres"] = scene.add_batched_meshes_simple(
            "/bodies/spheres", verts, faces, batched_wxyzs=ident, batched_positions=zeros,
            batched_scales=view.radius.astype(np.float32), batched_colors=colours, lod="off",
            cast_shadow=False, receive_shadow=False)
        if view.dim > 1 and view.spin_dim:
            dv, df = unit_sphere(0 if coarse else 1)
            self._batch["dots"] = scene.add_batched_meshes_simple(
                "/bodies/dots", dv, df, batched_wxyzs=ident, batched_positions=zeros,
                batched_scales=(MANY_DOT * view.radius).astype(np.float32), batched_colors=(255, 255, 255),
                lod="off", cast_shadow=False, receive_shadow=False)
        self._add_shadows(view)

    def _add_shadows(self, view: ViewRun) -> None:
        """Blob shadows on the floor (3D scenes with one): a cheap depth cue that works under
        software GL too."""
        if self._floor is None:
            return
        n = view.n_bodies
        dv, df = disc(8 if n > DETAILED_BODIES else 24)
        self._batch["shadows"] = self.scene.add_batched_meshes_simple(
            "/bodies/shadows", dv, df, batched_wxyzs=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
            batched_positions=np.zeros((n, 3)), batched_scales=view.radius.astype(np.float32),
            batched_colors=SHADOW_COLOUR, opacity=SHADOW_OPACITY, lod="off", cast_shadow=False, receive_shadow=False)
        self._shadow_colours = None

    def _remove_com(self) -> None:
        if self._com is not None:
            self._com.remove()
            self._com = None
        if self._com_path is not None:
            self._com_path.remove()
            self._com_path = None

    def _remove_contact_nodes(self, keep_chains: bool = False) -> None:
        for arrows in self._arrows.values():
            arrows.clear()
        if self._point is not None:
            self._point.remove()
            self._point = None
        if keep_chains:
            return
        chains = self._batch.pop("chains", None)
        if chains is not None:
            chains.remove()
            self._colours = np.zeros((0, 3), np.uint8)  # see _show_chains: resend the spheres' colours
        self._chain_capacity = 0

    # ------------------------------------------------------------------------------------------
    # What changes with time

    def show_frame(self, frame: Frame) -> None:
        """Move everything that changes with time to `frame`."""
        view = self.view
        if view is None:
            return
        self.frame = frame
        self.lift = self._lift_for(frame)
        self._hidden = self.look.hidden(frame.positions)
        if self.many:
            self._show_batch(frame)
        else:
            self._show_meshes(frame)
        if self.options.forces and not self.many:
            self._show_forces(frame)
        self._show_vectors(frame)
        self._show_com(frame)
        self._show_images(frame)
        if self._past:
            self._show_past(frame)
        self._apply_clip(frame)
        self.look.frame_shown(frame)

    def _show_past(self, frame: Frame) -> None:
        """Each body's path up to the time shown, in its colour (colours resent when the number of
        segments per body changes)."""
        view = self.view
        k = int(np.searchsorted(view.path_times, frame.t, side="right"))
        pieces = []
        for i in range(view.n_bodies):
            path = np.concatenate((view.paths[i][:k], frame.positions[i][None]), axis=0)
            segments = view.trail_breaks(_segments(path)) if _periodic(view) else _segments(path)
            pieces.append(segments if len(segments) else _segments(path[-1:]))
        counts = tuple(len(piece) for piece in pieces)
        past = self._past[0]
        if counts != self._past_counts:
            colours = as_linear(body_colours(view.n_bodies))
            past.colors = np.repeat(colours, counts, axis=0)[:, None, :].repeat(2, axis=1)
            self._past_counts = counts
        past.points = np.concatenate(pieces).astype(np.float32)

    def _apply_clip(self, frame: Frame) -> None:
        """Hide the bodies the clip plane hides (`self._hidden`), whichever way they are drawn:
        one node each, or instances of one mesh (scaled to nothing), with their shadows."""
        hidden, view = self._hidden, self.view
        if self._bodies:
            for body, off in zip(self._bodies, hidden):
                if body["frame"].visible == bool(off):
                    body["frame"].visible = not off
        shown = (~hidden).astype(np.float32)
        was, self._clipped = self._clipped, bool(hidden.any())
        if self._clipped or was:  # once nothing is hidden, the full sizes are sent back once
            for key, size in (("spheres", 1.0), ("dots", MANY_DOT)):
                batch = self._batch.get(key)
                if batch is not None:
                    batch.batched_scales = (size * view.radius * shown).astype(np.float32)
        shadows = self._batch.get("shadows")
        if shadows is not None and self.options.shadows and hidden.any():
            shadows.batched_scales = (np.asarray(shadows.batched_scales, np.float32) * shown).astype(np.float32)

    def _lift_for(self, frame: Frame) -> Lift | None:
        """How the overlays are placed for this frame and eye (see the module docstring): onto
        the plane just above the spheres (1D, 2D), or 2.5 radii towards the eye (3D)."""
        view, eye = self.view, self.eye
        if view is None or eye is None or self.many:
            return None
        r = float(view.radius.max())
        if view.dim < 3:
            height = 1.06 * r
            if eye[2] <= 1.5 * height:
                return None  # looking from the side or below: leave them in the plane
            return Lift(eye, 1.0 - height / eye[2])
        anchor = frame.contacts[0].point if frame.contacts else frame.com
        distance = float(np.linalg.norm(eye - anchor)) if anchor is not None else 0.0
        if distance <= 5 * r:
            return None
        return Lift(eye, max(0.3, 1.0 - 2.5 * r / distance))

    def _frame_colours(self, frame: Frame) -> np.ndarray:
        if self.look.picked is not None:
            links = frame.contact_links()
            return self.look.colours(self._base_colours(frame), links.i, links.j)
        return self._base_colours(frame)

    def _base_colours(self, frame: Frame) -> np.ndarray:
        mode = self.options.colour_by
        view = self.view
        if mode == "body" or view is None:
            return body_colours(len(frame.positions))
        lo, hi = self._colour_range
        if mode == "speed":
            values = np.linalg.norm(frame.velocities, axis=-1)
        elif mode == "kinetic energy":
            values = 0.5 * view.mass * np.sum(frame.velocities**2, axis=-1)
        else:
            values = frame.contact_links().counts(len(frame.positions)).astype(float)
        return colour_map(values, lo, hi)

    def _show_meshes(self, frame: Frame) -> None:
        cuts: dict[int, list[tuple[np.ndarray, float]]] = {}
        for c in frame.contacts:
            cuts.setdefault(c.i, []).append((c.normal, c.compression[0]))
            if c.j is not None:
                cuts.setdefault(c.j, []).append((-c.normal, c.compression[1]))
        colours = self._frame_colours(frame)
        recolour = not np.array_equal(colours, self._colours)
        self._colours = colours
        for i, body in enumerate(self._bodies):
            body["frame"].position = tuple(frame.positions[i])
            body["spin"].wxyz = tuple(frame.wxyz[i])
            if recolour:
                body["sphere"].color = tuple(int(c) for c in colours[i])
            if i in cuts or i in self._compressed:
                body["sphere"].vertices = compressed_sphere(body["r"], cuts.get(i, []), SUBDIVISIONS).astype(np.float32)
                if body["outline"] is not None:
                    body["outline"].visible = i in cuts
        self._compressed = set(cuts)
        if self.view is not None and self.view.dim < 3:
            self._show_rings(frame, set(cuts))
        self._show_shadows(frame)

    def _show_rings(self, frame: Frame, pressed: set[int]) -> None:
        """The undeformed outline of each sphere in contact (an overlay: see the docstring)."""
        for i in list(self._rings):
            if i not in pressed:
                self._rings.pop(i).remove()
        a = np.linspace(0, 2 * np.pi, 97)
        unit = np.stack((np.cos(a), np.sin(a), np.zeros_like(a)), -1)
        for i in pressed:
            body = self._bodies[i]
            points = frame.positions[i] + body["r"] * unit
            if self.lift is not None:
                points = self.lift.point(points)
            segs = _segments(points).astype(np.float32)
            if i in self._rings:
                self._rings[i].points = segs
            else:
                colour = tuple(int(c) for c in darker(tuple(int(c) for c in self._colours[i]), 0.6))
                self._rings[i] = self.scene.add_line_segments(f"/overlay/ring{i}", segs, colour, thickness=2.0,
                                                              thickness_units="screen")

    def _show_points(self, frame: Frame) -> None:
        """Many bodies as points: the ones the clip plane leaves, in the colour mode's colours."""
        points = self._batch["points"]
        shown = ~self._hidden if len(self._hidden) == len(frame.positions) else np.ones(len(frame.positions), bool)
        colours = self._frame_colours(frame)
        if not np.array_equal(colours, self._colours) or self._clipped or shown.sum() != len(points.points):
            points.colors = colours[shown]
            self._colours = colours
        points.points = frame.positions[shown].astype(np.float32)

    def _show_batch(self, frame: Frame) -> None:
        if self.points:
            self._show_points(frame)
            return
        view = self.view
        spheres = self._batch["spheres"]
        positions = frame.positions.astype(np.float32)
        spheres.batched_positions = positions
        colours = self._frame_colours(frame)
        if not np.array_equal(colours, self._colours):
            spheres.batched_colors = colours
            self._colours = colours
        chains = self.options.forces and self.options.chains
        # See-through spheres only while there are chains to see through them.
        opacity = CHAIN_OPACITY if chains and len(frame.contact_links().i) else 1.0
        if self._opacity.get(-1) != opacity:
            # Always a number (1.0: opaque), so the batched material switches cleanly.
            spheres.opacity = opacity
            self._opacity[-1] = opacity
        dots = self._batch.get("dots")
        if dots is not None:
            offset = rotate(frame.wxyz, SPIN_DOT) * view.radius[:, None]
            dots.batched_positions = (frame.positions + offset).astype(np.float32)
        self._show_shadows(frame)
        if chains:
            self._show_chains(frame)
        elif "chains" in self._batch:
            # Hidden, not removed: removing one batched mesh made viser's other batched meshes
            # vanish until their next update.
            self._batch["chains"].visible = False

    def _show_images(self, frame: Frame) -> None:
        """In a periodic box, a copy of each sphere across every side it crosses (plain spheres
        in the body's colour: `ViewRun.images`), in one batched mesh grown in blocks."""
        view = self.view
        if view is None or not _periodic(view):
            return
        body, centre = view.images(frame.positions)
        k = len(body)
        handle = self._batch.get("images")
        cap = 0 if handle is None else self._image_capacity
        if k > cap:
            if handle is not None:
                handle.remove()
                self._colours = np.zeros((0, 3), np.uint8)  # (see _show_chains: resent with the next frame)
            cap = self._image_capacity = IMAGE_BLOCK * -(-k // IMAGE_BLOCK)
            verts, faces = unit_sphere(2)
            handle = self._batch["images"] = self.scene.add_batched_meshes_simple(
                "/bodies/images", verts, faces, batched_wxyzs=np.tile([1.0, 0.0, 0.0, 0.0], (cap, 1)),
                batched_positions=np.zeros((cap, 3)), batched_scales=np.zeros(cap, np.float32),
                batched_colors=np.zeros((cap, 3), np.uint8), lod="off", cast_shadow=False, receive_shadow=False)
        pos, scales = np.zeros((cap, 3), np.float32), np.zeros(cap, np.float32)
        colours = np.zeros((cap, 3), np.uint8)
        pos[:k], scales[:k] = centre, view.radius[body]
        if k and len(self._colours):
            colours[:k] = self._colours[body]
        handle.batched_positions, handle.batched_scales, handle.batched_colors = pos, scales, colours

    def _show_shadows(self, frame: Frame) -> None:
        shadows = self._batch.get("shadows")
        if shadows is None or self.view is None:
            return
        view = self.view
        if shadows.visible != self.options.shadows:
            shadows.visible = self.options.shadows
        if not self.options.shadows:
            return
        point, normal = self._floor
        height = (frame.positions - point) @ normal
        foot = frame.positions - height[:, None] * normal + 0.03 * view.radius[:, None] * normal
        shadows.batched_positions = foot.astype(np.float32)
        # A blob shadow shrinks and fades as the sphere rises: how far up it is reads at once.
        lift = np.maximum(height - view.radius, 0.0) / view.radius
        shadows.batched_scales = (view.radius / (1 + 0.15 * lift)).astype(np.float32)
        colours = faded(SHADOW_COLOUR, FLOOR_COLOUR, 1 / (1 + 0.5 * lift))
        if self._shadow_colours is None or not np.array_equal(colours, self._shadow_colours):
            shadows.batched_colors = colours
            self._shadow_colours = colours

    def _show_chains(self, frame: Frame) -> None:
        """Force chains: a cylinder from each body's centre to the other's (or to the wall), its
        radius growing with the normal force, the strongest dark red."""
        view = self.view
        links = frame.contact_links()
        strong = links.force > 1e-9 * max(view.max_normal_force, 1e-300)
        strong &= links_shown(links.i, links.j, self._hidden)
        i, j, point, force = links.i[strong], links.j[strong], links.point[strong], links.force[strong]
        start = frame.positions[i]
        other = frame.positions[np.maximum(j, 0)]
        if _periodic(view):  # across a periodic side: to the other body's nearest image
            other = start + embed3(nearest_image((other - start)[:, :view.dim], view.model.period))
        end = np.where((j >= 0)[:, None], other, point)
        k = len(i)
        if k > self._chain_capacity:
            old = self._batch.pop("chains", None)
            if old is not None:
                # Removing a batched mesh made viser's other batched meshes vanish until their
                # colours were sent again: resend them with the next frame.
                old.remove()
                self._colours = np.zeros((0, 3), np.uint8)
            # Room for the run's most links at once, in steps of CHAIN_BLOCK: every slot is drawn
            # (unused ones at zero size), so a power of two wasted up to half the chains' work.
            self._chain_capacity = CHAIN_BLOCK * max(1, -(-max(k, view.max_links) // CHAIN_BLOCK))
            cv, cf = cylinder(CHAIN_SEGMENTS)
            cap = self._chain_capacity
            self._batch["chains"] = self.scene.add_batched_meshes_simple(
                "/contact/chains", cv, cf, batched_wxyzs=np.tile([1.0, 0, 0, 0], (cap, 1)),
                batched_positions=np.zeros((cap, 3)), batched_scales=np.zeros((cap, 3), np.float32),
                batched_colors=darker(CHAIN_COLOUR, 0.85), lod="off",
                cast_shadow=False, receive_shadow=False)
        if "chains" not in self._batch:
            return
        cap = self._chain_capacity
        r_min = float(view.radius.min())
        share = np.sqrt(force / max(view.max_normal_force, 1e-300))
        d = end - start
        lengths = np.linalg.norm(d, axis=-1)
        # One colour; the force is in the thickness (per-frame colours cost a quarter of the
        # message for a thousand links).
        wxyz = np.tile(np.array([1.0, 0.0, 0.0, 0.0], np.float32), (cap, 1))
        pos = np.zeros((cap, 3), np.float32)
        scales = np.zeros((cap, 3), np.float32)
        if k:
            wxyz[:k] = quats_from_z(d)
            pos[:k] = start
            radius = r_min * (0.03 + 0.3 * share)
            scales[:k] = np.stack((radius, radius, lengths), -1)
        chains = self._batch["chains"]
        if not chains.visible:
            chains.visible = True
        chains.batched_wxyzs = wxyz
        chains.batched_positions = pos
        chains.batched_scales = scales

    def _show_forces(self, frame: Frame) -> None:
        """Normal and friction force at each contact point, on both bodies (action, reaction),
        in the plane of the centres."""
        tails_n, vec_n, tails_f, vec_f, points = [], [], [], [], []
        for c in frame.contacts:
            if not self.look.contact_shown(self._hidden, c.i, c.j):
                continue
            p = c.point
            points.append(p)
            fn = c.normal_force * self._force_scale
            tails_n += [p] + ([p] if c.j is not None else [])
            vec_n += [fn] + ([-fn] if c.j is not None else [])
            if c.friction_force is not None:
                ft = c.friction_force * self._friction_scale
                tails_f += [p] + ([p] if c.j is not None else [])
                vec_f += [ft] + ([-ft] if c.j is not None else [])
        r = float(self.view.radius.max()) if self.view is not None else 1.0
        lift = self.lift
        self._arrows["normal"].show(np.array(tails_n).reshape(-1, 3), np.array(vec_n).reshape(-1, 3), r, lift)
        self._arrows["friction"].show(np.array(tails_f).reshape(-1, 3), np.array(vec_f).reshape(-1, 3), r, lift)
        if points:
            where = tuple(lift.point(points[0])) if lift is not None else tuple(points[0])
            size = 0.09 * r * (lift.s if lift is not None else 1.0)
            if self._point is None:
                self._point = self.scene.add_icosphere("/contact/point", radius=size, color=POINT_COLOUR,
                                                       subdivisions=2, position=where, cast_shadow=False)
            else:
                self._point.position = where
                if abs(self._point.radius - size) > 1e-3 * size:
                    self._point.radius = size
        elif self._point is not None:
            self._point.remove()
            self._point = None

    def _show_vectors(self, frame: Frame) -> None:
        view = self.view
        if frame.velocities is None or view is None:
            return
        r = float(view.radius.max())
        if self.options.velocity:
            self._vectors["velocity"].show(frame.positions, frame.velocities * self._velocity_scale, r, self.lift)
        if self.options.momentum:
            p = view.mass[:, None] * frame.velocities
            self._vectors["momentum"].show(frame.positions, p * self._momentum_scale, r, self.lift)

    def _show_com(self, frame: Frame) -> None:
        view = self.view
        if not self.options.com or frame.com is None or view is None:
            return
        r = float(view.radius.max())
        lift = self.lift
        where = lift.point(frame.com) if lift is not None else frame.com
        size = lift.s if lift is not None else 1.0
        ring = np.linspace(0, 2 * np.pi, 49)
        circle = np.stack((0.3 * r * np.cos(ring), 0.3 * r * np.sin(ring), np.zeros_like(ring)), -1)
        if self._com is None:
            self._com = self.scene.add_icosphere("/com_marker", radius=0.14 * r, color=COM_COLOUR, subdivisions=2,
                                                 position=tuple(where), cast_shadow=False)
            self._com_ring = self.scene.add_line_segments("/com_marker/ring", _segments(circle * size), COM_COLOUR,
                                                          thickness=2.5, thickness_units="screen")
            if view.com_path is not None:
                self._com_path = self.scene.add_line_segments("/com_path", _segments(view.com_path), (90, 90, 90),
                                                              thickness=1.5, thickness_units="screen")
        self._com.position = tuple(where)
        if abs(self._com.radius - 0.14 * r * size) > 1e-3 * r:
            self._com.radius = 0.14 * r * size
            self._com_ring.points = _segments(circle * size).astype(np.float32)

    # ------------------------------------------------------------------------------------------

    def show_ghosts(self, paths: list[np.ndarray] | None) -> None:
        """Faint trajectories of an ensemble: paths[m] is (N, T, 3) for member m; None clears."""
        for handle in self._ghosts:
            handle.remove()
        self._ghosts = []
        if not paths:
            return
        n = paths[0].shape[0]
        colours = body_colours(n)
        for i in range(n):
            segs = np.concatenate([_segments(embed3(p[i])) for p in paths], axis=0).astype(np.float32)
            self._ghosts.append(self.scene.add_line_segments(
                f"/ensemble/{i}", segs, lighter(tuple(int(c) for c in colours[i]), GHOST_COLOUR_MIX),
                thickness=1.2, thickness_units="screen"))
