"""The main job keeps its amplitude (issue 25, docs/accuracy.md "The whole response"): the
elastic portal frame at the settings of cases/portal_frame.toml as they are ([grid] cell size,
[solver] shape function, scheme, CFL, transfer), on a shortened run, against the continuum FE
model (frame_fe_model.py, 9-node quadrilaterals at 0.05 m element edges, read at the particle
the run's tracker follows).

The main job's limits over its 0.25 s: every sway peak within 1% of the continuum model, and the
energy lost to the discretisation (``numerical_loss``) within 0.3% of the energy in play, the
mean of kinetic plus strain energy over the record, F u_static (the study's measure). The shortened run (T_SHORT, past the first peak) holds the first to the same 1%
and the second to the same budget spent no faster than the record allows: 0.3% x T_SHORT / 0.25
(the loss grows steadily over the record at these settings: docs/accuracy.md). The full record
is the study's (``pmpm bench accuracy --response``), not a CI run's.
"""
import dataclasses
import os
import sys

import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, os.path.dirname(__file__))
import frame_fe_model as fem  # noqa: E402

from pmpm.build import build_solver
from pmpm.io.tracking import Tracker  # noqa: E402
from pmpm.scene.config import load_scene  # noqa: E402

CASE = os.path.join(os.path.dirname(__file__), "..", "..", "cases", "portal_frame.toml")
T_RECORD = 0.25          # the main job's end time
T_SHORT = 0.03           # past the first peak (0.019-0.020 s), before the first trough ends
PEAK_LIMIT = 0.01        # issue 25: every peak within 1% of the continuum model
ENERGY_LIMIT = 0.003     # issue 25: the elastic energy kept within 0.3% over the record
FE_H0, FE_LEVEL, FE_MODES = 0.2, 2, 20   # as test_frame_continuum.py (its cached model; 0.3% of converged)


@pytest.fixture(scope="module")
def run():
    scene = load_scene(CASE, "elastic")[0]
    scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, end_time=T_SHORT),
                                output=dataclasses.replace(scene.output, checkpoint_interval=None))
    s = build_solver(scene, MPI.COMM_SELF)
    tracker = Tracker([tr for tr in scene.output.track if tr.name == "upper_left_joint"], s)
    t, u = [0.0], [0.0]
    while s.t < T_SHORT * (1 - 1e-12):
        s.step()
        t.append(s.t)
        u.append(float(tracker.sample()[0, 0]))
    return scene, s, np.array(t), np.array(u)


def _fe(scene, t):
    fe = fem.frame_fe(FE_H0, FE_LEVEL)
    px, py = fem.mpm_track_point(fe.data, scene.grid.cell_size)
    probe = fe.basis.probes(np.array([[px], [py]]))
    omega, phi = fe.modes(FE_MODES)
    static, _ = fe.static()
    q = (phi.T @ fe.f) / omega ** 2
    u_static = float((probe @ static)[0])
    return u_static - ((probe @ phi)[0] * q) @ np.cos(np.outer(omega, t)), u_static


def test_first_peak_within_one_percent_of_the_continuum(run):
    scene, s, t, u = run
    fe_u, _ = _fe(scene, t)
    peak, fe_peak = u.max(), fe_u.max()
    assert abs(peak - fe_peak) / fe_peak < PEAK_LIMIT, (peak, fe_peak)


def test_energy_lost_within_the_records_budget(run):
    scene, s, t, u = run
    _, u_static = _fe(scene, t[:2])
    in_play = scene.loads.forces[0].force[0] * u_static
    loss = s.energies()["numerical_loss"]
    budget = ENERGY_LIMIT * T_SHORT / T_RECORD
    assert abs(loss) / in_play < budget, (loss / in_play, budget)   # lost or gained
