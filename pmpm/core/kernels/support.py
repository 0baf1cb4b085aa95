"""Which grid nodes a set of particles interpolates from (set-up of body-attached supports)."""
import numba as nb

from pmpm.core.shape import basis_of, corner_count, corner_point, particle_weights

__all__ = ["mark_support"]


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
