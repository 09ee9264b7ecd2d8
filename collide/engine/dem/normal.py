"""Normal force: linear (k delta, springs in series) or Hertz (4/3 E* sqrt(R*) delta^1.5): docs/design.md section 9."""

from __future__ import annotations

import math

from collide.engine.jit import jit_inline


@jit_inline
def normal_elastic(hertz, k, estar, rstar, delta):
    """Elastic normal force and stiffness dF/d delta: linear k delta, or Hertz 4/3 E* sqrt(R*) delta^1.5."""
    if hertz:
        root = math.sqrt(rstar * delta)
        return 4.0 / 3.0 * estar * root * delta, 2.0 * estar * root
    return k * delta, k


@jit_inline
def normal_curvature(hertz, estar, rstar, delta):
    """How `normal_elastic`'s stiffness changes with the overlap, d^2F/d delta^2: none for the
    linear spring, Hertz's E* sqrt(R* / delta) (its stiffness over 2 delta) at delta > 0."""
    if hertz:
        return estar * math.sqrt(rstar / delta)
    return 0.0


@jit_inline
def normal_energy(hertz, k, estar, rstar, delta):
    """The energy `normal_elastic`'s spring holds at overlap delta: k delta^2 / 2, or Hertz's
    8/15 E* sqrt(R*) delta^2.5."""
    if hertz:
        return 8.0 / 15.0 * estar * math.sqrt(rstar * delta) * delta * delta
    return 0.5 * k * delta * delta
