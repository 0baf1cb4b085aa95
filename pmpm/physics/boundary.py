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

from pmpm.core.effects import Effect
from pmpm.errors import ConfigError

__all__ = ["BoxBoundaries", "apply_boundary_masks", "check_boundaries", "check_boxes_hold", "select_nodes", "COMPONENTS", "FACES"]
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


def check_boxes_hold(boundaries, grid, x, reach):
    """Refuse a box support that would hold nothing: one whose nodes all lie inside the grid
    (none on its edge) and that no particle at ``x`` reaches at the start (a particle in cell c
    reaches nodes c - reach + 1 .. c + reach per axis). A node support acts only on material
    over it, and the grid has no memory between steps, so such a box constrains nothing unless
    material happens to come to it; on a grid edge it is a floor or a wall and may wait for it."""
    boxes = [(k, bc) for k, bc in enumerate(boundaries) if bc.body is None]
    if not boxes:
        return
    near = np.zeros(grid.nodes, dtype=bool)
    cells = np.floor((x - grid.origin) * grid.inv_h).astype(np.int64)
    hit = np.zeros(grid.cells, dtype=bool)
    hit[np.clip(cells[:, 0], 0, grid.cells[0] - 1), np.clip(cells[:, 1], 0, grid.cells[1] - 1)] = True
    for di in range(-reach + 1, reach + 1):
        for dj in range(-reach + 1, reach + 1):
            # near[c + d] |= hit[c] for the offsets a particle's stencil covers
            i0, i1 = max(0, di), min(grid.nodes[0], grid.cells[0] + di)
            j0, j1 = max(0, dj), min(grid.nodes[1], grid.cells[1] + dj)
            near[i0:i1, j0:j1] |= hit[i0 - di:i1 - di, j0 - dj:j1 - dj]
    i = np.arange(grid.nodes[0])
    j = np.arange(grid.nodes[1])
    X, Y = np.broadcast_arrays(*grid.node_coords(i[:, None], j[None, :]))
    edge = np.zeros(grid.nodes, dtype=bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    for k, bc in boxes:
        sel = _select(X, Y, bc, 1e-6 * grid.h)
        if sel.any() and not (sel & edge).any() and not (sel & near).any():
            raise ConfigError(f"boundary[{k}]", "box holds nothing: it lies inside the grid and no "
                                                "material reaches its nodes (to hold a body's face "
                                                "anywhere, attach the support: body = ..., face = ...)")


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


class BoxBoundaries(Effect):
    """The scene's ``[[boundary]]`` boxes as the grid window's masks (effect ``boundary``):
    checked against the grid and the particles at construction, marked on every new window."""

    name = "boundary"
    #: the implicit integrator holds the masked components (its held degrees of freedom)
    implicit_support = True

    def __init__(self, boundaries):
        self.boundaries = boundaries

    @classmethod
    def create(cls, scene, setup):
        if not scene.boundaries:
            return None
        check_boundaries(scene.boundaries, setup.grid)
        check_boxes_hold(scene.boundaries, setup.grid, setup.points["x"], setup.reach)
        return cls(scene.boundaries)

    def on_window(self, s):
        apply_boundary_masks(s.window, self.boundaries)
