"""The three-storey frame through the front end against an independent frame model (issue 22, item 5).

cases/frame_3storey.toml (the SAC LA 3-storey moment frame, two of its four bays, written as
nodes, members and named W sections) in its ``elastic`` variant under the step lateral load, at
the coarse grid CI can afford (0.2 m cells, 3 x 3 particles per cell: the W14 columns are two
cells deep), to 0.7 s: past the roof's first peak (0.44 s) and 0.74 of the fundamental period
(T1 = 0.944 s in the frame model). The independent model is frame2d_model.py (Timoshenko
beam-columns with joint panels, exact modal step response; it reads the scene file and shares no
code with pmpm). The study command ``python -m pmpm.benchmarks.studies.frame_3storey`` runs the
same comparison on finer grids and over 1.5 s, and the second period from a run loaded in a
pattern that excites mode 2 alone (docs/portal_frame.md section 11): T2 needs finer cells than CI
affords (12.7% long at 0.2 m, 4.0% at 0.1 m, converging on the frame model's), so it is not
checked here.

Checked, the bounds being the issue's:
(a) the first period, from the fit of the three left joints' records by the undamped step
    response's modal form (three frequencies shared by the joints; the case's load pattern is
    mostly mode 1, so T1 is what the window determines), within 3% of the frame model's; the same
    fit of the frame model's own record over the same window recovers its T1 within 0.5%, so the
    estimator is sound on this window, and its residual on the MPM record stays below 3% of the
    largest drift;
(b) the roof's first peak (its step-load peak drift) within 5%;
(c) the whole history of each joint within 5% RMS of the frame model's (relative to its largest
    drift: the issue's peak bound applied to every sample, so a drift between peaks counts);
(d) energy: the undamped elastic scene conserves it, so |external work - kinetic - strain| stays
    below 1% of the external work over the whole run, losses and gains both counted.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.benchmarks.studies import frame_3storey as study

CELL, PPC, T_END = 0.2, 3, 0.7


@pytest.fixture(scope="module")
def result():
    model = study.frame_model()
    run = study.run_cell(CELL, PPC, T_END, every=10, comm=MPI.COMM_SELF, progress=False)
    return study.compare(run, model), run


def test_first_period_matches_the_frame_model(result):
    cmp, _ = result
    print("periods", cmp["periods"], "frame", cmp["frame_periods"], "fit residual", cmp["fit_residual"],
          "estimator on the frame model's record", cmp["frame_fit_ratios"])
    assert abs(cmp["frame_fit_ratios"][0] - 1.0) < 0.005
    assert cmp["fit_residual"] < 0.03
    assert abs(cmp["period_ratios"][0] - 1.0) < 0.03, cmp["period_ratios"]


def test_roof_peak_drift_matches_the_frame_model(result):
    cmp, _ = result
    print("roof first peak", cmp["roof_first_peak"], "frame", cmp["frame_roof_first_peak"])
    assert abs(cmp["roof_first_peak_ratio"] - 1.0) < 0.05


def test_whole_history_of_every_floor(result):
    cmp, run = result
    print("rms gaps", cmp["rms_gap"])
    assert run["t"][-1] >= T_END
    assert all(g < 0.05 for g in cmp["rms_gap"]), cmp["rms_gap"]


def test_energy_is_conserved(result):
    cmp, run = result
    print("energy gap", cmp["energy_gap"], "external work at the end", run["external_work"][-1])
    assert run["external_work"][-1] > 0
    assert cmp["energy_gap"] < 0.01
    assert np.all(np.isfinite(run["loss"]))
