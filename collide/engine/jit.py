"""The kernels' decorators: numba's `njit` with the engine's options when this process runs the
compiled kernels (`collide.engine.tier` decides), or nothing, so the same code runs as Python."""

from __future__ import annotations

from collide.engine import tier

if tier.COMPILED:
    from numba import config, njit

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
else:
    def jit(function):
        """Interpreted: the kernel as plain Python."""
        return function

    jit_inline = jit
