"""Essential boundary conditions on grid nodes chosen by boxes or attached to a body's face.

Types: ``fixed`` (both components zero), ``roller_x`` (free to slide along x, y fixed),
``roller_y`` (free along y, x fixed), ``velocity`` (both components prescribed).

A box selects the nodes whose coordinates lie in it (inclusive, with a tolerance of 1e-6 h).

A boundary attached to a body (``body = "beam"``, ``face = "left"``, no box) selects, at any
resolution, the nodes that hold that face: the face's particles are the body's outermost layer
on that side (within half a particle spacing of its extreme particle), and the nodes are those
whose shape function (B-spline or GIMP, as the scene interpolates) is nonzero at one of them and
that lie on the face's side of that layer, outside the material. On a grid edge this is the edge
node line over the face plus the edge nodes the face's corner particles reach beyond it (the
basis is interpolatory at a grid edge, so the grid velocity on the face is exactly the
prescribed one); no node inside the body is constrained, so the clamp does not stiffen the body
over a resolution-dependent length. Inside the grid the same rule fixes the nodes just outside
the face, which holds the face only partly (the face's particles also interpolate from free
nodes inside the body): clamp a face on a grid edge.

Each rank marks the nodes of its own window; ghost nodes get the owner's marks, so the
BCs apply wherever a rank touches the boundary and nowhere else.
"""
import logging

import numpy as np

from pmpm.errors import ConfigError

__all__ = ["apply_boundary_masks", "check_boundaries", "select_nodes", "COMPONENTS", "face_node_sets",
           "FACES"]
logger = logging.getLogger(__name__)

#: velocity components each boundary type prescribes
COMPONENTS = {"fixed": (0, 1), "roller_x": (1,), "roller_y": (0,), "velocity": (0, 1)}
_COMPONENTS = COMPONENTS
#: face name -> (axis, side): side -1 the lower extreme of the body along axis, +1 the upper
FACES = {"left": (0, -1), "right": (0, 1), "bottom": (1, -1), "top": (1, 1)}


def _select(X, Y, bc, tol):
    return ((X >= bc.lower[0] - tol) & (X <= bc.upper[0] + tol)
            & (Y >= bc.lower[1] - tol) & (Y <= bc.upper[1] + tol))


def face_node_sets(boundaries, bodies, grid, points, shape_of):
    """Global node masks (grid.nodes) of the body-attached boundaries, keyed by the boundary
    (its frozen config) as ``select_nodes`` looks them up in ``window.node_sets``.

    Parameters
    ----------
    boundaries, bodies : the scene's BoundaryConfig and BodyConfig tuples
    grid : pmpm.core.grid.Grid
    points : dict of the scene's global points (``x``, ``vol``, ``body``)
    shape_of : callable(index array) -> the transfer kernels' ``shape`` for those points
    """
    from pmpm.core.kernels.support import mark_support
    names = [b.name for b in bodies]
    sets = {}
    for k, bc in enumerate(boundaries):
        if bc.body is None:
            continue
        body = names.index(bc.body)
        axis, side = FACES[bc.face]
        idx = np.nonzero(points["body"] == body)[0]
        thickness = bodies[body].thickness
        spacing = np.sqrt(points["vol"][idx] / thickness)
        coord = points["x"][idx, axis]
        extreme = coord.min() if side < 0 else coord.max()
        layer = idx[np.abs(coord - extreme) <= 0.5 * spacing]
        mask = np.zeros(grid.nodes, dtype=np.int8)
        x = np.ascontiguousarray(points["x"][layer])
        mark_support(x, mask, grid.origin, grid.inv_h, grid.cells[0], grid.cells[1], shape_of(layer))
        # only the nodes on the face's side of the layer: outside the material
        node = grid.origin[axis] + grid.h * np.arange(grid.nodes[axis])
        outside = node <= extreme + 1e-6 * grid.h if side < 0 else node >= extreme - 1e-6 * grid.h
        keep = np.zeros(grid.nodes, dtype=bool)
        if axis == 0:
            keep[outside, :] = True
        else:
            keep[:, outside] = True
        sets[bc] = (mask > 0) & keep
        if not sets[bc].any():
            raise ConfigError(f"boundary[{k}]", f"face {bc.face!r} of body {bc.body!r} reaches no grid node")
        logger.info("boundary %r: %d node(s) hold face %r of body %r", bc.name, int(sets[bc].sum()),
                    bc.face, bc.body)
    return sets


def check_boundaries(boundaries, grid):
    """Refuse a boundary box that selects no node of the global grid (body-attached boundaries
    are checked when their nodes are found, ``face_node_sets``)."""
    i = np.arange(grid.nodes[0])
    j = np.arange(grid.nodes[1])
    X, Y = grid.node_coords(i[:, None], j[None, :])
    X, Y = np.broadcast_arrays(X, Y)
    for k, bc in enumerate(boundaries):
        if bc.body is None and not _select(X, Y, bc, 1e-6 * grid.h).any():
            raise ConfigError(f"boundary[{k}]", "box selects no grid node")


def select_nodes(window, bc):
    """Boolean (window.shape) mask of the window's nodes of boundary ``bc`` (a body-attached
    boundary's global mask is in ``window.node_sets``, from ``face_node_sets``)."""
    if bc.body is not None:
        lo, shape = window.lo, window.shape
        return window.node_sets[bc][lo[0]:lo[0] + shape[0], lo[1]:lo[1] + shape[1]]
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
