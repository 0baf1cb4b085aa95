"""Pushover of the portal frame (cases/portal_pushover.toml, pmpm/physics/pushover.py) against
theory and the independent continuum model (issue 23).

(a) initial stiffness: an elastic push of the joint by 20 mm over 0.03 s (two quarter-sine
    velocity ramps of 15 ms, no constant part) and a 10 ms hold, 0.05 m cells. The stiffness is
    the base shear (both base reactions) averaged over the hold (1.5 cycles of the members'
    ringing, +-1.5%), over the joint's drift; it must equal the plane-stress finite-element
    model's P / static drift (tests/verification/frame_fe_model.py, levels 0-2 of 0.2 m elements
    and their Richardson extrapolation) within 2% (the issue's tolerance; the MPM at 0.05 m is
    itself within 0.8% of it in static drift: docs/portal_frame.md section 8).
(b) sway mechanism: the elastoplastic frame with non-hardening steel (hardening = 0: the
    collapse load is a rigid-perfectly-plastic theorem) pushed 0.1 m over 0.065 s (ramps of
    15 ms), 0.05 m cells. The plastic collapse load of the sway mechanism (hinges at both column
    bases and both beam ends at the column faces), by virtual work with the cuts' own Mp (their
    A, Z integrated from the particles, docs/structural_results.md):
        P_c = (2 Mp,col + 2 Mp,beam (1 + 2 e / L_b)) / h,
    e = half the column depth (the beam's hinge offset from the column axis), L_b the clear
    span, h the beam axis height. The base shear over the constant-velocity part past first
    yield and at rest after the push must lie within 5% of P_c (the issue's tolerance); the
    base shear never exceeds P_c by more than 5% while the push moves at constant velocity.

The CSV and plot the run writes are checked to exist with their columns and marks.
"""
import math
import os
import shutil
import sys

import numpy as np
import pytest

import pmpm

sys.path.insert(0, os.path.dirname(__file__))
import frame_fe_model as fem  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASE = os.path.join(ROOT, "cases", "portal_pushover.toml")
ELASTIC = {"type": "linear_elastic", "E": 207e9, "nu": 0.3, "density": 7850.0}


def _base_shear(r):
    R = r.reactions
    return -(np.asarray(R["left_base"]["Rx"]) + np.asarray(R["right_base"]["Rx"]))


def _fe_stiffness():
    """P / static drift of the FE model: levels 0-2 at h0 = 0.2 m, Richardson-extrapolated."""
    drifts = [fem.frame_fe(0.2, level).static()[1] for level in (0, 1, 2)]
    drift = fem.richardson(drifts)[0]
    return fem.read_scene().load[0] / drift, drifts


def test_initial_stiffness_matches_the_fe_model():
    push, hold_from, end = 0.02, 0.03, 0.04
    r = pmpm.run(CASE, dataframes=False, overrides={
        "materials.steel": ELASTIC, "output.fields": ["x", "x0", "v", "stress"],
        "output.deformed_plot": {"track": "upper_left_joint", "component": "ux", "color": "stress", "scale": 5.0},
        "output.section": [], "pushover.displacement": push, "pushover.duration": hold_from,
        "pushover.ramp": hold_from / 2, "solver.end_time": end, "output.history_interval": 5e-4})
    t = np.asarray(r.histories["upper_left_joint"]["time"])
    u = np.asarray(r.histories["upper_left_joint"]["ux"])
    hold = t > hold_from + 1e-9
    k_mpm = _base_shear(r)[hold].mean() / u[hold].mean()
    k_fe, _ = _fe_stiffness()
    assert k_mpm == pytest.approx(k_fe, rel=0.02)
    e = r.energies
    # at rest during the hold: the kinetic energy is a small fraction of the strain energy
    assert np.max(np.asarray(e["kinetic"])[hold] / np.asarray(e["strain_energy"])[hold]) < 0.01


@pytest.fixture(scope="module")
def mechanism_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pushover")
    shutil.copy(CASE, out / "portal_pushover.toml")
    r = pmpm.run(str(out / "portal_pushover.toml"), write=True, dataframes=False, overrides={
        "materials.steel.hardening": 0.0, "pushover.displacement": 0.1, "pushover.duration": 0.065,
        "pushover.ramp": 0.015, "solver.end_time": 0.065, "output.checkpoint_interval": 1.0,
        "output.directory": str(out / "results")})
    return r, out / "results"


def _collapse_load(h5_path):
    import json
    import h5py
    from pmpm.results.post import read_tables
    sections = read_tables(h5_path)["sections"]
    with h5py.File(h5_path, "r") as f:
        scene = json.loads(f.attrs["scene"])
    bodies = {b["name"]: b["geometry"] for b in scene["bodies"]}
    col, beam = bodies["left column"], bodies["beam"]
    e = col["depth"] / 2
    L_b = beam["end"][0] - beam["start"][0]
    h = beam["start"][1]
    mp_col = 0.5 * (sections["left_column_base"]["attrs"]["Mp"] + sections["right_column_base"]["attrs"]["Mp"])
    mp_beam = 0.5 * (sections["beam_left_end"]["attrs"]["Mp"] + sections["beam_right_end"]["attrs"]["Mp"])
    return (2 * mp_col + 2 * mp_beam * (1 + 2 * e / L_b)) / h


def test_reaches_the_sway_mechanism_load(mechanism_run):
    from pmpm.results.capacity import capacity_curve
    r, results = mechanism_run
    c = capacity_curve(r.path)
    P_c = _collapse_load(r.path)
    t, V = c["t"], c["base_shear"]
    spec = r.scene.pushover
    assert c["first_yield"] is not None
    steady = (t > c["first_yield"]["t"] + 0.01) & (t < spec["duration"] - spec["ramp"])
    assert steady.sum() >= 5
    assert np.mean(V[steady]) == pytest.approx(P_c, rel=0.05)
    assert np.max(V[steady]) < 1.05 * P_c
    assert V[-1] == pytest.approx(P_c, rel=0.05)       # at rest after the push
    assert c["kinetic_ratio"][-1] < 0.01


def test_capacity_files(mechanism_run):
    r, results = mechanism_run
    from pmpm.io import ownership
    from pmpm.io.plot import scene_stem
    from pmpm.results.capacity import write_capacity  # what the CLI writes after a run
    with ownership.writing(scene_stem(r.path)):        # as pmpm.results.post does
        made = write_capacity(r.path, str(results))
    csv = [p for p in made if p.endswith("_capacity.csv")]
    assert csv and os.path.exists(csv[0].replace(".csv", ".png"))
    data = np.genfromtxt(csv[0], delimiter=",", names=True)
    assert data.dtype.names == ("t", "drift", "base_shear", "kinetic_ratio")
    assert np.nanmax(data["drift"]) == pytest.approx(0.1, rel=0.02)
