"""newton = "krylov": the current operator solved by FGMRES on a kept factorisation of an
earlier one (pmpm/core/implicit/kept_factorisation.py), also when the unknowns changed.

The operator is a chain of 2-component nodes named by global node numbers g, with a diagonal
that varies along the chain (so that a factorisation mapped onto the wrong nodes is a poor
preconditioner). The old operator holds nodes 0..29, the new one 2..31: two nodes left, two
came. The mapped preconditioner M is P^-1 restricted to the 28 shared nodes (that is (A_SS -
L)^-1 with L the Schur term of the two nodes that left, of rank 2: only node 2 couples to them)
and a Jacobi step on the 2 new nodes (4 rows), so M A - I has rank at most 2 + 2 x 4 = 10 and
GMRES converges in at most 11 iterations (exact arithmetic). Shown to fail on a planted bug
(restored): rows mapped by position instead of by name (``KeptFactorisation.fit`` treating the
new rows as P's): 30 iterations without convergence, then a refactorisation (2, not 1).
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core.implicit.linear_solver import LinearSolver

#: GMRES's relative tolerance here: the answer is compared with a dense solve to 1e-8
RTOL = 1e-12


def _chain(nodes):
    """Block-CSR of the chain on global node numbers ``nodes`` (consecutive), numbered 0.. here,
    and its dense matrix."""
    n = len(nodes)
    rows, indptr, cols, vals = np.arange(n), [0], [], []
    dense = np.zeros((2 * n, 2 * n))
    for a, g in enumerate(nodes):
        for b in (a - 1, a, a + 1):
            if 0 <= b < n:
                blk = np.array([[3.0 + 40.0 * (g % 3 == 0), 0.5], [0.5, 3.0 + 0.1 * g]]) if a == b else -np.eye(2)
                cols.append(b)
                vals.append(blk)
                dense[2 * a:2 * a + 2, 2 * b:2 * b + 2] = blk
        indptr.append(len(cols))
    nnz = np.diff(indptr)
    keys = (2 * np.asarray(nodes)[:, None] + np.arange(2)).reshape(-1)
    return (n, 0, rows, np.array(indptr), np.array(cols), np.array(vals), nnz, np.zeros(n, np.int64), keys), dense


def _solver(its=30):
    return LinearSolver(MPI.COMM_SELF, {}, krylov=(RTOL, its))


def test_changed_unknowns_use_the_kept_factorisation():
    lin = _solver()
    old, _ = _chain(list(range(0, 30)))
    new, dense = _chain(list(range(2, 32)))
    lin.set_operator(*old)
    lin.solve(np.ones(60))
    assert lin.factorisations == 1
    lin.set_operator(*new)
    rhs = np.sin(np.arange(60.0))
    before = lin.iterations
    x = lin.solve(rhs)
    ref = np.linalg.solve(dense, rhs)
    assert np.abs(x - ref).max() <= 1e-8 * np.abs(ref).max()
    assert lin.factorisations == 1                  # the kept one served
    assert lin.iterations - before <= 11            # the rank bound (module docstring)
    lin.destroy()


def test_a_stalled_gmres_refactors_and_still_solves():
    """A budget too small for the changed operator (2 iterations): the GMRES stalls, the
    current operator is factored (one more factorisation) and the solve is then exact."""
    lin = _solver(its=2)
    old, _ = _chain(list(range(0, 30)))
    new, dense = _chain(list(range(2, 32)))
    lin.set_operator(*old)
    lin.solve(np.ones(60))
    lin.set_operator(*new)
    rhs = np.cos(np.arange(60.0))
    x = lin.solve(rhs)
    assert lin.factorisations == 2
    ref = np.linalg.solve(dense, rhs)
    assert np.abs(x - ref).max() <= 1e-8 * np.abs(ref).max()
    lin.destroy()


@pytest.mark.parametrize("scale", [1.0, 1.05])
def test_same_unknowns_new_values(scale):
    """The same rows with new values (a tangent that changed where material yields): the kept
    factorisation preconditions the new operator, whose solve is the new one's."""
    lin = _solver()
    old, _ = _chain(list(range(0, 30)))
    lin.set_operator(*old)
    lin.solve(np.ones(60))
    new, dense = _chain(list(range(0, 30)))
    new[5][10:14] *= scale                          # five nodes' blocks change
    dense[:, :] = 0.0
    rows, indptr, cols, vals = new[2:6]
    for a in rows:
        for k in range(indptr[a], indptr[a + 1]):
            dense[2 * a:2 * a + 2, 2 * cols[k]:2 * cols[k] + 2] = vals[k]
    lin.set_operator(*new)
    rhs = np.arange(60.0)
    x = lin.solve(rhs)
    ref = np.linalg.solve(dense, rhs)
    assert np.abs(x - ref).max() <= 1e-8 * np.abs(ref).max()
    assert lin.factorisations == 1
    lin.destroy()


def test_kept_only_rescaled_to_the_current_diagonal_is_exact_for_a_diagonal_change():
    """newton = "accelerated": the kept factorisation applied as S P^-1 S with S = sqrt(d_P / d)
    (kept_factorisation._diagonal_scale). Where the current operator is P rescaled on both
    sides, A = T P T with T diagonal (a node whose weight changed), its diagonal is T^2 d_P,
    so S = T^-1 and S P^-1 S = A^-1 exactly: the solve equals a dense solve of A to round-off,
    where P^-1 alone is off by the rescaling. Fails with the rescaling applied on one side
    only."""
    lin = LinearSolver(MPI.COMM_SELF, {}, kept_only=True)
    op, P = _chain(list(range(0, 20)))
    d_P = np.diag(P).copy()
    lin.reference_diagonal = d_P
    lin.set_operator(*op)
    assert lin.factorisations == 1
    t = 1.0 + 0.5 * np.sin(np.arange(40.0))     # every row's weight changed, by up to a half
    A = t[:, None] * P * t[None, :]
    lin.refit(op[-1], np.diag(A).copy())
    rhs = np.cos(np.arange(40.0))
    x = lin.solve(rhs)
    ref = np.linalg.solve(A, rhs)
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
    assert lin.factorisations == 1
    plain = np.linalg.solve(P, rhs)
    assert np.abs(plain - ref).max() > 0.1 * np.abs(ref).max()   # (the rescaling is what makes it exact)
    lin.destroy()


@pytest.mark.parametrize("left", [(0, 1), (0, 1, 13)])
def test_kept_only_clamps_the_rows_that_left(left):
    """newton = "accelerated" after rows left the system (kept_factorisation.clamp_departed):
    the kept P of the chain's nodes 0..29 serves an operator without the nodes ``left``. The
    current operator is then P's principal submatrix on the nodes that stayed (the same blocks,
    the couplings to the departed nodes gone), and the capacitance form of P's solve with the
    departed unknowns held at zero is its exact inverse: the solve equals a dense solve of the
    submatrix to round-off. Fails with the clamp left out (P^-1 with zero on the departed rows,
    what the remapping did before: the stayed node next to a departed one feels it free)."""
    lin = LinearSolver(MPI.COMM_SELF, {}, kept_only=True)
    op, P = _chain(list(range(0, 30)))
    lin.reference_diagonal = np.diag(P).copy()
    lin.set_operator(*op)
    stayed = np.array([g for g in range(30) if g not in left])
    rows = (2 * stayed[:, None] + np.arange(2)).reshape(-1)
    A = P[np.ix_(rows, rows)]
    keys = op[-1][rows]
    assert lin.kept.clamp_departed(keys)
    lin.refit(keys, np.diag(A).copy())
    rhs = np.cos(np.arange(len(rows)) + 0.3)
    x = lin.solve(rhs)
    ref = np.linalg.solve(A, rhs)
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
    assert lin.factorisations == 1
    # one back-substitution per departed row, once: a second step with the same rows solves
    # nothing more for the clamp
    assert len(lin.kept.columns) == 2 * len(left)
    assert lin.kept.clamp_departed(keys) and len(lin.kept.columns) == 2 * len(left)
    lin.destroy()


def test_kept_only_too_many_departed_rows_refuse_the_kept_factorisation():
    """More departed rows than the limit: clamp_departed declines (the caller refactors)."""
    lin = LinearSolver(MPI.COMM_SELF, {}, kept_only=True)
    op, P = _chain(list(range(0, 30)))
    lin.reference_diagonal = np.diag(P).copy()
    lin.set_operator(*op)
    keys = op[-1][20:]                              # 10 nodes, 20 rows left
    assert not lin.kept.clamp_departed(keys, limit=19)
    assert lin.kept.clamp_departed(keys, limit=20)
    lin.destroy()
