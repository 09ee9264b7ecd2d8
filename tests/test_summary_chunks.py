"""What is worked out a chunk at a time to bound memory is the same as worked out whole: the JSON
summary's bodies (`summary.write_summary_json`) and the residuals' spring energy
(`diagnostics.conserved`)."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from collide import diagnostics, summary
from collide.run import run_scene
from collide.scene import parse_scene


@pytest.fixture(scope="module")
def run():
    """Seven spheres in a periodic DEM box, some crossing its sides."""
    bodies = [{"name": f"b{k}", "radius": 0.05, "mass": 1.0, "position": [0.1 + 0.13 * k, 0.5],
               "velocity": [1.0 - 0.3 * k, 4.0 * (-1) ** k]} for k in range(7)]
    raw = {"name": "chunks", "dim": 2, "duration": 0.15, "integrator": "dem", "body": bodies,
           "contact": {"k": 1e4, "restitution": 0.8, "mu": 0.3},
           "domain": {"lower": [0.0, 0.0], "upper": [1.0, 1.0], "periodic": ["x", "y"]}}
    return run_scene(parse_scene(raw), record=False, tol=1e-4)


def test_the_json_summary_written_in_chunks_is_the_whole_summary(run, monkeypatch):
    whole = json.dumps(summary.run_summary(run)) + "\n"
    monkeypatch.setattr(summary, "BODY_CHUNK", 3)
    out = io.StringIO()
    summary.write_summary_json(summary.run_summary(run, bodies=False), run, out)
    assert out.getvalue() == whole
    assert len(json.loads(whole)["bodies"]) == 7 and any(b["images"] != [0, 0] for b in json.loads(whole)["bodies"])


def test_the_spring_energy_summed_in_chunks_is_the_sum_taken_whole(run, monkeypatch):
    model, final = run.result.model, run.result.final
    s = np.stack([run.result.initial.s[0], final.s[0]])[:, None]  # two states, one member
    s[1, 0, 1] = s[1, 0, 0] + [0.093, 0.0]  # a pair pressed together
    args = (model, np.zeros(2), s, np.zeros_like(s), np.zeros(s.shape[:-1] + (1,)), np.zeros((2, 1)))
    contacts = diagnostics.all_contacts(model)
    whole = diagnostics.conserved(*args, contacts=contacts).spring
    monkeypatch.setattr(diagnostics, "CONTACT_CHUNK", 4)
    chunked = diagnostics.conserved(*args, contacts=contacts).spring
    assert len(contacts) > 4 and np.all(whole[1] > 0.0)
    assert np.array_equal(chunked, whole)
