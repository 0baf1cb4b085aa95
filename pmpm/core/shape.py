"""B-spline shape functions on the background grid, one axis at a time.

Each function takes the particle coordinate in cell units ``s = (x - origin) / h`` along one
axis and the number of cells ``n`` along that axis, and returns

    start, (w_0 .. w_{K-1}), (g_0 .. g_{K-1})

the first global node index of the particle's support, the weights of nodes ``start + k`` and
their derivatives in cell units (the caller multiplies by 1/h). The 2-D weight of node
(start_x + a, start_y + b) is ``wx[a] * wy[b]``; its gradient is ``(gx[a] wy[b], wx[a] gy[b]) / h``.

Grid edges use boundary-modified B-splines (Steffen, Kirby & Berzins 2008): the spline is built
on a lattice extended by one ghost node beyond each edge, and the ghost node is eliminated by
linear extrapolation from the two nearest real nodes (v_ghost = 2 v_edge - v_inner). Its weight
therefore moves onto the edge node (x2) and the inner node (x-1). This keeps the partition of
unity and linear completeness for every particle in the grid, makes the basis interpolatory at
the edge (a fixed edge node fixes the material there exactly), and never indexes outside the
grid. For the cubic spline the result is exactly Steffen's modified cubic B-spline.

K (the stencil width) is 2 (linear), 3 (quadratic) and 4 (cubic); the ghost width a slab needs
is 1, 2 and 2 node columns (a particle in cell c touches nodes c-1 .. c+2 at most).

Domain interpolation (``solver.interpolation = "ugimp"`` or ``"cpgimp"``, cubic only): the
B-spline GIMP. Each particle carries the half-lengths (lx, ly) of its rectangular domain, in
cell units; its weight of node i along an axis is the node's cubic B-spline averaged over the
domain, S_i(s) = 1/(b - a) * integral_a^b N_i, with [a, b] = [s - l, s + l]. The average is exact
(the antiderivative of the cubic B-spline is a piecewise quartic), and its derivative is
(N_i(b) - N_i(a)) / (b - a). A particle's support widens by l on each side, so K = 5 for
l <= 1/2 (the half-lengths are capped there) and the ghost width is 3 (a particle in cell c
touches nodes c-2 .. c+3). At the grid edges the domain is clamped to the grid, [a, b] =
[max(s - l, 0), min(s + l, n)] (the part of a particle's domain outside the grid holds no
material), and the boundary-modified splines above are averaged over it: since they sum to 1 on
[0, n], so does their average, which keeps the partition of unity for every particle in the
grid. Linear completeness holds in the interior; within l of an edge the weights reproduce the
centre of the clamped domain instead of s (a shift of at most l / 2). ``ugimp`` keeps the initial
half-lengths; ``cpgimp`` stretches each with the diagonal of the strain increment (the domain
follows the material's stretch along the axes).

CPDI (``solver.interpolation = "cpdi"``, any basis): the convected particle domain
interpolation CPDI1 of Sadeghirad, Brannon & Burghardt (IJNME 86, 2011, eq. 25-27). A
particle's domain is the parallelogram spanned by the half-vectors r1 = F (lx, 0) and
r2 = F (0, ly) (lx, ly the initial half-lengths in cell units, the ``domain`` field that GIMP
uses too, and F the particle's deformation gradient), with corners
x_c = x_p - r1 - r2, x_p + r1 - r2, x_p + r1 + r2, x_p - r1 + r2 (c = 1..4). The weight of node
i is the mean of its basis function N_i (any of the B-splines above) at the corners,
w_ip = 1/4 sum_c N_i(x_c), and its gradient grad w_ip = sum_c N_i(x_c) g_c with the constant
per-particle vectors g_1 = -g_3 = a / V, g_2 = -g_4 = b / V, a = (r1y - r2y, r2x - r1x),
b = (r1y + r2y, -r1x - r2x), V = 4 (r1 x r2) (the domain's area, > 0 while det F > 0). Since
sum_c x_c (x) g_c = I, the gradient of a linear field is exact, and the weights reproduce
x_p (the mean of the corners). The transfer kernels therefore treat the corners as four
sub-points of the basis (``cpdi_corners``): no basis gradient is used. A particle touches the
union of its corners' supports; while that fits one box of K + 1 nodes per axis (``cpdi_boxes``)
the kernels visit each of its nodes once (at most 25 visits with cubic B-splines), else each
corner's K^2 nodes (4 x 16 = 64). Grid edges: a corner outside the grid is clamped onto it per axis; each corner's basis
then sums to 1 (the boundary-modified B-splines do on [0, n]), so the partition of unity holds
for every particle, as for GIMP, and sum_c g_c = 0 keeps the gradients' sum zero; linear
completeness holds where no corner is clamped. The kernels receive ``(tag, domain, F, escape)``,
``tag`` the basis's, ``escape`` an int64 array [count, first particle] to which they report a
corner whose support leaves the rank's grid window (its contribution is dropped; the solver
stops the run, see ``ghost_width``).
"""
import math

import numba as nb
import numpy as np
from numba import types
from numba.extending import overload

__all__ = ["SHAPES", "SHAPE_TAGS", "INTERPOLATIONS", "weights", "particle_weights", "block_weights",
           "block_domain", "stencil", "BLOCK", "linear", "quadratic", "cubic", "cubic_gimp",
           "block_coordinates", "ghost_width", "min_cells", "shape_argument", "MAX_HALF_LENGTH",
           "GIMP_INTERPOLATIONS", "cpdi_corners", "corner_count", "corner_point", "basis_of",
           "corner_share", "CPDI_REACH", "is_cpdi", "cpdi_boxes"]


@nb.njit(cache=True, inline="always")
def linear(s, n):
    """Linear hat functions (the classic MPM basis): 2 nodes per axis."""
    c = min(max(int(math.floor(s)), 0), n - 1)
    f = s - c
    return c, (1.0 - f, f), (-1.0, 1.0)


@nb.njit(cache=True, inline="always")
def quadratic(s, n):
    """Quadratic B-splines centred on nodes: 3 nodes per axis, boundary-modified at the edges.

    With c the nearest node and f = s - c in [-1/2, 1/2), the weights of nodes c-1, c, c+1 are
    (1/2 - f)^2 / 2, 3/4 - f^2, (1/2 + f)^2 / 2 (branch-free closed forms of the B-spline)."""
    c = int(math.floor(s + 0.5))
    f = s - c
    a = 0.5 - f
    b = 0.5 + f
    w0, w1, w2 = 0.5 * a * a, 0.75 - f * f, 0.5 * b * b
    g0, g1, g2 = -a, -2.0 * f, b
    if c - 1 < 0:  # ghost node -1 -> 2x onto node 0, -1x onto node 1
        return 0, (w1 + 2 * w0, w2 - w0, 0.0), (g1 + 2 * g0, g2 - g0, 0.0)
    if c + 1 > n:  # ghost node n+1 -> 2x onto node n, -1x onto node n-1
        return n - 2, (0.0, w0 - w2, w1 + 2 * w2), (0.0, g0 - g2, g1 + 2 * g2)
    return c - 1, (w0, w1, w2), (g0, g1, g2)


@nb.njit(cache=True, inline="always")
def cubic(s, n):
    """Cubic B-splines (the paper's choice): 4 nodes per axis, boundary-modified at the edges.

    With c = floor(s) and f = s - c in [0, 1), the weights of nodes c-1 .. c+2 are
    (1-f)^3/6, (3f^3 - 6f^2 + 4)/6, (-3f^3 + 3f^2 + 3f + 1)/6, f^3/6 (branch-free). A point on
    the far edge (s = n, where CPDI clamps its corners) takes c = n - 1, f = 1: weight 1 on node n."""
    c = min(int(math.floor(s)), n - 1)
    f = s - c
    e = 1.0 - f
    f2 = f * f
    f3 = f2 * f
    w0 = e * e * e * (1.0 / 6.0)
    w1 = 0.5 * f3 - f2 + 2.0 / 3.0
    w2 = (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) * (1.0 / 6.0)
    w3 = f3 * (1.0 / 6.0)
    g0 = -0.5 * e * e
    g1 = 1.5 * f2 - 2.0 * f
    g2 = -1.5 * f2 + f + 0.5
    g3 = 0.5 * f2
    if c - 1 < 0:
        return 0, (w1 + 2 * w0, w2 - w0, w3, 0.0), (g1 + 2 * g0, g2 - g0, g3, 0.0)
    if c + 2 > n:
        return n - 3, (0.0, w0, w1 - w3, w2 + 2 * w3), (0.0, g0, g1 - g3, g2 + 2 * g3)
    return c - 1, (w0, w1, w2, w3), (g0, g1, g2, g3)


# -- B-spline GIMP (cubic) ------------------------------------------------------------------

#: largest domain half-length, in cells: keeps the support within 5 nodes per axis
MAX_HALF_LENGTH = 0.5


@nb.njit(cache=True, inline="always")
def _spline_and_integral(x):
    """The cubic B-spline N(x) centred on 0 and its antiderivative Phi(x) = int_{-2}^x N,
    branch-free: with u = |x|, N = ((2-u)_+^3 - 4 (1-u)_+^3) / 6 and
    Phi = 1/2 + sign(x) P(u), P(u) = int_0^u N = Q(min(u, 1)) + (1 - (2 - max(u, 1))_+^4) / 24,
    Q(t) = 2t/3 - t^3/3 + t^4/8 (the integral over the inner piece)."""
    u = abs(x)
    p = max(2.0 - u, 0.0)
    r = max(1.0 - u, 0.0)
    n_ = (p * p * p - 4.0 * r * r * r) * (1.0 / 6.0)
    t = min(u, 1.0)
    t2 = t * t
    q = t * (2.0 / 3.0) - t2 * t * (1.0 / 3.0) + t2 * t2 * 0.125
    e = min(max(2.0 - max(u, 1.0), 0.0), 1.0)
    e2 = e * e
    half = q + (1.0 - e2 * e2) * (1.0 / 24.0)
    return n_, 0.5 + math.copysign(half, x)


@nb.njit(cache=True, inline="always")
def _averaged(i, a, b, da, db, inv_len):
    """Node i's (unmodified) cubic B-spline averaged over [a, b], and its derivative by the
    particle coordinate when the ends move with it at rates da, db (0 where clamped)."""
    na, pa = _spline_and_integral(a - i)
    nb_, pb = _spline_and_integral(b - i)
    w = (pb - pa) * inv_len
    return w, (nb_ * db - na * da - w * (db - da)) * inv_len


@nb.njit(cache=True)
def cubic_gimp(s, l, n):
    """B-spline GIMP weights of a particle at ``s`` with domain half-length ``l`` (cell units,
    0 < l <= 1/2): 5 nodes per axis, the domain clamped to the grid and the boundary-modified
    cubic B-splines averaged over it (see the module docstring)."""
    a = s - l
    da = 1.0
    if not a > 0.0:  # also NaN: clamped (a diverged particle must not index outside the grid)
        a = 0.0
        da = 0.0
    elif not a < n:  # a particle beyond the far edge (the step stops it afterwards)
        a = n - 1.0
        da = 0.0
    b = s + l
    db = 1.0
    if not b < n:
        b = float(n)
        db = 0.0
    if not b > a:
        b = a + 1e-9
    inv_len = 1.0 / (b - a)
    c = min(max(int(math.floor(a)), 0), n - 1)
    st = c - 1
    w0, g0 = _averaged(st, a, b, da, db, inv_len)
    w1, g1 = _averaged(st + 1, a, b, da, db, inv_len)
    w2, g2 = _averaged(st + 2, a, b, da, db, inv_len)
    w3, g3 = _averaged(st + 3, a, b, da, db, inv_len)
    w4, g4 = _averaged(st + 4, a, b, da, db, inv_len)
    # eliminate the ghost nodes -1 and n+1 (v_ghost = 2 v_edge - v_inner) as in ``cubic`` and
    # slide the 5-node window back onto the grid
    if st < 0:  # node -1 is w0; node 4 (w4) cannot be reached from a < 1
        return 0, (w1 + 2 * w0, w2 - w0, w3, w4, 0.0), (g1 + 2 * g0, g2 - g0, g3, g4, 0.0)
    if st + 4 == n + 1:  # node n+1 is w4
        return n - 4, (0.0, w0, w1, w2 - w4, w3 + 2 * w4), (0.0, g0, g1, g2 - g4, g3 + 2 * g4)
    if st + 4 == n + 2:  # node n+1 is w3, node n+2 (w4) is out of reach
        return n - 4, (0.0, 0.0, w0, w1 - w3, w2 + 2 * w3), (0.0, 0.0, g0, g1 - g3, g2 + 2 * g3)
    return st, (w0, w1, w2, w3, w4), (g0, g1, g2, g3, g4)


#: name in the scene -> kernel
SHAPES = {"linear": linear, "quadratic": quadratic, "cubic": cubic}

#: name in the scene -> the tag the transfer kernels receive. The tag's *type* (a tuple of 2, 3
#: or 4 floats) selects the basis when numba compiles a kernel, so each basis gets its own
#: specialised, cacheable machine code. (Passing the jitted function itself would work too,
#: but its type embeds a memory address and defeats numba's on-disk cache.)
SHAPE_TAGS = {"linear": (0.0,) * 2, "quadratic": (0.0,) * 3, "cubic": (0.0,) * 4}

#: ``solver.interpolation``: point B-splines, or B-spline GIMP with fixed (uGIMP) or stretching
#: (cpGIMP) particle domains
INTERPOLATIONS = ("point", "ugimp", "cpgimp", "cpdi")
#: the interpolations of the B-spline GIMP (cubic only); ``cpdi`` takes any basis
GIMP_INTERPOLATIONS = ("ugimp", "cpgimp")
#: the shape functions each GIMP interpolation is defined for
GIMP_SHAPES = ("cubic",)
#: cells by which a CPDI corner may lie beyond its particle's cell before its support leaves a
#: slab's window (the ghost width adds it to the basis's)
CPDI_REACH = 2
#: the tag of the cubic GIMP (5 nodes per axis); the kernels receive ``(GIMP_TAG, domain)``,
#: ``domain`` the (N, 2) half-lengths in cell units, a particle field
GIMP_TAG = (0.0,) * 5


def shape_argument(name, interpolation="point", domain=None, F=None, escape=None):
    """What the transfer kernels take as ``shape``: the point tag, ``(GIMP_TAG, domain)``, or
    for CPDI ``(tag, domain, F, escape)`` (``escape``: int64 [count, first particle], see the
    module docstring; a fresh one when None)."""
    if interpolation == "point":
        return SHAPE_TAGS[name]
    if interpolation == "cpdi":
        if escape is None:
            escape = np.array([0, -1], dtype=np.int64)
        return (SHAPE_TAGS[name], domain, F, escape)
    return (GIMP_TAG, domain)


def is_cpdi(shape):
    """At compile time: is the numba type of ``shape`` the CPDI tuple (tag, domain, F, escape)?"""
    return isinstance(shape, types.BaseTuple) and not isinstance(shape, types.UniTuple) \
        and len(shape) == 4 and isinstance(shape[1], types.Array)


def _is_gimp(shape):
    """At compile time: is the numba type of ``shape`` the GIMP pair (tag, domain array)?"""
    return isinstance(shape, types.BaseTuple) and not isinstance(shape, types.UniTuple) \
        and len(shape) == 2 and isinstance(shape[1], types.Array)


def stencil(shape):
    """Nodes per axis of one (sub-)point's support (K; for CPDI each corner's)."""
    if isinstance(shape[0], tuple):
        return 5 if len(shape) == 2 else len(shape[0])
    return len(shape)


@overload(stencil)
def _stencil_overload(shape):
    if _is_gimp(shape):
        return lambda shape: 5
    if is_cpdi(shape):
        count = shape[0].count
        return lambda shape: count
    count = shape.count
    return lambda shape: count


def weights(tag, s, n):
    """``start, w, g`` of the basis named by ``tag`` (see ``SHAPE_TAGS``)."""
    return {2: linear, 3: quadratic, 4: cubic}[len(tag)](s, n)


@overload(weights)
def _weights_overload(tag, s, n):
    count = tag.count
    if count == 2:
        return lambda tag, s, n: linear(s, n)
    if count == 3:
        return lambda tag, s, n: quadratic(s, n)
    if count == 4:
        return lambda tag, s, n: cubic(s, n)
    return None


def particle_weights(shape, s, n, p, axis):
    """``start, w, g`` of particle ``p`` along ``axis`` (``s`` its coordinate in cell units) for
    point tags and the GIMP pair alike."""
    if isinstance(shape[0], tuple):
        return cubic_gimp(s, shape[1][p, axis], n)
    return weights(shape, s, n)


@overload(particle_weights)
def _particle_weights_overload(shape, s, n, p, axis):
    if _is_gimp(shape):
        return lambda shape, s, n, p, axis: cubic_gimp(s, shape[1][p, axis], n)
    return lambda shape, s, n, p, axis: weights(shape, s, n)


# -- a block of particles at a time --------------------------------------------------------
#
# The transfer kernels evaluate the weights of BLOCK particles at once into small buffers and
# then do the particles' scatters or gathers from there. The evaluation loops below run over
# contiguous coordinates without branches, so the compiler turns them into SIMD code (8
# particles per AVX-512 instruction here); the per-particle version above cannot be
# vectorised, its callers scatter into the grid. Particles whose support touches a grid edge
# (rare: the outermost cells) are redone afterwards with the scalar function, which owns the
# boundary modification. Measured: the cubic MUSL step went from about 121 to 100 ns per
# particle (docs/performance.md).

#: particles per block: the buffers (2 x 2K x BLOCK doubles) stay in the L1 cache
BLOCK = 64
#: coordinates beyond this (and NaN) would wrap the int64 node index past the edge tests
#: above; the scalar functions clamp them onto the grid instead (a diverged particle must not
#: make a kernel write outside its window before the run stops)
_HUGE = 1e15


@nb.njit(cache=True)
def _linear_block(s, nq, n, start, W):
    for q in range(nq):
        c = min(max(math.floor(s[q]), 0.0), n - 1.0)
        f = s[q] - c
        W[0, q] = 1.0 - f
        W[1, q] = f
        W[2, q] = -1.0
        W[3, q] = 1.0
        start[q] = np.int64(c)


@nb.njit(cache=True)
def _quadratic_block(s, nq, n, start, W):
    for q in range(nq):
        c = math.floor(s[q] + 0.5)
        f = s[q] - c
        a = 0.5 - f
        b = 0.5 + f
        W[0, q] = 0.5 * a * a
        W[1, q] = 0.75 - f * f
        W[2, q] = 0.5 * b * b
        W[3, q] = -a
        W[4, q] = -2.0 * f
        W[5, q] = b
        start[q] = np.int64(c) - 1
    for q in range(nq):  # supports reaching a ghost node: the boundary-modified weights
        if start[q] < 0 or start[q] + 2 > n or not abs(s[q]) < _HUGE:
            i0, w, g = quadratic(s[q], n)
            _put(W, q, start, i0, w, g)


@nb.njit(cache=True)
def _cubic_block(s, nq, n, start, W):
    for q in range(nq):
        c = math.floor(s[q])
        f = s[q] - c
        e = 1.0 - f
        f2 = f * f
        f3 = f2 * f
        W[0, q] = e * e * e * (1.0 / 6.0)
        W[1, q] = 0.5 * f3 - f2 + 2.0 / 3.0
        W[2, q] = (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) * (1.0 / 6.0)
        W[3, q] = f3 * (1.0 / 6.0)
        W[4, q] = -0.5 * e * e
        W[5, q] = 1.5 * f2 - 2.0 * f
        W[6, q] = -1.5 * f2 + f + 0.5
        W[7, q] = 0.5 * f2
        start[q] = np.int64(c) - 1
    for q in range(nq):  # supports reaching a ghost node: the boundary-modified weights
        if start[q] < 0 or start[q] + 3 > n or not abs(s[q]) < _HUGE:
            i0, w, g = cubic(s[q], n)
            _put(W, q, start, i0, w, g)


@nb.njit(cache=True, inline="always")
def _integrals(t):
    """Phi(t + 1 - k), k = 0..3: the antiderivative of the cubic B-spline at the offsets of
    nodes c-1 .. c+2 from a point c + t of cell c (Phi is 1 to the left of these, 0 to the
    right), with Q(t) = 2t/3 - t^3/3 + t^4/8 the integral of the inner piece from 0 to t."""
    e = 1.0 - t
    t2 = t * t
    e2 = e * e
    qt = t * (2.0 / 3.0) - t2 * t * (1.0 / 3.0) + t2 * t2 * 0.125
    qe = e * (2.0 / 3.0) - e2 * e * (1.0 / 3.0) + e2 * e2 * 0.125
    return 1.0 - e2 * e2 * (1.0 / 24.0), 0.5 + qt, 0.5 - qe, t2 * t2 * (1.0 / 24.0)


@nb.njit(cache=True)
def _cubic_gimp_block(s, L, nq, n, start, W):
    """The interior GIMP weights in closed form (the domain inside the grid, the support away
    from the ghost nodes: no clamping, 1 / (b - a) = 1 / (2 l)); the rest by ``cubic_gimp``.

    With a = s - l in cell ca and b = s + l in cell cb = ca or ca + 1 (2 l <= 1), the weight of
    node ca - 1 + k is (Phi(b - i) - Phi(a - i)) / (2 l) and its derivative
    (N(b - i) - N(a - i)) / (2 l); Phi and N at the four nodes around each end come from the
    end's offset in its cell (``_integrals`` and the cubic B-spline weights), shifted by one node
    for b when cb = ca + 1. Branch-free, so the loop vectorises."""
    for q in range(nq):
        l = L[q]
        inv = 0.5 / l
        a = s[q] - l
        b = s[q] + l
        ca = math.floor(a)
        cb = math.floor(b)
        fa = a - ca
        fb = b - cb
        up = cb - ca          # 0 or 1
        keep = 1.0 - up
        A0, A1, A2, A3 = _integrals(fa)
        B0, B1, B2, B3 = _integrals(fb)
        ea = 1.0 - fa
        eb = 1.0 - fb
        fa2 = fa * fa
        fb2 = fb * fb
        na0 = ea * ea * ea * (1.0 / 6.0)
        na1 = 0.5 * fa2 * fa - fa2 + 2.0 / 3.0
        na2 = (-3.0 * fa2 * fa + 3.0 * fa2 + 3.0 * fa + 1.0) * (1.0 / 6.0)
        na3 = fa2 * fa * (1.0 / 6.0)
        nb0 = eb * eb * eb * (1.0 / 6.0)
        nb1 = 0.5 * fb2 * fb - fb2 + 2.0 / 3.0
        nb2 = (-3.0 * fb2 * fb + 3.0 * fb2 + 3.0 * fb + 1.0) * (1.0 / 6.0)
        nb3 = fb2 * fb * (1.0 / 6.0)
        # b's values on the 5 nodes ca-1 .. ca+3: (B0..B3, 0) or, one cell up, (1, B0..B3)
        W[0, q] = (keep * B0 + up - A0) * inv
        W[1, q] = (keep * B1 + up * B0 - A1) * inv
        W[2, q] = (keep * B2 + up * B1 - A2) * inv
        W[3, q] = (keep * B3 + up * B2 - A3) * inv
        W[4, q] = (up * B3) * inv
        W[5, q] = (keep * nb0 - na0) * inv
        W[6, q] = (keep * nb1 + up * nb0 - na1) * inv
        W[7, q] = (keep * nb2 + up * nb1 - na2) * inv
        W[8, q] = (keep * nb3 + up * nb2 - na3) * inv
        W[9, q] = (up * nb3) * inv
        start[q] = np.int64(ca) - 1
    for q in range(nq):
        if start[q] < 0 or start[q] + 4 > n or not abs(s[q]) < _HUGE:
            i0, w, g = cubic_gimp(s[q], L[q], n)
            _put(W, q, start, i0, w, g)


@nb.njit(cache=True, inline="always")
def _put(W, q, start, i0, w, g):
    start[q] = i0
    for k in range(len(w)):
        W[k, q] = w[k]
        W[len(w) + k, q] = g[k]


def block_weights(tag, s, L, nq, n, start, W):
    """Weights of the ``nq`` coordinates ``s`` (cell units) of the basis named by ``tag``:
    ``start[q]`` the first node, ``W[k, q]`` the weight of node start + k and ``W[K + k, q]``
    its derivative (K = stencil(tag)); the block form of ``weights``. ``L`` holds the block's
    domain half-lengths along this axis (GIMP only; see ``block_domain``)."""
    if isinstance(tag[0], tuple):
        _cubic_gimp_block(s, L, nq, n, start, W)
    else:
        {2: _linear_block, 3: _quadratic_block, 4: _cubic_block}[len(tag)](s, nq, n, start, W)


@overload(block_weights)
def _block_weights_overload(tag, s, L, nq, n, start, W):
    if _is_gimp(tag):
        return lambda tag, s, L, nq, n, start, W: _cubic_gimp_block(s, L, nq, n, start, W)
    count = tag.count
    if count == 2:
        return lambda tag, s, L, nq, n, start, W: _linear_block(s, nq, n, start, W)
    if count == 3:
        return lambda tag, s, L, nq, n, start, W: _quadratic_block(s, nq, n, start, W)
    if count == 4:
        return lambda tag, s, L, nq, n, start, W: _cubic_block(s, nq, n, start, W)
    return None


def block_domain(shape, p0, nq, axis, L):
    """L[q] = the domain half-length of particle p0 + q along ``axis`` (GIMP; else nothing)."""
    if isinstance(shape[0], tuple):
        L[:nq] = shape[1][p0:p0 + nq, axis]


@overload(block_domain)
def _block_domain_overload(shape, p0, nq, axis, L):
    if _is_gimp(shape):
        def copy(shape, p0, nq, axis, L):
            d = shape[1]
            for q in range(nq):
                L[q] = d[p0 + q, axis]
        return copy
    return lambda shape, p0, nq, axis, L: None


@nb.njit(cache=True, inline="always")
def block_coordinates(x, p0, nq, axis, origin, inv_h, s):
    """s[q] = (x[p0 + q, axis] - origin) / h: a block's coordinates in cell units, contiguous."""
    for q in range(nq):
        s[q] = (x[p0 + q, axis] - origin) * inv_h


_POINT_GHOSTS = {"linear": 1, "quadratic": 2, "cubic": 2}


def ghost_width(name, interpolation="point"):
    """Node columns a slab must borrow from each neighbour for this basis (GIMP: a particle in
    cell c reaches nodes c-2 .. c+3). CPDI: the basis's width plus ``CPDI_REACH`` cells, the
    distance a corner may lie beyond its particle's cell (a particle stretched further at a slab
    boundary stops the run: the kernels report it through the shape's ``escape`` array)."""
    if interpolation == "cpdi":
        return _POINT_GHOSTS[name] + CPDI_REACH
    if interpolation != "point":
        return 3
    return _POINT_GHOSTS[name]


def min_cells(name, interpolation="point"):
    """Fewest cells per axis for which the boundary modification is well defined (GIMP: the
    5-node window must fit on the grid; CPDI: the basis's)."""
    if interpolation not in ("point", "cpdi"):
        return 4
    return {"linear": 1, "quadratic": 2, "cubic": 3}[name]


# -- CPDI: the corners of the particle domains ------------------------------------------------

@nb.njit(cache=True, inline="always")
def _onto(v, n):
    """v clamped onto [0, n] (NaN -> 0: a diverged particle must not index outside the grid)."""
    v = v if v > 0.0 else 0.0
    return v if v < n else float(n)


@nb.njit(cache=True, inline="always")
def cpdi_corners(domain, F, p, sx, sy, ncx, ncy):
    """Particle p's domain corners (cell units, clamped onto the grid; the particle at
    (sx, sy)) and its gradient vectors: ``(cx1..cx4), (cy1..cy4), ax, ay, bx, by`` with
    (ax, ay) = a / V = g_1 = -g_3 and (bx, by) = b / V = g_2 = -g_4 (1/cell; see the module
    docstring). V = 4 r1 x r2; it is 0 only once det F = 0 (NaN then: the F check stops it)."""
    lx = domain[p, 0]
    ly = domain[p, 1]
    r1x = F[p, 0] * lx
    r1y = F[p, 2] * lx
    r2x = F[p, 1] * ly
    r2y = F[p, 3] * ly
    cross = r1x * r2y - r1y * r2x
    inv = 0.25 / cross if cross != 0.0 else math.nan
    cx = (_onto(sx - r1x - r2x, ncx), _onto(sx + r1x - r2x, ncx),
          _onto(sx + r1x + r2x, ncx), _onto(sx - r1x + r2x, ncx))
    cy = (_onto(sy - r1y - r2y, ncy), _onto(sy + r1y - r2y, ncy),
          _onto(sy + r1y + r2y, ncy), _onto(sy - r1y + r2y, ncy))
    return cx, cy, (r1y - r2y) * inv, (r2x - r1x) * inv, (r1y + r2y) * inv, -(r1x + r2x) * inv


# -- CPDI: the four corners' weights on one node box, a block at a time ----------------------
#
# A particle's corners lie within a fraction of a cell of each other while its domain is small
# (4 particles per cell: half-lengths of a quarter cell), so along each axis their first nodes
# differ by at most one and their K-node supports fit one box of K + 1 nodes. ``cpdi_boxes``
# evaluates the basis at a block's corners (no derivatives: CPDI's gradient comes from the
# corners' weights) and pads each corner's K weights onto its particle's box, branch-free so
# the loop vectorises; the transfer kernels then visit each box node once (K or K + 1 nodes per
# axis, at most 25 with cubic B-splines, instead of 4 K^2 = 64). A particle that does not fit (a corner's
# support on a boundary-modified node, corners more than one first node apart, or the box
# leaving the grid window) is flagged, and the kernels take the per-corner path for it.

@nb.njit(cache=True, inline="always")
def _interior_linear(t):
    c = math.floor(t)
    f = t - c
    return c, (1.0 - f, f)


@nb.njit(cache=True, inline="always")
def _interior_quadratic(t):
    c = math.floor(t + 0.5)
    f = t - c
    a = 0.5 - f
    b = 0.5 + f
    return c - 1.0, (0.5 * a * a, 0.75 - f * f, 0.5 * b * b)


@nb.njit(cache=True, inline="always")
def _interior_cubic(t):
    c = math.floor(t)
    f = t - c
    e = 1.0 - f
    f2 = f * f
    f3 = f2 * f
    return c - 1.0, (e * e * e * (1.0 / 6.0), 0.5 * f3 - f2 + 2.0 / 3.0,
                     (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) * (1.0 / 6.0), f3 * (1.0 / 6.0))


@nb.njit(cache=True, inline="always")
def _pad2(U, c, q, d, w):
    """U[c, a, q] = corner c's weight of box node a: w[a - d] (zero off its support; d = 0, 1).
    One function per stencil width, written out: a loop over the tuple would not vectorise."""
    e = 1.0 - d
    U[c, 0, q] = e * w[0]
    U[c, 1, q] = e * w[1] + d * w[0]
    U[c, 2, q] = d * w[1]


@nb.njit(cache=True, inline="always")
def _pad3(U, c, q, d, w):
    e = 1.0 - d
    U[c, 0, q] = e * w[0]
    U[c, 1, q] = e * w[1] + d * w[0]
    U[c, 2, q] = e * w[2] + d * w[1]
    U[c, 3, q] = d * w[2]


@nb.njit(cache=True, inline="always")
def _pad4(U, c, q, d, w):
    e = 1.0 - d
    U[c, 0, q] = e * w[0]
    U[c, 1, q] = e * w[1] + d * w[0]
    U[c, 2, q] = e * w[2] + d * w[1]
    U[c, 3, q] = e * w[3] + d * w[2]
    U[c, 4, q] = d * w[3]


def _make_boxes(interior, pad, K):
    # two passes over the block, so that each loop has few enough memory streams for the
    # compiler to vectorise it (one loop over all four corners' 20 box weights did not)
    def boxes(tag, C, nq, n, lo, width, start, U, ok):
        hi = min(n - (K - 1.0), lo + width - (K + 1.0))   # the last first node of a box
        for q in range(nq):
            s0 = interior(C[0, q])[0]
            s1 = interior(C[1, q])[0]
            s2 = interior(C[2, q])[0]
            s3 = interior(C[3, q])[0]
            b = min(min(s0, s1), min(s2, s3))
            e = max(max(s0, s1), max(s2, s3))
            start[q] = np.int64(b)
            ok[q] = 1.0 + (e - b) if (e - b <= 1.0) & (b >= lo) & (b >= 0.0) & (e <= hi) else 0.0
        for c in range(4):
            for q in range(nq):
                s, w = interior(C[c, q])
                pad(U, c, q, min(max(s - start[q], 0.0), 1.0), w)
    return boxes


def cpdi_boxes(tag, C, nq, n, lo, width, start, U, ok):
    """One axis of a block's CPDI node boxes. ``C[c, q]``: corner c of particle q along the axis
    (cell units, on the grid [0, n]); ``lo``, ``width``: the grid window's nodes along it.
    Writes ``start[q]``, the box's first node, ``U[c, a, q]`` (a = 0 .. K), corner c's basis
    weight of box node start + a, and ``ok[q]``: 0.0 when particle q does not fit a box along
    this axis (see above; then start and U are not to be used), else 1.0 plus the spread of its
    corners' first nodes (0 or 1): the box has K - 1 + ok[q] nodes along the axis."""
    raise NotImplementedError  # only called from jitted code (the overload below)


_BOXES = {2: _make_boxes(_interior_linear, _pad2, 2), 3: _make_boxes(_interior_quadratic, _pad3, 3),
          4: _make_boxes(_interior_cubic, _pad4, 4)}


@overload(cpdi_boxes)
def _cpdi_boxes_overload(tag, C, nq, n, lo, width, start, U, ok):
    return _BOXES[tag.count]


# The per-particle kernels (point loads, support marking) visit a particle's sub-points: the
# particle itself (point, GIMP) or its four corners (CPDI), each weighted by ``corner_share``
# with the basis ``basis_of(shape)``.

def corner_count(shape):
    """Sub-points per particle: 4 (CPDI corners) or 1."""
    return 4 if isinstance(shape[0], tuple) and len(shape) == 4 else 1


@overload(corner_count)
def _corner_count_overload(shape):
    if is_cpdi(shape):
        return lambda shape: 4
    return lambda shape: 1


def corner_point(shape, p, sx, sy, c, ncx, ncy):
    """Sub-point ``c`` of particle p at (sx, sy), cell units: corner c (CPDI) or the particle."""
    if isinstance(shape[0], tuple) and len(shape) == 4:
        cx, cy = cpdi_corners(shape[1], shape[2], p, sx, sy, ncx, ncy)[:2]
        return cx[c], cy[c]
    return sx, sy


@overload(corner_point)
def _corner_point_overload(shape, p, sx, sy, c, ncx, ncy):
    if is_cpdi(shape):
        def corner(shape, p, sx, sy, c, ncx, ncy):
            cx, cy, _, _, _, _ = cpdi_corners(shape[1], shape[2], p, sx, sy, ncx, ncy)
            return cx[c], cy[c]
        return corner
    return lambda shape, p, sx, sy, c, ncx, ncy: (sx, sy)


def basis_of(shape):
    """The shape argument a sub-point is weighted with: the CPDI basis's tag, else ``shape``."""
    return shape[0] if isinstance(shape[0], tuple) and len(shape) == 4 else shape


@overload(basis_of)
def _basis_of_overload(shape):
    if is_cpdi(shape):
        return lambda shape: shape[0]
    return lambda shape: shape


def corner_share(shape):
    """Each sub-point's share of its particle: 1/4 (CPDI corners) or 1."""
    return 0.25 if isinstance(shape[0], tuple) and len(shape) == 4 else 1.0


@overload(corner_share)
def _corner_share_overload(shape):
    if is_cpdi(shape):
        return lambda shape: 0.25
    return lambda shape: 1.0
