"""Counts a user may set in the environment, read and checked without loading the engine (the
CLI checks them before a command runs, and the engine reads them where it uses them)."""

from __future__ import annotations

import os

# At most this many threads step a batch's members or a DEM run (default: every core the
# process may use); a Dask worker sets 1, its cluster being shaped to the cores already.
THREADS_VARIABLE = "COLLIDE_THREADS"
# A DEM run's recording: a frame each K steps (`collide run --frame-steps K`).
FRAME_STEPS_VARIABLE = "COLLIDE_FRAME_STEPS"
COUNT_VARIABLES = (THREADS_VARIABLE, FRAME_STEPS_VARIABLE)


def count_setting(name: str) -> int | None:
    """The count set in the environment variable `name`, None if unset or empty. Anything but a
    whole number >= 1 is refused (ValueError naming the variable): a typo must not run silently
    with the default."""
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"{name}: a whole number >= 1, got '{text}'")
    return int(text)


def check_count_settings() -> None:
    """Refuse a malformed count in the environment before anything runs."""
    for name in COUNT_VARIABLES:
        count_setting(name)
