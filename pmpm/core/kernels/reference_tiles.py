"""Plain NumPy twins of the grid-tile kernels (pmpm.core.kernels.grid_ops), for tests: which
tiles a set of particles makes active, and the grid passes restricted to active tiles, written
as masks over the whole window."""
import numpy as np

__all__ = ["mark_tiles_reference", "tile_node_mask", "zero_tiles_reference"]


def mark_tiles_reference(x, origin, h, lo, shape, reach, tile, active=None):
    """Active tiles (count_x, count_y) of the window at global node ``lo`` with ``shape`` nodes
    after the particles at ``x``: the tiles of every node c - reach + 1 .. c + reach per axis
    of each particle's cell c that lie in the window, or'ed into ``active`` if given."""
    count = (-(-shape[0] // tile), -(-shape[1] // tile))
    out = np.zeros(count, dtype=bool) if active is None else active.copy()
    c = np.floor((x - np.asarray(origin)) / h).astype(np.int64) - np.asarray(lo)
    for axis_i in range(-reach + 1, reach + 1):
        for axis_j in range(-reach + 1, reach + 1):
            i, j = c[:, 0] + axis_i, c[:, 1] + axis_j
            inside = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1])
            out[i[inside] // tile, j[inside] // tile] = True
    return out


def tile_node_mask(active, tile, shape):
    """Boolean (nx, ny): the nodes that lie in an active tile."""
    return np.repeat(np.repeat(active, tile, axis=0), tile, axis=1)[:shape[0], :shape[1]]


def zero_tiles_reference(G, active, tile):
    """A copy of ``G`` with every field of the active tiles' nodes zero."""
    out = G.copy()
    out[tile_node_mask(active, tile, G.shape[:2])] = 0.0
    return out
