"""Where particles are after a step: outside the grid, or outside the rank's slab."""
import math

import numba as nb
import numpy as np

__all__ = ["count_strays", "stray", "cell_columns"]


@nb.njit(cache=True, inline="always")
def stray(x, vol, p, origin, inv_h, ncx, ncy, axis, c0, c1):
    """Particle p's (outside, leaving, inverted) as 0 or 1, as ``count_strays`` counts them
    (the same expressions: a kernel that counts them in its own pass, pmpm.core.kernels.mls's
    fused G2P, agrees with it on every float)."""
    inverted = 0 if vol[p] > 0.0 else 1
    sx = (x[p, 0] - origin[0]) * inv_h
    sy = (x[p, 1] - origin[1]) * inv_h
    if not (0.0 <= sx < ncx and 0.0 <= sy < ncy):
        return 1, 0, inverted
    c = int(math.floor(sx if axis == 0 else sy))
    return 0, (1 if c < c0 or c >= c1 else 0), inverted


@nb.njit(cache=True)
def count_strays(x, vol, origin, inv_h, ncx, ncy, axis, c0, c1):
    """Count particles outside the grid and, of the rest, those whose cell column along
    ``axis`` is outside the owned columns [c0, c1). Non-finite positions count as outside.
    Also counts particles whose volume is no longer positive (material turned inside out: only
    a diverging run does that)."""
    outside = 0
    leaving = 0
    inverted = 0
    for p in range(x.shape[0]):
        o, lv, inv = stray(x, vol, p, origin, inv_h, ncx, ncy, axis, c0, c1)
        outside += o
        leaving += lv
        inverted += inv
    return outside, leaving, inverted


def cell_columns(x, origin, inv_h, axis):
    """Cell column index of each particle along ``axis`` (numpy; used only when needed)."""
    return np.floor((x[:, axis] - origin[axis]) * inv_h).astype(np.int64)

