"""How long a run may go: the step limits (light: the CLI shows them in its help)."""

from __future__ import annotations

MAX_STEPS_DEFAULT = 20_000_000  # a run with a duration: it ends, the limit only guards a runaway
# A run with no duration ends by itself: when nothing can meet again (or, in DEM, at rest). One
# that has not after this many steps is refused, not left to run for minutes: a chain of soft 1D
# spheres with long free flights took 2e7 DEM steps (134 s) without ending. The built-ins that end
# by themselves take 9 to 31 065 steps.
OPEN_RUN_STEPS = 1_000_000
# ... or this many contacts' worth of steps, if more: a step the user made fine (demo-bonus at
# dt = 1e-8 takes 1.3e6 steps for its one contact) is theirs to pay for, up to the limit of a
# run with a duration.
OPEN_RUN_CONTACTS = 50
# The report's update (the seed) steps every body at every step, 90-180 ns per body and step
# (measured: 26 spheres in 1D, 8 in 2D), so its limit is also in body-steps: 1e8 is 9-18 s of
# CPU, where 2e7 steps of 26 spheres took 48 s and of 8 spheres 29 s before the run was refused.
SEED_BODY_STEPS = 100_000_000


def step_limit(durations: list[float | None], max_steps: int | None, steps_per_contact: float = 0.0,
               every_body: int = 0) -> int:
    """The steps a run may take: `max_steps` if given, else by whether every member has a duration
    (and, for one that has not, by the steps one contact takes at its step); `every_body`: the
    bodies a step updates where every step updates all of them (the seed), 0 otherwise."""
    if max_steps is not None:
        return max_steps
    if all(d is not None for d in durations):
        limit = MAX_STEPS_DEFAULT
    else:
        limit = int(max(OPEN_RUN_STEPS, min(MAX_STEPS_DEFAULT, OPEN_RUN_CONTACTS * steps_per_contact)))
    if every_body:
        limit = min(limit, max(OPEN_RUN_STEPS, SEED_BODY_STEPS // every_body))
    return limit
