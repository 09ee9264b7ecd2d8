"""How long a run may go: the step limits (light: the CLI shows them in its help)."""

from __future__ import annotations

MAX_STEPS_DEFAULT = 20_000_000  # a run with a duration: it ends, the limit only guards a runaway
# A run with no duration ends by itself: when nothing can meet again (or, in DEM, at rest). One
# that has not after this many steps is refused, not left to run for minutes: a chain of soft 1D
# spheres with long free flights took 2e7 DEM steps (134 s) without ending. The built-ins that end
# by themselves take 9 to 31 065 steps.
OPEN_RUN_STEPS = 1_000_000


def step_limit(durations: list[float | None], max_steps: int | None) -> int:
    """The steps a run may take: `max_steps` if given, else by whether every member has a duration."""
    if max_steps is not None:
        return max_steps
    return MAX_STEPS_DEFAULT if all(d is not None for d in durations) else OPEN_RUN_STEPS
