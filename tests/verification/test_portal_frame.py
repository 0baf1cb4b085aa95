"""The paper's portal frame against independent theory (docs/verification.md sections 2 and 6).

Elastic: the upper-left joint's response is compared with a small Euler-Bernoulli frame model
(frame_beam_model.py: consistent mass, Newmark) built from the same sections, with the mass of
the column stubs above the beam centre line that the continuum model carries. The MPM strips
are softer than the centre-line beam model by their shear deformation and the flexibility of the
joint panel (the column web between the flanges carries the joint's shear, see
docs/portal_frame.md), which is why the tolerance is the issue's 10%, not tighter.

Elastoplastic: yielding makes the peak larger and leaves a permanent drift; plastic strain sits
at the column bases and the beam-column joints; the base moment never exceeds the plastic moment
by more than the kinematic hardening allows; the energy balance closes within 1%.

The default resolution of the case (0.05 m cells) is used; each run covers 0.1 s (2.5 periods).
"""
import math
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import frame_beam_model as beam  # noqa: E402
import frame_runs  # noqa: E402

T_END = 0.1
SIGMA_Y, ALPHA, E = 470e6, 0.05, 207e9
Z_COLUMN = 3.048e-3


def _run(variant):
    # shared with test_frame_continuum.py (one elastic run per session, see frame_runs.py)
    return frame_runs.run_frame(variant, T_END)


def _peak_and_period(t, u):
    """First maximum, and the sway period: twice the median spacing of the crossings of half the
    first peak (the static level of an undamped step response), interpolated linearly. Higher
    modes shift single peaks and troughs but hardly these crossings. The same estimator is
    applied to both models."""
    i = int(np.argmax(u[t < 0.03]))
    d = u - 0.5 * u[i]
    k = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
    return u[i], t[i], 2 * float(np.median(np.diff(tc)))


@pytest.fixture(scope="module")
def elastic():
    return _run("elastic")


@pytest.fixture(scope="module")
def elastoplastic():
    return _run("elastoplastic")


def test_elastic_first_peak_and_period_match_the_beam_model(elastic):
    tb, ub = beam.portal_frame_response(t_end=T_END, stub_mass=True)
    peak_b, _, period_b = _peak_and_period(tb, ub)
    peak_m, _, period_m = _peak_and_period(elastic["t"], elastic["ux"])
    print(f"MPM peak {peak_m * 1e3:.2f} mm period {period_m * 1e3:.2f} ms; "
          f"beam {peak_b * 1e3:.2f} mm {period_b * 1e3:.2f} ms")
    assert peak_m == pytest.approx(peak_b, rel=0.10)
    assert period_m == pytest.approx(period_b, rel=0.10)
    # the continuum is the softer of the two (shear, joint panel), never the stiffer
    assert peak_m > peak_b * 0.98


def test_elastic_energy_is_conserved(elastic):
    """Undamped, elastic: kinetic + internal work equals the external work within 1%."""
    e = elastic["energies"]
    work = np.array([x["external_work"] for x in e])
    gap = np.array([x["kinetic"] + x["internal_work"] - x["external_work"] for x in e])
    assert np.all(np.abs(gap) <= 0.01 * work.max())


def test_yielding_raises_the_peak_and_leaves_a_drift(elastic, elastoplastic):
    peak_el = elastic["ux"][elastic["t"] < 0.03].max()
    peak_ep = elastoplastic["ux"][elastoplastic["t"] < 0.03].max()
    assert peak_ep > peak_el
    # the centre of oscillation over the last full period moves in the load direction
    window = lambda r: r["ux"][(r["t"] > T_END - 0.04)].mean()  # noqa: E731 (one period)
    drift = window(elastoplastic) - window(elastic)
    assert drift > 0.5e-3, drift
    assert elastoplastic["energies"][-1]["plastic_work"] > 0


def test_plastic_strain_sits_at_bases_and_joints(elastoplastic):
    p = elastoplastic["solver"].particles
    x0, work = p["x0"], p["plastic_work"] * p["vol"]
    near_base = x0[:, 1] < 0.7
    near_joint = (x0[:, 1] > 3.0) & ((np.abs(x0[:, 0]) < 0.8) | (np.abs(x0[:, 0] - 6.096) < 0.8))
    hinge = near_base | near_joint
    assert work[hinge].sum() >= 0.9 * work.sum()
    top = p["eps_p_eq"] >= 0.5 * p["eps_p_eq"].max()
    assert np.all(hinge[top])


def test_base_moment_bounded_by_plastic_moment_with_hardening(elastoplastic):
    """|M| <= Z (sigma_y + c eps_p): Ziegler hardening with c = alpha E / (1 - alpha) shifts the
    yield surface by at most c times the plastic strain; 5% for the band's spread of stress."""
    p = elastoplastic["solver"].particles
    eps_p = p["eps_p_eq"][p["x0"][:, 1] < 0.4].max()
    bound = Z_COLUMN * (SIGMA_Y + ALPHA * E / (1 - ALPHA) * eps_p)
    m = np.abs(elastoplastic["moments"])
    assert m.max() <= 1.05 * bound, (m.max(), bound)
    assert m.max() > 0.5 * Z_COLUMN * SIGMA_Y  # the bases carry real bending


def test_energy_balance_with_plastic_dissipation(elastoplastic):
    """kinetic + recoverable strain + plastic work = external work, within 1% of that work."""
    e = elastoplastic["energies"]
    work = np.array([x["external_work"] for x in e])
    gap = np.array([x["kinetic"] + x["strain"] + x["plastic_work"] - x["external_work"] for x in e])
    assert np.all(np.abs(gap) <= 0.01 * work.max()), np.abs(gap).max() / work.max()
