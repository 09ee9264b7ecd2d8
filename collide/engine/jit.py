"""The kernels' decorators: numba's `njit` with the engine's options when this process runs the
compiled kernels (`collide.engine.tier` decides), or nothing, so the same code runs as Python."""

from __future__ import annotations

import importlib.util

from collide.engine import tier


def _skip_blas_probe() -> None:
    """numba's target set-up, which loading a cached kernel needs, imports scipy.linalg (0.2 s of
    CPU, a sixth of a compiled run's start) only to record whether BLAS is there for its matrix
    products. The kernels use none. Record it from whether scipy is installed, as numba's probe
    would; scipy.linalg is then imported only if something compiles a BLAS call."""
    from numba.np import linalg

    probe = linalg.ensure_blas

    def unprobed() -> None:
        raise ImportError("not probed")

    linalg.ensure_blas = unprobed
    try:
        from numba.np import arraymath
    finally:
        linalg.ensure_blas = probe
    arraymath.ensure_blas = probe
    arraymath._HAVE_BLAS = importlib.util.find_spec("scipy") is not None


if tier.COMPILED:
    from numba import config, njit

    _skip_blas_probe()

    # The cache folder named after every kernel source (tier.cache_key): never a stale callee.
    config.CACHE_DIR = str(tier.cache_dir())
    # error_model="numpy": a division by zero gives inf or NaN (checked after each step) instead
    # of raising, which also keeps the compiled code smaller.
    jit = njit(cache=True, error_model="numpy", nogil=True)
    # Pieces called per contact, per body or per substep, which allocate nothing (a contact
    # law's parts, a body's turn; the event engine's step with its kicks, friction solve,
    # geometry and mode values): inlined into the loops, and without reference counting
    # (`_nrt=False`, as numba's own sort and string helpers): a call each time, and the atomic
    # counts of each array passed, cost more than the physics (a quarter of the DEM step; the
    # event engine's steps 2-5 times, measured).
    jit_inline = njit(cache=True, error_model="numpy", nogil=True, forceinline=True, _nrt=False)
    # Large pieces of that kind called from several places (the event engine's step, friction
    # solve, hold, mode values, decision, settling): called, not copied into every call site,
    # which multiplied the machine code (the cache 32 MB) and the compile's time; still without
    # reference counting, which was most of the gain. Kernel times unchanged, measured.
    jit_call = njit(cache=True, error_model="numpy", nogil=True, _nrt=False)
else:
    def jit(function):
        """Interpreted: the kernel as plain Python."""
        return function

    jit_inline = jit
    jit_call = jit
