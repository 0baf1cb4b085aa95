"""The neo-Hookean material point against closed forms (Bonet & Wood 2008, sec. 6.4.3:
sigma = mu/J (b - I) + lambda ln J / J I), its numba kernel against the NumPy twin, and its
wiring in the solver (the run keeps F; the energy is W(F))."""
import math

import numpy as np
import pytest
from mpi4py import MPI
from scipy.optimize import brentq

from pmpm.build import build_solver
from pmpm.physics.materials import make_material
from pmpm.physics.materials.linear_elastic import elastic_increment
from pmpm.physics.materials.neo_hookean import lame, neo_hookean_reference
from pmpm.scene.config import parse_scene

E, NU = 1e6, 0.3
MU, LAM = lame(E, NU)
TABLE = {"type": "neo_hookean", "E": E, "nu": NU, "density": 1050.0}
FORMS = ("plane_strain", "plane_stress")
#: round-off of stresses of order E (the closed forms and the kernel differ only in the order
#: of a few floating-point operations, and the plane-stress Newton stops at 1e-14 relative)
TOL = 1e-9 * E


def _stress(F2, formulation, f33=None):
    """Drive the material as the solver does: stress (N, 4) and F33 from F (N, 2, 2)."""
    F2 = np.asarray(F2, dtype=float).reshape(-1, 4)
    F = np.column_stack([F2, np.ones(len(F2)) if f33 is None else f33])
    mat = make_material(TABLE, "materials.m", formulation)
    stress = np.zeros((len(F), 4))
    mat.update_stress(stress, np.zeros((len(F), 3)), {"F": F}, np.zeros(len(F), np.int32), -1)
    return stress, F[:, 4]


def test_uniaxial_stretch_plane_strain():
    """F = diag(l, 1, 1): sxx = mu (l^2 - 1)/l + lambda ln l / l, syy = szz = lambda ln l / l."""
    for l in (0.6, 0.9, 1.0, 1.5, 3.0):
        stress, f33 = _stress([[l, 0], [0, 1]], "plane_strain")
        p = LAM * math.log(l) / l
        np.testing.assert_allclose(stress[0], [MU * (l * l - 1) / l + p, p, 0.0, p], atol=TOL)
        assert f33[0] == 1.0


def test_uniaxial_stress_plane_stress():
    """Uniaxial stress: F = diag(l, s, s) with syy = szz = 0, i.e. mu (s^2 - 1) + lambda ln(l s^2)
    = 0 (solved here by bisection, independently of the kernel's Newton); then
    sxx = mu (l^2 - 1)/J + lambda ln J / J with J = l s^2, stored times s (per initial thickness)."""
    for l in (0.7, 1.01, 1.5, 2.5):
        s = brentq(lambda s: MU * (s * s - 1) + LAM * math.log(l * s * s), 1e-3, 10.0, xtol=1e-15)
        stress, f33 = _stress([[l, 0], [0, s]], "plane_stress")
        J = l * s * s
        assert f33[0] == pytest.approx(s, rel=1e-12)
        np.testing.assert_allclose(stress[0], [s * (MU * (l * l - 1) / J + LAM * math.log(J) / J), 0, 0, 0],
                                   atol=TOL)
    # small stretch: the slope is Young's modulus (the model's small-strain limit)
    eps = 1e-6
    s = brentq(lambda s: MU * (s * s - 1) + LAM * math.log((1 + eps) * s * s), 0.5, 2.0, xtol=1e-16)
    stress, _ = _stress([[1 + eps, 0], [0, s]], "plane_stress")
    assert stress[0, 0] / eps == pytest.approx(E, rel=1e-5)  # O(eps) nonlinearity
    assert (1 - s) / eps == pytest.approx(NU, rel=1e-5)


@pytest.mark.parametrize("formulation", FORMS)
def test_simple_shear(formulation):
    """F = [[1, g], [0, 1]] (J = 1, and F33 = 1 solves szz = 0 in plane stress too):
    sxy = mu g, sxx = mu g^2, syy = szz = 0."""
    for g in (0.01, 0.5, 2.0):
        stress, f33 = _stress([[1, g], [0, 1]], formulation)
        np.testing.assert_allclose(stress[0], [MU * g * g, 0.0, MU * g, 0.0], atol=TOL)
        assert f33[0] == pytest.approx(1.0, abs=1e-14)


@pytest.mark.parametrize("formulation", FORMS)
def test_small_strain_limit_is_linear_elasticity(formulation):
    """F = I + eps: the stress equals the linear elastic one of the formulation to O(eps^2)."""
    eps = 1e-7 * np.array([[1.0, 0.4], [-0.7, 2.0]])
    stress, _ = _stress(np.eye(2) + eps, formulation)
    e = (eps[0, 0], eps[1, 1], eps[0, 1] + eps[1, 0])
    linear = elastic_increment(E, NU, formulation == "plane_strain", *e)
    np.testing.assert_allclose(stress[0], linear, rtol=0, atol=1e-12 * E)  # O(eps^2) = 1e-14 E


@pytest.mark.parametrize("formulation", FORMS)
def test_rigid_rotation_leaves_the_stress_unchanged_in_the_rotated_frame(formulation):
    """F' = R F gives sigma' = R sigma R^T (the model is objective; F33 unchanged)."""
    F = np.array([[1.3, 0.4], [-0.2, 0.8]])
    base, s0 = _stress(F, formulation)
    for theta in (0.3, 2.0, -2.9):
        R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
        rot, s1 = _stress(R @ F, formulation)
        sig = np.array([[base[0, 0], base[0, 2]], [base[0, 2], base[0, 1]]])
        expect = R @ sig @ R.T
        np.testing.assert_allclose(rot[0], [expect[0, 0], expect[1, 1], expect[0, 1], base[0, 3]], atol=TOL)
        assert s1[0] == pytest.approx(s0[0], rel=1e-12)
    assert np.abs(base[0, :3]).max() > 0.1 * E  # a stress large enough for the test to mean something


@pytest.mark.parametrize("formulation", FORMS)
def test_kernel_matches_numpy_twin(formulation):
    """Random F with det > 0 (stretches 0.5 .. 2): kernel and 3x3-matrix twin agree."""
    rng = np.random.default_rng(5)
    F2 = np.eye(2) + 0.4 * rng.normal(size=(500, 2, 2))
    F2 = F2[np.linalg.det(F2) > 0.2]
    stress, f33 = _stress(F2, formulation)
    F = np.column_stack([F2.reshape(-1, 4), np.ones(len(F2))])
    ref, s_ref = neo_hookean_reference(F, E, NU, formulation == "plane_strain")
    np.testing.assert_allclose(f33, s_ref, rtol=1e-12)
    np.testing.assert_allclose(stress, ref, atol=1e-9 * np.abs(ref).max())
    if formulation == "plane_stress":  # the twin's szz before zeroing: the Newton's residual
        mu_res = MU * (s_ref ** 2 - 1) + LAM * np.log(np.linalg.det(F2) * s_ref)
        assert np.abs(mu_res).max() < 1e-8 * E


def test_material_that_needs_F_makes_the_run_keep_it_and_report_W():
    """A neo-Hookean body keeps F without the output asking, and the reported strain energy is
    sum vol0 W(F): after a step it matches the model's W computed here from the stored F."""
    scene = parse_scene({
        "formulation": "plane_strain",
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.25, "cells": [8, 8]},
        "materials": {"m": TABLE},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.5, 0.5], "upper": [1.5, 1.5],
                    "velocity": ["0.3 * (y - 1.0)", "0.1 * (x - 1.0)"]}],
        "solver": {"end_time": 1.0},
        "output": {"fields": ["x", "stress"]},
    }, "nh.toml")
    s = build_solver(scene, MPI.COMM_SELF)
    assert s.keeps_F
    for _ in range(3):
        s.step()
    F = s.particles["F"]
    assert np.abs(F[:, :4] - [1, 0, 0, 1]).max() > 1e-4  # it deformed
    C = np.einsum("pji,pjk->pik", F[:, :4].reshape(-1, 2, 2), F[:, :4].reshape(-1, 2, 2))
    lnJ = np.log(np.linalg.det(F[:, :4].reshape(-1, 2, 2)))
    W = 0.5 * MU * (np.trace(C, axis1=1, axis2=2) + 1 - 3) - MU * lnJ + 0.5 * LAM * lnJ ** 2
    # W ~ mu eps^2 is the difference of O(mu) terms: with eps ~ 1e-3 the sums lose ~6 digits of
    # the 16 (a different order of the same operations differs at ~1e-10 relative)
    assert s.energies()["strain"] == pytest.approx(float(np.sum(W * s.particles["vol0"])), rel=1e-8)
    ref, _ = neo_hookean_reference(F, E, NU, True)
    np.testing.assert_allclose(s.particles["stress"], ref, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize("formulation", FORMS)
def test_internal_work_converges_to_the_stored_energy(formulation):
    """A block set spinning, stretching and shearing (J from 0.97 to 1.02): the integrated
    stress power sum V sigma : d (the solver's internal work) must equal the stored energy
    sum vol0 W(F) up to the time-integration error, which is first order in dt (forward-Euler
    F, trapezoid power). So halving the step halves the mismatch (ratio 2 within 15%), and the
    Richardson extrapolation 2 m(dt/2) - m(dt) leaves only the O(dt^2) rest: below 1e-3 of W.
    A stress that is not work-conjugate to W with pmpm's volume (e.g. the plane-stress Cauchy
    stress without the thickness stretch, off by 1 - F33 ~ 1.4% here) leaves a mismatch that
    does not vanish with dt."""
    mismatch = []
    for cfl in (0.2, 0.1):
        scene = parse_scene({
            "formulation": formulation,
            "grid": {"origin": [0.0, 0.0], "cell_size": 0.25, "cells": [12, 12]},
            "materials": {"m": {"type": "neo_hookean", "E": 1e5, "nu": 0.3, "density": 1000.0}},
            "bodies": [{"shape": "rectangle", "material": "m", "lower": [1.0, 1.0], "upper": [2.0, 2.0],
                        "velocity": ["3.0 * (x - 1.5)", "-1.0 * (y - 1.5) + 2.0 * (x - 1.5)"]}],
            "solver": {"end_time": 0.1, "cfl": cfl},
        }, "energy.toml")
        s = build_solver(scene, MPI.COMM_SELF)
        while s.t < 0.1 - 1e-12:
            s.step()
        e = s.energies()
        mismatch.append((e["internal_work"] - e["strain"]) / e["strain"])
    assert mismatch[0] / mismatch[1] == pytest.approx(2.0, rel=0.15)
    assert abs(2 * mismatch[1] - mismatch[0]) < 1e-3
