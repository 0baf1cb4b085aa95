"""Supports attached to a body's face, held by a constraint on the grid velocity.

A ``[[boundary]]`` with ``body`` and ``face`` (no box) holds the face's particles: the body's
outermost layer of particles on that side (within half a particle spacing of its extreme
particle, at the start). A particle moves with the interpolated grid velocity
v_p = sum_i N_ip v_i, so the support is the linear constraint on the nodal velocities

    N v = v_bc      (one row per held particle and constrained component)

imposed after each grid update (and on the MUSL re-mapped velocity) by the smallest change of
kinetic energy, the projection in the nodal mass norm:

    A = N M^-1 N^T,   A lambda = N v - v_bc,   v <- v - M^-1 N^T lambda

(M the lumped nodal masses; a node a box boundary fixes is not changed: its column is dropped,
as if its mass were infinite). Where the rows are dependent (more held particles along the face
than node rows under it, as with 4 particles per cell and cubic B-splines) A is singular but
the system is consistent (v = v_bc satisfies it); the kernel
(pmpm.core.kernels.support.support_solve) factorises A by Cholesky with diagonal pivoting and
stops at the pivots below ``RANK_TOLERANCE`` of its largest diagonal (the dependent rows),
which imposes every independent row exactly. Nothing depends on where the face lies relative to
the grid: on a grid edge, inside the grid, on or off the node lines the held particles get
exactly the prescribed velocity, and since positions move with the same velocity, a fixed face
stays where it is.

The constraint's impulse on node i is J_i = -m_i (M^-1 N^T lambda)_i = -(N^T lambda)_i: the
support's reaction (summed over the owned nodes into pmpm.results.reactions, as the nodal BCs'
impulses are), and its work J . v_new (zero for a fixed support: N v_new = 0) enters the energy
balance. The held particles' own velocities are set to the prescribed one after the grid-to-
particle transfer (their FLIP update would otherwise carry the free nodes' old velocities), and
the momentum this removes is part of the reaction.

MPI: a rank owns the held particles in its slab, and their stencils lie in its window (the ghost
width guarantees it; CPDI reports a corner that leaves it). The constraint couples particles
and nodes across ranks, so each projection gathers every rank's rows (node numbers, weights)
with the nodes' mass and velocity from the owner's window (complete there after the halo sum)
in one allgather; every rank then solves the same system in the same order (rows sorted by
particle id, columns by global node number) and corrects the nodes of its own window, owned
and ghost alike, so the ghost copies stay equal to their owners'. The reaction and the work are
summed over owned nodes only, as for the nodal BCs. One rank: no gather.
"""
import logging

import numpy as np

from pmpm.core.effects import Effect
from pmpm.core.kernels import MOM
from pmpm.core.kernels.support import row_width, support_gather, support_rows, support_solve
from pmpm.errors import ConfigError
from pmpm.physics.boundary import COMPONENTS, FACES

__all__ = ["HeldFaces", "face_layer", "RANK_TOLERANCE"]
logger = logging.getLogger(__name__)

#: pivots of A = N M^-1 N^T below this fraction of its largest diagonal belong to dependent
#: rows (they vanish in exact arithmetic); round-off puts them near 1e-16 of the largest
RANK_TOLERANCE = 1e-6


def face_layer(bc, bodies, points):
    """Indices into ``points`` of the face layer of ``bc``'s body: its particles within half a
    particle spacing of the body's extreme particle on the face's side (empty if the body has
    none)."""
    names = [b.name for b in bodies]
    body = names.index(bc.body)
    axis, side = FACES[bc.face]
    idx = np.nonzero(points["body"] == body)[0]
    if not len(idx):
        return idx
    spacing = np.sqrt(points["vol"][idx] / bodies[body].thickness)
    coord = points["x"][idx, axis]
    extreme = coord.min() if side < 0 else coord.max()
    return idx[np.abs(coord - extreme) <= 0.5 * spacing]


class HeldFaces(Effect):
    """The supports attached to bodies' faces of a scene, as velocity constraints.

    Parameters
    ----------
    boundaries, bodies : the scene's BoundaryConfig and BodyConfig tuples
    points : dict of the scene's global points (``x``, ``vol``, ``body``; a point's index is its id)
    grid : pmpm.core.grid.Grid
    """

    name = "supports"

    @classmethod
    def create(cls, scene, setup):
        if not any(b.body is not None for b in scene.boundaries):
            return None
        held = cls(scene.boundaries, scene.bodies, setup.points, setup.grid)
        if scene.contact is not None:
            raise ConfigError(f"boundary[{held.index[0]}]", "a boundary attached to a body does not work with "
                                                            "[contact] (give it a box)")
        return held

    def __init__(self, boundaries, bodies, points, grid):
        self.grid = grid
        self.index = [k for k, bc in enumerate(boundaries) if bc.body is not None]
        self.boundaries = [boundaries[k] for k in self.index]
        n = len(self.boundaries)
        # hold[b, d]: support b prescribes component d, to velocity vel[b, d]
        self.hold = np.zeros((n, 2), dtype=bool)
        self.vel = np.zeros((n, 2))
        # which support holds each component of each held particle (by id): where two faces
        # meet at a corner particle, each component goes to the later boundary that prescribes
        # it, as for overlapping boxes
        n_points = len(points["x"])
        which = np.full((n_points, 2), -1, dtype=np.int32)
        centroids = []
        for b, (k, bc) in enumerate(zip(self.index, self.boundaries)):
            for d in COMPONENTS[bc.type]:
                self.hold[b, d] = True
                self.vel[b, d] = bc.velocity[d]
            layer = face_layer(bc, bodies, points)
            if not len(layer):
                raise ConfigError(f"boundary[{k}]", f"face {bc.face!r} of body {bc.body!r} holds no "
                                                    f"particle (the body has none in the grid)")
            for d in COMPONENTS[bc.type]:
                which[layer, d] = b
            centroids.append(points["x"][layer].mean(axis=0))
            logger.info("boundary %r: holds %d particle(s) of face %r of body %r", bc.name, len(layer),
                        bc.face, bc.body)
        ids = np.nonzero((which >= 0).any(axis=1))[0].astype(np.int64)   # a particle's id is its point's index
        which = which[ids]
        for b, k in enumerate(self.index):
            if not (which == b).any():
                raise ConfigError(f"boundary[{k}]", "holds nothing: the later attached boundaries "
                                                    "prescribe every component of its particles")
        order = np.argsort(ids)
        self.ids, self.which = ids[order], which[order]
        #: default moment point of each support's reaction: the centroid of its held particles
        self.centroids = {bc: c for bc, c in zip(self.boundaries, centroids)}
        #: the solver of the projection (the numba kernel; tests swap in its NumPy twin)
        self.solve = support_solve

    # -- set-up -------------------------------------------------------------------------------
    def mark(self, particles):
        """Give ``particles`` the field ``support`` (n, 2): the support holding each component
        (-1: free). It travels with the particles (migration, sorting, checkpoints)."""
        particles.add_field("support", (2,), np.int32, -1)
        pos = np.searchsorted(self.ids, particles["id"])
        pos = np.minimum(pos, max(len(self.ids) - 1, 0))
        if len(self.ids):
            held = self.ids[pos] == particles["id"]
            particles["support"][held] = self.which[pos[held]]

    def add_fields(self, particles, setup=None):
        self.mark(particles)

    # -- effect hooks: the grid's velocities after the update and the re-map, the particles'
    def after_grid_update(self, s, damped_work):
        self.project(s, MOM, impulse=True)

    def after_grid_velocity(self, s, field):
        self.project(s, field)

    def after_g2p(self, s):
        # (the MUSL re-map carried their FLIP velocity; the re-mapped velocity is projected in
        # after_grid_velocity)
        self.hold_particles(s)

    # -- each step ----------------------------------------------------------------------------
    def _local_rows(self, solver):
        """This rank's held particles' rows: (ids, support, nodes (n, R), weights (n, R))."""
        p, g = solver.particles, self.grid
        idx = np.nonzero((p["support"] >= 0).any(axis=1))[0]
        shape = solver.shape
        nodes = np.empty((len(idx), row_width(shape)), dtype=np.int64)
        weights = np.empty((len(idx), row_width(shape)))
        if len(idx):
            support_rows(idx, p["x"], g.origin, g.inv_h, g.cells[0], g.cells[1], shape, nodes, weights)
        return idx, p["id"][idx], p["support"][idx], nodes, weights

    def project(self, solver, field, impulse=False):
        """Impose the supports on the nodal velocities in window fields ``field``, ``field + 1``
        (1: after the grid update, whose velocity change in fields 3, 4 is corrected with them;
        5: the MUSL re-mapped velocity). ``impulse``: the constraint's impulses are the step's
        reaction (added to the reactions effect's sums and the support work to the energy balance)."""
        w, g = solver.window, self.grid
        G = w.G
        _, ids, sup, nodes, weights = self._local_rows(solver)
        ny = g.nodes[1]
        # the nodes' data from this rank's window (complete after the halo sum)
        mass = np.empty(nodes.shape)
        vel = np.empty((*nodes.shape, 2))
        fixed = np.empty((*nodes.shape, 2), dtype=np.bool_)
        support_gather(nodes, G, w.ox, w.oy, ny, field, w.bc_mask, mass, vel, fixed)
        data = (ids, sup, nodes, weights, mass, vel, fixed)
        if solver.comm.Get_size() > 1:
            data = tuple(np.concatenate(parts) for parts in zip(*solver.comm.allgather(data)))
        ids, sup, nodes, weights, mass, vel, fixed = data
        if not len(ids):
            return
        # the same rows in the same order on every rank count: by particle id
        order = np.argsort(ids, kind="stable")
        U, dv, J = self.solve(sup[order], nodes[order], weights[order], mass[order], vel[order],
                              fixed[order], self.vel, len(self.boundaries), RANK_TOLERANCE)
        # correct the nodes of this window (owned and ghost)
        gi, gj = U // ny - w.ox, U % ny - w.oy
        here = (gi >= 0) & (gi < w.shape[0]) & (gj >= 0) & (gj < w.shape[1])
        G[gi[here], gj[here], field:field + 2] += dv[here]
        if field == 1:
            G[gi[here], gj[here], 3:5] += dv[here]
        if impulse:
            v_new = G[gi[here], gj[here], field:field + 2]
            self._account(solver, U[here], J[here], v_new, gi[here], gj[here])

    def _account(self, solver, U, J, v_new, gi, gj):
        """Reactions and work of the constraint impulses ``J`` over this rank's owned nodes."""
        axis, lo, hi = solver._owned_local
        k = gi if axis == 0 else gj
        mine = (k >= lo) & (k < hi)
        solver.external_work += float(np.sum(J[mine].sum(axis=2) * v_new[mine]))   # J . v_new
        reactions = solver.effect("reactions")
        if reactions is None:
            return
        g = self.grid
        x = g.origin[0] + g.h * (U // g.nodes[1])
        y = g.origin[1] + g.h * (U % g.nodes[1])
        for b, k_bc in enumerate(self.index):
            if k_bc not in reactions.index:
                continue
            row = reactions.index.index(k_bc)
            Jx, Jy = J[mine, 0, b], J[mine, 1, b]
            reactions.sums[row, 0] += Jx.sum()
            reactions.sums[row, 1] += Jy.sum()
            reactions.sums[row, 2] += np.sum(x[mine] * Jy) - np.sum(y[mine] * Jx)

    def hold_particles(self, solver):
        """The held particles' velocities take the prescribed components (after the grid-to-
        particle transfer); the momentum this removes is the support's, added to its reaction
        by the owner of each particle."""
        p = solver.particles
        sup = p["support"]
        idx = np.nonzero((sup >= 0).any(axis=1))[0]
        if not len(idx):
            return
        sup = sup[idx]
        held = sup >= 0
        target = np.where(held, self.vel[np.maximum(sup, 0), [0, 1]], p["v"][idx])
        change = p["m"][idx, None] * (target - p["v"][idx])
        p["v"][idx] = target
        reactions = solver.effect("reactions")
        if reactions is None:
            return
        x = p["x"][idx]
        for b, k_bc in enumerate(self.index):
            if k_bc not in reactions.index:
                continue
            row = reactions.index.index(k_bc)
            cx = np.where(sup[:, 0] == b, change[:, 0], 0.0)
            cy = np.where(sup[:, 1] == b, change[:, 1], 0.0)
            reactions.sums[row, 0] += cx.sum()
            reactions.sums[row, 1] += cy.sum()
            reactions.sums[row, 2] += np.sum(x[:, 0] * cy - x[:, 1] * cx)
