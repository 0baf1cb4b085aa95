"""CPDI1 (``solver.interpolation = "cpdi"``, Sadeghirad, Brannon & Burghardt 2011): the weights
and gradients against theory (partition of unity, linear completeness: a linear field and its
gradient reproduced exactly), the kernels against the NumPy twin written from the paper's
formulas, the grid edges (corners clamped onto the grid), the slab window (a corner beyond it is
dropped and reported) and the per-particle users of the shape (point loads, attached supports)."""
import numpy as np
import pytest

from pmpm.core import kernels as K
from pmpm.core.kernels.reference import (cpdi_basis_matrix, g2p_deformation_reference,
                                         g2p_velocity_reference, p2g_reference)
from pmpm.core.kernels.support import mark_support
from pmpm.core.shape import CPDI_REACH, ghost_width, shape_argument

CELLS = (9, 7)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])
ORDERS = {"linear": 1, "quadratic": 2, "cubic": 3}


def _F(rng, n, size=0.4):
    """Random deformation gradients with det F > 0: rotation times a stretch and a shear."""
    th = rng.uniform(-np.pi, np.pi, n)
    c, s = np.cos(th), np.sin(th)
    U = np.stack([1 + rng.uniform(-size, 2 * size, n), rng.uniform(-size, size, n),
                  np.zeros(n), 1 + rng.uniform(-size, 2 * size, n)], axis=1).reshape(n, 2, 2)
    U[:, 1, 0] = U[:, 0, 1]
    R = np.stack([c, -s, s, c], axis=1).reshape(n, 2, 2)
    A = R @ U
    assert (np.linalg.det(A) > 0).all()
    return np.concatenate([A.reshape(n, 4), np.ones((n, 1))], axis=1)


def _particles(n=300, seed=1, interior=False):
    rng = np.random.default_rng(seed)
    lo, hi = (1.5, np.array(CELLS) - 1.5) if interior else (0.0, np.array(CELLS))
    x = ORIGIN + rng.uniform(lo, hi, (n, 2)) * H
    if not interior:
        x[:5, 0] = ORIGIN[0] + 1e-9           # on the edges: corners clamped onto the grid
        x[5:10, 1] = ORIGIN[1] + CELLS[1] * H - 1e-9
    domain = rng.uniform(0.05, 0.3, (n, 2))
    return {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
            "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4)), "domain": domain,
            "F": _F(rng, n)}


def _nodes():
    X = ORIGIN[0] + H * np.arange(CELLS[0] + 1)
    Y = ORIGIN[1] + H * np.arange(CELLS[1] + 1)
    return np.meshgrid(X, Y, indexing="ij")


@pytest.mark.parametrize("order", [1, 2, 3])
def test_the_twin_reproduces_a_linear_field_and_its_gradient_inside(order):
    """sum_i N_i = 1, sum_i x_i N_i = x_p and sum_i x_i (x) grad N_i = I (exactly, to round-off)
    for sheared, stretched and rotated domains whose corners stay inside the grid: this fixes
    the signs of a, b and V in the paper's gradient."""
    p = _particles(interior=True)
    N, dN = cpdi_basis_matrix(order, p["x"], ORIGIN, H, CELLS, p["domain"], p["F"])
    X, Y = _nodes()
    np.testing.assert_allclose(N.sum(axis=(1, 2)), 1, atol=1e-13)
    np.testing.assert_allclose(np.einsum("pij,ij->p", N, X), p["x"][:, 0], atol=1e-13)
    np.testing.assert_allclose(np.einsum("pij,ij->p", N, Y), p["x"][:, 1], atol=1e-13)
    grad = np.stack([np.einsum("pijd,ij->pd", dN, X), np.einsum("pijd,ij->pd", dN, Y)], axis=1)
    np.testing.assert_allclose(grad, np.broadcast_to(np.eye(2), grad.shape), atol=1e-12)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_partition_of_unity_at_the_edges(order):
    """Particles on and near the edges (their corners clamped onto the grid): weights sum to 1,
    gradients to 0 (sum_c g_c = 0), every weight on a grid node."""
    p = _particles()
    N, dN = cpdi_basis_matrix(order, p["x"], ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(N.sum(axis=(1, 2)), 1, atol=1e-13)
    np.testing.assert_allclose(dN.sum(axis=(1, 2)), 0, atol=1e-11)


def _shape(name, p, escape=None):
    return shape_argument(name, "cpdi", p["domain"], p["F"], escape)


def _grid():
    return np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))


@pytest.mark.parametrize("name", ["linear", "quadratic", "cubic"])
def test_p2g_matches_the_twin(name):
    p = _particles()
    gravity = np.array([0.3, -9.8])
    G = _grid()
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], gravity, None, None, None,
          G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], _shape(name, p))
    fext = p["m"][:, None] * gravity
    mass, mom, force = p2g_reference(ORDERS[name], p["x"], p["m"], p["v"], p["vol"], p["stress"],
                                     fext, ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-10, atol=1e-10)
    assert G[..., 0].sum() == pytest.approx(p["m"].sum(), rel=1e-13)   # partition of unity


@pytest.mark.parametrize("name", ["linear", "quadratic", "cubic"])
def test_g2p_velocity_matches_the_twin_and_remaps_the_momentum(name):
    p = _particles()
    rng = np.random.default_rng(7)
    G = _grid()
    G[..., 1:5] = rng.normal(size=G[..., 1:5].shape)
    vel, dvel = G[..., 1:3].copy(), G[..., 3:5].copy()
    v = p["v"].copy()
    dx = np.empty_like(v)
    K.g2p_velocity(p["x"], p["m"], v, 0.2, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1],
                   _shape(name, p), True, dx, 0.5)
    ref = g2p_velocity_reference(ORDERS[name], p["x"], p["v"], vel, dvel, 0.2, ORIGIN, H, CELLS,
                                 p["domain"], p["F"])
    np.testing.assert_allclose(v, ref, rtol=1e-12, atol=1e-12)
    N, _ = cpdi_basis_matrix(ORDERS[name], p["x"], ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(dx, 0.5 * np.einsum("pij,ijd->pd", N, vel), atol=1e-12)
    np.testing.assert_allclose(G[..., 5:7], np.einsum("pij,p,pd->ijd", N, p["m"], v), atol=1e-12)


@pytest.mark.parametrize("name", ["linear", "quadratic", "cubic"])
def test_g2p_kinematics_matches_the_twin(name):
    """Strain, spin, F, volume and polar rotation from L = sum_c v(x_c) (x) g_c."""
    p = _particles()
    rng = np.random.default_rng(3)
    G = _grid()
    G[..., 5:7] = rng.normal(size=G[..., 5:7].shape)
    vel = G[..., 5:7].copy()
    n = len(p["m"])
    F0 = p["F"].copy()
    vol0 = p["vol"].copy()
    de, dq, vol = np.empty((n, 3)), np.empty((n, 2)), p["vol"].copy()
    dt = 1e-3
    shape = _shape(name, p)            # holds p["F"], which the kernel advances
    K.g2p_kinematics(p["x"], p["m"], vol, None, de, None, p["F"], vol0, dq, 5, None, dt,
                     None, None, None, None, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], shape)
    de_r, _, F_r, vol_r, dth = g2p_deformation_reference(ORDERS[name], p["x"], vel, F0, vol0, dt,
                                                         ORIGIN, H, CELLS, p["domain"])
    np.testing.assert_allclose(de, de_r, atol=1e-12)
    np.testing.assert_allclose(p["F"], F_r, atol=1e-12)
    np.testing.assert_allclose(vol, vol_r, rtol=1e-12)
    np.testing.assert_allclose(np.arctan2(dq[:, 1], dq[:, 0]), dth, atol=1e-10)


def test_a_linear_velocity_field_gives_its_gradient_exactly():
    """Grid velocities v = A x + c: every particle whose corners are inside gets L = A."""
    p = _particles(interior=True)
    A = np.array([[0.3, -1.2], [0.7, 0.1]])
    X, Y = _nodes()
    G = _grid()
    G[..., 5] = A[0, 0] * X + A[0, 1] * Y + 2.0
    G[..., 6] = A[1, 0] * X + A[1, 1] * Y - 1.0
    n = len(p["m"])
    de, dw, vol = np.empty((n, 3)), np.empty(n), p["vol"].copy()
    dt = 0.01
    K.g2p_kinematics(p["x"], p["m"], vol, None, de, dw, None, None, None, 5, None, dt,
                     None, None, None, None, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], _shape("linear", p))
    np.testing.assert_allclose(de, np.broadcast_to(dt * np.array([A[0, 0], A[1, 1], A[0, 1] + A[1, 0]]), de.shape), atol=1e-13)
    np.testing.assert_allclose(dw, 0.5 * dt * (A[1, 0] - A[0, 1]), atol=1e-13)


def test_a_window_gets_the_slice_of_the_full_grid_and_a_corner_beyond_it_is_reported():
    """A slab owning cell columns [6, 9) of 20 has the node window [6 - g, 9 + g) (g the
    ghost width, as decomposition/decomp.py lays it out): with domains of a fraction of a cell it
    receives exactly the full grid's values there. One particle stretched by more than
    CPDI_REACH cells along x is dropped from the window (nothing written outside it) and
    reported in ``escape`` with its index."""
    rng = np.random.default_rng(5)
    cells = (20, 7)
    n = 200
    x = ORIGIN + np.stack([rng.uniform(6, 9, n), rng.uniform(0, cells[1], n)], axis=1) * H
    p = {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
         "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4)),
         "domain": rng.uniform(0.05, 0.3, (n, 2)), "F": _F(rng, n, size=0.2)}
    q = int(np.argmax(x[:, 0]))
    for name in ("linear", "cubic"):
        g = ghost_width(name, "cpdi")
        lo, hi = 6 - g, 9 + g
        full = np.zeros((cells[0] + 1, cells[1] + 1, K.N_FIELDS))
        win = np.zeros((hi - lo, cells[1] + 1, K.N_FIELDS))
        esc = np.array([0, -1], dtype=np.int64)
        for G, ox in ((full, 0), (win, lo)):
            K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
                  G, ox, 0, ORIGIN, 1 / H, cells[0], cells[1], shape_argument(name, "cpdi", p["domain"], p["F"], esc))
        np.testing.assert_array_equal(full[lo:hi], win)
        assert esc[0] == 0
        F = p["F"].copy()
        F[q, :4] = [(CPDI_REACH + 2.0) / p["domain"][q, 0], 0.0, 0.0, 1.0]   # r1 = reach + 2 cells
        win[:] = 0
        K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
              win, lo, 0, ORIGIN, 1 / H, cells[0], cells[1], shape_argument(name, "cpdi", p["domain"], F, esc))
        assert esc[0] == 2 and esc[1] == q        # corners 2 and 3 (x_p + r1 -+ r2)
        # the two dropped corners' mass is missing, nothing else
        assert win[..., 0].sum() == pytest.approx(p["m"].sum() - 0.5 * p["m"][q], rel=1e-13)


def test_point_loads_take_a_quarter_at_each_corner():
    p = _particles(50)
    idx = np.arange(50)
    load_id = np.zeros(50, np.int32)
    load_w = np.full(50, 1 / 50)
    load_vec = np.array([[2.0, -1.0]])
    G = _grid()
    K.scatter_point_loads(idx, p["x"], load_id, load_w, load_vec, G, 0, 0, ORIGIN, 1 / H,
                          CELLS[0], CELLS[1], _shape("cubic", p))
    fext = load_w[:, None] * load_vec[0]
    _, _, force = p2g_reference(3, p["x"], p["m"], p["v"], p["vol"], np.zeros((50, 4)), fext,
                                ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(G[..., 3:5], force, atol=1e-13)


@pytest.mark.parametrize("name", ["linear", "cubic"])
def test_attached_supports_mark_the_nodes_any_corner_reaches(name):
    p = _particles(40)
    mask = np.zeros((CELLS[0] + 1, CELLS[1] + 1), np.int8)
    mark_support(p["x"], mask, ORIGIN, 1 / H, CELLS[0], CELLS[1], _shape(name, p))
    N, _ = cpdi_basis_matrix(ORDERS[name], p["x"], ORIGIN, H, CELLS, p["domain"], p["F"])
    # a node is reached when a corner's weight is nonzero; the mean N can vanish only where all
    # four do (the B-splines are non-negative)
    np.testing.assert_array_equal(mask.astype(bool), (N > 0).any(axis=0))


def _box_spread(p):
    """Per particle, the largest difference of its corners' cells along either axis (a particle
    whose corners' supports do not share one (K + 1)-node box takes the kernels' per-corner path)."""
    s = (p["x"] - ORIGIN) / H
    F, d = p["F"], p["domain"]
    r1 = np.stack([F[:, 0], F[:, 2]], 1) * d[:, :1]
    r2 = np.stack([F[:, 1], F[:, 3]], 1) * d[:, 1:]
    c = np.floor(np.clip(np.stack([s - r1 - r2, s + r1 - r2, s + r1 + r2, s - r1 + r2]), 0, CELLS))
    return (c.max(axis=0) - c.min(axis=0)).max(axis=1)


@pytest.mark.parametrize("name", ["linear", "quadratic", "cubic"])
def test_both_paths_match_the_twin_when_domains_stretch_past_a_cell(name):
    """Domains stretched up to 3 times, inside the grid: some particles fit one node box, others
    (corners two or more cells apart) take the per-corner path; every transfer matches the twin."""
    rng = np.random.default_rng(11)
    p = _particles(200, seed=4, interior=True)
    th = rng.uniform(-np.pi, np.pi, 200)
    lam = rng.uniform(0.5, 3.0, (200, 2))
    c, sn = np.cos(th), np.sin(th)
    p["F"] = np.stack([c * lam[:, 0], -sn * lam[:, 1], sn * lam[:, 0], c * lam[:, 1],
                       np.ones(200)], axis=1)      # a rotation times a stretch up to 3
    spread = _box_spread(p)
    assert (spread <= 1).sum() > 20 and (spread >= 2).sum() > 20     # both paths are exercised
    order = ORDERS[name]
    gravity = np.array([0.3, -9.8])
    G = _grid()
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], gravity, None, None, None,
          G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], _shape(name, p))
    mass, mom, force = p2g_reference(order, p["x"], p["m"], p["v"], p["vol"], p["stress"],
                                     p["m"][:, None] * gravity, ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-10, atol=1e-10)
    G[..., 1:7] = rng.normal(size=G[..., 1:7].shape)
    vel, dvel = G[..., 1:3].copy(), G[..., 3:5].copy()
    v, dx = p["v"].copy(), np.empty_like(p["v"])
    G5 = G[..., 5:7].copy()
    K.g2p_velocity(p["x"], p["m"], v, 0.2, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1],
                   _shape(name, p), True, dx, 0.5)
    ref = g2p_velocity_reference(order, p["x"], p["v"], vel, dvel, 0.2, ORIGIN, H, CELLS,
                                 p["domain"], p["F"])
    np.testing.assert_allclose(v, ref, rtol=1e-12, atol=1e-12)
    N, _ = cpdi_basis_matrix(order, p["x"], ORIGIN, H, CELLS, p["domain"], p["F"])
    np.testing.assert_allclose(G[..., 5:7] - G5, np.einsum("pij,p,pd->ijd", N, p["m"], v), atol=1e-12)
    n = len(p["m"])
    F0, vol0 = p["F"].copy(), p["vol"].copy()
    de, dq, vol = np.empty((n, 3)), np.empty((n, 2)), p["vol"].copy()
    K.g2p_kinematics(p["x"], p["m"], vol, None, de, None, p["F"], vol0, dq, 5, None, 1e-3,
                     None, None, None, None, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], _shape(name, p))
    de_r, _, F_r, vol_r, _ = g2p_deformation_reference(order, p["x"], G[..., 5:7], F0, vol0, 1e-3,
                                                       ORIGIN, H, CELLS, p["domain"])
    np.testing.assert_allclose(de, de_r, atol=1e-12)
    np.testing.assert_allclose(p["F"], F_r, atol=1e-12)
