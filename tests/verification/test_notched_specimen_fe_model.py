"""The notched specimen's FE model (tests/verification/notched_specimen_fe_model.py) checked on
its own, against closed forms, before it serves as the reference of test_fracture_specimen.py.

- Its plane-stress return mapping (the numba point update and its NumPy twin) on an
  equibiaxial strain path, where the closed form is known: elastic s = E eps / (1 - nu), then,
  on the yield surface with Ziegler's rule (d back = d lambda c xi / sigma_y, xi_xx = xi_yy =
  sigma_y), d lambda = ds / c and d eps_p = d lambda / 2, so the tangent is
  ds / d eps = 1 / ((1 - nu) / E + 1 / (2 c)), c = alpha E / (1 - alpha); d lambda summed is
  eps_p_eq, and the stress stays on the surface (Phi(sigma - back) = sigma_y to round-off).
- Its mesh: the node columns follow the notch arcs (the area is the plate's less the two
  half discs, plus the circular segments the chords leave, L^3 / (12 R) each) and the shape-function gradients reproduce a linear
  field exactly.
Planted bug (checked once): the hardening's c / sigma_y left out of the back-stress update ->
the tangent is wrong by orders of magnitude and the first check fails.
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import notched_specimen_fe_model as fe  # noqa: E402

E, NU, SY, ALPHA = 200e9, 0.3, 355e6, 0.01


def _closed_form(eps):
    c = ALPHA * E / (1 - ALPHA)
    ey = SY * (1 - NU) / E
    tangent = 1.0 / ((1 - NU) / E + 1.0 / (2 * c))
    return np.where(eps <= ey, E * eps / (1 - NU), SY + tangent * (eps - ey))


def test_return_mapping_on_an_equibiaxial_path():
    mat = fe.PlaneStressJ2(E, NU, SY, ALPHA)
    d = 2e-4
    n = 200
    sig, back = np.zeros(3), np.zeros(3)
    sig2, back2 = np.zeros((1, 3)), np.zeros((1, 3))
    de = np.array([d, d, 0.0])
    eq = eq2 = 0.0
    for k in range(1, n + 1):
        eq += fe._point_update(sig, back, de, mat.C, mat.a, mat.V, mat.Vinv, SY, mat.c)
        sig2, back2, dl = mat.update(sig2, back2, de[None])
        eq2 += dl[0]
        want = float(_closed_form(np.array(k * d)))
        assert math.isclose(sig[0], want, rel_tol=1e-9) and math.isclose(sig[1], want, rel_tol=1e-9)
        assert abs(sig[2]) < 1e-6
        np.testing.assert_allclose(sig2[0], sig, rtol=1e-12, atol=1e-3)
    xi = sig - back
    assert math.isclose(math.sqrt(xi[0] ** 2 - xi[0] * xi[1] + xi[1] ** 2 + 3 * xi[2] ** 2), SY, rel_tol=1e-10)
    # eps_p_eq: the plastic part of the strain, twice d eps_p,xx on this path
    eps_p = n * d - sig[0] * (1 - NU) / E
    assert math.isclose(eq, 2 * eps_p, rel_tol=1e-9) and math.isclose(eq2, eq, rel_tol=1e-12)


def test_mesh_follows_the_notches():
    sp = fe.SPECIMEN
    nodes, elems = fe.mesh(0.002)
    dndx, dndy, det = fe._gradients(nodes, elems)
    area = det.sum()   # Gauss weights 1
    exact = sp["length"] * sp["width"] - math.pi * sp["radius"] ** 2
    # the arcs are replaced by chords between the node columns: each chord of length L cuts a
    # circular segment of area L^3 / (12 R) (to leading order) off each notch
    ny = int(round(sp["width"] / 0.002))
    bottom = nodes[::ny + 1]
    on_arc = (bottom[:-1, 1] > 0) | (bottom[1:, 1] > 0)
    chords = np.linalg.norm(np.diff(bottom, axis=0), axis=1)[on_arc]
    segments = 2 * np.sum(chords ** 3) / (12 * sp["radius"])
    assert area > exact and area - exact < 1.1 * segments
    f = 3.0 * nodes[:, 0] - 2.0 * nodes[:, 1]
    gx = np.einsum("ma,mga->mg", f[elems], dndx)
    gy = np.einsum("ma,mga->mg", f[elems], dndy)
    assert np.abs(gx - 3.0).max() < 1e-9 and np.abs(gy + 2.0).max() < 1e-9
