"""One implicit step's equations on a rank's grid window: the residual, the tangent and the
linear solve that Newton's method (pmpm.core.implicit.newton) iterates.

    R(u) = f_ext(t + dt) + f_int(u) - M a_{n+1}(u)          (dynamics; statics: no M term)
    -dR/du = K_mat + K_geo + M / (beta dt^2)

f_int and K come from the particles (pmpm.core.implicit.kernels) with the stresses the
materials compute from the step-start state for the trial increment (never accumulated over
iterations: the start state is copied once, each trial starts from the copy). Components
held by a boundary condition are eliminated (rows and columns), their increment is the
prescribed one. The halo sums make every rank's residual complete on its owned nodes; the
tangent's ghost rows are summed by PETSc.
"""
import logging

import numpy as np

from pmpm.core.implicit import kernels as IK
from pmpm.core.implicit.diagonal import diagonal_entries
from pmpm.core.implicit.dofs import StepDofs, blocks_to_csr

__all__ = ["GridProblem"]
logger = logging.getLogger(__name__)


def _check_stencils_in_window(s, x):
    """RuntimeError on every rank unless every particle's stencil at ``x`` lies in its rank's
    grid window along the slab axis (nodes c - reach + 1 .. c + reach of its cell c, clipped to
    the grid: pmpm.core.grid.GridWindow). The step's kernels index the window without bounds
    checks, so a particle its rank should have handed on (a missed migration) would make them
    write past the nodal arrays: heap corruption far from the cause (issue 37). Collective."""
    w, g, axis = s.window, s.grid, s.axis
    inside = True
    if len(x) and w.reach is not None:
        c = np.floor((x[:, axis] - g.origin[axis]) * g.inv_h)
        n = g.cells[axis]
        lo = np.clip(c - w.reach + 1, 0, n)
        hi = np.clip(c + w.reach, 0, n)
        first = w.lo[axis]
        inside = bool(np.all((lo >= first) & (hi < first + w.shape[axis])))
    outside = s.decomp.allreduce_sum(0 if inside else 1)
    if outside:
        raise RuntimeError(f"implicit step: a particle's stencil reaches past its rank's grid window on {int(outside)} "
                           f"rank(s) (a particle was not handed to its slab's owner before the step)")


class GridProblem:
    """The equations of one step of length ``rule.dt`` (``rule`` None: statics).

    Parameters
    ----------
    s : pmpm.core.solver.Solver
        Its particles, materials, window and decomposition (read; the particles are not
        changed here).
    linear : pmpm.core.implicit.linear_solver.LinearSolver
    rule : pmpm.core.implicit.newmark.Newmark or None
    fext : ndarray (nx, ny, 2)
        External nodal forces at the step's end (halo-summed).
    v, a : ndarray (nx, ny, 2) or None
        Nodal velocity and acceleration at the step's start (dynamics).
    fext_start : ndarray (nx, ny, 2), optional
        External nodal forces at the step's start (HHT-alpha only: its residual weighs the
        start's forces by -alpha).
    edges : pmpm.core.implicit.edges.EdgeSlaves, optional
        Edge nodes slaved to their inward neighbours (the grid's scattered fields already
        folded): the particles read expanded increments, forces and the tangent are folded.
    """

    def __init__(self, s, linear, rule, fext, v, a, fext_start=None, terms=(), edges=None):
        self.s, self.linear, self.rule = s, linear, rule
        # slaved edge nodes (pmpm.core.implicit.edges; None: every node with mass is an unknown)
        self.edges = edges
        w, g = s.window, s.grid
        self.mass = w.G[..., 0]
        held = w.bc_mask.astype(bool)
        self.dofs = StepDofs(self.mass, s.mass_cutoff, held, s._owned_local, s.decomp,
                             IK.stencil_span(s.shape))
        self.fext, self.v, self.a = fext, v, a
        self.alpha = rule.alpha if rule is not None else 0.0
        self.fext_start = fext_start
        self.geometry = (w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape)
        p = s.particles
        # the step's reference configuration, copied: the commit moves the particles and pushes
        # their volumes forward in place before the terms' last evaluations of the converged
        # increment (the supports' work, Rayleigh's dissipation, the reactions), which must see
        # the positions the window was built for. A particle's stencil at its end position can
        # reach a node column past its rank's window (a B-spline reaches one node below its cell
        # and two above, the ghost width is two: a particle that crosses the upper slab boundary
        # in the step has no spare column), and the kernels do not check bounds (issue 37: the
        # Northridge run's heap corruption).
        self.x = p["x"].copy()
        self.vol = p["vol"].copy()
        _check_stencils_in_window(s, self.x)
        self.stress0 = p["stress"].copy()
        self.state0 = [{name: (p[name].copy() if p.fields.get(name) is not None else None)
                        for name in m.state_fields} for m in s.materials]
        n = p.n
        self.f = np.empty((n, 4))
        self.E = np.empty((n, 3))
        self.D = np.empty((n, 3, 3))
        self.free = ~self.dofs.held[self.dofs.owned_active].reshape(-1)
        self.evaluations = 0
        self.tangents = 0
        self.refits = 0         # steps mapped onto a kept factorisation ("accelerated")
        self._evaluated = None
        self.force_scale = 0.0
        # the effects' terms (pmpm.core.implicit.terms): their forces at the step's start
        self.terms = tuple(terms)
        self.term_start = [t.begin(self) for t in self.terms]
        self.force_scale = self._start_force_scale()

    # -- the state of a trial increment ----------------------------------------------------
    def evaluate(self, u):
        """f, E and the trial stresses S and material states of the increment ``u`` (kept:
        the tangent at the u whose residual was just computed reuses them)."""
        if self._evaluated is not None and np.array_equal(self._evaluated, u):
            return
        self._evaluated = u.copy()
        U = u if self.edges is None else self.edges.expand(u.copy())
        IK.deformation_increment(self.x, U, *self.geometry, self.f, self.E)
        p = self.s.particles
        self.S = self.stress0.copy()
        self.state = [{k: (v.copy() if v is not None else None) for k, v in st.items()} for st in self.state0]
        several = len(self.s.materials) > 1
        for k, m in enumerate(self.s.materials):
            m.update_stress(self.S, self.E, self.state[k], p["mat"], k if several else -1)
        self.evaluations += 1

    def internal_force(self, u):
        """Halo-summed f_int (nx, ny, 2) of the increment ``u`` (evaluates it)."""
        self.evaluate(u)
        R = np.zeros(self.mass.shape + (2,))
        IK.internal_force(self.x, self.vol, self.S, self.f, R, *self.geometry)
        return self.fold_and_sum(R)

    def fold_and_sum(self, F):
        """``F`` (a window array of forces the particles scattered, in place) folded onto the
        slaved edge nodes' targets (T^T F) and halo-summed. The fold comes before the halo sum:
        a slaved node and its targets are in the stencils of the particles that touch it
        (pmpm.core.implicit.edges), so each rank folds its own particles' share inside its
        window, and the sum then completes the targets. The effects' terms fold their
        particles' forces here too (Rayleigh's viscous stress)."""
        if self.edges is not None:
            self.edges.fold(F)
        self.s.decomp.sum_halo(F)
        return F

    def assemble(self, S, f, D):
        """The tangent's blocks (rows of the step's unknowns, pmpm.core.implicit.kernels'
        layout) of the particles' stresses ``S``, deformation gradients ``f`` and material
        matrices ``D`` at the step's start positions, folded onto the slaved edge nodes
        (T^T K T: assembled with rows for the slaved nodes too, then folded, then those rows
        dropped). The material's tangent and the effects' terms (Rayleigh's a1 K_0) use it."""
        d = self.dofs
        span = d.span
        lid, rows = (d.lid, d.n_local) if self.edges is None else self.edges.extended_lid(d.lid)
        Kb = np.zeros((rows, span * span, 2, 2))
        IK.assemble_blocks(self.x, self.vol, S, f, D, lid, Kb, *self.geometry)
        if self.edges is not None:
            self.edges.fold_tangent(Kb, lid, span)
            Kb = Kb[:d.n_local]
        return Kb

    def expand(self, W):
        """``W`` (a window array, in place) with the slaved edge nodes' values extrapolated from
        their targets (unchanged without slaved nodes)."""
        return W if self.edges is None else self.edges.expand(W)

    def _start_force_scale(self):
        """The norm of the internal and external forces at the step's start (u = 0); keeps
        the start's total force F_n for HHT-alpha."""
        fint0 = self.internal_force(np.zeros(self.mass.shape + (2,)))
        self.fint_start = fint0   # (the supports' forces at the step's start: pmpm.core.implicit.scheme)
        if self.alpha:
            self.force_start = fint0 + self.fext_start
            for f in self.term_start:
                if f is not None:
                    self.force_start += f
        fi = self.dofs.owned_values(fint0)
        fe = self.dofs.owned_values(self.fext)
        return float(np.sqrt(self.s.decomp.allreduce_sum(
            float(np.dot(fi[self.free], fi[self.free]) + np.dot(fe[self.free], fe[self.free])))))

    def residual(self, u):
        """(owned residual vector with held components zero, its global 2-norm)."""
        R = self.internal_force(u)
        R += self.fext
        for term in self.terms:
            term.add_residual(self, u, R)
        if self.alpha:   # HHT: the forces at n + 1 + alpha
            R *= 1.0 + self.alpha
            R -= self.alpha * self.force_start
        if self.rule is not None:
            R -= self.mass[..., None] * self.rule.acceleration(u, self.v, self.a)
        r = self.dofs.owned_values(R)
        r[~self.free] = 0.0
        return r, float(np.sqrt(self.s.decomp.allreduce_sum(float(np.dot(r, r)))))

    # -- the linear algebra -------------------------------------------------------------------
    def tangent(self, u):
        """Assemble K at ``u`` (materials' tangents at the trial state) and hand it to PETSc."""
        self.evaluate(u)
        p, d = self.s.particles, self.dofs
        several = len(self.s.materials) > 1
        for k, m in enumerate(self.s.materials):
            m.tangent(self.stress0, self.state0[k], self.S, self.state[k], self.E, self.D, p["mat"],
                      k if several else -1)
        span = d.span
        Kb = self.assemble(self.S, self.f, self.D)   # (T^T K T with slaved edge nodes)
        if self.linear.kept_only:   # (before the terms: the diagonal of kept_diagonal's kind)
            self.linear.reference_diagonal = self._diagonal_of_D()
        for term in self.terms:   # (folded by the terms: ``assemble``, ``fold_and_sum``)
            term.add_tangent(self, u, Kb)
        if self.alpha:
            Kb *= 1.0 + self.alpha
        diag = self._diagonal(Kb)
        node_i, node_j = np.nonzero(d.active)
        nb = int(np.count_nonzero(np.any(Kb != 0.0, axis=(2, 3)))) + d.n_local
        rows = np.empty(d.n_local, np.int64)
        indptr = np.empty(d.n_local + 1, np.int64)
        cols = np.empty(nb, np.int64)
        vals = np.empty((nb, 2, 2))
        nrows, nnz = blocks_to_csr(Kb, d.lid, node_i, node_j, d.gid, d.held, diag, d.row_owned, span,
                                   rows, indptr, cols, vals)
        self.linear.set_operator(d.n_owned, d.start, rows[:nrows], indptr[:nrows + 1], cols[:nnz],
                                 vals[:nnz], d.diag_nnz, d.off_nnz, self._row_keys())
        self.linear.unknowns = (d.active.copy(), d.held.copy())
        self.tangents += 1

    def _row_keys(self):
        """Names of the owned rows that do not depend on the step's numbering: 2 (global grid
        node index) + component (a kept factorisation's rows are matched by them)."""
        w, g = self.s.window, self.s.grid
        i, j = np.nonzero(self.dofs.owned_active)
        node = (i + w.ox).astype(np.int64) * (g.cells[1] + 1) + (j + w.oy)
        return (2 * node[:, None] + np.arange(2)).reshape(-1)

    def factorisation_fits(self):
        """Whether the linear solver holds a factorisation (of an earlier step's tangent) whose
        unknowns are this step's: the same active and held node components on every rank (a
        modified Newton may start from it; collective)."""
        key = self.linear.unknowns
        same = key is not None and key[0].shape == self.dofs.active.shape and \
            np.array_equal(key[0], self.dofs.active) and np.array_equal(key[1], self.dofs.held)
        return self.s.decomp.allreduce_sum(0 if same else 1) == 0

    def kept_diagonal(self, u):
        """The owned rows' diagonal of the tangent at ``u`` as ``newton = "accelerated"``
        compares it from step to step: the material's and initial-stress part
        (pmpm.core.implicit.diagonal) halo-summed, plus the mass term; the effects' terms are
        left out (the same at the factorisation and later, so the ratio is like for like).
        Collective. Leaves the materials' tangents in ``self.D``."""
        self.evaluate(u)
        p = self.s.particles
        several = len(self.s.materials) > 1
        for k, m in enumerate(self.s.materials):
            m.tangent(self.stress0, self.state0[k], self.S, self.state[k], self.E, self.D, p["mat"],
                      k if several else -1)
        return self._diagonal_of_D()

    def _diagonal_of_D(self):
        """kept_diagonal's sum with the materials' tangents already in ``self.D``."""
        W = np.zeros(self.mass.shape + (2,))
        diagonal_entries(self.x, self.vol, self.S, self.f, self.D, W, *self.geometry)
        self.s.decomp.sum_halo(W)
        if self.rule is not None:
            W += (self.rule.mass_factor * self.mass)[..., None]
        return self.dofs.owned_values(W)

    def fit_kept_factorisation(self, u):
        """``newton = "accelerated"``: whether this step can start on the kept factorisation
        of an earlier tangent (collective). Its rows are matched to this step's by grid node:
        rows that left since it was factored are clamped in its solves (a node that only the
        tail of one particle's spline reached is a near-mechanism of P that the current system
        does not have: free, it made the first correction raise the residual three- to
        tenfold on the three-storey frame, docs/implicit.md), new rows get a Jacobi step
        (pmpm.core.implicit.kept_factorisation). It is rescaled so that its diagonal is the
        current one, and the step assembles no tangent unless the accelerated iteration
        stalls. Where too many rows have left (``kept_factorisation.DEPARTED_LIMIT``) the step
        refactors, as ``"modified"`` does."""
        keys = self._row_keys()
        kept = self.linear.kept
        if kept.keys is None or not kept.clamp_departed(keys):
            return False
        self.linear.refit(keys, self.kept_diagonal(u))
        self.refits += 1
        return True

    def _diagonal(self, Kb):
        """What the owned nodes' diagonals receive: the mass term m / (beta dt^2), and on a held
        component a positive stand-in of the row's scale (its own stiffness or mass term)."""
        d = self.dofs
        m = self.mass[d.active]
        diag = np.zeros((d.n_local, 2))
        if self.rule is not None:
            diag += (self.rule.mass_factor * m)[:, None]
        centre = (d.span * d.span) // 2
        stiff = np.abs(np.stack([Kb[:, centre, 0, 0], Kb[:, centre, 1, 1]], axis=1))
        held = d.held[d.active]
        stand_in = np.where(stiff + diag > 0.0, stiff + diag, 1.0)
        return np.where(held, stand_in, diag)

    def solve(self, r):
        return self.linear.solve(r)

    def dot(self, a, b):
        return float(self.s.decomp.allreduce_sum(float(np.dot(a, b))))

    def add(self, u, du, step):
        """u + step du on the window (the correction's ghost values from their owners)."""
        W = np.empty_like(u)
        self.dofs.to_window(du, W)
        self.s.decomp.fill(W)
        return u + step * W

    def held_increment(self, dt):
        """The prescribed increments of the held components (dt times the prescribed velocity)."""
        w = self.s.window
        return np.where(self.dofs.held, dt * w.bc_vel, 0.0)
