"""The integrators: the report's update, and symmetric compositions of Verlet substeps.

The compositions step the contact phase of each island in the compiled engine
(`collide.engine.event.substep.step`): a symmetric composition of velocity-Verlet (kick-drift-kick)
substeps gamma h is second order and symplectic for one substep and of higher order for more,
and every one of them applies forces as equal and opposite impulses, so linear and angular
momentum are conserved to round-off whatever the step.
"""

from __future__ import annotations

from dataclasses import dataclass

_CBRT2 = 2.0 ** (1.0 / 3.0)
_Y1 = 1.0 / (2.0 - _CBRT2)
# Yoshida (1990) fourth order; Kahan & Li (1997) s9odr6a sixth order.
YOSHIDA4 = (_Y1, -_CBRT2 * _Y1, _Y1)
# Suzuki (1990) fourth order in five substeps, and Yoshida (1990) sixth order in seven (his
# solution A): the event search's trials between Yoshida4's reach and a whole kahan6 step.
_S1 = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
SUZUKI4 = (_S1, _S1, 1.0 - 4.0 * _S1, _S1, _S1)
_Y6 = (0.784513610477560, 0.235573213359357, -1.17767998417887)
YOSHIDA6 = _Y6 + (1.0 - 2.0 * sum(_Y6),) + _Y6[::-1]
_KL6_HALF = (0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
             0.08221359629355080023)
KAHAN6 = _KL6_HALF + (0.79854399093482996340,) + _KL6_HALF[::-1]


@dataclass(frozen=True)
class Integrator:
    """An integrator: its substep weights, order without friction, linear stability limit
    (omega h), and whether it locates contact starts and ends and friction mode changes exactly
    (the seed's update keeps the report's fixed grid instead)."""

    name: str
    weights: tuple[float, ...]
    order: int
    stability: float
    events: bool


INTEGRATORS: dict[str, Integrator] = {
    "seed": Integrator("seed", (1.0,), 1, 2.0, events=False),
    "verlet": Integrator("verlet", (1.0,), 2, 2.0, events=True),
    "yoshida4": Integrator("yoshida4", YOSHIDA4, 4, 2.0 / (_CBRT2 * _Y1), events=True),
    "kahan6": Integrator("kahan6", KAHAN6, 6, 2.0 / max(abs(x) for x in KAHAN6), events=True),
    # The fixed-step DEM kernel (collide.engine.dem): velocity Verlet, contacts switch at steps.
    "dem": Integrator("dem", (1.0,), 2, 2.0, events=False),
}
