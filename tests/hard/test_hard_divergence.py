"""A fixed time step above the stable limit (issue "hard cases", part 2).

"A scene may fix its time step instead of the CFL rule; a fixed step above the stable limit is
warned about at start, and if the run then diverges pmpm notices it within a few steps (energy
growth or non-finite values), stops every rank with a message that names the stable time step,
and keeps the last good state."

Each test runs ``mpirun -n 3 python -m pmpm.cli cases/hard/fixed_step_too_large.toml --variant V``
in a temporary directory (with a timeout, so a hang fails instead of blocking the suite) and
checks the exit code, the start-up warning, the one error line and the stable step it names,
how soon after the divergence became evident the run stopped, and the saved checkpoint.
"""
import json
import math
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hard_cases import ENERGY_TOLERANCE, load, scene_path, wave_speed  # noqa: E402

CASE = "fixed_step_too_large"
#: "within a few steps": pmpm checks the energy balance every 10 steps (non-finite values every
#: step), so a divergence must be caught at most 10 steps after it became evident
FEW_STEPS = 10
#: the named stable step may differ from h / (c + max|v|) of the initial state by the change of
#: max|v| before the divergence (|v| / c < 2% here) and by its 3-digit rounding in the message
STABLE_STEP_RTOL = 0.05


def _mpirun(n, args, cwd, timeout=240):
    cmd = ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none",
           sys.executable, "-m", "pmpm.cli", *args]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _stable_step_and_onset(variant):
    """The stable step of the initial state (CFL rule with C = 1) and the first step at which the
    divergence is evident in a serial run: the kinetic energy (which, unlike the internal work,
    cannot go negative) above twice the energy supplied."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    scene = load(CASE, variant)
    s = build_solver(scene, MPI.COMM_SELF)
    stable = s.grid.h / (wave_speed(s) + s.vmax)
    onset = None
    try:
        while onset is None and s.step_count < 200:
            s.step()
            e = s.energies()
            if e["kinetic"] > 2 * (s.initial_energy + e["external_work"]):
                onset = s.step_count
    except Exception:  # the serial run stopped: it diverged at this step at the latest
        onset = s.step_count + 1
    return stable, scene.solver.time_step, onset


@pytest.mark.parametrize("variant", ["x3", "x10"])
def test_fixed_step_above_the_limit_is_warned_caught_named_and_the_last_good_state_kept(tmp_path, variant):
    stable, dt, onset = _stable_step_and_onset(variant)
    assert dt > 2.5 * stable and onset is not None  # the scene does diverge, quickly
    shutil.copy(scene_path(CASE), tmp_path)
    res = _mpirun(3, [CASE + ".toml", "--variant", variant, "--no-plots"], tmp_path)
    out = res.stdout + res.stderr
    assert res.returncode == 3, out                     # every rank stopped, run failed
    assert "above the stable limit" in out              # warned at start

    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("pmpm: error:")]
    assert len(errors) == 1, out
    named = re.search(r"stable step is about ([0-9.eE+-]+) s", errors[0])
    assert named, f"the message does not name the stable time step: {errors[0]}"
    assert abs(float(named.group(1)) / stable - 1) <= STABLE_STEP_RTOL, (
        f"named stable step {named.group(1)} s, the scene's is {stable:.3g} s: {errors[0]}")
    stopped = re.search(r"\(step (\d+)", errors[0])
    assert stopped, errors[0]
    assert int(stopped.group(1)) <= onset + FEW_STEPS, (
        f"diverging from step {onset}, stopped at step {stopped.group(1)}")

    # the last good state: a complete checkpoint from before the divergence, finite, and within
    # the energy tolerance (2% of the energy in play)
    results = tmp_path / f"{CASE}_results"
    ckpts = []
    for name in os.listdir(results):
        if name.endswith(".lastgood.h5"):  # the last good state has its own file
            with h5py.File(results / name, "r") as f:
                if f.attrs.get("complete", False):
                    ckpts.append((int(f.attrs["step"]), name))
    assert ckpts, "no complete checkpoint saved"
    step, name = max(ckpts)
    assert step < onset
    with h5py.File(results / name, "r") as f:
        fields = {k: f["particles"][k][:] for k in f["particles"]}
        attrs = json.loads(f.attrs["attrs"])
    for k in ("x", "v", "stress", "vol", "m"):
        assert np.isfinite(fields[k]).all(), k
    kinetic = 0.5 * float(np.sum(fields["m"] * np.sum(fields["v"] ** 2, axis=1)))
    supplied = attrs["initial_energy"] + attrs["external_work"]
    scale = max(kinetic, abs(attrs["internal_work"]),
                abs(attrs["initial_energy"]) + abs(attrs["external_work"]))
    assert kinetic + attrs["internal_work"] - supplied <= ENERGY_TOLERANCE * scale
    assert math.isfinite(kinetic)
