"""A results file of pmpm before issue 40 (layout ``pmpm-results-2``: ids, initial positions and
every field in every frame, float64, uncompressed) is still read by ``pmpm plot``, ``pmpm
export`` and :func:`pmpm.load_results`, and a restart refuses to append to it in one line.

The old file is written explicitly in the old layout (:func:`pmpm.io.legacy.write_layout2`) from a
real run of cases/bar.toml at ``output.precision = "double"``, so both files hold the same numbers:
everything read from the old one must equal what is read from the new one, exactly.
Shown to fail: with ``pmpm.io.layout.READ_LAYOUTS`` holding only the current layout, every test
but the restart's fails (the file is refused); with ``OutputFile._check_layout``'s layout check
removed, the restart appends frames of the new layout to the old file (and fails later, not in
one line).
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import pmpm
from pmpm.io.legacy import write_layout2

REPO = Path(__file__).resolve().parents[2]
SCENE = """
[output]
interval = 0.5
history_interval = 0.02
fields = ["x", "x0", "v", "m", "stress", "strain", "mat"]
precision = "double"
checkpoint_interval = 0.5
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``(new, old)``: a 1.5 s bar run's results file and the same results in the old layout."""
    folder = tmp_path_factory.mktemp("old_layout")
    text = (REPO / "cases" / "bar.toml").read_text()
    head, _, tail = text.partition("[output]")
    tracks = tail[tail.index("[[output.track]]"):]
    scene = folder / "bar.toml"
    scene.write_text(head.replace("end_time = 10.0", "end_time = 1.5") + SCENE + tracks)
    proc = _pmpm(folder, str(scene), "--no-plots", "-q")
    assert proc.returncode == 0, proc.stderr
    new = folder / "bar_results" / "bar.h5"
    old_dir = folder / "old"
    old_dir.mkdir()
    old = Path(write_layout2(new, old_dir / "bar.h5"))
    with h5py.File(old, "r") as f:
        assert f.attrs["layout"] == "pmpm-results-2" and "particles" not in f
        assert f["frames/id"].dtype == np.int64 and f["frames/x0"].shape[0] == f["frames/time"].shape[0]
        assert f["frames/x"].compression is None
    return scene, new, old


def _pmpm(cwd, *args):
    return subprocess.run([sys.executable, "-m", "pmpm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, PYTHONPATH=str(REPO)))


def test_load_results_reads_the_old_layout(runs):
    _, new, old = runs
    a, b = pmpm.load_results(new, dataframes=False), pmpm.load_results(old, dataframes=False)
    assert sorted(a.frames) == sorted(b.frames) == sorted(["id", "x", "x0", "v", "m", "stress", "strain", "mat"])
    for name in a.frames:
        np.testing.assert_array_equal(a.frames[name], b.frames[name])
    np.testing.assert_array_equal(a.frame_times, b.frame_times)
    for track in a.histories:
        np.testing.assert_array_equal(a.histories[track], b.histories[track])
    np.testing.assert_array_equal(a.energies, b.energies)


def test_plot_and_export_read_the_old_layout(runs):
    _, new, old = runs
    proc = _pmpm(old.parent, "plot", str(old), "-o", str(old.parent / "plots"))
    assert proc.returncode == 0, proc.stderr
    assert any(p.endswith(".png") for p in os.listdir(old.parent / "plots"))
    import meshio
    for path in (new, old):
        proc = _pmpm(path.parent, "export", str(path), "--format", "vtu", "-o", str(path.parent / "vtu"))
        assert proc.returncode == 0, proc.stderr
    names = sorted(n for n in os.listdir(new.parent / "vtu") if n.endswith(".vtu"))
    assert names and names == sorted(n for n in os.listdir(old.parent / "vtu") if n.endswith(".vtu"))
    for name in names:
        m_new, m_old = meshio.read(new.parent / "vtu" / name), meshio.read(old.parent / "vtu" / name)
        np.testing.assert_array_equal(m_new.points, m_old.points)
        assert sorted(m_new.point_data) == sorted(m_old.point_data)
        for key in m_new.point_data:
            np.testing.assert_array_equal(m_new.point_data[key], m_old.point_data[key])


def test_a_restart_refuses_to_append_to_the_old_layout(runs, tmp_path):
    """The checkpoints are fine, the results file is of the old layout: one line, nothing
    appended (the file unchanged)."""
    scene, new, old = runs
    folder = tmp_path / "restart"
    shutil.copytree(new.parent, folder / "bar_results")
    shutil.copy(scene, folder / "bar.toml")
    shutil.copy(old, folder / "bar_results" / "bar.h5")
    before = (folder / "bar_results" / "bar.h5").read_bytes()
    proc = _pmpm(folder, "bar.toml", "--restart", "bar_results/bar.h5", "--no-plots", "-q")
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pmpm: error: ") and \
        "written by an older pmpm (layout 'pmpm-results-2')" in lines[0], proc.stderr
    assert (folder / "bar_results" / "bar.h5").read_bytes() == before
