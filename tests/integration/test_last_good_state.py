"""The last good state (issue 10, point 4): when a run fails, the newest state that passed the
health checks goes to ``<stem>.lastgood.h5``; it never replaces a regular checkpoint, and
``--restart`` continues from it.

A healthy elastic block is run in-process on one rank; after step ``BAD_AFTER`` one particle's
velocity is set to NaN (what a diverging step produces), which the solver's per-step check
finds in the next step. The health checks run every ENERGY_CHECK_INTERVAL steps and before
each regular checkpoint, so the newest healthy state is known exactly.
"""
import hashlib
import os

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core.solver import ENERGY_CHECK_INTERVAL, Solver
from pmpm.errors import UnstableRunError
from pmpm.runner import Run
from pmpm.scene.config import parse_scene

BAD_AFTER = 25  # steps; not a multiple of the energy-check interval (10) nor a checkpoint step


def _scene(tmp_path, end_time=1.0, cfl=0.5):
    return parse_scene({
        "grid": {"cell_size": 0.5, "cells": [8, 4]},
        "materials": {"steel": {"type": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0}},
        "bodies": [{"shape": "rectangle", "material": "steel", "lower": [1.0, 0.5], "upper": [3.0, 1.5],
                    "velocity": ["0.01 * sin(pi * x / 4)", 0.0]}],
        "solver": {"end_time": end_time, "cfl": cfl},
        # every 0.13 s, about 5.5 steps of 0.0238 s: checkpoints fall between energy checks
        "output": {"checkpoint_interval": 0.13, "directory": str(tmp_path / "out")},
    }, str(tmp_path / "block.toml"))


def _digest(path):
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def test_failure_keeps_the_newest_healthy_state_apart_and_restart_uses_it(tmp_path, monkeypatch):
    scene = _scene(tmp_path)
    run = Run(scene, MPI.COMM_SELF)
    base = str(tmp_path / "out" / "block")
    regular = {}
    original_step = Solver.step

    def step(solver):
        dt = original_step(solver)
        if solver.step_count == BAD_AFTER:
            solver.particles["v"][3, 0] = np.nan
            for k in (0, 1):  # the regular checkpoints as they are when the trouble starts
                if os.path.exists(f"{base}.ckpt{k}.h5"):
                    regular[k] = _digest(f"{base}.ckpt{k}.h5")
        return dt

    monkeypatch.setattr(Solver, "step", step)
    with pytest.raises(UnstableRunError):
        run.execute()
    monkeypatch.setattr(Solver, "step", original_step)

    assert regular, "no regular checkpoint before the failure: the test checks nothing"
    for k, digest in regular.items():  # untouched by the failure
        assert _digest(f"{base}.ckpt{k}.h5") == digest
    steps = []
    for k in regular:
        with h5py.File(f"{base}.ckpt{k}.h5", "r") as f:
            steps.append(int(f.attrs["step"]))
    with h5py.File(f"{base}.lastgood.h5", "r") as f:
        assert f.attrs["complete"]
        good = int(f.attrs["step"])
        t_good = float(f.attrs["time"])
        for name in ("x", "v", "stress"):
            assert np.isfinite(f["particles"][name][:]).all(), name
    # the newest state that passed a check: the last energy check at or before BAD_AFTER, or a
    # later checkpoint (checked before it was written), whichever is newer
    newest_checked = max([BAD_AFTER // ENERGY_CHECK_INTERVAL * ENERGY_CHECK_INTERVAL]
                         + [s for s in steps if s <= BAD_AFTER])
    assert good == newest_checked

    # --restart from the last good state continues at its time and finishes
    again = Run(_scene(tmp_path, end_time=0.8), MPI.COMM_SELF, restart=f"{base}.lastgood.h5")
    assert again.solver.t == t_good and again.solver.step_count == good
    summary = again.execute()
    assert summary["time"] == pytest.approx(0.8, rel=1e-12)
    # the step rule may change on restart (to continue a diverged run with a smaller step)
    slower = Run(_scene(tmp_path, cfl=0.25), MPI.COMM_SELF, restart=f"{base}.lastgood.h5", write=False)
    s = slower.solver
    assert s.dt == pytest.approx(0.25 * s.grid.h / (s.wave_speed + s.vmax), rel=1e-12)


def test_a_nan_in_the_initial_state_saves_no_last_good_state(tmp_path, monkeypatch):
    run = Run(_scene(tmp_path), MPI.COMM_SELF)
    run.solver.particles["stress"][0, 0] = np.nan
    with pytest.raises(UnstableRunError):
        run.execute()
    assert not os.path.exists(tmp_path / "out" / "block.lastgood.h5")
