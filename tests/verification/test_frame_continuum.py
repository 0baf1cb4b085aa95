"""The MPM portal frame against a plane-stress finite-element model of the same strips (issue 11).

frame_fe_model.py models the continuum the MPM discretises (the strips of cases/portal_frame.toml
with their thickness rule, fixed bases and load box; 9-node quadrilaterals, scikit-fem; it shares
no code with pmpm) and is refined on nested meshes here (0.2, 0.1, 0.05 m element edges, cached
for the session). The MPM runs at the case's 0.05 m cells:

(a) static drift: a run with mass-proportional damping alpha = 2 omega_1 (critical for the first
    mode, through the scene's ``loads.damping`` key), read at T_SETTLE;
(b) sway period: the undamped elastic run of test_portal_frame.py (shared, 0.1 s), through the
    frame tests' estimator (twice the median spacing of the half-peak crossings), against the
    same estimator on the FE step response sampled the same way;
(c) first peak of the undamped step response, and its time.

Tolerance, per quantity: tol = e_FE + e_res (+ the terms named at each test), both from the
continuum model's own convergence (no figure of an earlier pmpm run enters):
- e_FE = 3 |Richardson - finest| / Richardson: the FE reference's discretisation error from its
  own refinement (Roache's grid convergence index with his safety factor 3 for a three-level
  study; the observed order, about 1.3, is set by the re-entrant corners of the joints and the
  clamped base corners and is the same for every quantity, see docs/portal_frame.md section 8);
- e_res = 3 |q_FE(node spacing of the MPM grid) - Richardson| / Richardson: the error the same
  continuum shows when discretised with nodes as far apart as the MPM's (0.05 m: the 0.1 m
  9-node quadrilaterals), with the same safety factor. The error at a given node spacing is
  set by the corner singularities, which every discretisation of this continuum meets alike;
  the MPM's cubic B-splines are, like the FE's quadratics, complete to second degree between
  its nodes, and the factor 3 covers their different constants (and the MPM's particle
  quadrature and time stepping).
The time of the first peak is the exception: it is set by higher modes (127 and 245 Hz) that
the 0.05 m MPM grid rings weaker than the continuum, so it is checked against the bound those
modes give, between the continuum's peak time and the first mode's alone (half its period).
"""
import math
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import frame_fe_model as fem  # noqa: E402
import frame_runs  # noqa: E402

T_UNDAMPED = 0.1      # the elastic run test_portal_frame.py reads too (one run per session)
T_SETTLE = 0.06       # damped run: (1 + w1 t) exp(-w1 t) = 9e-4 of the first mode left
FE_H0, FE_LEVELS, FE_MODES = 0.2, (0, 1, 2), 20
GCI_SAFETY = 3.0

MPM_CELL = 0.05       # the case's cells: the MPM's node spacing
# truncating the dynamic part to FE_MODES modes moves the FE peak by 0.011 mm of 47.85 (80 modes:
# docs/portal_frame.md section 8); counted as 0.05% so the bound holds with margin
E_MODES = 5e-4


def _resolution_error(study, q):
    """e_res: the FE's own error, with the safety factor, on the mesh whose nodes are as far
    apart as the MPM grid's (9-node quadrilaterals: two node spacings per element)."""
    row = next(r for r in study["rows"] if abs(r["h"] / 2 - MPM_CELL) < 1e-12)
    value = study["richardson"][q]["value"]
    return GCI_SAFETY * abs(row[q] - value) / abs(value)


def _fe(study, q):
    """(FE reference value, its relative error bound e_FE)."""
    r = study["richardson"][q]
    return r["value"], GCI_SAFETY * r["error"] / abs(r["value"])


@pytest.fixture(scope="session")
def fe_study():
    return fem.refinement_study(FE_LEVELS, FE_H0, FE_MODES)


@pytest.fixture(scope="module")
def undamped():
    return frame_runs.run_frame("elastic", T_UNDAMPED)


def test_fe_model_carries_the_scenes_mass_and_load(fe_study):
    """The FE strips weigh rho sum(A L) of the members and carry the whole load (independent of
    the mesh: the thickness rule gives each strip exactly A), and refining converges."""
    data = fem.read_scene()
    fe = fem.frame_fe(FE_H0, FE_LEVELS[0])
    mass = data.rho * sum(m.area * math.dist(m.start, m.end) for m in data.members)
    assert fe.total_mass() == pytest.approx(mass, rel=1e-10)   # exact quadrature of a constant
    assert fe.f.sum() == pytest.approx(data.load[0], rel=1e-12)
    for q in ("drift", "T1", "peak"):
        r = fe_study["richardson"][q]
        assert 0.5 < r["order"] < 4, (q, r)                    # monotone, asymptotic convergence
        assert r["error"] / abs(r["value"]) < 0.005, (q, r)    # and the finest level close to it


def test_static_drift_of_a_damped_run_matches_the_fe_model(fe_study):
    """(a): under critical damping of the first mode its part of the response has fallen to
    r = (1 + w1 t) e^(-w1 t) of the static value at T_SETTLE (9e-4): the reading is divided by
    (1 - r); the first mode carries 97% of the static drift (FE), so that correction is right to
    0.03 r, and the underdamped higher modes have decayed by e^(-alpha t / 2) = 1e-4 of their
    3% share; r itself is added to the tolerance to cover both and the slight mismatch of alpha
    (set from the FE's first period) with the MPM's."""
    drift_fe, e_fe = _fe(fe_study, "drift")
    w1 = 2 * math.pi / fe_study["richardson"]["T1"]["value"]
    run = frame_runs.run_frame("elastic", T_SETTLE, damping=2 * w1)
    settle = (1 + w1 * run["t"][-1]) * math.exp(-w1 * run["t"][-1])   # at the last sample
    drift = run["ux"][-1] / (1 - settle)
    tol = e_fe + _resolution_error(fe_study, "drift") + settle
    print(f"static drift: MPM {drift * 1e3:.3f} mm (read {run['ux'][-1] * 1e3:.3f} mm at {run['t'][-1]:.4f} s), "
          f"FE {drift_fe * 1e3:.3f} mm ({drift / drift_fe - 1:+.2%}, tolerance {tol:.2%})")
    assert drift == pytest.approx(drift_fe, rel=tol)


def test_sway_period_matches_the_fe_model(fe_study, undamped):
    """(b): same estimator, same sampling (every 20 steps of the MPM, 9.3e-5 s) on both."""
    _, _, period = fem.peak_and_period(undamped["t"], undamped["ux"])
    period_fe, e_fe = _fe(fe_study, "period_est")
    tol = e_fe + _resolution_error(fe_study, "period_est")
    print(f"sway period: MPM {period * 1e3:.3f} ms, FE {period_fe * 1e3:.3f} ms "
          f"(first mode {fe_study['richardson']['T1']['value'] * 1e3:.3f} ms; "
          f"{period / period_fe - 1:+.2%}, tolerance {tol:.2%})")
    assert period == pytest.approx(period_fe, rel=tol)


def test_first_peak_matches_the_fe_model(fe_study, undamped):
    """(c): the peak within e_FE + e_res + E_MODES; sampling every 9.3e-5 s lowers a peak of the
    first mode by at most (w1 dt)^2 / 8 = 3e-5, not counted. The peak's time lies between the
    continuum's and the first mode's alone (T1 / 2): the higher modes that pull the continuum's
    peak earlier (127 and 245 Hz) ring weaker on the 0.05 m MPM grid, and at most not at all;
    each end widened by its own FE error."""
    peak, t_peak, _ = fem.peak_and_period(undamped["t"], undamped["ux"])
    peak_fe, e_fe = _fe(fe_study, "peak")
    t_fe, e_fe_t = _fe(fe_study, "t_peak")
    T1, e_fe_T1 = _fe(fe_study, "T1")
    tol = e_fe + _resolution_error(fe_study, "peak") + E_MODES
    lo, hi = t_fe * (1 - e_fe_t), 0.5 * T1 * (1 + e_fe_T1)
    print(f"first peak: MPM {peak * 1e3:.3f} mm at {t_peak:.5f} s, FE {peak_fe * 1e3:.3f} mm at {t_fe:.5f} s "
          f"({peak / peak_fe - 1:+.2%}, tolerance {tol:.2%}; time within [{lo:.5f}, {hi:.5f}] s)")
    assert peak == pytest.approx(peak_fe, rel=tol)
    assert t_fe < 0.5 * T1  # the continuum's higher modes do pull its peak earlier
    assert lo <= t_peak <= hi
