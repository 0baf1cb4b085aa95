"""The nonlocal fracture criterion's smoothing (pmpm.physics.fracture_nonlocal) against closed forms.

One pass particles -> grid -> particles with the linear hat functions N_j,

    u_p <- sum_j N_j(x_p) (sum_q N_j(x_q) m_q u_q) / (sum_q N_j(x_q) m_q),

- keeps sum_p m_p u_p exactly (sum_p m_p N_j(x_p) is the nodal mass the average divides by);
- reproduces a linear field at particles whose nodes have a symmetric particle lattice around
  them (the interior of a uniform lattice);
- spreads a single particle's value with a variance per axis of 2 var(N) = h^2 / 3 for a
  continuous material, plus s^2 / 6 on a lattice of spacing s (the hat sampled at the particles:
  for a particle at a quarter cell, 2 particles per cell, the sum is 0.375 h^2 = h^2 / 3 + (h/2)^2 / 6,
  worked out in the test's comment);
- (k, f) = smoothing_passes(l*, h) give (k + f) h^2 / 3 = l*^2 / 12, the variance of a uniform
  average over a segment of length l*;
and the kernels equal their NumPy twin (dense weights) on scattered particles.
Planted bugs caught (checked once, then restored): the gather's weights (fy, 1 - fy) swapped
(the linear field and the variance fail); the division by the nodal mass left out (the
conservation fails).
"""
import numpy as np
import pytest

from pmpm.physics.fracture_nonlocal import gather_index, nodal_average, scatter_index, smoothing_passes
from pmpm.physics.materials.fracture import fail_where, kernel_params

H = 0.01
ORIGIN = np.array([0.0, 0.0])


def _lattice(nx, ny, ppc=2):
    s = H / ppc
    xs = (np.arange(nx * ppc) + 0.5) * s
    ys = (np.arange(ny * ppc) + 0.5) * s
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return np.c_[X.ravel(), Y.ravel()]


def _pass(x, m, u, nx, ny):
    grid = np.zeros((nx + 1, ny + 1, 2))
    mat = np.zeros(len(x), np.int32)
    scatter_index(x, m, u, mat, -1, grid, 0, 0, ORIGIN, 1.0 / H)
    nodal_average(grid)
    out = u.copy()
    gather_index(x, mat, -1, grid, out, 0, 0, ORIGIN, 1.0 / H)
    return out


def _pass_reference(x, m, u, nx, ny):
    """The twin: the dense matrix of the hat weights S (particles x nodes)."""
    t = (x - ORIGIN) / H
    i, j = np.floor(t[:, 0]).astype(int), np.floor(t[:, 1]).astype(int)
    fx, fy = t[:, 0] - i, t[:, 1] - j
    S = np.zeros((len(x), (nx + 1) * (ny + 1)))
    rows = np.arange(len(x))
    for di, wx in ((0, 1 - fx), (1, fx)):
        for dj, wy in ((0, 1 - fy), (1, fy)):
            np.add.at(S, (rows, (i + di) * (ny + 1) + j + dj), wx * wy)
    mass = S.T @ m
    avg = np.where(mass > 0, (S.T @ (m * u)) / np.where(mass > 0, mass, 1.0), 0.0)
    return S @ avg


def test_one_pass_conserves_reproduces_linear_and_spreads_by_the_closed_form_variance():
    nx = ny = 12
    x = _lattice(nx, ny)
    m = np.full(len(x), 2.0)
    # conservation of sum m u for any field
    rng = np.random.default_rng(3)
    u = rng.random(len(x))
    assert abs((m * _pass(x, m, u, nx, ny)).sum() - (m * u).sum()) <= 1e-12 * (m * u).sum()
    # a linear field, away from the lattice's edges (where the nodes' particles are one-sided)
    lin = 0.3 + 2.0 * x[:, 0] / H - 0.7 * x[:, 1] / H
    inner = np.all((x > 2 * H) & (x < (nx - 2) * H), axis=1)
    assert np.abs(_pass(x, m, lin, nx, ny) - lin)[inner].max() <= 1e-12
    # a delta at the particle at a quarter cell of node (6, 6): variance h^2/3 + s^2/6 per axis.
    # 1-D check of the sum: the node values 0.375 (node 6) and 0.125 (node 7) (weights 0.75, 0.25
    # over the node's 2 particle masses); sum_p N_j(x_p) (x_p - c)^2 = 2 (x_j - c)^2 + 0.375 h^2
    # over a node's four particles at +-h/4, +-3h/4; so 0.375 (2/16 + 0.375) + 0.125 (2 9/16 + 0.375)
    # = 0.375 h^2 = h^2/3 + (h/2)^2/6.
    q = np.argmin(np.hypot(x[:, 0] - 6.25 * H, x[:, 1] - 6.25 * H))
    delta = np.zeros(len(x))
    delta[q] = 1.0
    out = _pass(x, m, delta, nx, ny)
    w = m * out / (m * out).sum()
    for axis in (0, 1):
        var = (w * (x[:, axis] - x[q, axis]) ** 2).sum()
        assert var == pytest.approx(H * H / 3 + (H / 2) ** 2 / 6, rel=1e-12)
        assert (w * (x[:, axis] - x[q, axis])).sum() == pytest.approx(0.0, abs=1e-12 * H)


def test_kernels_equal_their_numpy_twin_on_scattered_particles():
    nx, ny = 8, 6
    rng = np.random.default_rng(7)
    x = rng.random((300, 2)) * [nx * H, ny * H]
    m = rng.random(300) + 0.5
    u = rng.random(300)
    assert np.abs(_pass(x, m, u, nx, ny) - _pass_reference(x, m, u, nx, ny)).max() <= 1e-13


@pytest.mark.parametrize("lstar, h", [(0.004, 0.002), (0.004, 0.001), (0.006, 0.002), (0.001, 0.002)])
def test_passes_give_the_variance_of_the_average_over_lstar(lstar, h):
    k, f = smoothing_passes(lstar, h)
    assert k >= 0 and 0.0 <= f < 1.0
    assert (k + f) * h * h / 3 == pytest.approx(lstar ** 2 / 12, rel=1e-12)


def test_a_point_fails_only_where_its_own_index_and_the_average_both_reach_one():
    """fail_where: the criterion exceeded at the point and over l* (docs/fracture.md, "The
    nonlocal criterion"). Four points: average and own index both >= 1 (fails), the average
    >= 1 but the own index below (a point beside a crack path, into which the average spreads
    the path's index: stays intact), the own index >= 1 but the average below (a lone strained
    point: intact), both below (intact); an intact point's damage is the smaller of the two.
    Planted bug caught (checked once, then restored): the own index's condition left out (the
    failure on the average alone, as before this test): the second point fails."""
    settings = {"model": "void_growth", "eta": 0.3, "fracture_energy": 2.0e4, "characteristic_length": 0.006}
    fp = kernel_params(settings, 200e9, 0.3, 0.002)
    average = np.array([1.2, 1.05, 0.7, 0.4])
    index = np.array([1.3, 0.8, 1.6, 0.5])
    n = len(average)
    stress = np.tile([400e6, 100e6, 20e6, 0.0], (n, 1))
    eff, crack, damage = np.zeros((n, 4)), np.zeros((n, 2)), np.zeros(n)
    count = fail_where(average, index, np.zeros(n, np.int32), -1, stress, eff, crack, damage, fp)
    assert count == 1
    assert damage[0] == 1.0 and crack[0, 1] > 0.0 and np.array_equal(eff[0], stress[0])
    assert damage[1:].tolist() == [0.8, 0.7, 0.4]
    assert not eff[1:].any() and not crack[1:].any()
