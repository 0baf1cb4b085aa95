"""The XDMF sidecar is kept current while a run goes (pmpm.io.OutputFile with ``xdmf``): a run
that is killed (SIGKILL: no Python clean-up at all) or ends at ``max_steps`` leaves a sidecar that
meshio reads, with exactly the frames written so far, and the same document that ``pmpm export
--format xdmf`` (pmpm.io.write_xdmf, which rebuilds the views from scratch) writes for the file.
"""
import os
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read()

#: runs the command line and SIGKILLs itself right after its KILL_AFTER-th frame is written
KILLER = """\
import os, signal, sys
from pmpm.runner import Run
from pmpm.cli import main
written = [0]
original = Run.write_frame
def write_frame(self):
    original(self)
    written[0] += 1
    if written[0] == int(os.environ["KILL_AFTER"]):
        os.kill(os.getpid(), signal.SIGKILL)
Run.write_frame = write_frame
sys.exit(main(sys.argv[1:]))
"""


def _run(tmp_path, args, kill_after=None, scene=BAR):
    (tmp_path / "bar.toml").write_text(scene)
    env = dict(os.environ, PYTHONPATH=ROOT, KILL_AFTER=str(kill_after or 0))
    code = ["-c", KILLER] if kill_after else ["-m", "pmpm.cli"]
    return subprocess.run([sys.executable, *code, "bar.toml", "--no-plots", "-q", *args], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=300)


def _check_sidecar(h5, frames_expected):
    xdmf = h5[:-3] + ".xdmf"
    with h5py.File(h5, "r") as f:
        times = f["frames/time"][()]
        stress = f["frames/stress"][()]
    complete = np.flatnonzero(np.isfinite(times))
    assert len(complete) == frames_expected
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        reader.read_points_cells()
        assert reader.num_steps == frames_expected
        for k in range(reader.num_steps):
            t, point_data, _ = reader.read_data(k)
            assert t == times[complete[k]]
            assert np.array_equal(point_data["sxx"], stress[complete[k], :, 0])
    # the running writer's document is the one write_xdmf builds from the finished file
    live = open(xdmf).read()
    from pmpm.io import write_xdmf
    again = write_xdmf(h5, h5[:-3] + ".again.xdmf")
    assert open(again).read() == live


def test_a_run_killed_midway_leaves_a_sidecar_of_its_frames(tmp_path):
    res = _run(tmp_path, [], kill_after=3)
    assert res.returncode == -signal.SIGKILL, res.stdout + res.stderr
    _check_sidecar(str(tmp_path / "bar_results" / "bar.h5"), 3)


def test_a_run_ended_by_max_steps_leaves_a_sidecar_of_its_frames(tmp_path):
    """bar.toml steps 0.0248 s and writes a frame every 0.5 s: 50 steps end at t = 1.24 s, after
    the frames at 0, 0.5 and 1 s (the run writes no frame at a max_steps end)."""
    res = _run(tmp_path, [], scene=BAR.replace("end_time = 10.0", "end_time = 10.0\nmax_steps = 50"))
    assert res.returncode == 0, res.stdout + res.stderr
    _check_sidecar(str(tmp_path / "bar_results" / "bar.h5"), 3)
