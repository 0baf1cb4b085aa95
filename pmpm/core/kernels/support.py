"""The interpolation rows of held particles (supports attached to a body, pmpm.physics.supports),
and which grid nodes a set of particles interpolates from.

A held particle's velocity is sum_i N_ip v_i; ``support_rows`` lists its nonzero weights N_ip
with the global node numbers, as the transfer kernels compute them (point B-spline, GIMP, or
CPDI's mean over the domain's corners), so that the constraint sum_i N_ip v_i = 0 is exactly
the velocity the particle is moved with. ``support_rows_reference`` is its NumPy twin.
"""
import numba as nb

from pmpm.core.shape import basis_of, corner_count, corner_point, corner_share, particle_weights, stencil

__all__ = ["mark_support", "support_rows", "support_rows_reference", "row_width"]


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
    from pmpm.core.kernels.reference import basis_matrix
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

