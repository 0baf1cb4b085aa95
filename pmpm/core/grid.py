"""The background grid and a rank's window onto it.

The global grid is a uniform lattice of square cells (``cells[0] x cells[1]``, nodes one more
per axis). A rank never allocates the global grid: it holds a *window*, the node columns it owns
along the decomposition axis plus ghost columns on each side, and the full extent of the other
axis. With one rank the window is the whole grid. Node (i, j) of the global grid lives at
``G[i - ox, j - oy]`` in the window.
"""
import logging

import numpy as np

from pmpm.core.kernels import N_FIELDS

__all__ = ["Grid", "GridWindow"]
logger = logging.getLogger(__name__)


class Grid:
    """Geometry of the global grid.

    Parameters
    ----------
    origin : sequence of 2 floats
        Position of node (0, 0).
    h : float
        Cell size.
    cells : sequence of 2 ints
        Cells per axis.
    """

    def __init__(self, origin, h, cells):
        self.origin = np.asarray(origin, dtype=np.float64)
        self.h = float(h)
        self.inv_h = 1.0 / self.h
        self.cells = (int(cells[0]), int(cells[1]))
        self.nodes = (self.cells[0] + 1, self.cells[1] + 1)
        self.upper = self.origin + self.h * np.asarray(self.cells, dtype=np.float64)

    def cell_of(self, x, axis):
        """Cell index along ``axis`` of positions ``x`` (N, 2)."""
        return np.floor((x[:, axis] - self.origin[axis]) * self.inv_h).astype(np.int64)

    def inside(self, x):
        """Boolean mask: positions strictly inside the grid (a particle needs a cell)."""
        s = (x - self.origin) * self.inv_h
        return np.all((s >= 0) & (s < np.asarray(self.cells)), axis=1)

    def node_coords(self, i, j):
        """Physical coordinates of global node indices (arrays)."""
        return self.origin[0] + self.h * i, self.origin[1] + self.h * j


class GridWindow:
    """The nodal fields a rank holds: a node-interleaved array ``G`` over its window.

    Parameters
    ----------
    grid : Grid
    axis : int
        Decomposition axis (0: slabs of x-columns, 1: slabs of y-rows).
    window : (int, int)
        Global node range [w0, w1) held along ``axis``.
    """

    def __init__(self, grid, axis, window):
        self.grid = grid
        self.axis = axis
        lo = [0, 0]
        hi = list(grid.nodes)
        lo[axis], hi[axis] = window
        self.lo = tuple(lo)
        self.shape = (hi[0] - lo[0], hi[1] - lo[1])
        self.G = np.zeros((*self.shape, N_FIELDS), dtype=np.float64)
        self.bc_mask = np.zeros((*self.shape, 2), dtype=np.int8)
        self.bc_vel = np.zeros((*self.shape, 2), dtype=np.float64)

    @property
    def ox(self):
        return self.lo[0]

    @property
    def oy(self):
        return self.lo[1]

    def node_coords(self):
        """Coordinates (X, Y) of every node of the window, each of shape ``self.shape``."""
        i = np.arange(self.lo[0], self.lo[0] + self.shape[0])
        j = np.arange(self.lo[1], self.lo[1] + self.shape[1])
        X, Y = self.grid.node_coords(i[:, None], j[None, :])
        return np.broadcast_to(X, self.shape), np.broadcast_to(Y, self.shape)

    def reset(self):
        """Zero every nodal field (step 1 of the paper)."""
        self.G.fill(0.0)
