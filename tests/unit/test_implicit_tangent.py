"""The implicit integrator's stiffness is the derivative of its internal force (docs/implicit.md).

- Each material's tangent against a central finite difference of its own stress update:
  exact for the elastic matrix and the bilinear J2 consistent tangent (to the difference's
  round-off, ~1e-8 here), and for the paper's smooth model the rate form's E_t, which the
  sub-stepped update's derivative approaches as the increment shrinks (the difference is
  O(N |de| / eps_y): 1e-3 at |de| = 1e-4 eps_y, N = 10).
- The assembled tangent (numba blocks) equals the NumPy twin's dense matrix written from the
  equations, and both equal a finite-difference derivative of -f_int in an elastic and in a
  plastic state (bilinear J2, where a third of the points yield).

Shown to fail on planted bugs (restored): the geometric term dropped in assemble_blocks, B's
shear row with f_xx in place of f_xy, the sign of u v^T / w flipped in the plane-stress J2
tangent (the material test and the assembled test both fail).
"""
import numpy as np
import pytest

from pmpm.core.implicit import kernels as IK
from pmpm.core.implicit import reference as RF
from pmpm.core.shape import SHAPE_TAGS
from pmpm.physics.materials import make_material

E_S, NU, SY = 200e9, 0.3, 400e6


def _material(kind, formulation="plane_stress"):
    t = {"type": kind, "E": E_S, "nu": NU, "density": 7850.0}
    if kind != "linear_elastic":
        t.update(yield_stress=SY, hardening=0.05)
    return make_material(t, "materials.s", formulation)


def _update(m, s0, st0, de):
    s = s0.copy()
    st = {k: (v.copy() if v is not None else None) for k, v in st0.items()}
    m.update_stress(s, de, st, np.zeros(len(s), np.int32), -1)
    return s, st


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
@pytest.mark.parametrize("kind, size, tol", [("linear_elastic", 3e-3, 1e-7), ("bilinear_vonmises", 3e-3, 1e-7),
                                             ("smooth_vonmises", 2e-7, 1e-2)])
def test_material_tangent_is_the_derivative_of_its_update(kind, size, tol, formulation):
    m = _material(kind, formulation)
    rng = np.random.default_rng(3)
    n = 20
    s0 = np.zeros((n, 4))
    s0[:, :3] = rng.normal(size=(n, 3))
    if formulation == "plane_strain":
        s0[:, 3] = NU * (s0[:, 0] + s0[:, 1])
    # start states between 0.9 and 1.0 of the yield surface: the smooth model's own range (past
    # it, H1 = (Phi / sigma_y)^N makes the rate form so stiff that no small increment is small)
    dev = s0 - s0[:, [0, 1, 3]].mean(axis=1)[:, None] * np.array([1, 1, 0, 1])
    phi = np.sqrt(1.5 * (dev[:, 0] ** 2 + dev[:, 1] ** 2 + dev[:, 3] ** 2) + 3 * dev[:, 2] ** 2)
    if formulation == "plane_stress":
        phi = np.sqrt(s0[:, 0] ** 2 - s0[:, 0] * s0[:, 1] + s0[:, 1] ** 2 + 3 * s0[:, 2] ** 2)
    s0 *= (SY * rng.uniform(0.9, 1.0, n) / phi)[:, None]
    st0 = {k: np.zeros((n,) + sh) for k, sh in m.state_fields.items()}
    de = rng.normal(scale=size, size=(n, 3))
    s1, st1 = _update(m, s0, st0, de)
    D = np.zeros((n, 3, 3))
    m.tangent(s0, st0, s1, st1, de, D, np.zeros(n, np.int32), -1)
    fd = np.zeros((n, 3, 3))
    h = 1e-6 * size
    for j in range(3):
        e = np.zeros((n, 3))
        e[:, j] = h
        fd[:, :, j] = (_update(m, s0, st0, de + e)[0][:, :3] - _update(m, s0, st0, de - e)[0][:, :3]) / (2 * h)
    if kind != "linear_elastic":
        assert "eps_p_eq" in st1 and (st1["eps_p_eq"] > 0).sum() >= 3   # plastic points are tested
    err = np.abs(D - fd).max(axis=(1, 2)) / np.abs(fd).max(axis=(1, 2))
    assert err.max() < tol


def _setup(kind, plastic_scale):
    rng = np.random.default_rng(1)
    cells, h, origin = (6, 5), 0.5, np.array([0.1, -0.2])
    nx, ny = cells[0] + 1, cells[1] + 1
    n = 30
    x = origin + rng.uniform(0.15, 0.85, (n, 2)) * np.array(cells) * h
    vol = rng.uniform(0.5, 1.0, n) * 0.05
    m = _material(kind)
    s0 = np.zeros((n, 4))
    s0[:, :3] = rng.normal(size=(n, 3)) * plastic_scale
    st0 = {k: np.zeros((n,) + sh) for k, sh in m.state_fields.items()}
    U = rng.normal(size=(nx, ny, 2)) * 1e-3
    geom = (0, 0, origin, 1 / h, cells[0], cells[1], SHAPE_TAGS["cubic"])
    return x, vol, m, s0, st0, U, geom, (origin, h, cells)


def _internal(x, vol, m, s0, st0, U, geom):
    n = len(x)
    f, E = np.empty((n, 4)), np.empty((n, 3))
    IK.deformation_increment(x, U, *geom, f, E)
    S, st = _update(m, s0, st0, E)
    R = np.zeros(U.shape)
    IK.internal_force(x, vol, S, f, R, *geom)
    return R, f, E, S, st


@pytest.mark.parametrize("kind, scale", [("linear_elastic", 1e8), ("bilinear_vonmises", 1e8)])
def test_assembled_tangent_is_the_derivative_of_the_internal_force(kind, scale):
    x, vol, m, s0, st0, U, geom, (origin, h, cells) = _setup(kind, scale)
    R, f, E, S, st = _internal(x, vol, m, s0, st0, U, geom)
    if kind != "linear_elastic":
        assert (st["eps_p_eq"] > 0).sum() >= 5
    n = len(x)
    D = np.empty((n, 3, 3))
    m.tangent(s0, st0, S, st, E, D, np.zeros(n, np.int32), -1)
    nx, ny = U.shape[:2]
    lid = np.arange(nx * ny).reshape(nx, ny)
    span = IK.stencil_span(SHAPE_TAGS["cubic"])
    Kb = np.zeros((nx * ny, span * span, 2, 2))
    IK.assemble_blocks(x, vol, S, f, D, lid, Kb, *geom)
    K = RF.blocks_to_dense(Kb, lid, span)
    # the twin, from the equations
    f_ref, E_ref = RF.deformation_reference(3, x, U, origin, h, cells)
    np.testing.assert_allclose(E_ref, E, rtol=0, atol=1e-14 * np.abs(E).max())
    np.testing.assert_allclose(RF.internal_force_reference(3, x, vol, S, f_ref, origin, h, cells), R,
                               rtol=0, atol=1e-12 * np.abs(R).max())
    K_ref = RF.tangent_reference(3, x, vol, S, f_ref, D, origin, h, cells)
    assert np.abs(K - K_ref).max() <= 1e-12 * np.abs(K_ref).max()
    # and the derivative of -f_int, by central differences
    ndof = 2 * nx * ny
    fd = np.zeros((ndof, ndof))
    eps = 1e-9
    for k in range(ndof):
        d = np.zeros(ndof)
        d[k] = eps
        d = d.reshape(nx, ny, 2)
        fd[:, k] = -(_internal(x, vol, m, s0, st0, U + d, geom)[0]
                     - _internal(x, vol, m, s0, st0, U - d, geom)[0]).reshape(-1) / (2 * eps)
    assert np.abs(K - fd).max() <= 1e-6 * np.abs(fd).max()
