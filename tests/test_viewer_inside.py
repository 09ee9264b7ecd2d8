"""Inside the pile (issue 54, item 5), without a browser: picking a sphere by the click's ray,
the clip plane's mask, the picked sphere's values from the engine's records, and the histograms
against numpy on the run's recorded states. (tests/test_viewer_browser_inside.py does it in a
browser.)"""

from __future__ import annotations

import numpy as np
import pytest

from collide.engine import layout
from collide.run import run_scene
from collide.scene import Scene, parse_scene
from viewer.clip import ClipPlane, highlight, links_shown, neighbours_of
from viewer.histograms import frame_histograms
from viewer.picking import pick_sphere, sphere_report
from viewer.state import ViewRun


def small_pile(n: int = 36, duration: float = 1.5, rest: float | None = 1e-6, seed: int = 3) -> Scene:
    """n glass spheres dropped from a loose lattice into an open box (the built-in pile's recipe,
    smaller): with `rest`, the run ends once they have settled."""
    rng = np.random.default_rng(seed)
    per = 4
    cells = [(i, j, k) for k in range(n // per**2 + 1) for i in range(per) for j in range(per)][:n]
    bodies = [{"name": f"g{m + 1}", "material": "glass", "radius": 0.005,
               "position": [(i + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4), (j + 0.5) * 0.011 + rng.uniform(-1e-4, 1e-4),
                            0.007 + k * 0.011],
               "velocity": [*rng.normal(0.0, 0.05, 2).tolist(), 0.0]} for m, (i, j, k) in enumerate(cells)]
    side = per * 0.011
    walls = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    walls += [{"point": [side * (s < 0) if a == c else 0.0 for c in range(3)],
               "normal": [float(s) if a == c else 0.0 for c in range(3)]} for a in range(2) for s in (1, -1)]
    raw = {"name": "small-pile", "dim": 3, "dt": "auto", "integrator": "dem", "tol": 4e-2,
           "duration": duration, "gravity": [0.0, 0.0, -9.81],
           "contact": {"model": "hertz", "restitution": 0.3, "tangential": "spring", "mu": 0.5,
                       "rolling_friction": 0.05},
           "material": [{"name": "glass", "density": 2500.0, "youngs_modulus": 5e6, "poisson_ratio": 0.25}],
           "body": bodies, "wall": walls}
    if rest is not None:
        raw["rest"] = rest
    return parse_scene(raw, "small-pile")


@pytest.fixture(scope="module")
def pile() -> ViewRun:
    return ViewRun(run_scene(small_pile()))


# ---------------------------------------------------------------------------------------------
# Picking


STEP = 1e-3


def _entry_steps(origin: np.ndarray, d: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 hidden: np.ndarray) -> np.ndarray:
    """The step at which a point marching along the ray first lands in each shown sphere (a
    large number if never): independent of the closed-form intersection."""
    points = origin + np.arange(0.0, 2.0, STEP)[:, None] * d
    inside = (np.linalg.norm(points[:, None] - centres[None], axis=-1) <= radii) & ~hidden
    return np.where(inside.any(axis=0), inside.argmax(axis=0), 10**9)


def test_the_ray_picks_the_nearest_sphere_it_hits():
    rng = np.random.default_rng(7)
    centres = rng.uniform(-0.3, 0.3, (40, 3))
    radii = rng.uniform(0.02, 0.06, 40)
    hidden = rng.random(40) < 0.2
    hits = 0
    for _ in range(60):
        origin = rng.normal(0.0, 1.0, 3)
        origin *= 1.2 / np.linalg.norm(origin)
        target = centres[rng.integers(40)] + rng.normal(0.0, 0.04, 3)
        d = (target - origin) / np.linalg.norm(target - origin)
        got = pick_sphere(origin, d * 3.7, centres, radii, hidden)  # the direction's length does not matter
        steps = _entry_steps(origin, d, centres, radii, hidden)
        if steps.min() == 10**9:
            assert got is None
        else:
            # The nearest entered (two entered within one marching step are a tie).
            assert got is not None and steps[got] <= steps.min() + 1, (got, steps.argmin())
            hits += 1
    assert hits >= 30


def test_the_ray_skips_hidden_spheres_and_what_lies_behind_it():
    centres = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 0.0, -1.0]])
    radii = np.full(3, 0.1)
    origin, d = np.zeros(3), np.array([0.0, 0.0, 1.0])
    assert pick_sphere(origin, d, centres, radii) == 0
    assert pick_sphere(origin, d, centres, radii, np.array([True, False, False])) == 1
    assert pick_sphere(origin, -d, centres, radii) == 2
    assert pick_sphere(origin, np.array([1.0, 0.0, 0.0]), centres, radii) is None
    assert pick_sphere(np.array([0.0, 0.0, 1.05]), d, centres, radii) == 0  # from inside it
    assert pick_sphere(np.array([0.0, 0.0, 1.5]), d, centres, radii) == 1  # the first is behind


# ---------------------------------------------------------------------------------------------
# The clip plane and the highlight


def test_the_clip_plane_hides_the_centres_beyond_it_and_their_contacts():
    rng = np.random.default_rng(1)
    positions = rng.uniform(0.0, 0.1, (200, 3))
    plane = ClipPlane(on=True, axis=1, offset=0.04, keep="below")
    hidden = plane.hidden(positions)
    assert np.array_equal(hidden, positions[:, 1] > 0.04)
    plane.keep = "above"
    assert np.array_equal(plane.hidden(positions), positions[:, 1] < 0.04)
    plane.on = False
    assert not plane.hidden(positions).any()
    i = rng.integers(0, 200, 300)
    j = np.where(rng.random(300) < 0.2, -1 - rng.integers(0, 5, 300), rng.integers(0, 200, 300))
    kept = links_shown(i, j, hidden)
    for a, b, k in zip(i, j, kept):
        assert k == (not hidden[a] and (b < 0 or not hidden[b]))


def test_the_highlight_marks_the_picked_sphere_and_its_neighbours():
    i, j = np.array([0, 2, 3, 4, 2]), np.array([2, 5, -1, 2, -2])
    assert list(neighbours_of(i, j, 2)) == [0, 4, 5]
    base = np.full((6, 3), 100, np.uint8)
    out = highlight(base, 2, neighbours_of(i, j, 2))
    assert tuple(out[2]) == (230, 0, 180)
    assert all(tuple(out[k]) == (255, 140, 0) for k in (0, 4, 5))
    assert tuple(out[1]) == tuple(out[3]) and out[1].mean() > 150  # faded towards grey


def test_the_drawing_hides_clipped_spheres_one_node_each_and_instanced(pile):
    """The same mask, whichever way the spheres are drawn: instanced (many) scaled to nothing,
    one node each (few) made invisible; the force chains of hidden spheres are not drawn."""
    import viser

    from viewer.scene3d import SceneDrawer

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(pile)
        frame = pile.frame(pile.t1)
        mid = float(np.median(frame.positions[:, 0]))
        drawer.look.clip = ClipPlane(on=True, axis=0, offset=mid)
        drawer.show_frame(frame)
        hidden = frame.positions[:, 0] > mid
        assert 0 < hidden.sum() < len(hidden)
        scales = np.asarray(drawer._batch["spheres"].batched_scales, float).reshape(len(hidden), -1)[:, 0]
        assert np.all(scales[hidden] == 0) and np.allclose(scales[~hidden], pile.radius[~hidden])
        chains = drawer._batch.get("chains")
        if chains is not None:
            drawn = np.asarray(chains.batched_scales, float)[:, 2] > 0
            links = frame.contact_links()
            strong = links.force > 1e-9 * pile.max_normal_force
            assert drawn.sum() == (strong & links_shown(links.i, links.j, hidden)).sum()
        drawer.look.clip.on = False
        drawer.show_frame(frame)
        scales = np.asarray(drawer._batch["spheres"].batched_scales, float).reshape(len(hidden), -1)[:, 0]
        assert np.allclose(scales, pile.radius)
        few = ViewRun(run_scene(small_pile(8, 0.05, rest=None)))
        drawer.show_run(few)
        frame = few.frame(few.t1)
        drawer.look.clip = ClipPlane(on=True, axis=1, offset=0.015)
        drawer.look.picked = 0
        drawer.show_frame(frame)
        hidden = frame.positions[:, 1] > 0.015
        assert [not b["frame"].visible for b in drawer._bodies] == list(hidden)
        assert tuple(drawer.body_colours()[0]) == (230, 0, 180)
    finally:
        server.stop()


# ---------------------------------------------------------------------------------------------
# The picked sphere's values and the histograms


def test_a_settled_sphere_is_held_up_by_its_contacts(pile):
    """At rest, a sphere's recorded contact forces sum to minus its weight (force balance), and
    the report lists exactly its contacts of the frame: at the last full frame the engine
    recorded, and at the run's very end, where it records only some contacts' forces and the
    others' last records hold."""
    for t in (float(_full_frames(pile)[-1]), pile.t1):
        _check_balance(pile, t)


def _check_balance(pile: ViewRun, t: float) -> None:
    frame = pile.frame(t)
    links = frame.contact_links()
    counts = links.counts(pile.n_bodies)
    speed = np.linalg.norm(frame.velocities, axis=-1)
    assert speed.max() < 0.01  # settled: the run ended at rest
    checked = 0
    for k in np.flatnonzero(counts >= 2)[:10]:
        report = sphere_report(pile, t, int(k))
        assert len(report.contacts) == counts[k]
        weight = np.array([0.0, 0.0, -report.weight])
        assert np.allclose(report.net_contact_force, -weight, atol=0.01 * report.weight), k
        assert report.position == pytest.approx(frame.positions[k])
        checked += 1
    assert checked >= 5


def _records_at(view: ViewRun, t: float) -> np.ndarray:
    rec = view.traj.records
    return rec[rec[:, layout.R_T] == t]


def _full_frames(view: ViewRun) -> np.ndarray:
    """The recorded times at which the engine recorded every engaged contact's forces (a frame;
    other record times hold single contacts' peaks, and the run's last time only some)."""
    times, counts = np.unique(view.traj.records[:, layout.R_T], return_counts=True)
    iv = view.traj.intervals
    end = np.where(np.isnan(iv[:, layout.V_END]), np.inf, iv[:, layout.V_END])
    engaged = ((iv[:, layout.V_START][None] <= times[:, None]) & (times[:, None] < end[None])).sum(axis=1)
    return times[counts == engaged]


def test_histograms_are_numpys_counts_of_the_recorded_states(pile):
    """At a recorded frame: speeds binned as numpy bins the sampled velocities; contacts per
    sphere as the spheres' overlaps count them; normal forces as numpy bins the engine's records
    at that time (the clip plane's hidden spheres and their contacts left out)."""
    frames = _full_frames(pile)
    for t in (float(frames[len(frames) // 3]), float(frames[-1])):
        frame = pile.frame(t)
        hidden = frame.positions[:, 0] > float(np.median(frame.positions[:, 0]))
        speed, count, force = frame_histograms(frame, hidden)
        v = pile.sample(np.array([t])).v[0, 0]
        want = np.histogram(np.linalg.norm(v, axis=-1)[~hidden], bins=speed.edges)[0]
        assert np.array_equal(speed.counts, want) and speed.total == (~hidden).sum()
        s = pile.sample(np.array([t])).s[0, 0]
        gap = np.linalg.norm(s[:, None] - s[None], axis=-1) - 2 * pile.radius[0]
        np.fill_diagonal(gap, np.inf)
        walls = [(np.asarray(w.point, float), np.asarray(w.normal, float)) for w in pile.scene.walls]
        touching = (gap < 0).sum(axis=1) + sum(((s - p) @ n < pile.radius) for p, n in walls)
        assert np.array_equal(count.counts, np.bincount(touching[~hidden], minlength=len(count.counts)))
        rows = _records_at(pile, t)
        i, j = rows[:, layout.R_I].astype(int), rows[:, layout.R_J].astype(int)
        keep = links_shown(i, j, hidden)
        want = np.histogram(np.abs(rows[keep, layout.R_FN]), bins=force.edges)[0]
        assert np.array_equal(force.counts, want) and force.total == keep.sum() > 0
        x, y = force.outline()
        assert len(x) == len(y) and y.max() == force.counts.max()


def test_a_sphere_of_a_run_given_as_frames_reads_from_its_frame():
    """A replayed frames run (no engine records): the pick reads the frame's own values."""
    from viewer.frames import settling_pile
    from viewer.picking import frame_report, report_markdown

    run = settling_pile(40, duration=0.2)
    frame = run.frame(run.t1)
    links = frame.contact_links()
    k = int(np.argmax(links.counts(run.n_bodies)))
    report = frame_report(run, frame, k)
    assert len(report.contacts) == links.counts(run.n_bodies)[k] > 0
    assert report.position == pytest.approx(frame.positions[k])
    text = report_markdown(report)
    assert f"**{run.names[k]}** (body {k})" in text and "nan" not in text


def test_a_new_run_of_the_same_bodies_keeps_the_chains_node_and_draws_its_own_links(pile):
    """A slider change draws a new run of the same bodies: the force chains' batch is kept (not
    built again in the page), and shows exactly the new frame's links, none of the old run's."""
    import viser

    from viewer.scene3d import SceneDrawer

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawer = SceneDrawer(server.scene)
        drawer.show_run(pile)
        drawer.show_frame(pile.frame(pile.t1))
        chains = drawer._batch["chains"]
        assert (np.asarray(chains.batched_scales, float)[:, 2] > 0).sum() > 0
        drawer.show_run(pile)  # the same bodies again, shown from the start: no links yet
        start = pile.frame(pile.t0)
        drawer.show_frame(start)
        assert drawer._batch["chains"] is chains
        links = start.contact_links()
        strong = links.force > 1e-9 * pile.max_normal_force
        assert (np.asarray(chains.batched_scales, float)[:, 2] > 0).sum() == strong.sum()
        drawer.set_options(forces=False)  # forces off: the batch goes
        assert "chains" not in drawer._batch
    finally:
        server.stop()
