"""B-spline GIMP (cubic, ``solver.interpolation = "ugimp" / "cpgimp"``): partition of unity for
every particle near a grid edge, linear completeness inside, gradients against finite
differences, the scalar and block kernels against the quadrature twin (pmpm.core.kernels.reference
.gimp_1d), the reach the ghost width is sized for, and the transfer kernels against the NumPy
reference on the whole grid and on a window."""
import numpy as np
import pytest

from pmpm.core import kernels as K
from pmpm.core.kernels.reference import g2p_velocity_reference, gimp_1d, p2g_reference
from pmpm.core.shape import (BLOCK, MAX_HALF_LENGTH, _cubic_gimp_block, cubic_gimp, ghost_width,
                             shape_argument)

N = 9  # cells along the test axis


def _dense(s, l, n=N):
    """Dense (n+1,) weights and derivatives from the scalar kernel."""
    start, w, g = cubic_gimp(s, l, n)
    assert 0 <= start and start + 4 <= n  # never indexes outside the grid
    W, G = np.zeros(n + 1), np.zeros(n + 1)
    W[start:start + 5] = w
    G[start:start + 5] = g
    return W, G


def _samples(l, n=N):
    """Every position class: interior, within l of an edge (domain clamped), within 2 + l of an
    edge (support on the ghost nodes), exactly on the edges and next to cell faces."""
    s = np.linspace(0.0, n, 40 * n, endpoint=False)
    edge = np.array([0.0, 1e-12, 0.5 * l, l - 1e-9, l, l + 1e-9, 1.0, 2.0 - l, 2.0 + l, 2.5])
    return np.concatenate([s, edge, n - 1e-12 - edge[1:], [n - 1e-12]])


HALF_LENGTHS = [0.125, 0.25, 0.37, MAX_HALF_LENGTH]


@pytest.mark.parametrize("l", HALF_LENGTHS)
def test_partition_of_unity_everywhere_including_edges(l):
    for s in _samples(l):
        W, G = _dense(s, l)
        assert W.sum() == pytest.approx(1.0, abs=1e-13)   # rounding of a sum of 5 terms
        assert G.sum() == pytest.approx(0.0, abs=1e-11)   # d/ds of 1 (derivatives are O(1/l))
        assert W.min() >= -1e-14                          # averages of non-negative splines


@pytest.mark.parametrize("l", HALF_LENGTHS)
def test_linear_completeness_inside_and_clamped_centre_at_edges(l):
    """sum S_i x_i is the centre of the (clamped) domain: s away from the edges, the centre of
    [max(s - l, 0), min(s + l, n)] within l of one (the documented edge rule)."""
    nodes = np.arange(N + 1)
    for s in _samples(l):
        W, G = _dense(s, l)
        a, b = max(s - l, 0.0), min(s + l, N)
        assert W @ nodes == pytest.approx(0.5 * (a + b), abs=1e-12)
        slope = 0.5 * (float(s - l > 0) + float(s + l < N))  # d/ds of the clamped centre
        assert G @ nodes == pytest.approx(slope, abs=1e-10)


@pytest.mark.parametrize("l", HALF_LENGTHS)
def test_matches_quadrature_twin(l):
    s = _samples(l)
    Wr, Gr = gimp_1d(s, l, N)
    for k, sk in enumerate(s):
        W, G = _dense(sk, l)
        np.testing.assert_allclose(W, Wr[k], atol=1e-13)  # Gauss quadrature is exact for cubics
        np.testing.assert_allclose(G, Gr[k], atol=1e-11)


@pytest.mark.parametrize("l", HALF_LENGTHS)
def test_gradient_matches_finite_differences(l):
    eps = 1e-6
    for s in _samples(l):
        if min(abs(s - l), abs(s + l - N), s, N - s) < 2 * eps:
            continue  # the derivative jumps where the domain starts to be clamped
        Wp, _ = _dense(s + eps, l)
        Wm, _ = _dense(s - eps, l)
        _, G = _dense(s, l)
        # central differences: error eps^2 |S'''| / 6 with S''' = O(1/l^2), plus rounding 1e-16/eps
        np.testing.assert_allclose(G, (Wp - Wm) / (2 * eps), atol=1e-7)


def test_tends_to_the_point_spline_as_the_domain_shrinks():
    """Away from the edges (within l of one the clamped domain's centre differs from s by up to
    l / 2, the documented edge rule)."""
    from pmpm.core.shape import cubic
    l = 1e-5
    for s in _samples(0.25):
        if s < l or s > N - l:
            continue
        start, w, _ = cubic(s, N)
        P = np.zeros(N + 1)
        P[start:start + 4] = w
        W, _ = _dense(s, l)
        np.testing.assert_allclose(W, P, atol=1e-9)  # S = N + l^2 N'' / 6 + ...: 1e-10 * O(1)


@pytest.mark.parametrize("l", HALF_LENGTHS)
def test_reach_is_within_the_ghost_width(l):
    """A particle in cell c touches nodes c-2 .. c+3 at most: the slab ghost width 3."""
    g = ghost_width("cubic", "ugimp")
    for s in _samples(l):
        W, G = _dense(s, l)
        c = min(int(np.floor(s)), N - 1)
        touched = np.nonzero((W != 0) | (G != 0))[0]
        assert touched.min() >= c - g + 1 and touched.max() <= c + g


def test_block_kernel_equals_scalar_kernel():
    rng = np.random.default_rng(3)
    for l in HALF_LENGTHS:
        s = np.concatenate([_samples(l), rng.uniform(0, N, 200)])
        for p0 in range(0, len(s), BLOCK):
            q = s[p0:p0 + BLOCK]
            L = np.full(BLOCK, l)
            start = np.empty(BLOCK, np.int64)
            W = np.empty((10, BLOCK))
            S = np.zeros(BLOCK)
            S[:len(q)] = q
            _cubic_gimp_block(S, L, len(q), N, start, W)
            for k, sk in enumerate(q):
                i0, w, g = cubic_gimp(sk, l, N)
                Wd = np.zeros(N + 1)
                Wd[i0:i0 + 5] = w
                Wb = np.zeros(N + 1)
                Wb[start[k]:start[k] + 5] = W[:5, k]
                np.testing.assert_allclose(Wb, Wd, atol=1e-14)
                Gd = np.zeros(N + 1)
                Gd[i0:i0 + 5] = g
                Gb = np.zeros(N + 1)
                Gb[start[k]:start[k] + 5] = W[5:, k]
                np.testing.assert_allclose(Gb, Gd, atol=1e-12)


def test_diverged_coordinates_stay_on_the_grid():
    for s in (np.nan, -1e30, 1e30, -3.0, N + 3.0):
        start, _, _ = cubic_gimp(s, 0.25, N)
        assert 0 <= start <= N - 4


# -- the transfer kernels with the GIMP shape ---------------------------------------------------

CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])


def _particles(n=300, seed=1):
    rng = np.random.default_rng(seed)
    x = ORIGIN + rng.uniform(0, 1, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 1e-9           # on the lower edge: clamped domains
    x[5:10, 1] = ORIGIN[1] + CELLS[1] * H - 1e-9
    domain = rng.uniform(0.05, MAX_HALF_LENGTH, (n, 2))
    return {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
            "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4)), "domain": domain}


def test_p2g_matches_reference():
    p = _particles()
    gravity = np.array([0.3, -9.8])
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    shape = shape_argument("cubic", "ugimp", p["domain"])
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], gravity, None, None, None,
          G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], shape)
    fext = p["m"][:, None] * gravity
    mass, mom, force = p2g_reference(3, p["x"], p["m"], p["v"], p["vol"], p["stress"], fext,
                                     ORIGIN, H, CELLS, p["domain"])
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-10, atol=1e-10)
    assert G[..., 0].sum() == pytest.approx(p["m"].sum(), rel=1e-13)  # partition of unity


def test_g2p_velocity_matches_reference():
    p = _particles()
    rng = np.random.default_rng(7)
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    G[..., 1:5] = rng.normal(size=G[..., 1:5].shape)
    vel, dvel = G[..., 1:3].copy(), G[..., 3:5].copy()
    v = p["v"].copy()
    dx = np.empty_like(v)
    shape = shape_argument("cubic", "ugimp", p["domain"])
    K.g2p_velocity(p["x"], p["m"], v, 0.2, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], shape, True, dx, 0.5)
    ref = g2p_velocity_reference(3, p["x"], p["v"], vel, dvel, 0.2, ORIGIN, H, CELLS, p["domain"])
    np.testing.assert_allclose(v, ref, rtol=1e-12, atol=1e-12)


def test_p2g_on_a_window_equals_the_slice_of_the_full_grid():
    """Particles in cell columns [3, 6) touch only nodes [3 - 2, 6 + 2] = [1, 8] with GIMP."""
    p = _particles()
    sx = (p["x"][:, 0] - ORIGIN[0]) / H
    keep = (sx >= 3) & (sx < 6)
    p = {k: np.ascontiguousarray(v[keep]) for k, v in p.items()}
    g = ghost_width("cubic", "ugimp")
    lo, hi = 3 - g + 1, 6 + g - 1   # nodes c-2 .. c+3 for c in 3 .. 5
    full = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    win = np.zeros((hi - lo + 1, CELLS[1] + 1, K.N_FIELDS))
    shape = shape_argument("cubic", "ugimp", p["domain"])
    for G, ox in ((full, 0), (win, lo)):
        K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
              G, ox, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], shape)
    np.testing.assert_array_equal(full[lo:hi + 1], win)
    assert not full[:lo].any() and not full[hi + 1:].any()


def test_point_loads_use_the_domain_weights():
    p = _particles(50)
    idx = np.arange(50)
    load_id = np.zeros(50, np.int32)
    load_w = np.full(50, 1 / 50)
    load_vec = np.array([[2.0, -1.0]])
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    shape = shape_argument("cubic", "ugimp", p["domain"])
    K.scatter_point_loads(idx, p["x"], load_id, load_w, load_vec, G, 0, 0, ORIGIN, 1 / H,
                          CELLS[0], CELLS[1], shape)
    fext = load_w[:, None] * load_vec[0]
    _, _, force = p2g_reference(3, p["x"], p["m"], p["v"], p["vol"], np.zeros((50, 4)), fext,
                                ORIGIN, H, CELLS, p["domain"])
    np.testing.assert_allclose(G[..., 3:5], force, atol=1e-13)
