"""The environment a command uses to tell the engine how to run its kernels (read by
`collide.engine.tier` when the engine is first imported).

Which runs are quicker interpreted is decided above the engine, in `collide.hint`: it sets
HINT_VARIABLE before the engine is imported; COLLIDE_JIT, when set, overrides it.
"""

from __future__ import annotations

import os

HINT_VARIABLE = "COLLIDE_JIT_HINT"


def jit_setting() -> str:
    """COLLIDE_JIT as the engine reads it: "compiled", "interpreted" or "auto" (unset or other)."""
    setting = os.environ.get("COLLIDE_JIT", "auto").strip().lower()
    if setting in ("1", "yes", "true", "on"):
        return "compiled"
    if setting in ("0", "no", "false", "off"):
        return "interpreted"
    return "auto"
