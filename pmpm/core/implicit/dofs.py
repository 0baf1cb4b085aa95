"""The unknowns of one implicit step: which nodes take part, their global numbers, and the
step's matrix in the block form PETSc takes (pmpm.core.implicit.linear_solver).

Mass rule (docs/implicit.md): a node is an unknown when its mass after the halo sum exceeds
the run's mass cutoff (``solver.mass_cutoff`` times the largest particle mass, the rule the
explicit step uses to give a node a velocity). A node below it holds no material that could
carry a row; its increment is zero. Every other node, however little material it holds,
stays in the system: in dynamics its row holds m / (beta dt^2) on the diagonal, so the
matrix stays positive definite wherever the material is stable, and the default direct solve
does not mind the spread of the diagonal that the edge nodes bring.

Numbering: the owner of a node (pmpm's slab decomposition) numbers its active nodes in window
order after the active nodes of the lower ranks (an exclusive scan); ghost columns receive the
owners' numbers by the halo fill. Rows of a rank are therefore one contiguous range: the
ownership ranges of the PETSc matrix are pmpm's slabs.
"""
import numba as nb
import numpy as np

__all__ = ["StepDofs", "blocks_to_csr"]


class StepDofs:
    """Active nodes and their numbers on this rank's window for one step.

    Parameters
    ----------
    mass : ndarray (nx, ny)
        Nodal mass after the halo sum (ghosts hold the owners' totals).
    cutoff : float
    held : ndarray (nx, ny, 2) of bool
        Components with an essential boundary condition.
    owned : (int, int, int)
        (axis, first, last) owned window columns along the decomposition axis.
    decomp : decomposition.SlabDecomposition
    span : int
        Offsets per axis between two coupled nodes (2K - 1).
    """

    def __init__(self, mass, cutoff, held, owned, decomp, span):
        axis, c0, c1 = owned
        self.shape = mass.shape
        self.active = mass > cutoff
        own = np.zeros(self.shape, dtype=bool)
        index = [slice(None), slice(None)]
        index[axis] = slice(c0, c1)
        own[tuple(index)] = True
        self.own = own
        self.owned_active = self.active & own
        self.n_owned = int(self.owned_active.sum())
        self.start = int(decomp.exscan_sum(self.n_owned))
        self.n_global = int(decomp.allreduce_sum(self.n_owned))
        # global numbers + 1 (0: no unknown), owners' numbers copied into the ghost columns
        numbers = np.zeros(self.shape + (1,))
        numbers[self.owned_active, 0] = self.start + 1 + np.arange(self.n_owned)
        decomp.fill(numbers)
        self.gid = numbers[..., 0].astype(np.int64) - 1
        self.lid = np.full(self.shape, -1, dtype=np.int64)
        self.n_local = int(self.active.sum())
        self.lid[self.active] = np.arange(self.n_local)
        self.row_gid = self.gid[self.active]
        self.row_owned = own[self.active]
        self.held = held & self.active[..., None]
        self.span = span
        self.diag_nnz, self.off_nnz = self._neighbour_counts(span)

    def _neighbour_counts(self, span):
        """Active neighbours within the coupling reach of every owned active node, in owned
        and in ghost columns (the matrix's preallocation, an upper bound)."""
        r = span // 2
        nx, ny = self.shape
        a = np.pad(self.active, r)
        o = np.pad(self.active & self.own, r)
        diag = np.zeros(self.shape, dtype=np.int64)
        total = np.zeros(self.shape, dtype=np.int64)
        for di in range(span):
            for dj in range(span):
                total += a[di:di + nx, dj:dj + ny]
                diag += o[di:di + nx, dj:dj + ny]
        sel = self.owned_active
        return diag[sel], total[sel] - diag[sel]

    def owned_values(self, W):
        """The owned active nodes' rows of the window array ``W`` (nx, ny, 2), flattened in
        the order of their global numbers."""
        return W[self.owned_active].reshape(-1)

    def to_window(self, values, W):
        """Write owned values (``owned_values`` order) into ``W`` (zero elsewhere); the caller
        fills the ghosts."""
        W[...] = 0.0
        W[self.owned_active] = values.reshape(-1, 2)


@nb.njit(cache=True)
def blocks_to_csr(Kb, lid, node_i, node_j, gid, held, diag, row_owned, span, rows, indptr, cols, vals):
    """The assembled blocks ``Kb[row, offset, 2, 2]`` as block CSR with global numbers, the
    rows and columns of held components eliminated (zero, and ``diag`` on the diagonal of an
    owned node's held component), ``diag`` (n_local, 2) added on the owned nodes' diagonals
    (the mass term). ``node_i``/``node_j``: window indices of each local row's node. Blocks that
    are all zero are left out. Returns the number of blocks written."""
    r = span // 2
    nx, ny = lid.shape
    nnz = 0
    nrows = 0
    indptr[0] = 0
    for row in range(Kb.shape[0]):
        i, j = node_i[row], node_j[row]
        start = nnz
        for off in range(span * span):
            ii = i + off // span - r
            jj = j + off % span - r
            if ii < 0 or jj < 0 or ii >= nx or jj >= ny:
                continue
            col = lid[ii, jj]
            if col < 0:
                continue
            centre = off == (r * span + r)
            blk = np.zeros((2, 2))
            anything = False
            for a in range(2):
                for b in range(2):
                    v = Kb[row, off, a, b]
                    if held[i, j, a] or held[ii, jj, b]:
                        v = 0.0
                    if centre and a == b and row_owned[row]:
                        v += diag[row, a]
                    blk[a, b] = v
                    anything = anything or v != 0.0
            if not anything:
                continue
            cols[nnz] = gid[ii, jj]
            for a in range(2):
                for b in range(2):
                    vals[nnz, a, b] = blk[a, b]
            nnz += 1
        if nnz > start:
            rows[nrows] = gid[i, j]
            nrows += 1
            indptr[nrows] = nnz
    return nrows, nnz
