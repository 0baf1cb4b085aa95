"""Restart on any rank count from whatever a kill leaves (issue 35, deliverable 6).

A run of a small bar (400 particles, cases/bar.toml cut to 2 s with a checkpoint every 0.3 s) is
killed with SIGKILL on 1, 2 or 3 ranks at one of three phases of its second checkpoint, then
restarted from its results file on each other rank count, and must reproduce the uninterrupted
run's histories, energies and frames:

- ``before``: every rank kills itself as Run.checkpoint is entered (the newest checkpoint on disk
  is the first one, t = 0.3 s);
- ``during``: every rank kills itself right after it has written its part of the checkpoint's
  temporary file, before rank 0 renames it into place (the folder holds a complete hidden
  ``.pmpm-tmp`` file besides the first checkpoint; the restart must ignore it);
- ``after``: every rank kills itself as write_checkpoint returns (the newest is the second).

The kill is made by a wrapper (KILLER) that patches those functions in the child only: no
test hook in pmpm. Each killed run must die by the signal (mpirun reports it as a non-zero exit),
and the ``during`` case must leave the temporary: the test asserts both, so it cannot pass on a
run that was never interrupted at that phase.

Tolerance: only the order of floating-point sums differs between rank counts (round-off, 1e-16
a step over about 80 steps of a linear elastic bar that does not amplify it); a lost or repeated
step, or a wrongly restored state, moves the free end by a visible fraction of its amplitude
(0.016 m here). 1e-9 of each column's largest magnitude lies between the two by orders of
magnitude (tests/integration/test_restart_rank_counts.py, the same argument). Shown to fail:
with the restart keeping the rows written after its checkpoint (run.py's truncate_after=None in
a scratch edit) the 2 -> 1 ``during`` case failed (rows between 0.3 and 0.6 s twice), while
the ``after`` case, whose rows end at its checkpoint, rightly passed; without the run claim's
wait (below) the 3 -> 1 ``before`` case met the killed run's claim of a rank still dying.

It starts ``mpirun`` itself, so it is run by plain pytest; without mpirun it fails, not skips.
28 launches of a few seconds each: 180 s on the shared 2-CPU machine under load.
"""
import os
import shutil
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

from pmpm.io import read_energies, read_history

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = (open(os.path.join(ROOT, "cases", "bar.toml")).read()
       .replace("end_time = 10.0", "end_time = 2.0")
       # precision: the frames are compared to round-off, so they keep the solver's float64
       .replace("interval = 0.5\n", "interval = 0.5\ncheckpoint_interval = 0.3\nprecision = \"double\"\n", 1))

#: kills every rank of the command line with SIGKILL at the phase $KILL_PHASE of the second
#: checkpoint; the patched functions are looked up where runner.py calls them
KILLER = """\
import os, signal, sys
phase = os.environ["KILL_PHASE"]
calls = [0]
def kill():
    sys.stdout.flush(); sys.stderr.flush()
    os.kill(os.getpid(), signal.SIGKILL)
import pmpm.io, pmpm.io.checkpoint as ck
from pmpm.runner import Run
if phase == "before":
    original = Run.checkpoint
    def checkpoint(self, snap=None, path=None):
        if path is None:
            calls[0] += 1
            if calls[0] == 2:
                kill()
        return original(self, snap, path)
    Run.checkpoint = checkpoint
elif phase == "during":
    original = ck._write_file
    def _write_file(*args):
        original(*args)
        calls[0] += 1
        if calls[0] == 2:
            kill()
    ck._write_file = _write_file
else:
    import pmpm.runner
    original = pmpm.runner.write_checkpoint
    def write_checkpoint(*args, **kwargs):
        out = original(*args, **kwargs)
        calls[0] += 1
        if calls[0] == 2:
            kill()
        return out
    pmpm.runner.write_checkpoint = write_checkpoint
from pmpm.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _mpirun(n, args, cwd, phase=None, timeout=300):
    code = ["-c", KILLER] if phase else ["-m", "pmpm.cli"]
    cmd = ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none", sys.executable, *code,
           *args, "--no-plots", "-q"]
    env = dict(os.environ, PYTHONPATH=ROOT, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", KILL_PHASE=phase or "")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("whole")
    (folder / "bar.toml").write_text(BAR)
    r = _mpirun(1, ["bar.toml"], folder)
    assert r.returncode == 0, r.stderr
    return str(folder / "bar_results" / "bar.h5")


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    """(phase, ranks) -> the folder a run killed at that phase on that many ranks left."""
    made = {}

    def make(phase, ranks):
        if (phase, ranks) not in made:
            folder = tmp_path_factory.mktemp(f"killed_{phase}_{ranks}")
            (folder / "bar.toml").write_text(BAR)
            r = _mpirun(ranks, ["bar.toml"], folder, phase=phase)
            assert r.returncode != 0, (phase, ranks, r.stdout[-500:], r.stderr[-500:])  # killed
            out = folder / "bar_results"
            _wait_for_claim_holder(out / ".bar.pmpm-claim")
            temps = [n for n in os.listdir(out) if n.endswith(".pmpm-tmp")]
            with h5py.File(out / "bar.h5", "r") as f:
                t_last = float(np.nanmax(f["history/time"][()]))
            assert t_last < 1.0, t_last  # stopped at the second checkpoint (t = 0.6 s), not run out
            if phase == "during":
                assert temps, os.listdir(out)  # the kill came between the write and the rename
            made[(phase, ranks)] = folder
        return made[(phase, ranks)]
    return make


def _wait_for_claim_holder(claim, seconds=30):
    """mpirun may return while a rank it signalled is still dying; a restart at that moment is
    refused by the run claim (docs/output.md, a claim of a live process is respected). Wait
    until the killed run's rank 0 is gone, as a user would."""
    import json
    import time
    from pmpm.io.ownership import _alive
    if not claim.exists():
        return
    pid = int(json.loads(claim.read_text())["pid"])
    deadline = time.monotonic() + seconds
    while _alive(pid):
        assert time.monotonic() < deadline, f"the killed run's process {pid} is still alive"
        time.sleep(0.1)


def _assert_same_run(restarted, reference):
    with h5py.File(restarted, "r") as f, h5py.File(reference, "r") as g:
        assert np.array_equal(f["frames/time"][()], g["frames/time"][()])  # every frame, none lost
        x, x_ref = f["frames/x"][()], g["frames/x"][()]
    t, tracks, cols = read_history(restarted)
    t_ref, tracks_ref, cols_ref = read_history(reference)
    assert cols == cols_ref and len(t) == len(t_ref) and np.allclose(t, t_ref, rtol=0, atol=1e-12)
    for name, data in tracks_ref.items():
        scale = np.max(np.abs(data)) or 1.0
        assert np.allclose(tracks[name], data, rtol=0, atol=1e-9 * scale), name
    e, e_ref = read_energies(restarted), read_energies(reference)
    assert sorted(e) == sorted(e_ref) and len(e["time"]) == len(e_ref["time"])
    for column, data in e_ref.items():
        scale = np.max(np.abs(data)) or 1.0
        assert np.allclose(e[column], data, rtol=0, atol=1e-9 * scale), column
    assert np.allclose(x, x_ref, rtol=0, atol=1e-9 * np.max(np.abs(x_ref)), equal_nan=True)


@pytest.mark.parametrize("phase", ["before", "during", "after"])
@pytest.mark.parametrize("first,second", [(1, 2), (1, 3), (2, 1), (2, 3), (3, 1), (3, 2)])
def test_a_run_killed_at_a_checkpoint_restarts_on_another_rank_count(tmp_path, uninterrupted, killed,
                                                                     phase, first, second):
    folder = tmp_path / "run"
    shutil.copytree(killed(phase, first), folder)
    r = _mpirun(second, ["bar.toml", "--restart", "bar_results/bar.h5"], folder)
    assert r.returncode == 0, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    _assert_same_run(str(folder / "bar_results" / "bar.h5"), uninterrupted)
    # the killed checkpoint's temporary is gone with the run that claimed its names again
    # (without pmpm.io.ownership.remove_stale_temporaries the ``during`` cases keep it)
    assert not [n for n in os.listdir(folder / "bar_results") if n.endswith(".pmpm-tmp")]
