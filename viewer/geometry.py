"""Geometry for drawing: meshes, the compressed sphere, orientations and the camera fit.

Pure numpy. 1D and 2D scenes live in the z = 0 plane (docs/design.md section 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np


def embed3(x: np.ndarray) -> np.ndarray:
    """Vectors (..., D) with D = 1, 2 or 3 as (..., 3), padding with zeros (the z = 0 plane)."""
    x = np.asarray(x, dtype=float)
    if x.shape[-1] == 3:
        return x
    pad = np.zeros((*x.shape[:-1], 3 - x.shape[-1]))
    return np.concatenate((x, pad), axis=-1)


def orientation_wxyz(q: np.ndarray) -> np.ndarray:
    """Orientations (..., Q) as quaternions (..., 4) wxyz: Q = 0 none, 1 angle about z, 4 wxyz."""
    q = np.asarray(q, dtype=float)
    if q.shape[-1] == 4:
        return q / np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.zeros((*q.shape[:-1], 4))
    if q.shape[-1] == 0:
        out[..., 0] = 1.0
        return out
    half = 0.5 * q[..., 0]
    out[..., 0] = np.cos(half)
    out[..., 3] = np.sin(half)
    return out


def quat_from_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest rotation (wxyz) taking unit vector a to unit vector b."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    dot = float(a @ b)
    if dot < -1 + 1e-12:
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis = axis / np.linalg.norm(axis)
        return np.array([0.0, *axis])
    q = np.array([1.0 + dot, *np.cross(a, b)])
    return q / np.linalg.norm(q)


@lru_cache(maxsize=4)
def unit_sphere(subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere: vertices (V, 3) on the unit sphere and faces (F, 3)."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
             (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, float) / np.linalg.norm(p) for p in verts]

    def mid(i: int, j: int, cache: dict[tuple[int, int], int]) -> int:
        key = (min(i, j), max(i, j))
        if key not in cache:
            m = v[i] + v[j]
            v.append(m / np.linalg.norm(m))
            cache[key] = len(v) - 1
        return cache[key]

    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b, cache), mid(b, c, cache), mid(c, a, cache)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    vertices = np.array(v)
    vertices.setflags(write=False)
    f = np.array(faces, dtype=np.uint32)
    f.setflags(write=False)
    return vertices, f


def torus(major: float, minor: float, segments: int = 72, sides: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A ring in the body's xz-plane (a meridian), so it turns visibly under spin about z."""
    u = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    v = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rr = major + minor * np.cos(vv)
    verts = np.stack((rr * np.cos(uu), minor * np.sin(vv), rr * np.sin(uu)), axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a = i * sides + j
    b = ((i + 1) % segments) * sides + j
    c = ((i + 1) % segments) * sides + (j + 1) % sides
    d = i * sides + (j + 1) % sides
    faces = np.concatenate((np.stack((a, b, c), -1).reshape(-1, 3), np.stack((a, c, d), -1).reshape(-1, 3)))
    return verts, faces.astype(np.uint32)


def compressed_sphere(radius: float, cuts: list[tuple[np.ndarray, float]],
                      subdivisions: int = 3) -> np.ndarray:
    """Vertices of a sphere flattened where it presses on something.

    Each cut is (unit direction from the centre towards the contact, compression depth): the
    surface beyond `radius - depth` along that direction is pushed back onto the contact plane,
    giving the flat face a compressed spring-sphere shows.
    """
    verts = unit_sphere(subdivisions)[0] * radius
    out = verts.copy()
    for direction, depth in cuts:
        n = np.asarray(direction, float)
        n = n / np.linalg.norm(n)
        limit = radius - max(depth, 0.0)
        height = out @ n
        excess = np.maximum(height - limit, 0.0)
        out = out - excess[:, None] * n
    return out


@dataclass(frozen=True)
class CameraFit:
    """Where to put the camera: position, look-at point, up direction, vertical field of view."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov: float


def fit_camera(lo: np.ndarray, hi: np.ndarray, planar: bool, aspect: float = 1.2,
               fov_deg: float = 35.0, tilt_deg: float = 28.0, fill: float = 0.9) -> CameraFit:
    """A camera that sees the box [lo, hi]: looking down on the plane (tilted a little so the
    spheres read as 3D) for 1D and 2D scenes, from an oblique corner for 3D ones; as close as
    it can be with every corner of the box within `fill` of the view's half-width and
    half-height (perspective enlarges the near side, so the corners are projected)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = 0.5 * (lo + hi)
    size = np.maximum(hi - lo, 1e-6)
    fov = math.radians(fov_deg)
    tan_v = math.tan(fov / 2)
    tan_h = tan_v * aspect
    if planar:
        tilt = math.radians(tilt_deg)
        direction = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    else:
        direction = np.array([0.55, -0.75, 0.45])
        direction /= np.linalg.norm(direction)
    up = np.array([0.0, 0.0, 1.0])
    forward = -direction
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rel = corners - centre

    def fits(dist: float) -> bool:
        depth = dist - rel @ direction  # along the view direction, from the eye
        if np.any(depth <= 1e-9 * dist):
            return False
        return bool(np.all(np.abs(rel @ right) / depth <= fill * tan_h) and
                    np.all(np.abs(rel @ true_up) / depth <= fill * tan_v))

    far = float(np.linalg.norm(size)) / math.sin(min(fov / 2, math.atan(tan_h))) + 1e-9
    while not fits(far):
        far *= 2
    near = 0.0
    for _ in range(50):  # bisection on the distance: fits() is monotonic in it
        mid = 0.5 * (near + far)
        near, far = (near, mid) if fits(mid) else (mid, far)
    return CameraFit(tuple(centre + direction * far), tuple(centre), (0.0, 0.0, 1.0), fov)


def nice_cell(extent: float, cells: int = 20) -> float:
    """A grid cell size (1, 2 or 5 times a power of ten) giving about `cells` cells."""
    raw = max(extent, 1e-9) / cells
    exp = math.floor(math.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0**exp >= raw:
            return m * 10.0**exp
    return 10.0 ** (exp + 1)


def wall_box(point: np.ndarray, normal: np.ndarray, extent: float, thickness: float,
             planar: bool, height: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    """Pose and size of a thin box showing a wall: its face lies on the plane, behind the normal.

    Returns (centre (3,), wxyz (4,), dimensions (x, y, z)) with the box's x axis along the normal.
    """
    n = embed3(np.asarray(normal, float))
    n = n / np.linalg.norm(n)
    centre = embed3(np.asarray(point, float)) - 0.5 * thickness * n
    wxyz = quat_from_to(np.array([1.0, 0.0, 0.0]), n)
    # In the plane the normal has no z: the box stays upright, `height` tall.
    return centre, wxyz, (thickness, extent, height if planar else extent)


def quats_from_z(d: np.ndarray) -> np.ndarray:
    """Quaternions (K, 4) wxyz turning +z onto each direction of d (K, 3) (any length > 0)."""
    d = np.asarray(d, float)
    n = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    # q = (1 + z.n, z x n) normalised; z x n = (-n_y, n_x, 0).
    q = np.stack((1.0 + n[:, 2], -n[:, 1], n[:, 0], np.zeros(len(n))), axis=-1)
    opposite = q[:, 0] < 1e-9
    q[opposite] = (0.0, 1.0, 0.0, 0.0)  # -z: half a turn about x
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotate(wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors v (K, 3) (or one (3,)) turned by quaternions wxyz (K, 4)."""
    w, xyz = wxyz[:, :1], wxyz[:, 1:]
    v = np.broadcast_to(np.asarray(v, float), xyz.shape)
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)


def cylinder(segments: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A unit cylinder along +z from z = 0 to 1, radius 1, without caps: vertices, faces."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack((np.cos(a), np.sin(a)), -1)
    verts = np.concatenate((np.c_[ring, np.zeros(segments)], np.c_[ring, np.ones(segments)]))
    i = np.arange(segments)
    j = (i + 1) % segments
    faces = np.concatenate((np.stack((i, j, segments + j), -1), np.stack((i, segments + j, segments + i), -1)))
    return verts, faces.astype(np.uint32)


def disc(segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A unit disc in the xy-plane, facing +z: vertices, faces (a triangle fan)."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.concatenate(([[0.0, 0.0, 0.0]], np.stack((np.cos(a), np.sin(a), np.zeros(segments)), -1)))
    i = np.arange(segments)
    faces = np.stack((np.zeros(segments, int), 1 + i, 1 + (i + 1) % segments), -1)
    return verts, faces.astype(np.uint32)
