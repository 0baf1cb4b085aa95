"""A run stopped on one rank count and restarted on another, with the default ``io = "mpio"``,
gives the uninterrupted run's histories and keeps every frame (issue 35: a restart from 1 rank
onto 2 hung in Open MPI's ``pwritev`` with EINVAL and left ``case.h5`` unreadable).

It starts ``mpirun`` itself (as tests/integration/test_restart_and_failure.py does), so it is run
by plain pytest, not under mpirun; without mpirun it fails, it does not skip.

The cause, and why this test fails without the fix: serial HDF5 allocates a chunked dataset's
chunks incrementally, parallel HDF5 early; the mpio driver's collective write into a file laid
out by the serial driver fails (reproduced with a bare h5py script of one (1, 3200, 2)-chunked
dataset). pmpm now creates every extendible dataset with early allocation on one rank too
(pmpm.io.hdf5._early), and appends to an older file through rank 0. Without ``_early`` the 1 -> 2
case below times out and the file's later frames are lost (seen: exit 124, the pwritev message).
The scene has 3200 particles: the bar of cases/bar.toml at 0.125 m cells (with 400 the write
happened to succeed).
"""
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from pmpm.io import read_history

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = (open(os.path.join(ROOT, "cases", "bar.toml")).read()
       .replace("end_time = 10.0", "end_time = 2.0\n{max_steps}")
       # precision: the frames are compared to round-off, so they keep the solver's float64
       .replace("interval = 0.5\n", "interval = 0.1\ncheckpoint_interval = 0.3\nprecision = \"double\"\n", 1)
       .replace("cell_size = 0.5", "cell_size = 0.125").replace("cells = [54, 3]", "cells = [216, 12]"))


def _mpirun(n, args, cwd, timeout=300):
    cmd = ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none", sys.executable, "-m", "pmpm.cli",
           *args, "--no-plots", "-q"]
    env = dict(os.environ, PYTHONPATH=ROOT, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _scene(folder, max_steps=None):
    folder.mkdir(exist_ok=True)
    (folder / "bar.toml").write_text(BAR.format(max_steps=f"max_steps = {max_steps}" if max_steps else ""))
    return folder


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    folder = _scene(tmp_path_factory.mktemp("whole"))
    r = _mpirun(1, ["bar.toml"], folder)
    assert r.returncode == 0, r.stderr
    return str(folder / "bar_results" / "bar.h5")


@pytest.mark.parametrize("first,second", [(1, 2), (2, 1)])
def test_restart_on_another_rank_count_matches_the_uninterrupted_run(tmp_path, uninterrupted, first, second):
    folder = _scene(tmp_path, max_steps=300)  # stops at about t = 1.0, after the 0.9 s checkpoint
    r = _mpirun(first, ["bar.toml"], folder)
    assert r.returncode == 0, r.stderr
    _scene(tmp_path)  # the same scene without the step limit
    r = _mpirun(second, ["bar.toml", "--restart", "bar_results/bar.h5"], folder)
    assert r.returncode == 0, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    restarted = str(folder / "bar_results" / "bar.h5")
    with h5py.File(restarted, "r") as f, h5py.File(uninterrupted, "r") as g:
        assert np.array_equal(f["frames/time"][()], g["frames/time"][()])  # every frame, none lost
        x, x_ref = f["frames/x"][()], g["frames/x"][()]
    t, tracks, cols = read_history(restarted)
    t_ref, tracks_ref, cols_ref = read_history(uninterrupted)
    assert cols == cols_ref and np.allclose(t, t_ref, rtol=0, atol=1e-12)
    # Only the order of floating-point sums differs between rank counts (round-off, 1e-16 a
    # step, over about 600 steps of a linear elastic bar that does not amplify it); a lost or
    # repeated step, or a wrong restored state, moves the free end by a visible fraction of its
    # amplitude (0.16 m). 1e-9 of the amplitude lies between the two by orders of magnitude.
    for name, data in tracks_ref.items():
        scale = np.max(np.abs(data)) or 1.0
        assert np.allclose(tracks[name], data, rtol=0, atol=1e-9 * scale), name
    scale = np.max(np.abs(x_ref))
    assert np.allclose(x, x_ref, rtol=0, atol=1e-9 * scale, equal_nan=True)
