"""Shape functions: partition of unity, zero-sum gradients, support, edge interpolation, and
agreement with the independent reference and with Steffen's modified cubic B-spline."""
import numpy as np
import pytest

from pmpm.core.kernels.reference import bspline_1d
from pmpm.core.shape import SHAPES, cubic, min_cells

ORDERS = {"linear": 1, "quadratic": 2, "cubic": 3}
N_CELLS = 7


def _weights(name, s, n=N_CELLS):
    """Dense (n+1,) weights and gradients from the numba kernel (called as Python via .py_func)."""
    fn = SHAPES[name]
    start, w, g = fn(s, n)
    W, G = np.zeros(n + 1), np.zeros(n + 1)
    for k in range(len(w)):
        if w[k] != 0.0 or g[k] != 0.0:
            W[start + k] += w[k]
            G[start + k] += g[k]
    return start, W, G


def _samples(n=N_CELLS):
    # every cell, including both edge cells, the exact edge and points next to cell faces
    s = np.linspace(0.0, n, 20 * n, endpoint=False)
    return np.concatenate([s, [1e-12, n - 1e-12, 0.5, n - 0.5, 1.0 - 1e-13, 1.0]])


@pytest.mark.parametrize("name", list(SHAPES))
def test_partition_of_unity_and_zero_gradient_sum(name):
    for s in _samples():
        _, W, G = _weights(name, s)
        assert W.sum() == pytest.approx(1.0, abs=1e-14)
        assert G.sum() == pytest.approx(0.0, abs=1e-13)


@pytest.mark.parametrize("name", list(SHAPES))
def test_linear_completeness(name):
    """sum N_i x_i = x and sum dN_i x_i = 1: a linear field is reproduced everywhere."""
    nodes = np.arange(N_CELLS + 1)
    for s in _samples():
        _, W, G = _weights(name, s)
        assert W @ nodes == pytest.approx(s, abs=1e-12)
        assert G @ nodes == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("name", list(SHAPES))
def test_support_stays_within_reach_and_grid(name):
    reach = {"linear": (0, 1), "quadratic": (-1, 2), "cubic": (-1, 2)}[name]
    for s in _samples():
        start, W, _ = _weights(name, s)
        c = int(np.floor(s))
        touched = np.nonzero(np.abs(W) > 0)[0]
        assert touched.min() >= max(c + reach[0], 0)
        assert touched.max() <= min(c + reach[1], N_CELLS)
        assert 0 <= start and start + len(SHAPES[name](s, N_CELLS)[1]) - 1 <= N_CELLS


@pytest.mark.parametrize("name", ["quadratic", "cubic"])
def test_weights_nonnegative(name):
    for s in _samples():
        _, W, _ = _weights(name, s)
        assert W.min() >= -1e-15


@pytest.mark.parametrize("name", list(SHAPES))
def test_interpolatory_at_grid_edges(name):
    """A fixed edge node fixes the material exactly at the edge."""
    _, W, _ = _weights(name, 0.0)
    assert W[0] == pytest.approx(1.0, abs=1e-14)
    _, W, _ = _weights(name, N_CELLS - 1e-13)
    assert W[-1] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name", list(SHAPES))
def test_matches_independent_reference(name):
    s = _samples()
    Wr, Gr = bspline_1d(ORDERS[name], s, N_CELLS)
    for k, sk in enumerate(s):
        _, W, G = _weights(name, sk)
        np.testing.assert_allclose(W, Wr[k], atol=1e-13)
        if name != "linear" or abs(sk - round(sk)) > 1e-9:  # the hat's gradient jumps at nodes
            np.testing.assert_allclose(G, Gr[k], atol=1e-12)


def test_cubic_gradient_is_derivative_of_weight():
    eps = 1e-6
    for s in np.linspace(0.01, N_CELLS - 0.01, 97):
        _, Wp, _ = _weights("cubic", s + eps)
        _, Wm, _ = _weights("cubic", s - eps)
        _, _, G = _weights("cubic", s)
        np.testing.assert_allclose((Wp - Wm) / (2 * eps), G, atol=1e-8)


def test_cubic_edge_equals_steffen_modified_spline():
    """Steffen, Kirby & Berzins (2008): the boundary node's function on [0, h) is
    xi^3/6 - xi + 1 and the next node's on [-h, 0) (its left piece) is -xi^3/3 - xi^2 + 2/3."""
    for s in np.linspace(0.0, 0.999, 50):
        _, W, _ = _weights("cubic", s)
        assert W[0] == pytest.approx(s ** 3 / 6 - s + 1, abs=1e-14)
        xi = s - 1
        assert W[1] == pytest.approx(-xi ** 3 / 3 - xi ** 2 + 2 / 3, abs=1e-14)


def test_min_cells_are_enough():
    for name in SHAPES:
        n = min_cells(name)
        for s in np.linspace(0, n, 31, endpoint=False):
            _, W, _ = _weights(name, s, n)
            assert W.sum() == pytest.approx(1.0, abs=1e-14)
    assert cubic(0.5, 3)[0] == 0
