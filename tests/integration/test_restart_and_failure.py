"""Whole runs through the command line under mpirun: restart after SIGKILL, failures that stop
every rank with a message, refusal of more ranks than the grid holds.

Each test starts ``mpirun -n K python -m pmpm.cli ...`` in a temporary directory, with a
timeout so that a hang fails the test instead of blocking the suite.
"""
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read()


def _mpirun(n, args, cwd, timeout=240, wait=True):
    cmd = ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none",
           sys.executable, "-m", "pmpm.cli", *args]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    if not wait:
        return subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, start_new_session=True)
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _long_bar(tmp_path, name="bar.toml", end=120.0, extra=""):
    text = BAR.replace("end_time = 10.0", f"end_time = {end}").replace(
        # precision: the frames are compared to round-off, so they keep the solver's float64
        "interval = 0.5", f"interval = 5.0\ncheckpoint_interval = 10.0\nprecision = \"double\"{extra}")
    (tmp_path / name).write_text(text)
    return name


def _complete_checkpoints(path_base):
    done = []
    for k in (0, 1):
        try:
            with h5py.File(f"{path_base}.ckpt{k}.h5", "r") as f:
                if f.attrs.get("complete", False):
                    done.append(float(f.attrs["time"]))
        except OSError:
            pass
    return done


def test_sigkill_then_restart_on_another_rank_count_gives_the_same_result(tmp_path):
    """Kill a 2-rank run with SIGKILL after its second checkpoint, restart it on 1 rank: it
    loses at most one checkpoint interval and ends where an uninterrupted run ends (1e-12)."""
    full = tmp_path / "full"
    full.mkdir()
    case = _long_bar(full)
    res = _mpirun(2, [case, "--no-plots", "-q"], full)
    assert res.returncode == 0, res.stdout + res.stderr

    case = _long_bar(tmp_path)
    proc = _mpirun(2, [case, "--no-plots", "-q"], tmp_path, wait=False)
    base = str(tmp_path / "bar_results" / "bar")
    deadline = time.time() + 180
    while len(_complete_checkpoints(base)) < 2 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    killed_at = max(_complete_checkpoints(base), default=None)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert killed_at is not None and killed_at < 120.0, "the run ended before it could be killed"

    res = _mpirun(1, [case, "--restart", "bar_results/bar.h5", "--no-plots"], tmp_path)
    assert res.returncode == 0, res.stdout + res.stderr
    restarted = [ln for ln in res.stdout.splitlines() if "restarted from" in ln]
    t_restart = float(restarted[0].split("t = ")[1].split()[0])
    assert t_restart >= killed_at - 10.0 - 1e-9  # at most one checkpoint interval lost

    with h5py.File(full / "bar_results" / "bar.h5") as a, h5py.File(tmp_path / "bar_results" / "bar.h5") as b:
        np.testing.assert_allclose(b["frames/time"][:], a["frames/time"][:], rtol=1e-12)
        # relative to each field's magnitude in this bar: the frames (every 5 s, half a period)
        # all sit at zero crossings of the stress, so take the closed-form amplitudes instead:
        # length 25, velocity v0 = 0.1, stress E v0 / c = 100 * 0.1 / 10 = 1
        amplitude = {"x": 25.0, "v": 0.1, "stress": 1.0}
        for field in ("x", "v", "stress"):
            scale = amplitude[field]
            xa, xb = a[f"frames/{field}"][-1], b[f"frames/{field}"][-1]
            assert np.abs(xa - xb).max() <= 1e-12 * scale, field
        np.testing.assert_allclose(b["history/middle"][:], a["history/middle"][:], rtol=0, atol=1e-12 * 2.0)
        assert len(a["energies/time"]) == len(b["energies/time"])


def test_divergence_stops_every_rank_with_the_stable_step_and_saves_the_last_good_state(tmp_path):
    case = BAR.replace("cfl = 0.5", "time_step = 0.2   # ten times the stable step\nallow_unstable_time_step = true")
    (tmp_path / "bad.toml").write_text(case)
    res = _mpirun(2, ["bad.toml", "--no-plots"], tmp_path, timeout=120)
    assert res.returncode == 3, res.stdout + res.stderr
    out = res.stdout + res.stderr
    assert "above the stable limit" in out            # warned at start
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("pmpm: error:")]
    assert len(errors) == 1 and "stable step is about" in errors[0]
    # the last good state has its own file; the scene writes no regular checkpoints
    files = os.listdir(tmp_path / "bad_results")
    assert "bad.lastgood.h5" in files and not [f for f in files if ".ckpt" in f]
    with h5py.File(tmp_path / "bad_results" / "bad.lastgood.h5") as f:
        assert f.attrs["complete"]
        assert np.isfinite(f["particles/x"][:]).all() and np.isfinite(f["particles/v"][:]).all()


def test_particles_leaving_the_grid_error_lists_them(tmp_path):
    case = BAR.replace('velocity = ["0.1 * sin(pi * x / 50)", 0.0]', "velocity = [0.0, 2.0]")
    case = case.replace('type = "fixed"', 'type = "roller_y"')
    (tmp_path / "fly.toml").write_text(case)
    res = _mpirun(2, ["fly.toml", "--no-plots"], tmp_path, timeout=120)
    assert res.returncode == 3, res.stdout + res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("pmpm: error:")]
    assert len(errors) == 1 and "left the grid" in errors[0] and "id " in errors[0]


def test_particles_leaving_the_grid_can_be_removed(tmp_path):
    case = BAR.replace('velocity = ["0.1 * sin(pi * x / 50)", 0.0]', "velocity = [0.0, 2.0]")
    case = case.replace('type = "fixed"', 'type = "roller_y"')
    case = case.replace("end_time = 10.0", 'end_time = 2.0\non_particle_exit = "remove"')
    (tmp_path / "fly.toml").write_text(case)
    res = _mpirun(2, ["fly.toml", "--no-plots"], tmp_path, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "were removed" in res.stdout + res.stderr
    with h5py.File(tmp_path / "fly_results" / "fly.h5") as f:
        assert np.isnan(f["frames/x"][-1]).any()       # removed rows are NaN in later frames


def test_more_ranks_than_the_grid_holds_is_refused(tmp_path):
    case = BAR.replace("cells = [54, 3]", "cells = [54, 3]").replace(
        "[solver]", '[parallel]\naxis = "y"\n\n[solver]')
    (tmp_path / "narrow.toml").write_text(case)
    res = _mpirun(3, ["narrow.toml"], tmp_path, timeout=120)
    assert res.returncode == 2, res.stdout + res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("pmpm: error:")]
    assert len(errors) == 1 and "at most 2 ranks" in errors[0]
    assert not (tmp_path / "narrow_results").exists()


def test_an_exception_on_one_rank_stops_all_ranks(tmp_path):
    """An uncaught exception on one rank aborts the job (abort hook), no hang."""
    script = tmp_path / "boom.py"
    script.write_text(
        "from mpi4py import MPI\n"
        "from decomposition import install_abort_hook\n"
        "from pmpm.scene.config import load_scene\n"
        "from pmpm.build import build_solver\n"
        "install_abort_hook(MPI.COMM_WORLD)\n"
        f"s = build_solver(load_scene({os.path.join(ROOT, 'cases', 'bar.toml')!r})[0])\n"
        "for k in range(50):\n"
        "    if k == 10 and MPI.COMM_WORLD.rank == 1:\n"
        "        raise RuntimeError('injected failure on rank 1')\n"
        "    s.step()\n")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    t0 = time.time()
    res = subprocess.run(["mpirun", "-n", "2", "--oversubscribe", sys.executable, str(script)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode != 0
    assert (res.stdout + res.stderr).count("injected failure on rank 1") >= 1
    assert time.time() - t0 < 100
