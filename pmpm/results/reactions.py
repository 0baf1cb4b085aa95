"""Support reactions: the constraint forces of the essential boundary conditions.

The grid update (pmpm.core.kernels.grid_update) imposes a boundary node's prescribed velocity
by replacing the free velocity ``v_free`` the forces would give with ``v_bc``: the node's
momentum changes by the impulse ``J = m (v_bc - v_free)``. Those impulses are the supports'
action on the structure, the same that enter the energy balance (their work is ``J . v_bc``).
Summed over a boundary's owned nodes and over the steps since the previous sample, and divided
by the time elapsed, they give the boundary's reaction (Rx, Ry) and its moment M about a
point (anticlockwise positive): the mean over the sampling interval, which makes
``sum of loads + reactions = (change of total momentum) / interval`` hold exactly for the
particle momenta (FLIP transfers every nodal velocity change to the particles).

A boundary attached to a body holds particles instead of nodes (pmpm.physics.supports): its
impulses are those of its velocity constraint on the nodes, plus the momentum its held
particles' velocities lose when they are set to the prescribed one; they go into the same sums.

Under the implicit integrator (pmpm.core.implicit) the converged step gives the supports'
nodal forces themselves (``after_implicit_step``). In dynamics their trapezoid over the step
is the impulse the trapezoidal rule's momentum balance holds, summed like the explicit
impulses; in statics (``solver.analysis = "static"``, where time is only the loads' parameter)
a reaction is the equilibrium value of the last converged step, not a mean over the interval.

Nothing of this exists unless a boundary asks for its reaction: the kernel receives ``None``
and compiles without the bookkeeping. Each rank sums its owned nodes; the sums are added over
ranks once per sample (by pmpm.results.recorder, together with the section cuts).
A node component constrained by several boundary boxes reports to the last of them (whose
velocity it takes).
"""
import logging

import numpy as np

from pmpm.core.effects import Effect
from pmpm.physics.boundary import COMPONENTS, select_nodes

__all__ = ["Reactions", "node_centroid"]
logger = logging.getLogger(__name__)


def node_centroid(bc, grid, centroids=None):
    """Centroid of the global grid nodes inside the boundary's box (the default moment point);
    for a boundary attached to a body, of the particles it holds (``centroids[bc]``,
    pmpm.physics.supports)."""
    if bc.body is not None:
        return np.asarray(centroids[bc], dtype=np.float64)
    tol = 1e-6 * grid.h
    i = np.arange(grid.nodes[0])
    j = np.arange(grid.nodes[1])
    x = grid.origin[0] + grid.h * i
    y = grid.origin[1] + grid.h * j
    ix = (x >= bc.lower[0] - tol) & (x <= bc.upper[0] + tol)
    jy = (y >= bc.lower[1] - tol) & (y <= bc.upper[1] + tol)
    return np.array([x[ix].mean(), y[jy].mean()])


class Reactions(Effect):
    """Reaction bookkeeping of the boundaries that ask for it.

    Parameters
    ----------
    boundaries : sequence of BoundaryConfig
        All of the scene's boundaries (those with ``reaction`` are recorded).
    grid : Grid
    centroids : dict, optional
        The body-attached boundaries' held particles' centroids (``HeldFaces.centroids``).
    """

    name = "reactions"
    #: the implicit step hands over its converged support forces (``after_implicit_step``)
    implicit_support = True

    @classmethod
    def create(cls, scene, setup):
        if not any(b.reaction for b in scene.boundaries):
            return None
        supports = setup.effects.get("supports")
        return cls(scene.boundaries, setup.grid, supports.centroids if supports is not None else None,
                   static=scene.solver.analysis == "static")

    def __init__(self, boundaries, grid, centroids=None, static=False):
        self.grid = grid
        #: statics: ``sums`` hold the last converged step's forces (N, N m), not impulses
        self.static = static
        self.all_boundaries = boundaries
        self.index = [k for k, b in enumerate(boundaries) if b.reaction]
        self.boundaries = [boundaries[k] for k in self.index]
        self.names = [b.name for b in self.boundaries]
        self.points = np.array([b.moment_about if b.moment_about is not None else node_centroid(b, grid, centroids)
                                for b in self.boundaries], dtype=np.float64).reshape(-1, 2)
        self.sums = np.zeros((len(self.boundaries), 3))  # impulses Jx, Jy, moment about (0, 0)
        self.since = None   # time of the last sample
        self._arg = None

    def bind(self, window, all_boundaries):
        """Mark which reaction each node of ``window`` reports to (after every new window)."""
        ids = np.full((*window.shape, 2), -1, dtype=np.int32)
        for k, bc in enumerate(all_boundaries):
            sel = select_nodes(window, bc)
            for d in COMPONENTS[bc.type]:
                ids[sel, d] = self.index.index(k) if k in self.index else -1
        x0, y0 = self.grid.node_coords(window.ox, window.oy)
        self._arg = (ids, self.sums, float(x0), float(y0), self.grid.h)

    def kernel_arg(self):
        """The ``reaction`` argument of the grid-update kernel."""
        return self._arg

    # -- effect hooks
    def on_window(self, s):
        self.bind(s.window, self.all_boundaries)

    def grid_reaction(self):
        return self._arg

    def after_implicit_step(self, s, step):
        """A converged implicit step's support forces (pmpm.core.effects.ConvergedStep) into the
        sums of this rank's owned nodes: in statics the forces themselves (replacing the last
        step's), in dynamics their trapezoid times the step (an impulse, as the explicit step's)."""
        if step.static:
            self.sums[:] = 0.0
            self._add_forces(s, step.support_force, 1.0)
        else:
            self._add_forces(s, step.support_force, 0.5 * step.h)
            self._add_forces(s, step.support_force_start, 0.5 * step.h)

    def _add_forces(self, s, F, weight):
        """weight * F (window array, nodal forces) of the owned nodes into ``sums``: (Fx, Fy,
        moment about (0, 0)) per reaction, as the grid-update kernel adds its impulses."""
        ids, sums, x0, y0, h = self._arg
        axis, lo, hi = s._owned_local
        own = np.zeros(ids.shape[:2], dtype=bool)
        index = [slice(None), slice(None)]
        index[axis] = slice(lo, hi)
        own[tuple(index)] = True
        i, j = np.meshgrid(np.arange(ids.shape[0]), np.arange(ids.shape[1]), indexing="ij")
        for d in range(2):
            sel = own & (ids[..., d] >= 0)
            b, f = ids[sel, d], weight * F[sel, d]
            np.add.at(sums[:, d], b, f)
            if d == 0:   # moment z of (Fx, 0) at (x, y): -y Fx
                np.add.at(sums[:, 2], b, -(y0 + j[sel] * h) * f)
            else:        # moment z of (0, Fy): x Fy
                np.add.at(sums[:, 2], b, (x0 + i[sel] * h) * f)

    def take(self, t, allreduce_sum, summed=None):
        """(n, 3) reactions Rx, Ry (N) and M about each boundary's point (N m): the mean since
        the previous call (or since ``since``, set at the start or restart), over all ranks
        (NaN if no time passed); the sums restart.
        ``summed`` is this rank's sums already added over the ranks (to share an allreduce)."""
        total = allreduce_sum(self.sums.copy()) if summed is None else summed
        elapsed = None if self.since is None else t - self.since
        self.since = t
        if not self.static:
            self.sums[:] = 0.0
        if not elapsed or elapsed <= 0:
            return np.full((len(self.names), 3), np.nan)
        R = np.array(total, dtype=np.float64) if self.static else total / elapsed
        # moment about p of forces whose moment about (0, 0) is M0: M0 - p x R
        R[:, 2] -= self.points[:, 0] * R[:, 1] - self.points[:, 1] * R[:, 0]
        return R
