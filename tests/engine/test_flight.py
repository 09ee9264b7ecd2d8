"""Free flight (collide/engine/flight.py): a body's turn is the rotation about its spin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from collide.engine import flight


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis / np.linalg.norm(axis)])


@pytest.mark.parametrize("half", [1e-9, 1e-4, 0.00316, 0.00317, 0.0999, 0.1001, 0.7])
def test_turn_is_the_rotation_about_the_spin(half):
    """flight.turn takes small turns by series (to x^4 below a half angle of sqrt(1e-5), to x^8
    below 0.1) and larger ones by sin and cos: on either side of each switch, and from an
    arbitrary start, it is the rotation by |w| tau about w (a unit quaternion product) to
    round-off."""
    w = np.array([3.0, -4.0, 12.0])  # |w| = 13
    tau = 2.0 * half / 13.0
    start = _axis_angle(np.array([1.0, 2.0, -0.5]), 0.8)
    q = start.copy()
    flight.turn(q, w[0], w[1], w[2], tau, False)
    r = _axis_angle(w, 13.0 * tau)
    expected = np.array([r[0] * start[0] - r[1:] @ start[1:],
                         *(r[0] * start[1:] + start[0] * r[1:] + np.cross(r[1:], start[1:]))])
    assert np.abs(q - expected).max() < 4e-16
    assert abs(np.linalg.norm(q) - 1.0) < 4e-16


def test_many_small_turns_compose_to_one():
    """A thousand DEM-sized turns (series) about one axis make the one turn (sin and cos)."""
    w = np.array([0.3, 50.0, -7.0])
    many, once = _axis_angle(np.array([0.0, 0.0, 1.0]), 0.3), _axis_angle(np.array([0.0, 0.0, 1.0]), 0.3)
    for _ in range(1000):
        flight.turn(many, w[0], w[1], w[2], 1e-5, False)
    flight.turn(once, w[0], w[1], w[2], 1e-2, False)
    assert np.abs(many - once).max() < 1e-13


def _components(n: int, pairs: list[tuple[int, int]]) -> list[int]:
    """Each body's smallest fellow in its connected component (a plain graph search)."""
    neighbours: dict[int, set[int]] = {i: set() for i in range(n)}
    for i, j in pairs:
        if i >= 0 and j >= 0:
            neighbours[i].add(j)
            neighbours[j].add(i)
    label = [-1] * n
    for start in range(n):
        if label[start] >= 0:
            continue
        todo, seen = [start], {start}
        while todo:
            for other in neighbours[todo.pop()] - seen:
                seen.add(other)
                todo.append(other)
        for body in seen:
            label[body] = min(seen)
    return label


def test_contacts_folded_in_steps_give_the_components_and_counts_of_all_of_them():
    """account_contacts folds only the intervals opened since its last call (a jump costs the
    bodies, not the run's contacts so far): after folding in several steps, and after a window
    redone (fewer intervals than were folded), the speed scales are those of the whole contact
    graph (each body's fastest fellow in its component) and the counts each body's contacts."""
    from collide.engine.layout import CN_IVALS, V_I, V_J

    rng = np.random.default_rng(5)
    n = 9
    pairs = [(int(i), int(j)) if j >= 0 else (int(i), -1 - int(rng.integers(2)))
             for i, j in zip(rng.integers(0, n, 40), rng.integers(-2, n, 40)) if i != j]
    IV = np.zeros((len(pairs), 4))
    IV[:, V_I] = [i for i, _ in pairs]
    IV[:, V_J] = [j for _, j in pairs]
    V = rng.normal(size=(n, 3))
    parent, count, seen = np.arange(n), np.zeros(n), np.zeros(1, np.int64)
    CNT = np.zeros(4, np.int64)
    for upto in (0, 3, 11, 30, 12, len(pairs)):  # 30 -> 12: a window redone
        CNT[CN_IVALS] = upto
        flight.account_contacts(IV, CNT, parent, count, seen)
        label = _components(n, pairs[:upto])
        speed = np.linalg.norm(V, axis=1)
        fastest = [max(speed[b] for b in range(n) if label[b] == label[a]) for a in range(n)]
        assert np.array_equal(flight.speed_scales(V, n, parent), fastest)
        assert np.array_equal(count, [sum((i == b) + (j == b) for i, j in pairs[:upto]) for b in range(n)])
