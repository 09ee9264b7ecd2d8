"""An island's tables built by hand for the stage tests of tests/engine/event/."""

from __future__ import annotations

import numpy as np

from collide.engine import layout


def pressed_island(dim: int, seed: bool, wall: bool):
    """Two spinning spheres pressed together (and the first onto a wall), as an island's tables."""
    rng = np.random.default_rng(3)
    X = np.zeros((2, int(layout.NX)))
    X[0, layout.X_S:layout.X_S + 3] = [0.0, 0.031, 0.01]
    X[1, layout.X_S:layout.X_S + 3] = [0.04, 0.0, 0.0]
    X[:, layout.X_V:layout.X_V + 3] = rng.normal(size=(2, 3))
    X[:, layout.X_W:layout.X_W + 3] = rng.normal(size=(2, 3)) * 5
    if dim == 2:
        X[:, layout.X_S + 2] = X[:, layout.X_V + 2] = 0.0
        X[:, layout.X_W] = X[:, layout.X_W + 1] = 0.0
    mass, radius = np.array([0.03, 0.02]), np.array([0.03, 0.025])
    X[:, layout.X_M], X[:, layout.X_IM], X[:, layout.X_R] = mass, 1 / mass, radius
    X[:, layout.X_I] = 0.4 * mass * radius**2
    X[:, layout.X_II] = 1 / X[:, layout.X_I]
    nc = 2 if wall else 1
    C = np.zeros((nc, int(layout.NC)))
    CI = np.zeros((nc, int(layout.NCI)), np.int64)
    CI[0, :4] = [0, 1, 0, 1]
    C[0, layout.C_K], C[0, layout.C_REACH] = 750.0, radius.sum()
    WP = np.zeros((1, 6))
    if wall:
        WP[0] = [0.0, 0.0025, 0.0, 0.0, 1.0, 0.0]
        CI[1, :4] = [0, -1, 0, -1]
        C[1, layout.C_K], C[1, layout.C_REACH] = 1500.0, radius[0]
    return X, C, CI, WP, nc, np.array([0.0, -9.81, 0.0])
