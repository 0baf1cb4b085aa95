"""Essential boundary conditions on grid nodes chosen by boxes or attached to a body's face.

Types: ``fixed`` (both components zero), ``roller_x`` (free to slide along x, y fixed),
``roller_y`` (free along y, x fixed), ``velocity`` (both components prescribed).

A box selects the nodes whose coordinates lie in it (inclusive, with a tolerance of 1e-6 h).

A boundary attached to a body (``body = "beam"``, ``face = "left"``, no box) constrains no node:
it holds the face's particles by a constraint on the grid velocity (pmpm.physics.supports),
which holds anywhere in the grid.

Each rank marks the nodes of its own window; ghost nodes get the owner's marks, so the
BCs apply wherever a rank touches the boundary and nowhere else.
"""
import logging

import numpy as np

from pmpm.errors import ConfigError

__all__ = ["apply_boundary_masks", "check_boundaries", "select_nodes", "COMPONENTS", "FACES"]
logger = logging.getLogger(__name__)

#: velocity components each boundary type prescribes
COMPONENTS = {"fixed": (0, 1), "roller_x": (1,), "roller_y": (0,), "velocity": (0, 1)}
_COMPONENTS = COMPONENTS
#: face name -> (axis, side): side -1 the lower extreme of the body along axis, +1 the upper
FACES = {"left": (0, -1), "right": (0, 1), "bottom": (1, -1), "top": (1, 1)}


def _select(X, Y, bc, tol):
    return ((X >= bc.lower[0] - tol) & (X <= bc.upper[0] + tol)
            & (Y >= bc.lower[1] - tol) & (Y <= bc.upper[1] + tol))


def check_boundaries(boundaries, grid):
    """Refuse a boundary box that selects no node of the global grid (boundaries attached to a
    body are checked when their particles are found, pmpm.physics.supports)."""
    i = np.arange(grid.nodes[0])
    j = np.arange(grid.nodes[1])
    X, Y = grid.node_coords(i[:, None], j[None, :])
    X, Y = np.broadcast_arrays(X, Y)
    for k, bc in enumerate(boundaries):
        if bc.body is None and not _select(X, Y, bc, 1e-6 * grid.h).any():
            raise ConfigError(f"boundary[{k}]", "box selects no grid node")


def select_nodes(window, bc):
    """Boolean (window.shape) mask of the window's nodes of boundary ``bc`` (none for a
    boundary attached to a body: it holds particles, pmpm.physics.supports)."""
    if bc.body is not None:
        return np.zeros(window.shape, dtype=bool)
    X, Y = window.node_coords()
    return _select(X, Y, bc, 1e-6 * window.grid.h)


def apply_boundary_masks(window, boundaries):
    """Fill ``window.bc_mask`` / ``window.bc_vel`` from the scene's boundaries (later entries
    overwrite the prescribed velocity of earlier ones on shared components)."""
    window.bc_mask[:] = 0
    window.bc_vel[:] = 0.0
    for bc in boundaries:
        sel = select_nodes(window, bc)
        for d in _COMPONENTS[bc.type]:
            window.bc_mask[sel, d] = 1
            window.bc_vel[sel, d] = bc.velocity[d]
