"""A VTK time series as ParaView reads it: a `.pvd` collection and one `.vtp` PolyData file a frame.

Each `.vtp` holds the spheres as points (point data `radius` m, `velocity` m/s and `spin` rad/s
as 3 components, `id` the body's number) and the contacts pressed at that frame as lines
(cell data `i`, `j`, `overlap` m, `normal_force` N (magnitude), `normal_force_vector` N and, with
friction, `friction_force` N, both on body i). A contact with a wall runs from the sphere to an
extra point at the contact point on the wall, after the spheres: its `id` is -1 - wall (like j),
its radius, velocity and spin zero. Arrays are base64 binary (`format="binary"`, a UInt32 byte
count before the little-endian data: VTK's XML layout) or, with `ascii=True`, plain numbers.
Written with numpy and the standard library: the files are a few lines of XML.
"""

from __future__ import annotations

import base64
import struct
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from collide.export.frames import Frames

_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.int32): "Int32", np.dtype(np.int64): "Int64"}


def _data_array(name: str, values: np.ndarray, ascii: bool, components: int = 1) -> str:
    values = np.ascontiguousarray(values)
    head = f'<DataArray type="{_TYPES[values.dtype]}" Name={quoteattr(name)}'
    if components > 1:
        head += f' NumberOfComponents="{components}"'
    if ascii:
        body = " ".join(repr(float(x)) if values.dtype.kind == "f" else str(int(x)) for x in values.reshape(-1))
        return f'{head} format="ascii">{body}</DataArray>'
    raw = values.astype(values.dtype.newbyteorder("<"), copy=False).tobytes()
    body = base64.b64encode(struct.pack("<I", len(raw)) + raw).decode("ascii")
    return f'{head} format="binary">{body}</DataArray>'


def frame_polydata(frames: Frames, k: int, ascii: bool = False) -> str:
    """One frame as a VTK XML PolyData file (text)."""
    n = len(frames.names)
    rows = frames.contacts_at(k)
    pairs = frames.pairs[rows]
    wall = pairs[:, 1] < 0
    extra = frames.point[rows][wall]  # wall contacts end at their contact point on the wall
    points = np.concatenate((frames.s[k], extra))
    ids = np.concatenate((np.arange(n), pairs[wall, 1])).astype(np.int32)
    zeros = np.zeros((len(extra), 3))
    radius = np.concatenate((frames.radius, np.zeros(len(extra))))
    velocity = np.concatenate((frames.v[k], zeros))
    spin = np.concatenate((frames.w[k], zeros))
    ends = pairs[:, 1].astype(np.int64).copy()
    ends[wall] = n + np.arange(int(wall.sum()))
    connectivity = np.stack((pairs[:, 0].astype(np.int64), ends), axis=1).reshape(-1)
    offsets = 2 * np.arange(1, len(pairs) + 1, dtype=np.int64)
    normal = frames.normal_force[rows]
    cells = [_data_array("i", pairs[:, 0].astype(np.int32), ascii),
             _data_array("j", pairs[:, 1].astype(np.int32), ascii),
             _data_array("overlap", frames.overlap[rows], ascii),
             _data_array("normal_force", np.linalg.norm(normal, axis=1), ascii),
             _data_array("normal_force_vector", normal, ascii, 3)]
    if frames.friction is not None:
        cells.append(_data_array("friction_force", frames.friction[rows], ascii, 3))
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt32">',
        "<PolyData>",
        f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="{len(pairs)}" '
        'NumberOfStrips="0" NumberOfPolys="0">',
        '<PointData Scalars="radius" Vectors="velocity">',
        _data_array("radius", radius, ascii), _data_array("velocity", velocity, ascii, 3),
        _data_array("spin", spin, ascii, 3), _data_array("id", ids, ascii),
        "</PointData>",
        '<CellData Scalars="normal_force">', *cells, "</CellData>",
        "<Points>", _data_array("Points", np.asarray(points, float), ascii, 3), "</Points>",
        "<Lines>", _data_array("connectivity", connectivity, ascii), _data_array("offsets", offsets, ascii),
        "</Lines>",
        "</Piece>", "</PolyData>", "</VTKFile>", "",
    ]
    return "\n".join(lines)


def collection(frames: Frames, folder_name: str) -> str:
    """The `.pvd` collection: one DataSet per frame, its file relative to the `.pvd`."""
    rows = [f'<DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f"{folder_name}/{frame_name(k)}")}/>'
            for k, t in enumerate(frames.times.tolist())]
    return "\n".join(['<?xml version="1.0"?>',
                      '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                      "<Collection>", *rows, "</Collection>", "</VTKFile>", ""])


def frame_name(k: int) -> str:
    return f"frame_{k:05d}.vtp"


def write_frames(frames: Frames, folder: Path, ascii: bool = False) -> None:
    """Every frame's `.vtp` into `folder` (which exists)."""
    for k in range(len(frames.times)):
        (folder / frame_name(k)).write_text(frame_polydata(frames, k, ascii), encoding="ascii")
