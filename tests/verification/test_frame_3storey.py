"""The three-storey frame through the front end against an independent model (issue 22, item 5).

cases/frame_3storey.toml (the SAC LA 3-storey moment frame, two of its four bays, written as
nodes, members and named W sections) in its ``elastic`` variant under the step lateral load, at
0.1 m cells with the case's 2 x 2 particles per cell, to 0.6 s: past the roof's first peak
(0.43 to 0.49 s) and 0.65 of the fundamental period. About 5 minutes on this host.

The reference is the plane-stress continuum of the same strips (frame3_fe_model.py: scikit-fem,
9-node quadrilaterals, the expanded scene's bodies with the nodal masses as the joint panels'
density; it shares no solver code with pmpm), on its level-1 mesh (0.1 m elements: its T1 is
0.2% from the Richardson limit of levels 0-2, docs/portal_frame.md section 11), read at the
particles the MPM tracks. The second reference is the independent frame model (frame2d_model.py:
Timoshenko members, the columns continuous through the joints; it shares no code with pmpm or the
continuum model, and agrees with the continuum within 0.7% in T1 and T2, test_frame_3storey_fe.py):
(a) to (c) below are checked against it too. At 0.2 m cells the MPM is 3.3% long in T1 and 6% high
in the peak against the continuum (coarse strips are too flexible), so CI runs 0.1 m.

Checked, the bounds being the issue's (3% for periods, 5% for the peak drift):
(a) T1, from a least-squares fit of the three left joints' records by the undamped step
    response's modal form (three frequencies shared by the joints; the case's load pattern puts
    98% of the roof's static drift in mode 1, so T1 is what the window determines), within 3% of
    the continuum's; the same fit of the continuum's own record over the same window recovers its
    eigenperiod within 0.5%, so the estimator is sound on this window, and its residual on the
    MPM record stays below 3% of the largest drift;
(b) the roof's first peak (its largest drift in the window) within 5%;
(c) the whole history of each joint within 5% RMS of the continuum's (relative to its largest
    drift: the peak bound applied to every sample, so a drift between peaks counts);
(d) energy: the undamped elastic scene conserves it, so |external work - kinetic - strain| stays
    below 1% of the external work over the whole run, losses and gains both counted.
T2 is the study's (``python -m studies.frame_3storey``, a run loaded in a
mode-2 pattern): 0.6% from the continuum's at 0.1 m (3 x 3 particles), 0.1% at 0.05 m.
"""
import os
import sys

import numpy as np
import pytest
from mpi4py import MPI

from studies import frame_3storey as study

sys.path.insert(0, os.path.dirname(__file__))
import frame3_fe_model as f3  # noqa: E402

CELL, PPC, T_END = 0.1, 2, 0.6


@pytest.fixture(scope="module")
def result():
    run = study.run_cell(CELL, PPC, T_END, every=10, comm=MPI.COMM_SELF, progress=False)
    fe = f3.Frame3FE(f3.read_scene3(), 0.2, 1, track_cell=CELL)
    periods = fe.periods(3)
    ref = f3.responses(fe, run["t"])[0].T               # (samples, joints)
    frame = study.compare(run, study.frame_model())
    return run, periods, ref, frame


def test_first_period_matches_the_continuum(result):
    run, periods, ref, frame = result
    fitted, residual = study.fit_periods(run["t"], run["u"], periods)
    own, _ = study.fit_periods(run["t"], ref, periods)
    print("T1 MPM", fitted[0], "continuum", periods[0], "estimator on the continuum's record", own[0],
          "fit residual", residual, "| frame model T1", frame["frame_periods"][0])
    assert abs(own[0] / periods[0] - 1.0) < 0.005
    assert residual < 0.03
    assert abs(fitted[0] / periods[0] - 1.0) < 0.03


def test_roof_peak_drift_matches_the_continuum(result):
    run, _, ref, frame = result
    mpm, fe = run["u"][:, 2].max(), ref[:, 2].max()
    print("roof first peak MPM", mpm, "continuum", fe, "| frame model", frame["frame_roof_first_peak"])
    assert abs(mpm / fe - 1.0) < 0.05


def test_whole_history_of_every_floor(result):
    run, _, ref, _ = result
    assert run["t"][-1] >= T_END
    gaps = [np.sqrt(np.mean((run["u"][:, k] - ref[:, k]) ** 2)) / np.abs(ref[:, k]).max() for k in range(3)]
    print("rms gaps", gaps)
    assert all(g < 0.05 for g in gaps), gaps


def test_energy_is_conserved(result):
    run = result[0]
    gap = study.energy_gap(run)
    print("energy gap", gap, "external work at the end", run["external_work"][-1])
    assert run["external_work"][-1] > 0
    assert np.all(np.isfinite(run["loss"]))
    assert gap < 0.01


def test_period_peak_and_history_match_the_frame_model(result):
    # the check against an independent frame model: T1 within 3%, the step-load peak roof
    # drift within 5%, and (as for the continuum) every joint's whole history within 5% RMS
    run, _, _, frame = result
    print("against the frame model: T1", frame["period_ratios"][0], "roof first peak",
          frame["roof_first_peak_ratio"], "rms gaps", frame["rms_gap"])
    assert abs(frame["period_ratios"][0] - 1.0) < 0.03
    assert abs(frame["roof_first_peak_ratio"] - 1.0) < 0.05
    assert all(g < 0.05 for g in frame["rms_gap"]), frame["rms_gap"]
