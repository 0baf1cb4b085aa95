"""The background grid and a rank's window onto it.

The global grid is a uniform lattice of square cells (``cells[0] x cells[1]``, nodes one more
per axis). A rank never allocates the global grid: it holds a *window*, the node columns it owns
along the decomposition axis plus ghost columns on each side, and the full extent of the other
axis. With one rank the window is the whole grid. Node (i, j) of the global grid lives at
``G[i - ox, j - oy]`` in the window.

The node passes of a step (reset, grid update, momentum to velocity) run over the window's
*active tiles* only: squares of ``TILE`` x ``TILE`` nodes that a particle's stencil reaches or
the halo exchange writes into (pmpm.core.kernels.grid_ops says why the results do not change).
"""
import logging

import numpy as np

from pmpm.core.kernels import N_FIELDS
from pmpm.core.kernels.grid_ops import mark_tiles, zero_tiles

__all__ = ["Grid", "GridWindow", "TILE", "TILE_NODES_PER_PARTICLE", "choose_tile"]
logger = logging.getLogger(__name__)

#: nodes per side of a tile (docs/performance.md, "Small scenes", compares sizes); smaller
#: tiles follow a thin member more closely, larger ones cost fewer tile tests
TILE = 8
#: tiles only where the window has more than this many nodes per particle: marking the tiles
#: costs a pass over the particles, skipping a node saves a little, and the two break even at
#: about 3 nodes per particle on this machine (docs/performance.md, "Small scenes": the portal
#: frame's window, 1.6 nodes per particle, steps 20-30 us slower with tiles, the same frame in a
#: grid of 4 times the nodes, 6.3 per particle, 60 us faster); a block has 0.3
TILE_NODES_PER_PARTICLE = 4.0


def choose_tile(nodes, particles):
    """The tile size for a window of ``nodes`` nodes holding ``particles`` particles: ``TILE``
    where the window is sparse enough for the tiles to pay (``TILE_NODES_PER_PARTICLE``), else
    0 (every pass over the whole window). Either way the results are the same to the bit."""
    return TILE if nodes > TILE_NODES_PER_PARTICLE * max(particles, 1) else 0


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
    reach : int, optional
        A particle in cell c reaches nodes c - reach + 1 .. c + reach per axis (the shape's
        ``ghost_width``). None: no tiles, every pass covers the whole window.
    halo : (int, int)
        Window columns along ``axis`` at the lower and upper end that the halo exchange reads
        or writes (ghost columns and the owned columns a neighbour borrows): always active.
    tile : int
        Nodes per side of a tile, a power of two (0: no tiles).
    """

    def __init__(self, grid, axis, window, reach=None, halo=(0, 0), tile=TILE):
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
        self.reach = reach
        self.halo = tuple(halo)
        self.use_tiles(tile if reach is not None else 0)

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

    def use_tiles(self, tile):
        """Run the node passes over active tiles of ``tile`` x ``tile`` nodes (0: the whole
        window every step, as before the tiles). Every tile starts active, so the next reset
        clears whatever the window holds."""
        self.tile = int(tile)
        if not self.tile:
            self.active = self._always = None
            return
        if self.tile & (self.tile - 1):
            raise ValueError(f"tile must be a power of two (got {tile})")
        self._shift = self.tile.bit_length() - 1
        count = (-(-self.shape[0] // self.tile), -(-self.shape[1] // self.tile))
        self.active = np.ones(count, dtype=np.bool_)
        self._always = np.zeros(count, dtype=np.bool_)
        lower, upper = self.halo
        strips = [slice(None), slice(None)]
        if lower > 0:
            strips[self.axis] = slice(0, -(-lower // self.tile))
            self._always[tuple(strips)] = True
        if upper > 0:
            strips[self.axis] = slice((self.shape[self.axis] - upper) // self.tile, None)
            self._always[tuple(strips)] = True

    @property
    def tiles(self):
        """The kernels' ``tiles`` argument: (active, tile), or None for the whole window."""
        return None if self.active is None else (self.active, self.tile)

    def reset(self, x=None):
        """Zero every nodal field (step 1 of the paper); with tiles and particle positions
        ``x``, zero the tiles active so far (the others are zero already) and make active the
        tiles the particles' stencils at ``x`` reach, plus the halo strips."""
        if self.active is None:
            self.G.fill(0.0)
            return
        zero_tiles(self.G, self.active, self.tile)
        if x is None:
            self.active[...] = True
            return
        self.active[...] = self._always
        g = self.grid
        mark_tiles(x, g.origin, g.inv_h, self.ox, self.oy, self.shape[0], self.shape[1],
                   self.reach, self._shift, self.active)
