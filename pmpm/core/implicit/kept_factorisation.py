"""A factorisation of an earlier tangent as the preconditioner of a Krylov solve of the current
one (``[solver.implicit] newton = "krylov"``; docs/implicit.md, "Krylov solves on a kept
factorisation").

Newton's correction solves K(u) du = R with K the tangent of the current iterate. A direct
solve factors K every time it changes: at 0.05 m cells on the three-storey frame a MUMPS
factorisation costs 2-3 s, and where the frame yields the tangent changes every step. The
tangent of a step or two earlier differs from the current one only in the few particles whose
state changed: P^-1 K is then the identity plus a perturbation of small rank, and a flexible
GMRES on K preconditioned by P^-1 (one back-substitution per Krylov iteration) converges in a
few iterations to the *current* tangent's solution. Newton therefore keeps the consistent
tangent while a factorisation serves many steps; the linear solver refactors P from the
current operator when the Krylov solve does not converge within its iteration budget, or once
the back-substitutions beyond one a solve since the last factorisation add up to that budget
(pmpm.core.implicit.linear_solver).

Changed unknowns. The active nodes change as particles cross cells, so the current system's
rows need not be P's rows. Every row is named by its node's global grid index (and component);
the preconditioner maps the rows the two systems share onto P's numbering (on this rank: a node
P's rank owned and this rank still owns; a node that changed owner counts as new), applies P^-1
with zero on P's rows that left, and gives the new rows a Jacobi step on the current diagonal.
The mapping is rank-local (no collective decision), and only the Krylov iteration count, which
is the same on every rank, decides whether to refactor: a preconditioner that fits badly costs
iterations, never a wrong answer.
"""
import numpy as np

__all__ = ["KeptFactorisation", "DEPARTED_LIMIT"]

#: ``newton = "accelerated"``: the kept factorisation serves a step whose unknowns changed only
#: while at most this many of its rows (over all ranks) have left the system since it was
#: factored: each costs one back-substitution when it first leaves (its column of P^-1, kept
#: until the next factorisation) and a k x k capacitance solve per correction. About the cost of
#: one factorisation at 0.05 m cells on the three-storey frame (a factorisation 1.2 s, a
#: back-substitution 35 ms on 2 ranks: docs/implicit.md).
DEPARTED_LIMIT = 32


class KeptFactorisation:
    """The python-PC context holding P (a copy of a tangent), its factorisation and the map
    from the current rows onto P's.

    Parameters
    ----------
    PETSc : module
    comm : mpi4py communicator
    prefix : str
        The options prefix of the inner solve (the scene's ``[solver.petsc]`` options: by
        default LU by MUMPS with ``ksp_type = "preonly"``).
    """

    def __init__(self, PETSc, comm, prefix):
        self.PETSc, self.comm, self.prefix = PETSc, comm, prefix
        self.P = None
        self.ksp = None
        self.keys = None          # P's owned rows' names (global grid node index * 2 + component)
        self.identity = True      # the current rows are P's rows, in P's order
        self.factorisations = 0

    @property
    def ready(self):
        return self.P is not None

    def factor(self, A, keys, reference_diagonal=None):
        """P = a copy of A (collective), factored now; ``keys``: A's owned rows' names;
        ``reference_diagonal`` (``newton = "accelerated"``): the owned rows' diagonal of the
        kind ``fit`` will be given for later steps, computed with A (the rescaling below)."""
        PETSc = self.PETSc
        P = A.copy()
        # a new solver each time (P is a new matrix: its analysis is redone anyway; a KSP once
        # set up refuses an operator of other local sizes). Collective, as factor is.
        self.release()
        self.ksp = PETSc.KSP().create(comm=self.comm)
        self.ksp.setOptionsPrefix(self.prefix)
        self.ksp.setOperators(P)
        self.ksp.setFromOptions()
        self.ksp.setUp()             # the factorisation
        self.P = P
        self.b, self.z = P.createVecs()
        self.keys = keys.copy()
        self.identity = True
        self.reference = None if reference_diagonal is None else np.asarray(reference_diagonal, float).copy()
        self.scale = None
        self.factorisations += 1
        # the rows that left since (``clamp_departed``): P^-1 e_d per departed row name, the owned
        # part, computed once; the current set's columns and capacitance matrix
        self.columns = {}
        self.clamp = None

    def clamp_departed(self, keys, limit=DEPARTED_LIMIT):
        """Prepare the solves of a step whose owned rows are named ``keys``: P's rows that are
        not among them (rows that left, on any rank) are clamped in P's solve, by the
        capacitance (Woodbury) form of P's solve with those unknowns held at zero,

            z = y - W C^-1 y_D,    y = P^-1 b,  W = P^-1 E,  C = E^T W,  y_D = E^T y

        (E: the unit columns of the departed rows). Without it such a row stays free in P: a
        node that only the tail of one particle's B-spline reached is a near-mechanism there,
        and the first correction on the remapped factorisation raised the residual 3-10 times
        at 0.2 m and 200 times at 0.05 m on the three-storey frame (docs/implicit.md). Returns
        False (nothing prepared) when more than ``limit`` rows have left in all: the caller
        factors the current tangent instead. Collective."""
        left = np.flatnonzero(~np.isin(self.keys, keys, assume_unique=True))
        departed = self.comm.allgather([(int(self.keys[i]), int(i)) for i in left])
        names = [(rank, key, row) for rank, rows in enumerate(departed) for key, row in rows]
        if len(names) > limit:
            return False
        if not names:
            self.clamp = None
            return True
        me = self.comm.Get_rank()
        missing = [(rank, key, row) for rank, key, row in names if (rank, key) not in self.columns]
        for rank, key, row in missing:
            # (the same loop on every rank: each solve is collective)
            self.b.array[:] = 0.0
            if rank == me:
                self.b.array[row] = 1.0
            self.ksp.solve(self.b, self.z)
            self.columns[(rank, key)] = self.z.array_r.copy()
        W = np.stack([self.columns[(rank, key)] for rank, key, _ in names], axis=1)
        mine = [(j, row) for j, (rank, _, row) in enumerate(names) if rank == me]
        C = np.zeros((len(names), len(names)))
        for j, row in mine:
            C[j] = W[row]
        C = self.comm.allreduce(C)
        self.clamp = (W, np.linalg.inv(C), mine, len(names))
        return True

    def _clamped(self, y):
        """y - W C^-1 y_D (``clamp_departed``; y in P's numbering, owned rows). Collective."""
        if self.clamp is None:
            return y
        W, C_inv, mine, k = self.clamp
        yD = np.zeros(k)
        for j, row in mine:
            yD[j] = y[row]
        yD = self.comm.allreduce(yD)
        return y - W @ (C_inv @ yD)

    def fit(self, keys, diagonal):
        """Map the rows named ``keys`` (the current operator's owned rows, ``diagonal`` its
        owned diagonal) onto P's. Rank-local: no PETSc call here."""
        if self.P is None:
            return
        self.scale = None
        if keys.shape == self.keys.shape and np.array_equal(keys, self.keys):
            self.identity = True
            if self.reference is not None and diagonal is not None:
                self.scale = _diagonal_scale(self.reference, diagonal)
            return
        self.identity = False
        _, self.old_rows, self.new_rows = np.intersect1d(self.keys, keys, assume_unique=True, return_indices=True)
        if self.reference is not None and diagonal is not None:
            self.scale = _diagonal_scale(self.reference[self.old_rows], diagonal[self.new_rows])
        # a new row: a Jacobi step (its diagonal holds at least the mass term in dynamics and
        # the stand-in of a held component; a zero one, a statics node with no stiffness yet,
        # gets nothing)
        self.inv_diag = np.divide(1.0, diagonal, out=np.zeros_like(diagonal), where=diagonal != 0.0)

    def apply(self, pc, x, y):
        """y = P^-1 x on the shared rows (P's numbering), a Jacobi step on the new ones."""
        xa = x.array_r
        if self.identity:
            # this rank's rows are P's, but another rank's may not be: P's vectors, not x and y
            # (whose global size is the current operator's)
            self.b.array[:] = xa
            self.ksp.solve(self.b, self.z)
            y.array[:] = self.z.array_r
            return
        self.b.array[:] = 0.0
        self.b.array[self.old_rows] = xa[self.new_rows]
        self.ksp.solve(self.b, self.z)
        ya = y.array
        ya[:] = xa * self.inv_diag
        ya[self.new_rows] = self.z.array_r[self.old_rows]

    def solve_array(self, xa):
        """P^-1 xa on the shared rows, a Jacobi step on the new ones, as ``apply`` but on the
        owned rows' numpy array (``newton = "accelerated"``: the kept factorisation is the
        solver itself, no Krylov iteration around it). Collective."""
        s = 1.0 if self.scale is None else self.scale
        if self.identity:
            # (this rank's rows are P's; another rank's may have left: the clamp is global)
            self.b.array[:] = xa * s
            self.ksp.solve(self.b, self.z)
            return self._clamped(self.z.array_r) * s
        self.b.array[:] = 0.0
        self.b.array[self.old_rows] = xa[self.new_rows] * s
        self.ksp.solve(self.b, self.z)
        y = self._clamped(self.z.array_r)
        ya = xa * self.inv_diag
        ya[self.new_rows] = y[self.old_rows] * s
        return ya

    def release(self):
        """Destroy P and its solver (not ``destroy``: PETSc calls a python PC context's
        ``destroy(pc)`` when the PC goes)."""
        for obj in (self.ksp, self.P):
            if obj is not None:
                obj.destroy()
        self.ksp = self.P = None


def _diagonal_scale(reference, current):
    """S = sqrt(d_P / d) row by row (1 where either is not positive): S P^-1 S is the inverse
    of S^-1 P S^-1, whose diagonal is the current one. The rows whose stiffness changed most
    since P was factored are the light nodes at the material's edges, where a particle that
    moves a little changes the tail of a B-spline that reaches the node by a large fraction;
    without the rescaling the first correction on a kept factorisation raised the residual
    tenfold on the three-storey frame at 0.2 m (docs/implicit.md)."""
    ok = (reference > 0.0) & (current > 0.0)
    return np.where(ok, np.sqrt(np.where(ok, reference, 1.0) / np.where(ok, current, 1.0)), 1.0)
