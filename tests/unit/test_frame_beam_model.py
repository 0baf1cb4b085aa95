"""Checks of the independent beam model (tests/verification/frame_beam_model.py) against closed forms.

The beam model is the reference the MPM portal frame is judged against, so it must itself be right:
each test pins one ingredient (element stiffness, mass, rigid offsets, eigen solver, Newmark) to a closed
form, with a tolerance that follows from the discretisation, stated beside it.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

# tests/ is not a package and conftest files belong to others: load the module by path.
_PATH = Path(__file__).resolve().parents[1] / "verification" / "frame_beam_model.py"
_SPEC = importlib.util.spec_from_file_location("frame_beam_model", _PATH)
fbm = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault(_SPEC.name, fbm)  # dataclasses look the module up while the class is built
_SPEC.loader.exec_module(fbm)

# A steel-like cantilever, arbitrary but realistic numbers.
E, A, I, RHO, L = 2.0e11, 0.01, 1.0e-5, 7850.0, 2.0


def cantilever(n, angle=np.pi / 2, tip_offset=0.0):
    """Cantilever of n elements fixed at the origin, along ``angle``; optional rigid offset at the tip.

    With ``tip_offset`` e, the last node sits e beyond the flexible length L, joined by a rigid link.
    """
    model = fbm.FrameModel()
    c, s = np.cos(angle), np.sin(angle)
    ids = [model.add_node(k * L / n * c, k * L / n * s) for k in range(n + 1)]
    if tip_offset:
        model.nodes[-1] = ((L + tip_offset) * c, (L + tip_offset) * s)
    model.fix_node(ids[0])
    for k, (a, b) in enumerate(zip(ids[:-1], ids[1:])):
        off_j = (-tip_offset * c, -tip_offset * s) if k == n - 1 else (0.0, 0.0)
        model.add_element(a, b, E, A, I, RHO, off_j=off_j)
    return model, ids[-1]


def tip_solution(model, tip, force_xy):
    """Static displacement (ux, uy) of the tip under a tip force."""
    K, _, free = model.reduced()
    f = np.zeros(len(free))
    f[np.searchsorted(free, 3 * tip)] = force_xy[0]
    f[np.searchsorted(free, 3 * tip + 1)] = force_xy[1]
    u = np.linalg.solve(K, f)
    return u[np.searchsorted(free, 3 * tip)], u[np.searchsorted(free, 3 * tip + 1)]


@pytest.mark.parametrize("n", [1, 3, 8])
def test_cantilever_tip_deflection_is_exact(n):
    # Cubic Hermite elements reproduce the exact cubic deflection of an end-loaded prismatic beam, so
    # only round-off remains (condition number ~1e6 here): 1e-10 relative.
    model, tip = cantilever(n)
    ux, _ = tip_solution(model, tip, (1000.0, 0.0))
    assert ux == pytest.approx(1000.0 * L**3 / (3 * E * I), rel=1e-10)


@pytest.mark.parametrize("angle", [0.0, np.pi / 6, np.pi / 2])
def test_axial_bar_stiffness(angle):
    # Linear axial shape functions are exact for a bar with end load (constant force): EA/L to round-off;
    # an inclined bar also checks the rotation to global axes.
    model, tip = cantilever(4, angle=angle)
    P = 1.0e6
    ux, uy = tip_solution(model, tip, (P * np.cos(angle), P * np.sin(angle)))
    along = ux * np.cos(angle) + uy * np.sin(angle)
    assert P / along == pytest.approx(E * A / L, rel=1e-10)


def test_rigid_tip_offset():
    # Flexible length L plus a rigid link e: u = P L^3/(3EI) + P e L^2/(EI) + P e^2 L/(EI), exact again.
    e, P = 0.3, 1000.0
    model, tip = cantilever(2, tip_offset=e)
    ux, _ = tip_solution(model, tip, (P, 0.0))
    expected = P * L**3 / (3 * E * I) + P * e * L**2 / (E * I) + P * e**2 * L / (E * I)
    assert ux == pytest.approx(expected, rel=1e-10)


def test_consistent_mass_carries_total_mass():
    # A rigid translation must see the whole mass rho A L in both directions (consistent mass rows sum).
    model, _ = cantilever(5, angle=np.pi / 3)
    _, M = model.assemble()
    for direction in (0, 1):
        r = np.zeros(model.ndof)
        r[direction::3] = 1.0
        assert r @ M @ r == pytest.approx(RHO * A * L, rel=1e-12)


def test_cantilever_first_frequency():
    # Euler-Bernoulli: w1 = 1.8751^2 sqrt(EI/(m L^4)). Consistent-mass Hermite elements converge as h^4
    # from above; with 8 elements the error is ~1e-6, so 0.5% is loose on purpose (1.8751 is rounded too).
    model, _ = cantilever(8)
    K, M, _ = model.reduced()
    w2, phi = fbm.generalized_eigen(K, M)
    w1 = 1.8751**2 * np.sqrt(E * I / (RHO * A * L**4))
    assert np.sqrt(w2[0]) == pytest.approx(w1, rel=5e-3)
    # the modes come back mass-normalised
    np.testing.assert_allclose(phi.T @ M @ phi, np.eye(len(M)), atol=1e-8)


def test_cantilever_step_load_peaks_at_twice_static():
    # Undamped step load: each mode oscillates as (1 - cos w t) about its static share, so the tip peaks
    # near 2 u_static (the first mode carries ~97% of the tip flexibility; higher modes shift the peak by
    # a few per cent at most: 3%) and its time average over whole periods is u_static (1% over 10 periods).
    model, tip = cantilever(8)
    K, M, free = model.reduced()
    w2, _ = fbm.generalized_eigen(K, M)
    period = 2 * np.pi / np.sqrt(w2[0])
    f = np.zeros(len(free))
    f[np.searchsorted(free, 3 * tip)] = 1000.0
    nsteps = 2000
    t, u = fbm.newmark_average_acceleration(K, M, f, 10 * period / nsteps, nsteps)
    ux = u[:, np.searchsorted(free, 3 * tip)]
    static = 1000.0 * L**3 / (3 * E * I)
    _, peak = fbm.first_peak(t, ux)
    assert peak == pytest.approx(2 * static, rel=3e-2)
    assert ux[:-1].mean() == pytest.approx(static, rel=1e-2)
    # no numerical damping: the last cycle still swings to about twice the static value
    assert ux[-nsteps // 10:].max() == pytest.approx(2 * static, rel=3e-2)


def test_portal_frame_lateral_stiffness():
    # docs/verification.md section 2: direct stiffness with axial shortening 2.01e7 N/m (3%); the inextensible slope-deflection
    # closed form 2.06e7 N/m neglects axial shortening and so sits a few per cent higher (5%).
    k = fbm.portal_frame_stiffness()
    assert k == pytest.approx(2.01e7, rel=3e-2)
    assert k == pytest.approx(fbm.portal_frame_closed_form_stiffness(), rel=5e-2)
    assert fbm.portal_frame_closed_form_stiffness() == pytest.approx(2.06e7, rel=5e-3)


def test_portal_frame_clear_span_is_stiffer_and_quicker():
    # Rigid joint offsets shorten the flexible beam: more rotational restraint, less mass.
    k_c, k_o = fbm.portal_frame_stiffness(), fbm.portal_frame_stiffness(geometry="clear")
    T_c, T_o = fbm.portal_frame_modes()[0], fbm.portal_frame_modes(geometry="clear")[0]
    assert 1.0 < k_o / k_c < 1.1
    assert 0.9 < T_o / T_c < 1.0


def test_portal_frame_first_period():
    # docs/verification.md section 2: effective sway mass 640-810 kg on 2.01e7 N/m gives 0.035-0.04 s; bracket 0.03-0.045 s.
    periods = fbm.portal_frame_modes()
    assert 0.03 < periods[0] < 0.045
    assert np.all(np.diff(periods) < 0)


def test_portal_frame_step_response():
    # Dominated by the sway mode: first peak near 2P/k (43 mm, docs/verification.md section 2) after about half a period.
    t, ux = fbm.portal_frame_response(t_end=0.05)
    k, period = fbm.portal_frame_stiffness(), fbm.portal_frame_modes()[0]
    t_peak, peak = fbm.first_peak(t, ux)
    assert peak == pytest.approx(2 * fbm.LOAD / k, rel=3e-2)
    assert t_peak == pytest.approx(period / 2, rel=5e-2)


def test_plastic_helpers():
    # docs/verification.md section 2: My = sigma_y S = 1255 kN m (its S is the handbook 163 in^3, 0.1% below
    # 2I/d from the rounded I and d: 2e-3); P_c = (2 Mp,col + 2 min(Mp,col, Mp,beam))/h.
    assert fbm.first_yield_base_moment() == pytest.approx(1.255e6, rel=2e-3)
    mp_col, mp_beam = fbm.SIGMA_Y * 3.048e-3, fbm.SIGMA_Y * 1.0488e-3
    assert fbm.sway_collapse_load() == pytest.approx((2 * mp_col + 2 * mp_beam) / 3.658, rel=1e-12)
    props = fbm.portal_frame_properties()
    assert props["column"]["I"] == 4.4537e-4 and props["beam"]["Z"] == 1.0488e-3
    # the idealised plates of the MPM strips carry a little less than the tabulated (filleted) shapes
    for member in ("column", "beam"):
        assert 0.97 < props[member]["I_strip"] / props[member]["I"] < 1.0
