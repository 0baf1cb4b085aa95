"""Forces on particle sets, handled apart from the main particle loops.

A force set is usually a small part of the scene (a joint, a loaded edge). Testing every
particle for membership inside the transfer loops slowed the whole step by a third; these
kernels visit only the loaded particles (their indices ``idx``).
"""
import numba as nb

from pmpm.core.shape import basis_of, corner_count, corner_point, corner_share, particle_weights

__all__ = ["scatter_point_loads", "point_load_work"]


@nb.njit(cache=True)
def scatter_point_loads(idx, x, load_id, load_w, load_vec, G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Add each loaded particle's share w_p F_k of its set's force to the nodal forces (3, 4)
    (CPDI: a quarter at each corner, f_ext / 4 N_i(x_c))."""
    basis = basis_of(shape)
    share = corner_share(shape)
    for q in range(idx.shape[0]):
        p = idx[q]
        k = load_id[p]
        fx = share * load_w[p] * load_vec[k, 0]
        fy = share * load_w[p] * load_vec[k, 1]
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        for c in range(corner_count(shape)):
            cx, cy = corner_point(shape, p, sx, sy, c, ncx, ncy)
            i0, wx, _ = particle_weights(basis, cx, ncx, p, 0)
            j0, wy, _ = particle_weights(basis, cy, ncy, p, 1)
            if not _inside(i0 - ox, len(wx), G.shape[0]) or not _inside(j0 - oy, len(wy), G.shape[1]):
                continue  # a corner beyond the window: the transfer kernels report it
            for a in range(len(wx)):
                for b in range(len(wy)):
                    w = wx[a] * wy[b]
                    G[i0 + a - ox, j0 + b - oy, 3] += w * fx
                    G[i0 + a - ox, j0 + b - oy, 4] += w * fy


@nb.njit(cache=True, inline="always")
def _inside(first, count, size):
    return first >= 0 and first + count <= size


@nb.njit(cache=True)
def point_load_work(idx, dx, load_id, load_w, load_vec):
    """Work of the set forces over this step's particle moves ``dx``."""
    work = 0.0
    for q in range(idx.shape[0]):
        p = idx[q]
        k = load_id[p]
        work += load_w[p] * (load_vec[k, 0] * dx[p, 0] + load_vec[k, 1] * dx[p, 1])
    return work
