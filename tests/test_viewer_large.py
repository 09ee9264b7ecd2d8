"""Large runs in the viewer (issue 52, item 6): a run is prepared a block of plot times at a
time, and gives what one block gives; with too many engaged contacts for per-contact lines the
compression plot is the largest compression of any contact at each time, which the per-contact
lines bound from below everywhere and meet at each time's most compressed contact."""

from __future__ import annotations

import numpy as np
import pytest

import viewer.state as state
from collide.run import run_scene
from tests.test_viewer_inside import small_pile
from viewer.geometry import embed3


@pytest.fixture(scope="module")
def pile_run():
    return run_scene(small_pile(36, duration=0.4, rest=None))


def _prepared(run, monkeypatch, **limits) -> state.ViewRun:
    with monkeypatch.context() as m:
        for name, value in limits.items():
            m.setattr(state, name, value)
        return state.ViewRun(run)


def test_a_run_prepared_in_blocks_of_times_is_the_run_prepared_at_once(pile_run, monkeypatch):
    whole = _prepared(pile_run, monkeypatch, SAMPLE_BODY_TIMES=1 << 30)
    blocks = _prepared(pile_run, monkeypatch, SAMPLE_BODY_TIMES=5 * 36 + 7)  # 5 times a block, a remainder
    assert len(whole.times) > 20
    for a, b in zip(whole.plots.all, blocks.plots.all, strict=True):
        assert a.title == b.title and a.scale == b.scale and a.flat == b.flat and list(a.lines) == list(b.lines)
        for key in a.lines:
            np.testing.assert_array_equal(a.lines[key], b.lines[key])
    for lo_hi_a, lo_hi_b in ((whole.bounds(), blocks.bounds()), (whole.contact_bounds(), blocks.contact_bounds())):
        np.testing.assert_array_equal(lo_hi_a[0], lo_hi_b[0])
        np.testing.assert_array_equal(lo_hi_a[1], lo_hi_b[1])
    for key in ("max_speed", "max_momentum", "max_body_energy", "max_contacts", "max_links", "max_normal_force"):
        assert getattr(whole, key) == getattr(blocks, key), key
    np.testing.assert_array_equal(whole.com_path, blocks.com_path)
    np.testing.assert_array_equal(whole.paths, blocks.paths)
    assert set(whole._end_values) == set(blocks._end_values) == {whole.t0, whole.t1}


def test_too_many_engaged_contacts_plot_the_largest_compression(pile_run, monkeypatch):
    lines = _prepared(pile_run, monkeypatch).plots.compression.lines
    assert len(lines) == state.MAX_COMPRESSION_LINES and any(k.endswith("others (max)") for k in lines)
    few = _prepared(pile_run, monkeypatch, COMPRESSION_ENTRIES=10).plots.compression.lines
    (name, most), = few.items()
    assert name.endswith("contacts (max)")
    top = np.max(np.stack(list(lines.values())), axis=0)  # the shown contacts and the others' largest
    np.testing.assert_array_equal(most, top)
    assert most.max() > 0


def test_the_status_says_frames_are_rebuilt_above_the_contact_list(pile_run, monkeypatch):
    view = _prepared(pile_run, monkeypatch)
    assert not any("rebuilt from the trajectory" in line for line in view.status_lines())
    monkeypatch.setattr(state, "CONTACT_LIST_BODIES", 30)
    many = state.ViewRun(pile_run)
    assert many.paths is None
    # The box the bodies sweep, without their paths: every body at every path time, padded.
    s = embed3(many.sample(many.path_times).s[:, 0])
    np.testing.assert_array_equal(many.bounds()[0], (s - many.radius[None, :, None]).min(axis=(0, 1)))
    np.testing.assert_array_equal(many.bounds()[1], (s + many.radius[None, :, None]).max(axis=(0, 1)))
    said = f"{many.n_bodies} bodies: each frame rebuilt from the trajectory as the time moves"
    assert said in many.status_lines()[-1]
