"""Edge nodes slaved to their inward neighbours (``[solver.implicit] edge_mass_ratio``): an extended
B-spline basis of degree one at the material's edges (Hollig's extension; Yamaguchi, Moriguchi &
Terada 2021 for the implicit MPM), docs/implicit.md "The points as the quadrature of the strips".

Why: where a body's edge lies just past a grid line, the outermost node of the cubic B-splines
reaches the body through one row of points with weights of order 1e-5, and the point quadrature
leaves its functions with almost no stiffness (near-zero-energy modes, lambda ~ 1e-5 of their
exactly integrated energy: studies.implicit_quadrature); the portal's static push at 0.05 m was
2 % softer than with the grid moved by 0.02 m, where those nodes do not occur.

A node o is slaved when, along one axis direction e, the node o - e holds no material (o is at
the edge), o + e and o + 2e are unknowns, o is not held, and its mass is below ``ratio`` times
the lighter of the two; and when neither o + e nor o + 2e is itself such a candidate. Then

    u_o = 2 u_(o+e) - u_(o+2e)                    (linear extrapolation inward)

which keeps the partition of unity and linear fields exact (rigid motions, constant strains),
so N'_(o+e) = N_(o+e) + 2 N_o, N'_(o+2e) = N_(o+2e) - N_o: every scattered nodal quantity
(mass, momentum, forces, the residual) is folded, q_(o+e) += 2 q_o, q_(o+2e) -= q_o, q_o = 0,
the tangent is T^T K T, and nodal values are expanded back onto o before the particles read
them. The particles touching o lie in the cells on o's inward side (o - e has no material), so
o + e and o + 2e are in their stencils: the folded tangent keeps the kernels' block offsets,
and every fold stays inside a rank's window.

Parallel: each rank decides for its owned nodes from the halo-summed masses (the two passes,
candidates and then slaves, each filled into the ghost columns by their owners), so every rank
sees the owners' decisions on its ghosts.
"""
import numba as nb
import numpy as np

__all__ = ["EdgeSlaves", "fold_blocks", "owned_mask", "DIRECTIONS"]

#: code -> (di, dj): the direction from a slaved node to its two targets (code 0: not slaved)
DIRECTIONS = ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))


def _shifted(arr, di, dj, outside):
    """arr[i + di, j + dj] on every node (``outside`` where that leaves the window)."""
    out = np.full(arr.shape, outside, dtype=arr.dtype)
    nx, ny = arr.shape
    out[max(0, -di):nx - max(0, di), max(0, -dj):ny - max(0, dj)] = \
        arr[max(0, di):nx - max(0, -di), max(0, dj):ny - max(0, -dj)]
    return out


class EdgeSlaves:
    """The slaved nodes of one step on a rank's window.

    Parameters
    ----------
    mass : ndarray (nx, ny)
        Nodal mass after the halo sum (ghosts hold the owners' totals).
    cutoff : float
        The run's mass cutoff (a node above it is an unknown).
    held : ndarray (nx, ny, 2) of bool
    own : ndarray (nx, ny) of bool
        The rank's owned nodes.
    decomp : the slab decomposition (its ``fill``)
    ratio : float
        Slave a node lighter than ``ratio`` times its two inward neighbours.
    """

    def __init__(self, mass, cutoff, held, own, decomp, ratio):
        active = mass > cutoff
        free = active & ~np.asarray(held, bool).any(axis=-1)
        code = np.zeros(mass.shape)
        for c, (di, dj) in enumerate(DIRECTIONS[1:], 1):
            behind = _shifted(active, -di, -dj, False)
            a, b = _shifted(active, di, dj, False), _shifted(active, 2 * di, 2 * dj, False)
            lighter = np.minimum(_shifted(mass, di, dj, 0.0), _shifted(mass, 2 * di, 2 * dj, 0.0))
            ok = free & ~behind & a & b & (mass < ratio * lighter) & (code == 0)
            code[ok] = c
        candidate = self._filled(np.where(own, code, 0.0), decomp)
        slaved = np.zeros(mass.shape)
        for c, (di, dj) in enumerate(DIRECTIONS[1:], 1):
            clear = (_shifted(candidate, di, dj, 1.0) == 0) & (_shifted(candidate, 2 * di, 2 * dj, 1.0) == 0)
            slaved[(candidate == c) & clear] = c
        self.code = self._filled(np.where(own, slaved, 0.0), decomp).astype(np.int64)
        nx, ny = mass.shape
        oi, oj = np.nonzero(self.code)
        d = np.array(DIRECTIONS)[self.code[oi, oj]]
        ai, aj, bi, bj = oi + d[:, 0], oj + d[:, 1], oi + 2 * d[:, 0], oj + 2 * d[:, 1]
        # a ghost node whose targets leave the window: no particle of this rank touches it
        inside = (bi >= 0) & (bi < nx) & (bj >= 0) & (bj < ny)
        self.all_i, self.all_j = oi, oj
        self.oi, self.oj, self.ai, self.aj, self.bi, self.bj = oi[inside], oj[inside], ai[inside], aj[inside], \
            bi[inside], bj[inside]
        self.count_owned = int(np.count_nonzero(self.code[own]))

    @staticmethod
    def _filled(values, decomp):
        arr = np.ascontiguousarray(values[..., None])
        decomp.fill(arr)
        return arr[..., 0]

    def __len__(self):
        return len(self.all_i)

    def fold(self, W):
        """In place on a window array (nx, ny, ...): q_(o+e) += 2 q_o, q_(o+2e) -= q_o, q_o = 0
        (the transpose of the extension)."""
        q = W[self.oi, self.oj].copy()
        W[self.all_i, self.all_j] = 0.0
        np.add.at(W, (self.ai, self.aj), 2.0 * q)
        np.add.at(W, (self.bi, self.bj), -q)

    def expand(self, W):
        """In place on a window array (nx, ny, ...): u_o = 2 u_(o+e) - u_(o+2e) on the slaved
        nodes (the nodes a particle reads; their targets are unknowns or held)."""
        W[self.all_i, self.all_j] = 0.0
        W[self.oi, self.oj] = 2.0 * W[self.ai, self.aj] - W[self.bi, self.bj]
        return W

    def extended_lid(self, lid):
        """(local numbers of the unknowns followed by the slaved nodes, their count): the
        tangent is assembled with rows for the slaved nodes too, then folded."""
        ext = lid.copy()
        n = int(lid.max()) + 1 if lid.size else 0
        ext[self.oi, self.oj] = n + np.arange(len(self.oi))
        return ext, n + len(self.oi)

    def fold_tangent(self, Kb, lid_ext, span):
        """Fold the slaved rows and columns of the blocks ``Kb`` (assembled with ``lid_ext``)
        into their targets (T^T K T). Returns the number of blocks that fell outside the
        block offsets (0 by construction: the tests assert it)."""
        rows_i, rows_j = np.nonzero(lid_ext >= 0)
        order = np.argsort(lid_ext[rows_i, rows_j])
        slave_of = np.full(lid_ext.shape, -1, np.int64)
        slave_of[self.oi, self.oj] = np.arange(len(self.oi))
        return fold_blocks(Kb, lid_ext, rows_i[order], rows_j[order], slave_of, self.oi, self.oj, self.ai,
                           self.aj, self.bi, self.bj, span)


@nb.njit(cache=True)
def fold_blocks(Kb, lid, node_i, node_j, slave_of, oi, oj, ai, aj, bi, bj, span):
    """T^T K T on the blocks ``Kb[row, offset, 2, 2]`` (pmpm.core.implicit.kernels' layout):
    first every block whose column is a slaved node goes to its targets' columns (2x and -1x),
    then every slaved node's row to its targets' rows. Returns the blocks that fell outside the
    offsets."""
    r = span // 2
    nx, ny = lid.shape
    lost = 0
    for row in range(Kb.shape[0]):
        i, j = node_i[row], node_j[row]
        for off in range(span * span):
            ci = i + off // span - r
            cj = j + off % span - r
            if ci < 0 or cj < 0 or ci >= nx or cj >= ny:
                continue
            k = slave_of[ci, cj]
            if k < 0:
                continue
            for t in range(2):
                ti = ai[k] if t == 0 else bi[k]
                tj = aj[k] if t == 0 else bj[k]
                c = 2.0 if t == 0 else -1.0
                di = ti - i + r
                dj = tj - j + r
                if di < 0 or dj < 0 or di >= span or dj >= span:
                    lost += 1
                    continue
                for a in range(2):
                    for b in range(2):
                        Kb[row, di * span + dj, a, b] += c * Kb[row, off, a, b]
            for a in range(2):
                for b in range(2):
                    Kb[row, off, a, b] = 0.0
    for k in range(oi.shape[0]):
        row = lid[oi[k], oj[k]]
        for off in range(span * span):
            ci = oi[k] + off // span - r
            cj = oj[k] + off % span - r
            for t in range(2):
                ti = ai[k] if t == 0 else bi[k]
                tj = aj[k] if t == 0 else bj[k]
                c = 2.0 if t == 0 else -1.0
                trow = lid[ti, tj]
                di = ci - ti + r
                dj = cj - tj + r
                anything = False
                for a in range(2):
                    for b in range(2):
                        anything = anything or Kb[row, off, a, b] != 0.0
                if not anything:
                    continue
                if trow < 0 or di < 0 or dj < 0 or di >= span or dj >= span:
                    lost += 1
                    continue
                for a in range(2):
                    for b in range(2):
                        Kb[trow, di * span + dj, a, b] += c * Kb[row, off, a, b]
    return lost


def owned_mask(shape, owned):
    """The rank's owned nodes on its window: ``owned`` = (axis, first, last) window columns."""
    axis, c0, c1 = owned
    own = np.zeros(shape, dtype=bool)
    index = [slice(None), slice(None)]
    index[axis] = slice(c0, c1)
    own[tuple(index)] = True
    return own
