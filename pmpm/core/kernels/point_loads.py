"""Forces on particle sets, handled apart from the main particle loops.

A force set is usually a small part of the scene (a joint, a loaded edge). Testing every
particle for membership inside the transfer loops slowed the whole step by a third; these
kernels visit only the loaded particles (their indices ``idx``).
"""
import numba as nb

from pmpm.core.shape import particle_weights

__all__ = ["scatter_point_loads", "point_load_work"]


@nb.njit(cache=True)
def scatter_point_loads(idx, x, load_id, load_w, load_vec, G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Add each loaded particle's share w_p F_k of its set's force to the nodal forces (3, 4)."""
    for q in range(idx.shape[0]):
        p = idx[q]
        k = load_id[p]
        fx = load_w[p] * load_vec[k, 0]
        fy = load_w[p] * load_vec[k, 1]
        i0, wx, _ = particle_weights(shape, (x[p, 0] - origin[0]) * inv_h, ncx, p, 0)
        j0, wy, _ = particle_weights(shape, (x[p, 1] - origin[1]) * inv_h, ncy, p, 1)
        for a in range(len(wx)):
            for b in range(len(wy)):
                w = wx[a] * wy[b]
                G[i0 + a - ox, j0 + b - oy, 3] += w * fx
                G[i0 + a - ox, j0 + b - oy, 4] += w * fy


@nb.njit(cache=True)
def point_load_work(idx, dx, load_id, load_w, load_vec):
    """Work of the set forces over this step's particle moves ``dx``."""
    work = 0.0
    for q in range(idx.shape[0]):
        p = idx[q]
        k = load_id[p]
        work += load_w[p] * (load_vec[k, 0] * dx[p, 0] + load_vec[k, 1] * dx[p, 1])
    return work
