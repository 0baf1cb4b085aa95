"""The first fracture per member (body) in the structural results (issue 39, item 2's "first
fracture per member and its time in the structural results").

The notched plate of cases/fracture_notched_plate.toml (its held face's reaction recorded, so
the run has structural tables) with a second body, a small block far from the plate that
nothing loads: the plate fractures, the block does not. Asserted:
- ``Result.fractures`` has each body's count of failed points over the history times; the
  block's stays zero, the plate's is zero up to its first fracture and grows after it (it
  never decreases: a failed point stays failed);
- the first sampled time with a failed point (pmpm.results.recorder.first_fracture) is the
  run summary's first fracture (the end of the step it happened in) rounded up to the next
  history sample: at or after it, by less than one history interval;
- the written results give the same tables and ``<stem>_first_fracture.csv``.
Shown to fail: with the count taken from the wrong body column (body index + 1) the plate's
failures land on the block and the first assertion fails.
"""
import os

import numpy as np
import pytest

from pmpm.api import load_results, run
from pmpm.results.post import structural_outputs
from pmpm.results.recorder import first_fracture
from pmpm.scene.config import read_toml
from pmpm.scene.toml_writer import dumps

HISTORY = 1.0e-5


CASE = os.path.join(os.path.dirname(__file__), "..", "..", "cases", "fracture_notched_plate.toml")


def scene():
    data = read_toml(CASE)
    # a block beyond the plate's top edge, 6 mm away (more than the cubic B-splines' reach of
    # two 2 mm cells): nothing loads it
    data["bodies"].append({"name": "block", "shape": "rectangle", "material": "steel", "thickness": 0.01,
                           "lower": [0.02, 0.046], "upper": [0.03, 0.05]})
    data["grid"]["cells"] = [60, 30]
    data["solver"]["end_time"] = 8.0e-4
    data["output"].update(interval=8.0e-4, history_interval=HISTORY, directory="out", fields=["x", "damage"])
    return data


def test_first_fracture_per_member(tmp_path, monkeypatch):
    data = scene()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "plate.toml").write_text(dumps(data))
    r = run("plate.toml", write=True, dataframes=False)
    first = r.summary["first_fracture"]
    assert list(first) == ["plate"]
    plate, block = r.fractures["plate"], r.fractures["block"]
    assert np.all(block["failed"] == 0)
    failed, t = plate["failed"], plate["time"]
    assert np.all(np.diff(failed) >= 0) and failed[-1] > 0
    sampled = first_fracture(r.fractures)
    assert list(sampled) == ["plate"]
    assert first["plate"] - 1e-12 <= sampled["plate"] < first["plate"] + HISTORY + 1e-12
    assert np.all(failed[t < first["plate"] - 1e-12] == 0)
    # the written file: the same tables, and the first fracture per member as CSV
    back = load_results(r.path, dataframes=False)
    np.testing.assert_array_equal(back.fractures["plate"]["failed"], failed)
    made = structural_outputs(r.path, str(tmp_path))
    csv = [p for p in made if p.endswith("_first_fracture.csv")]
    assert len(csv) == 1
    lines = open(csv[0]).read().split()
    assert lines[0] == "member,t" and lines[1].split(",")[0] == "plate" and len(lines) == 2
    assert float(lines[1].split(",")[1]) == pytest.approx(sampled["plate"], rel=1e-8)
