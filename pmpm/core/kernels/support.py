"""The interpolation rows of held particles (supports attached to a body, pmpm.physics.supports),
and which grid nodes a set of particles interpolates from.

A held particle's velocity is sum_i N_ip v_i; ``support_rows`` lists its nonzero weights N_ip
with the global node numbers, as the transfer kernels compute them (point B-spline, GIMP, or
CPDI's mean over the domain's corners), so that the constraint sum_i N_ip v_i = 0 is exactly
the velocity the particle is moved with. ``support_rows_reference`` is its NumPy twin.
"""
import math

import numba as nb
import numpy as np

from pmpm.core.shape import basis_of, corner_count, corner_point, corner_share, particle_weights, stencil
from pmpm.core.kernels.reference import basis_matrix

__all__ = ["mark_support", "support_rows", "support_rows_reference", "row_width", "support_gather",
           "support_solve", "support_solve_reference"]


def row_width(shape):
    """Entries per held particle in ``support_rows``: sub-points x stencil^2 (CPDI cubic: 64)."""
    composite = isinstance(shape[0], tuple)        # the GIMP pair or the CPDI tuple
    cpdi = composite and len(shape) == 4
    return (4 if cpdi else 1) * stencil(shape) ** 2


@nb.njit(cache=True)
def support_rows(idx, x, origin, inv_h, ncx, ncy, shape, nodes, weights):
    """Fill row q of ``nodes`` / ``weights`` (len(idx) x ``row_width``) with the global node
    numbers i (ncy + 1) + j and weights of particle ``idx[q]`` (CPDI: each corner's share of
    its basis, so a node several corners reach appears several times; the entries add up).
    Unused entries get node -1, weight 0; zero weights are left out (a node whose weight is
    zero may have no mass)."""
    basis = basis_of(shape)
    share = corner_share(shape)
    nodes[:, :] = -1
    weights[:, :] = 0.0
    for q in range(idx.shape[0]):
        p = idx[q]
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        k = 0
        for c in range(corner_count(shape)):
            cx, cy = corner_point(shape, p, sx, sy, c, ncx, ncy)
            i0, wx, _ = particle_weights(basis, cx, ncx, p, 0)
            j0, wy, _ = particle_weights(basis, cy, ncy, p, 1)
            for a in range(len(wx)):
                for b in range(len(wy)):
                    w = share * wx[a] * wy[b]
                    if w != 0.0:
                        nodes[q, k] = (i0 + a) * (ncy + 1) + (j0 + b)
                        weights[q, k] = w
                        k += 1


def support_rows_reference(order, x, origin, h, cells, domain=None, F=None):
    """The twin of ``support_rows`` from the reference basis (pmpm.core.kernels.reference):
    the dense weights (P, nodes) of particles ``x`` on the whole grid, node i (ncy + 1) + j."""
    N, _ = basis_matrix(order, x, origin, h, cells, domain, F)
    return N.reshape(len(x), -1)


@nb.njit(cache=True)
def mark_support(x, mask, origin, inv_h, ncx, ncy, shape):
    """mask[i, j] = 1 for every global node (i, j) whose weight is nonzero at a particle of
    ``x`` (the particles of ``shape``'s domain array, in the same order; CPDI: at one of its
    corners)."""
    basis = basis_of(shape)
    for p in range(x.shape[0]):
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        for c in range(corner_count(shape)):
            cx, cy = corner_point(shape, p, sx, sy, c, ncx, ncy)
            i0, wx, _ = particle_weights(basis, cx, ncx, p, 0)
            j0, wy, _ = particle_weights(basis, cy, ncy, p, 1)
            for a in range(len(wx)):
                for b in range(len(wy)):
                    if wx[a] * wy[b] != 0.0:
                        mask[i0 + a, j0 + b] = 1



# -- the projection of the nodal velocities onto the supports' constraints ------------------
#
# pmpm.physics.supports gathers the held particles' rows (``support_rows``) with their nodes'
# mass, velocity and box-fixed flags (``support_gather``), on several ranks from every rank,
# and ``support_solve`` returns the nodal corrections. ``support_solve_reference`` is its NumPy
# twin (dense matrices and rank-one updates instead of the kernel's loops).

@nb.njit(cache=True)
def support_gather(nodes, G, ox, oy, ny, field, bc_mask, mass, vel, fixed):
    """Per entry of ``nodes`` (global node numbers i ny + j, -1 unused): the node's mass,
    velocity (window fields ``field``, ``field + 1``) and box-fixed flags from the window
    ``G`` / ``bc_mask`` (whose node (i, j) is at [i - ox, j - oy])."""
    for q in range(nodes.shape[0]):
        for k in range(nodes.shape[1]):
            n = nodes[q, k]
            if n < 0:
                mass[q, k] = 0.0
                vel[q, k, 0] = vel[q, k, 1] = 0.0
                fixed[q, k, 0] = fixed[q, k, 1] = False
                continue
            i = n // ny - ox
            j = n % ny - oy
            mass[q, k] = G[i, j, 0]
            vel[q, k, 0] = G[i, j, field]
            vel[q, k, 1] = G[i, j, field + 1]
            fixed[q, k, 0] = bc_mask[i, j, 0] != 0
            fixed[q, k, 1] = bc_mask[i, j, 1] != 0


@nb.njit(cache=True)
def _pivoted_cholesky_solve(A, r, tol):
    """A solution of the consistent PSD system A x = r: Cholesky with diagonal pivoting,
    stopped where the largest remaining pivot is at most ``tol`` times A's largest diagonal
    (the remaining rows are dependent on the ones taken); their unknowns are 0. ``A`` is
    overwritten."""
    n = A.shape[0]
    perm = np.arange(n)
    scale = 0.0
    for i in range(n):
        scale = max(scale, A[i, i])
    rank = 0
    for k in range(n):
        j = k   # the largest remaining pivot; of equal ones the row that came first
        for i in range(k + 1, n):
            if A[i, i] > A[j, j] or (A[i, i] == A[j, j] and perm[i] < perm[j]):
                j = i
        if not A[j, j] > tol * scale:
            break
        if j != k:   # swap rows and columns k and j (the whole matrix: simple, n is small)
            for c in range(n):
                A[k, c], A[j, c] = A[j, c], A[k, c]
            for c in range(n):
                A[c, k], A[c, j] = A[c, j], A[c, k]
            perm[k], perm[j] = perm[j], perm[k]
        d = math.sqrt(A[k, k])
        A[k, k] = d
        for i in range(k + 1, n):
            A[i, k] /= d
        # the trailing block stays whole (both triangles), so the swaps above stay valid
        for i in range(k + 1, n):
            for c in range(k + 1, i + 1):
                A[i, c] -= A[i, k] * A[c, k]
                A[c, i] = A[i, c]
        rank += 1
    y = np.zeros(n)
    for k in range(rank):           # L y = P r
        s = r[perm[k]]
        for c in range(k):
            s -= A[k, c] * y[c]
        y[k] = s / A[k, k]
    x = np.zeros(n)
    for k in range(rank - 1, -1, -1):   # L^T z = y
        s = y[k]
        for c in range(k + 1, rank):
            s -= A[c, k] * x[perm[c]]
        x[perm[k]] = s / A[k, k]
    return x


@nb.njit(cache=True)
def support_solve(sup, nodes, weights, mass, vel, fixed, vbc, n_supports, tol):
    """The M-norm projection of the nodal velocities onto N v = v_bc (pmpm.physics.supports).

    Rows are the held particles in the order given (``sup[q, d]`` the support that prescribes
    component d of particle q, -1 none, ``nodes`` / ``weights`` their entries, ``mass`` /
    ``vel`` / ``fixed`` the entries' node data); support b prescribes ``vbc[b, d]``. Returns the distinct
    nodes U (sorted global numbers), the velocity corrections dv (len(U), 2) and the constraint
    impulses J (len(U), 2, n_supports), J = -N^T lambda per support (0 at box-fixed nodes)."""
    n, R = nodes.shape
    count = 0
    for q in range(n):
        for k in range(R):
            if nodes[q, k] >= 0:
                count += 1
    flat = np.empty(count, dtype=np.int64)
    c = 0
    for q in range(n):
        for k in range(R):
            if nodes[q, k] >= 0:
                flat[c] = nodes[q, k]
                c += 1
    U = np.unique(flat)
    nU = len(U)
    col = np.full((n, R), -1, dtype=np.int64)
    N = np.zeros((n, nU))
    m_U = np.zeros(nU)
    v_U = np.zeros((nU, 2))
    f_U = np.zeros((nU, 2), dtype=np.bool_)
    for q in range(n):
        for k in range(R):
            if nodes[q, k] >= 0:
                j = np.searchsorted(U, nodes[q, k])
                col[q, k] = j
                N[q, j] += weights[q, k]
                m_U[j] = mass[q, k]
                v_U[j, 0] = vel[q, k, 0]
                v_U[j, 1] = vel[q, k, 1]
                f_U[j, 0] = fixed[q, k, 0]
                f_U[j, 1] = fixed[q, k, 1]
    dv = np.zeros((nU, 2))
    J = np.zeros((nU, 2, n_supports))
    minv = np.zeros(nU)
    for d in range(2):
        rows = np.zeros(n, dtype=np.int64)
        nr = 0
        for q in range(n):
            if sup[q, d] >= 0:
                rows[nr] = q
                nr += 1
        if nr == 0:
            continue
        for j in range(nU):
            minv[j] = 1.0 / m_U[j] if (m_U[j] > 0.0 and not f_U[j, d]) else 0.0
        A = np.zeros((nr, nr))
        rhs = np.zeros(nr)
        for a in range(nr):
            p = rows[a]
            s = -vbc[sup[p, d], d]
            for k in range(R):
                j = col[p, k]
                if j >= 0:
                    s += weights[p, k] * v_U[j, d]
            rhs[a] = s
            for b in range(a, nr):
                qq = rows[b]
                s = 0.0
                for k in range(R):
                    j = col[p, k]
                    if j >= 0:
                        s += weights[p, k] * minv[j] * N[qq, j]
                A[a, b] = s
                A[b, a] = s
        lam = _pivoted_cholesky_solve(A, rhs, tol)
        for a in range(nr):
            p = rows[a]
            for k in range(R):
                j = col[p, k]
                if j >= 0 and minv[j] > 0.0:
                    share = weights[p, k] * lam[a]
                    dv[j, d] -= minv[j] * share
                    J[j, d, sup[p, d]] -= share
    return U, dv, J


def _pivoted_solve_reference(A, r, tol):
    """The NumPy twin of ``_pivoted_cholesky_solve``: the same pivots (the largest remaining
    diagonal of the Schur complement, of equal ones the first row), chosen on the whole
    matrix by rank-one updates, then the chosen rows' system solved by ``numpy.linalg.solve``."""
    S = A.copy()
    scale = max(np.diag(A).max(), 0.0)
    chosen = []
    for _ in range(len(A)):
        d = np.diag(S).copy()
        d[chosen] = -np.inf
        j = int(np.argmax(d))
        if not d[j] > tol * scale:
            break
        chosen.append(j)
        S = S - np.outer(S[:, j], S[j, :]) / S[j, j]
    x = np.zeros(len(A))
    if chosen:
        x[chosen] = np.linalg.solve(A[np.ix_(chosen, chosen)], r[chosen])
    return x


def support_solve_reference(sup, nodes, weights, mass, vel, fixed, vbc, n_supports, tol):
    """The NumPy twin of ``support_solve``: dense N, A = N M^-1 N^T by matrix products, the
    same pivoted choice of independent rows (``_pivoted_solve_reference``)."""
    valid = nodes >= 0
    U, col = np.unique(nodes[valid], return_inverse=True)
    n = len(nodes)
    N = np.zeros((n, len(U)))
    rows = np.broadcast_to(np.arange(n)[:, None], nodes.shape)[valid]
    np.add.at(N, (rows, col), weights[valid])
    m_U = np.zeros(len(U))
    v_U = np.zeros((len(U), 2))
    f_U = np.zeros((len(U), 2), dtype=bool)
    m_U[col], v_U[col], f_U[col] = mass[valid], vel[valid], fixed[valid]
    dv = np.zeros((len(U), 2))
    J = np.zeros((len(U), 2, n_supports))
    for d in range(2):
        r = np.nonzero(sup[:, d] >= 0)[0]
        if not len(r):
            continue
        Nd = N[r]
        minv = np.where(f_U[:, d] | (m_U <= 0.0), 0.0, 1.0 / np.where(m_U > 0.0, m_U, 1.0))
        A = (Nd * minv) @ Nd.T
        rhs = Nd @ v_U[:, d] - vbc[sup[r, d], d]
        lam = _pivoted_solve_reference(A, rhs, tol)
        contrib = Nd * lam[:, None]
        dv[:, d] = -minv * contrib.sum(axis=0)
        for b in range(n_supports):
            J[:, d, b] = -np.where(minv > 0.0, contrib[sup[r, d] == b].sum(axis=0), 0.0)
    return U, dv, J
