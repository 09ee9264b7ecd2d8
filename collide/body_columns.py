"""A scene's bodies held as columns, one array per value, and read as a sequence of `Body`.

A scene of many spheres (a fill, a body table) is made from columns and handed to the engine as
columns: one `Body` object per sphere cost about 1.2 KB each (120 MB for 100 000 spheres, more
than the whole run's tables), the columns about 90 bytes plus the name. Code that reads one body,
or a few, indexes or iterates as before and gets `Body` values made on the fly; code that reads
them all asks `as_bodies(...)` for the columns.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from collide.scene_values import Body

SPIN_DIM = {1: 0, 2: 1, 3: 3}


class Bodies(Sequence):
    """N bodies of one dimension: names (N,), mass, radius, inertia (N,), position and velocity
    (N, dim), spin (N, 0 | 1 | 3), material names (N,) (None for none)."""

    __slots__ = ("names", "mass", "radius", "inertia", "position", "velocity", "spin", "material")

    def __init__(self, names: Sequence[str], mass: np.ndarray, radius: np.ndarray, inertia: np.ndarray,
                 position: np.ndarray, velocity: np.ndarray, spin: np.ndarray,
                 material: Sequence[str | None]) -> None:
        self.names = list(names)
        self.mass = np.asarray(mass, dtype=float)
        self.radius = np.asarray(radius, dtype=float)
        self.inertia = np.asarray(inertia, dtype=float)
        self.position = np.asarray(position, dtype=float)
        self.velocity = np.asarray(velocity, dtype=float)
        self.spin = np.asarray(spin, dtype=float)
        self.material = list(material)

    @classmethod
    def of(cls, bodies: Sequence[Body], dim: int) -> Bodies:
        """The columns of a sequence of `Body`."""
        n = len(bodies)
        return cls([b.name for b in bodies], np.array([b.mass for b in bodies], dtype=float),
                   np.array([b.radius for b in bodies], dtype=float),
                   np.array([b.inertia for b in bodies], dtype=float),
                   np.array([b.position for b in bodies], dtype=float).reshape(n, dim),
                   np.array([b.velocity for b in bodies], dtype=float).reshape(n, dim),
                   np.array([b.spin for b in bodies], dtype=float).reshape(n, SPIN_DIM[dim]),
                   [b.material for b in bodies])

    @property
    def dim(self) -> int:
        return self.position.shape[1]

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            return Bodies(self.names[index], self.mass[index], self.radius[index], self.inertia[index],
                          self.position[index], self.velocity[index], self.spin[index], self.material[index])
        i = range(len(self))[index]  # an int, negative counted from the end; IndexError past it
        return Body(self.names[i], float(self.mass[i]), float(self.radius[i]), float(self.inertia[i]),
                    tuple(self.position[i].tolist()), tuple(self.velocity[i].tolist()),
                    tuple(self.spin[i].tolist()), self.material[i])

    def __iter__(self) -> Iterator[Body]:
        rows = zip(self.names, self.mass.tolist(), self.radius.tolist(), self.inertia.tolist(),
                   map(tuple, self.position.tolist()), map(tuple, self.velocity.tolist()),
                   map(tuple, self.spin.tolist()), self.material)
        return (Body(*row) for row in rows)

    def __add__(self, other: Sequence[Body]) -> Bodies:
        more = as_bodies(other, self.dim)
        return Bodies(self.names + more.names, np.concatenate((self.mass, more.mass)),
                      np.concatenate((self.radius, more.radius)), np.concatenate((self.inertia, more.inertia)),
                      np.concatenate((self.position, more.position)), np.concatenate((self.velocity, more.velocity)),
                      np.concatenate((self.spin, more.spin)), self.material + more.material)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Bodies):
            return (self.names == other.names and self.material == other.material
                    and all(np.array_equal(getattr(self, c), getattr(other, c))
                            for c in ("mass", "radius", "inertia", "position", "velocity", "spin")))
        if isinstance(other, Sequence) and not isinstance(other, str):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]  # mutable columns, like a list

    def __repr__(self) -> str:
        return f"Bodies({len(self)} in {self.dim}D)"


def as_bodies(bodies: Sequence[Body], dim: int) -> Bodies:
    """The columns of any sequence of bodies (itself when it is held as columns)."""
    return bodies if isinstance(bodies, Bodies) else Bodies.of(bodies, dim)
