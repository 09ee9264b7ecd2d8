"""Columns for Rerun's `send_columns` built in numpy and Arrow (rerun's own builders convert
row by row in Python)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.encodings import Vec3DBatch


class _Arrow:
    """A ready Arrow array as a component batch (skips rerun's per-row Python conversion)."""

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def _rows_of(flat: pa.Array, width: int, rows: int, type_: pa.DataType | None = None) -> pa.ListArray:
    offsets = pa.array(np.arange(rows + 1, dtype=np.int32) * width)
    return pa.ListArray.from_arrays(offsets, flat, type=type_)


def _any_column(name: str, flat: np.ndarray, width: int, rows: int) -> rr.ComponentColumn:
    """An AnyValues column of `rows` rows of `width` values each, in the array's dtype (float64)."""
    column = rr.AnyBatchValue.column(name, _rows_of(pa.array(flat), width, rows))
    assert column is not None
    return column


def _strips_column(strips: np.ndarray) -> rr.ComponentColumn:
    """LineStrips3D strips (T, P, 3): one strip of P points per row, built in numpy."""
    rows, points = strips.shape[:2]
    inner = Vec3DBatch(strips.reshape(-1, 3).astype(np.float32)).as_arrow_array()
    array = _rows_of(inner, points, rows, rr.components.LineStrip3DBatch._ARROW_DATATYPE)
    return rr.ComponentColumn(rr.LineStrips3D.descriptor_strips(), _Arrow(array))
