"""The invariant every run keeps: bodies never end a run passed through one another (nor
through a wall). Checked on the run's result, after the engine, so that any hole left in the
engine's approach tests is a refusal with the cause, never a wrong answer.

A contact law turns the scene's energy into overlap, and no more: a linear spring at most
sqrt(2 E / k), Hertz at most (15 E / (8 E* sqrt(R*)))^(2/5), E the energy that can reach one
contact (the kinetic energy relative to the centre of mass, spin included; on walls all of it,
plus the fall under gravity from each start). A pair deeper than SLACK times its own bound has
gone into or through the other (in 1D: out of order), whenever it happened.
"""

from __future__ import annotations

import numpy as np

from collide.errors import RunError
from collide.model import TABLE_ESTAR, TABLE_K
from collide.scene import TOUCHING

# Over the energy's bound: the step's own energy error (within --tol, far below this) and a
# pile's settling under gravity stay well inside.
SLACK = 1.5
ULPS = 16.0  # positions' round-off, in units in the last place of the larger coordinate


def round_off(reach: np.ndarray | float, where: np.ndarray | float) -> np.ndarray | float:
    """An overlap that is no contact: spheres that start touching to round-off (the scene's
    TOUCHING share of r_i + r_j) and the positions' own round-off at coordinates of size `where`."""
    return TOUCHING * reach + ULPS * np.spacing(np.abs(where))


def available_energy(model, state) -> np.ndarray:
    """The energy (B,) J that can go into one contact: kinetic energy relative to the centre of
    mass (all of it with walls, which take momentum), spin included, plus the fall under gravity
    onto a wall from each body's start."""
    m, v = model.mass, state.v
    if not model.n_walls:
        v = v - (np.einsum("bn,bnd->bd", m, v) / m.sum(axis=1)[:, None])[:, None, :]
    energy = 0.5 * (m * (v ** 2).sum(-1)).sum(-1)
    if state.w.shape[-1]:
        energy = energy + 0.5 * (model.inertia * (state.w ** 2).sum(-1)).sum(-1)
    if model.gravity is not None and model.n_walls:
        height = np.einsum("bnd,wd->bwn", state.s, model.wall_normal) - \
            (model.wall_point * model.wall_normal).sum(-1)[None, :, None]
        into = np.maximum(-np.einsum("bd,wd->bw", model.gravity, model.wall_normal), 0.0)
        energy = energy + (m * (into[:, :, None] * np.maximum(height, 0.0)).max(axis=1)).sum(-1)
    return energy


def _depth(model, energy: float, k, estar, rstar) -> np.ndarray:
    """The deepest overlap the contact law reaches storing `energy`."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if model.hertz:
            return (15.0 * energy / (8.0 * estar * np.sqrt(rstar))) ** 0.4
        return np.sqrt(2.0 * energy / k)


def pair_depth(model, energy: float, b: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The deepest overlap (P,) each pair (i, j) of member b reaches with `energy`."""
    mi, mj = model.material[b, i], model.material[b, j]
    ri, rj = model.radius[b, i], model.radius[b, j]
    row = model.pair_table[b, mi, mj]
    return _depth(model, energy, row[..., TABLE_K], row[..., TABLE_ESTAR], ri * rj / (ri + rj))


def wall_depth(model, energy: float, b: int) -> np.ndarray:
    """The deepest overlap (N,) each sphere of member b reaches on a wall."""
    row = model.wall_table[b, model.material[b]]
    return _depth(model, energy, row[:, TABLE_K], row[:, TABLE_ESTAR], model.radius[b])


def deepest_any(model, energy: float, b: int) -> float:
    """A bound on every contact's overlap in member b: its softest pair (smallest radii) or wall."""
    mats = np.unique(model.material[b])
    table = model.pair_table[b][np.ix_(mats, mats)]
    small = np.sort(model.radius[b])[:2]
    rstar = small.prod() / small.sum() if len(small) > 1 else small[0]
    out = float(_depth(model, energy, table[..., TABLE_K].min(), table[..., TABLE_ESTAR].min(), rstar)) \
        if model.n_bodies > 1 else 0.0
    if model.n_walls:
        out = max(out, float(wall_depth(model, energy, b).max()))
    return out


GRID_FROM = 2000  # bodies from which the final pairs are found on a cell grid


def near_pairs(s: np.ndarray, within: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) holding every pair whose centres are within `within`: from GRID_FROM bodies
    (compiled) the DEM kernel's cell grid, exactly those; else those within it along the first
    axis, sorted along it, each body against the next, the one after, ... while any is that close
    (in a box of spheres in columns that is most of a column: 10 GB at 100 000 spheres)."""
    if len(s) >= GRID_FROM:
        from collide.engine import tier

        if tier.COMPILED:
            from collide.engine.dem.layout import NB
            from collide.engine.dem.neighbours import build_pairs

            P = np.zeros((len(s), 3))
            P[:, :s.shape[1]] = s
            i, j = build_pairs(P, np.zeros((len(s), int(NB))), len(s), s.shape[1], float(within))
            return i, j
    order = np.argsort(s[:, 0], kind="stable")
    x = s[order, 0]
    found_i, found_j = [], []
    for offset in range(1, len(order)):
        close = x[offset:] - x[:-offset] < within
        if not close.any():
            break
        found_i.append(order[:-offset][close])
        found_j.append(order[offset:][close])
    if not found_i:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(found_i), np.concatenate(found_j)


def passed_through(model, initial, final, max_overlap: np.ndarray | None = None,
                   free_since: np.ndarray | None = None) -> str | None:
    """Why a run broke the invariant (the first member that did), or None. `max_overlap` (B,):
    the deepest overlap any contact reached; `free_since` (B, N): when each body's last contact
    ended (its free flight to the end began), where the engine knows it."""
    energy = available_energy(model, initial)
    for b in range(model.batch):
        reason = _member(model, float(energy[b]), initial.s[b], final, b,
                         None if max_overlap is None else float(max_overlap[b]),
                         None if free_since is None else free_since[b])
        if reason:
            return (f"run {b}: " if model.batch > 1 else "") + reason
    return None


def _member(model, energy: float, start: np.ndarray, final, b: int, max_overlap: float | None,
            since: np.ndarray | None) -> str | None:
    reason = _final_pairs(model, energy, start, final, b)
    if not reason and model.n_walls:
        reason = _walls(model, energy, final, b)
    if not reason and since is not None and model.dim > 1 and model.n_bodies > 1:
        reason = _free_flight(model, energy, final, since, b)
    if not reason and max_overlap is not None:
        reason = _deepest(model, energy, max_overlap, b, float(np.abs(final.s[b]).max()))
    return reason


def _deepest(model, energy: float, overlap: float, b: int, where: float) -> str | None:
    bound = deepest_any(model, energy, b)
    floor = round_off(2.0 * float(model.radius[b].max()), where)
    if np.isfinite(overlap) and overlap > SLACK * bound + floor:
        return (f"a contact reached an overlap of {overlap:.3g} m, beyond the {bound:.3g} m the contact law can "
                "store from the scene's energy: its approach was found too late (the bodies went into each "
                "other); refused")
    return None


def _final_pairs(model, energy: float, start: np.ndarray, final, b: int) -> str | None:
    """Every pair near at the end; in 1D the neighbours of the starting order, which it keeps."""
    if model.n_bodies < 2:
        return None
    s, names = final.s[b], model.body_names
    if model.dim == 1:
        order = np.argsort(start[:, 0], kind="stable")
        i, j = order[:-1], order[1:]
        gap = s[j, 0] - s[i, 0]
    else:
        i, j = near_pairs(s, 2.0 * float(model.radius[b].max()))
        gap = np.sqrt(((s[j] - s[i]) ** 2).sum(-1))
    reach = model.radius[b, i] + model.radius[b, j]
    where = np.maximum(np.abs(s[i]).max(-1), np.abs(s[j]).max(-1)) if s.ndim > 1 else np.maximum(abs(s[i]), abs(s[j]))
    bad = gap < reach - SLACK * pair_depth(model, energy, b, i, j) - round_off(reach, where)
    if model.dim == 1:
        # Centres that crossed have passed through, however much energy the scene holds: the
        # energy bound counts all of it, and in a chain of soft 1D spheres heavy ones can drive
        # one contact past its pair's own bound (7 spheres at k = 0.17 N/m: 2r deep, order lost).
        bad |= gap < -round_off(reach, where)
    if not bad.any():
        return None
    k = int(np.argmax(bad))
    crossed = model.dim == 1 and gap[k] < 0
    what = "out of their starting order" if crossed else \
        "overlapping deeper than the contact law can press them with the scene's energy"
    why = ("the contact was too soft for the energy the chain drove into it, or the step did not resolve their "
           "approach; refused (use a stiffer contact or a smaller --dt)") if crossed else \
        "the step did not resolve their approach; refused"
    return (f"body.{names[i[k]]} and body.{names[j[k]]} ended the run passed through each other ({what}: centres "
            f"{gap[k]:.3g} m apart, {reach[k]:.3g} m at touch): {why}")


def _walls(model, energy: float, final, b: int) -> str | None:
    height = final.s[b] @ model.wall_normal.T - (model.wall_point * model.wall_normal).sum(-1)[None, :]  # (N, W)
    where = np.abs(final.s[b]).max(-1)[:, None] + np.abs(model.wall_point).max(-1)[None, :]
    bad = height < model.radius[b][:, None] - SLACK * wall_depth(model, energy, b)[:, None] - \
        round_off(model.radius[b][:, None], where)
    if not bad.any():
        return None
    i, w = np.unravel_index(int(np.argmax(bad)), bad.shape)
    return (f"body.{model.body_names[i]} ended the run through wall {w} (its centre {height[i, w]:.3g} m from it, "
            f"radius {model.radius[b, i]:.3g} m): the step did not resolve its approach; refused")


def _free_flight(model, energy: float, final, since: np.ndarray, b: int) -> str | None:
    """Pairs both of whose bodies flew freely since `since`: their relative motion is a straight
    line (the same gravity on both), so the nearest approach over that flight is closed form.
    Only pairs whose own flights overlap along x (padded by the radius) can have met."""
    t_end = float(final.t[b])
    s, v, r = final.s[b], final.v[b], model.radius[b]
    span = np.maximum(t_end - since, 0.0)
    back = s[:, 0] - v[:, 0] * span
    g = 0.0 if model.gravity is None else float(np.linalg.norm(model.gravity[b]))
    pad = r + 0.5 * g * span ** 2
    i, j = overlapping(np.minimum(s[:, 0], back) - pad, np.maximum(s[:, 0], back) + pad)
    for axis in range(1, s.shape[1]):  # their boxes overlap along the other axes too
        back = s[:, axis] - v[:, axis] * span
        lo, hi = np.minimum(s[:, axis], back) - pad, np.maximum(s[:, axis], back) + pad
        keep = (lo[i] <= hi[j]) & (lo[j] <= hi[i])
        i, j = i[keep], j[keep]
    if not len(i):
        return None
    common = np.minimum(span[i], span[j])
    d, u = s[j] - s[i], v[j] - v[i]
    uu = (u * u).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        when = np.clip(np.where(uu > 0, (d * u).sum(-1) / uu, 0.0), 0.0, common)
    near = np.sqrt(((d - u * when[:, None]) ** 2).sum(-1))
    reach = r[i] + r[j]
    where = np.maximum(np.abs(s[i]).max(-1), np.abs(s[j]).max(-1))
    bad = near < reach - SLACK * pair_depth(model, energy, b, i, j) - round_off(reach, where)
    if not bad.any():
        return None
    k = int(np.argmax(bad))
    names = model.body_names
    return (f"body.{names[i[k]]} and body.{names[j[k]]} passed through each other in free flight (centres "
            f"{near[k]:.3g} m apart at t = {t_end - when[k]:.6g} s, {reach[k]:.3g} m at touch): the step did not "
            "resolve their approach; refused")


def overlapping(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) whose intervals [lo, hi] overlap (sorted by lo: each against those that start
    before it ends)."""
    order = np.argsort(lo, kind="stable")
    starts = lo[order]
    ends = np.searchsorted(starts, hi[order], side="right")
    count = np.maximum(ends - np.arange(len(order)) - 1, 0)
    first = np.repeat(np.arange(len(order)), count)
    offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    return order[first], order[first + 1 + offset]


def check_invariant(result) -> None:
    """Refuse (RunError) a result that broke the invariant."""
    reason = passed_through(result.model, result.initial, result.final, result.contacts.max_overlap,
                            getattr(result, "free_since", None))
    if reason:
        raise RunError(reason)
