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
"""
import math

import numba as nb
import numpy as np
from numba.extending import overload

__all__ = ["SHAPES", "SHAPE_TAGS", "weights", "block_weights", "BLOCK", "linear", "quadratic",
           "cubic", "block_coordinates", "ghost_width", "min_cells"]


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
    (1-f)^3/6, (3f^3 - 6f^2 + 4)/6, (-3f^3 + 3f^2 + 3f + 1)/6, f^3/6 (branch-free)."""
    c = int(math.floor(s))
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


#: name in the scene -> kernel
SHAPES = {"linear": linear, "quadratic": quadratic, "cubic": cubic}

#: name in the scene -> the tag the transfer kernels receive. The tag's *type* (a tuple of 2, 3
#: or 4 floats) selects the basis when numba compiles a kernel, so each basis gets its own
#: specialised, cacheable machine code. (Passing the jitted function itself would work too,
#: but its type embeds a memory address and defeats numba's on-disk cache.)
SHAPE_TAGS = {"linear": (0.0,) * 2, "quadratic": (0.0,) * 3, "cubic": (0.0,) * 4}


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
def _put(W, q, start, i0, w, g):
    start[q] = i0
    for k in range(len(w)):
        W[k, q] = w[k]
        W[len(w) + k, q] = g[k]


def block_weights(tag, s, nq, n, start, W):
    """Weights of the ``nq`` coordinates ``s`` (cell units) of the basis named by ``tag``:
    ``start[q]`` the first node, ``W[k, q]`` the weight of node start + k and ``W[K + k, q]``
    its derivative (K = len(tag)); the block form of ``weights``."""
    {2: _linear_block, 3: _quadratic_block, 4: _cubic_block}[len(tag)](s, nq, n, start, W)


@overload(block_weights)
def _block_weights_overload(tag, s, nq, n, start, W):
    count = tag.count
    if count == 2:
        return lambda tag, s, nq, n, start, W: _linear_block(s, nq, n, start, W)
    if count == 3:
        return lambda tag, s, nq, n, start, W: _quadratic_block(s, nq, n, start, W)
    if count == 4:
        return lambda tag, s, nq, n, start, W: _cubic_block(s, nq, n, start, W)
    return None


@nb.njit(cache=True, inline="always")
def block_coordinates(x, p0, nq, axis, origin, inv_h, s):
    """s[q] = (x[p0 + q, axis] - origin) / h: a block's coordinates in cell units, contiguous."""
    for q in range(nq):
        s[q] = (x[p0 + q, axis] - origin) * inv_h


def ghost_width(name):
    """Node columns a slab must borrow from each neighbour for this basis."""
    return {"linear": 1, "quadratic": 2, "cubic": 2}[name]


def min_cells(name):
    """Fewest cells per axis for which the boundary modification is well defined."""
    return {"linear": 1, "quadratic": 2, "cubic": 3}[name]
