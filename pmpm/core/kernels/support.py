"""Which grid nodes a set of particles interpolates from (set-up of body-attached supports)."""
import numba as nb

from pmpm.core.shape import particle_weights

__all__ = ["mark_support"]


@nb.njit(cache=True)
def mark_support(x, mask, origin, inv_h, ncx, ncy, shape):
    """mask[i, j] = 1 for every global node (i, j) whose weight is nonzero at a particle of
    ``x`` (the particles of ``shape``'s domain array, in the same order)."""
    for p in range(x.shape[0]):
        i0, wx, _ = particle_weights(shape, (x[p, 0] - origin[0]) * inv_h, ncx, p, 0)
        j0, wy, _ = particle_weights(shape, (x[p, 1] - origin[1]) * inv_h, ncy, p, 1)
        for a in range(len(wx)):
            for b in range(len(wy)):
                if wx[a] * wy[b] != 0.0:
                    mask[i0 + a, j0 + b] = 1
