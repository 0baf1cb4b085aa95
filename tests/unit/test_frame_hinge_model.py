"""Checks of the plastic-hinge frame model (tests/verification/frame_hinge_model.py), the
independent reference for the portal frame's hinge order (docs/structural_results.md)."""
import sys
from pathlib import Path

import numpy as np
import pytest

_DIR = Path(__file__).resolve().parents[1] / "verification"
sys.path.insert(0, str(_DIR))
import frame_beam_model as fbm  # noqa: E402
import frame_hinge_model as H  # noqa: E402


def test_elastic_step_peak_is_twice_the_static_drift():
    """Below yield the model is the elastic clear-span frame: the undamped step response of the
    sway mode peaks at twice the static drift P/k (k of frame_beam_model, clear geometry).
    Tolerance 3%: the rigid-plastic hinges' elastic springs add 1/50 to the members' end
    flexibility (HINGE_STIFFNESS) and the higher modes ride on the peak by about 1%."""
    r = H.hinge_response(0.01, t_end=0.04)
    static = 0.01 * fbm.LOAD / fbm.portal_frame_stiffness(geometry="clear")
    assert r["drift"].max() == pytest.approx(2 * static, rel=0.03)
    assert not r["order"]   # no hinge


def test_slow_push_collapses_at_the_sway_mechanism_load():
    """Under a load rising slowly (over about 14 sway periods) the last hinge of the sway
    mechanism forms at the mechanism's load
    P_c = (2 Mp,col + 2 Mp,beam (1 + 2 e / L_b)) / h (virtual work; e the rigid joint offsets,
    L_b the clear span: the beam hinges at the faces turn by (1 + 2e/L_b) times the sway).
    Tolerance 3%: the ramp's inertia (P rises 2% per period) and the hinge springs' flexibility."""
    col, beam = fbm._SECTIONS["column"], fbm._SECTIONS["beam"]
    e, Lb = col["d"] / 2, fbm.SPAN - col["d"]
    Pc = (2 * fbm.SIGMA_Y * col["Z"] + 2 * fbm.SIGMA_Y * beam["Z"] * (1 + 2 * e / Lb)) / fbm.HEIGHT
    frame = H.portal_hinge_frame()
    ramp = 0.5
    t, mh, _, drift = frame.run(1.3 * Pc, 1e-4, 0.5, sample_every=1, ramp=ramp)
    load = 1.3 * Pc * np.minimum(t / ramp, 1.0)
    at_mp = np.abs(mh) >= 0.999 * np.array([h["Mp"] for h in frame.hinges])
    mechanism = at_mp[:, [0, 1, 4, 5]].all(axis=1)   # both bases and both beam ends
    formed = np.flatnonzero(mechanism)[0]
    assert load[formed] == pytest.approx(Pc, rel=0.03)
    assert not at_mp[formed, 2:4].any()   # the column tops stay elastic
    # and then it runs away: the drift grows far beyond the elastic drift at P_c
    assert drift[-1] > 3 * Pc / fbm.portal_frame_stiffness(geometry="clear")
