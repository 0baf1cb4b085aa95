"""Counting sort of particles by cell: neighbours in memory touch neighbouring grid nodes."""
import numba as nb
import numpy as np

__all__ = ["cell_order", "permute_rows", "is_identity"]


@nb.njit(cache=True)
def cell_order(x, origin, inv_h, i_lo, i_hi, j_lo, j_hi):
    """Permutation that orders particles by cell (row-major over the window's cells
    [i_lo, i_hi) x [j_lo, j_hi)), stable within a cell. Particles outside are put last."""
    n = x.shape[0]
    ny = j_hi - j_lo
    ncell = (i_hi - i_lo) * ny
    key = np.empty(n, dtype=np.int32)
    count = np.zeros(ncell + 1, dtype=np.int64)
    for p in range(n):
        i = int(np.floor((x[p, 0] - origin[0]) * inv_h)) - i_lo
        j = int(np.floor((x[p, 1] - origin[1]) * inv_h)) - j_lo
        k = ncell
        if 0 <= i < i_hi - i_lo and 0 <= j < ny:
            k = i * ny + j
        key[p] = k
        count[k] += 1
    start = np.zeros(ncell + 1, dtype=np.int64)
    acc = 0
    for k in range(ncell + 1):
        start[k] = acc
        acc += count[k]
    order = np.empty(n, dtype=np.int64)
    for p in range(n):
        k = key[p]
        order[start[k]] = p
        start[k] += 1
    return order


@nb.njit(cache=True)
def is_identity(order):
    """True when ``order`` leaves every row where it is."""
    for i in range(order.shape[0]):
        if order[i] != i:
            return False
    return True


@nb.njit(cache=True)
def permute_rows(a, order, visited):
    """In place ``a[:] = a[order]`` for a 2-D byte view of a field, by following the cycles of
    the permutation: one row of scratch instead of a second copy of the field."""
    n = a.shape[0]
    visited[:] = False
    tmp = np.empty(a.shape[1], dtype=a.dtype)
    for start in range(n):
        if visited[start] or order[start] == start:  # fixed points: most rows between sorts
            continue
        tmp[:] = a[start]
        i = start
        while True:
            visited[i] = True
            j = order[i]
            if j == start:
                a[i] = tmp
                break
            a[i] = a[j]
            i = j
