"""The engine's small numerics (collide/engine/numerics.py): the hold system's factor and solve,
the cubic dip bound, buffers that grow."""

from __future__ import annotations

import math

import numpy as np
import pytest

from collide.engine import layout, numerics


@pytest.mark.parametrize("symmetric", [True, False])
def test_the_hold_system_is_solved_as_numpy_solves_it(symmetric):
    """W f = b by `factor` and `solve_factored`: L D L^T where W is symmetric (positive definite,
    as a stuck set's W is: J M^-1 J^T; from its lower triangle only, as `hold_matrix` builds it),
    LU with row swaps where it is not (the seed's levers), against numpy's solve to round-off;
    an exactly singular W is reported, not solved."""
    rng = np.random.default_rng(3)
    for m in (1, 4, 10, 16):
        # Contacts coupled through shared bodies: a sparse J, each contact on bodies of its own.
        J = rng.normal(size=(m, 3 * m)) * (rng.random((m, 3 * m)) < 0.2) + np.eye(m, 3 * m)
        W = J @ J.T if symmetric else J @ J.T + 0.1 * rng.normal(size=(m, m))
        A = np.zeros((48, 48))
        # Symmetric: the upper triangle is never built, so it must never be read.
        A[:m, :m] = np.where(np.tri(m, dtype=bool), W, np.nan) if symmetric else W
        piv = np.zeros(48, np.int64)
        b = rng.normal(size=48)
        expected = np.linalg.solve(W, b[:m])
        assert numerics.factor(A, piv, m, symmetric)
        numerics.solve_factored(A, piv, b, m, symmetric)
        # Condition numbers here are below 1e3: 1e-12 is a thousand times round-off.
        assert np.linalg.cond(W) < 1e3
        assert b[:m] == pytest.approx(expected, rel=1e-12, abs=1e-12 * np.abs(expected).max())
    A = np.zeros((4, 4))
    A[:2, :2] = [[1.0, 1.0], [1.0, 1.0]]  # two contacts that are one
    assert not numerics.factor(A, np.zeros(4, np.int64), 2, symmetric)


def test_a_dip_bound_skips_only_cubics_that_do_not_dip():
    """`hermite_dip` skips its samples where a bound shows the cubic stays above the floor: over
    random ends and rates (values near the floor, rates up to 40 times them), its answer is the
    samples' own."""
    rng = np.random.default_rng(11)

    def sampled(e0, e1, r0, r1, floor):
        if r0 >= 0.0 and r1 <= 0.0:
            return math.inf
        for i in range(1, int(layout.DIP_SAMPLES)):
            u = i / layout.DIP_SAMPLES
            p = ((2 * u**3 - 3 * u**2 + 1) * e0 + (u**3 - 2 * u**2 + u) * r0 + (3 * u**2 - 2 * u**3) * e1
                 + (u**3 - u**2) * r1)
            if p < floor:
                return u
        return math.inf

    answers = []
    for _ in range(20000):
        e0, e1 = rng.uniform(1e-10, 1.0, 2) * 10.0 ** rng.integers(-6, 1)
        r0, r1 = rng.normal(size=2) * 40 * max(e0, e1)
        got = numerics.hermite_dip(e0, e1, r0, r1, -1e-9)
        assert got == sampled(e0, e1, r0, r1, -1e-9)
        answers.append(got)
    dips = np.isfinite(answers).sum()
    assert 1000 < dips < 19000  # both kinds were tried


def test_engine_buffers_grow_to_any_row_asked_for():
    """An island opening more contacts at once than a buffer's doubling gave room for wrote past
    its end (a 64-sphere drop on a floor aborted the process): growth reaches the row asked for.
    The rule is checked as Python source (`py_func` when compiled): the kernels call it inside
    compiled code, and calling this helper's compiled dispatcher from Python, after a run has
    loaded the kernels that use it from numba's cache, fails in numba's boxing ("'descr' is
    NULL") on a freshly warmed cache."""
    for kernel, dtype in ((numerics.grow, float), (numerics.grow_int, np.int64)):
        grow = getattr(kernel, "py_func", kernel)
        buf = np.arange(64, dtype=dtype).reshape(16, 4)
        out = grow(buf, 500)
        assert out.shape[0] > 500 and out.shape[1] == 4
        assert (out[:16] == buf).all()
