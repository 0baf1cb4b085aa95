"""Modified Newton accelerated in the subspace of its own iterates (``[solver.implicit] newton =
"accelerated"``; docs/implicit.md, "Accelerated modified Newton").

A modified Newton iteration keeps a factorisation P of an earlier tangent and corrects by
z = P^-1 R(u). Where the structure yields, P and the current tangent K differ in the few
particles whose state changed, and the plain iteration converges only linearly, at the rate of
the spectral radius of I - P^-1 K: the frames then refactor every step or two, and at 0.05 m
cells on the three-storey frame a tangent (assembly and MUMPS factorisation) costs some 1.6 s
against 60 ms for a residual and a back-substitution (docs/implicit.md).

The iteration u -> u + z(u) is a fixed-point map, and the corrections it has already made span
the directions in which P^-1 K differs from the identity. Anderson's acceleration (Walker & Ni
2011; with a linear map it is GMRES on P^-1 K, the Krylov acceleration of Carlson & Miller
1998 that OpenSees calls KrylovNewton and recommends for frames, Scott & Fenves 2010) takes the
correction

    d_k = z_k - (dU + dZ) gamma,     gamma = argmin || z_k - dZ gamma ||_2

where the columns of dU are the last m corrections u_{i+1} - u_i and those of dZ the changes
z_{i+1} - z_i they caused (dZ ~ -P^-1 K dU: the information about K the residuals already
paid for). No tangent is assembled while this converges; one is assembled and factored (the
subspace cleared) only where it stalls: where an iteration leaves more than ``STALL_RATE`` of
the residual it started from, or after ``REFRESH_AFTER`` iterations on one factorisation in a
step. The least squares are solved on every rank from the same global Gram matrix (one
allreduce of an m x m matrix and an m vector an iteration), so the ranks take the same
correction.
"""
import numpy as np

__all__ = ["AndersonMixer", "DEPTH", "STALL_RATE", "REFRESH_AFTER"]

#: corrections kept in the subspace (OpenSees' KrylovNewton keeps up to 10 by default)
DEPTH = 8
#: an accelerated iteration that leaves more than this fraction of the residual it started
#: from has stalled: the tangent is refactored at its iterate
STALL_RATE = 0.7
#: iterations of one step on one factorisation before it is renewed in any case
REFRESH_AFTER = 12
#: a column of dZ whose part independent of the others is this small against its norm (squared:
#: the Gram matrix's pivots) adds nothing but round-off; the oldest columns go first
_DEPENDENT = 1e-12


class AndersonMixer:
    """The subspace of one step's corrections on one factorisation (module doc).

    Parameters
    ----------
    allreduce : callable
        Sums a numpy array over the ranks (the decomposition's ``allreduce_sum``).
    depth : int
        Columns kept.
    """

    def __init__(self, allreduce, depth=DEPTH):
        self.allreduce, self.depth = allreduce, depth
        self.clear()

    def clear(self):
        self.dU, self.dZ = [], []
        self._last = None      # (the last correction taken, the z it was computed from)

    def correction(self, z):
        """The accelerated correction for the modified-Newton correction ``z`` (owned rows):
        z itself while the subspace is empty."""
        if self._last is not None:
            d_prev, z_prev = self._last
            self.dU.append(d_prev)
            self.dZ.append(z - z_prev)
            if len(self.dU) > self.depth:
                del self.dU[0], self.dZ[0]
        d = z.copy()
        if self.dZ:
            gamma = self._least_squares(z)
            for g, du, dz in zip(gamma, self.dU, self.dZ):
                if g != 0.0:
                    d -= g * (du + dz)
        self._last = (d, z)
        return d

    def _least_squares(self, z):
        """argmin || z - dZ gamma || from the global Gram matrix, by Cholesky with the
        dependent columns (oldest first) given no weight."""
        m = len(self.dZ)
        local = np.empty((m + 1, m))
        Z = np.stack(self.dZ)
        local[:m] = Z @ Z.T
        local[m] = Z @ z
        total = self.allreduce(local)
        G, b = total[:m], total[m]
        keep = list(range(m))
        while keep:
            sub = G[np.ix_(keep, keep)]
            scale = np.sqrt(np.diag(sub))
            if np.all(scale > 0.0):
                S = sub / np.outer(scale, scale)
                try:
                    L = np.linalg.cholesky(S)
                except np.linalg.LinAlgError:
                    L = None
                if L is not None and np.min(np.diag(L)) ** 2 > _DEPENDENT:
                    y = np.linalg.solve(L.T, np.linalg.solve(L, b[keep] / scale))
                    gamma = np.zeros(m)
                    gamma[keep] = y / scale
                    return gamma
            keep = keep[1:]   # drop the oldest column and try again
        return np.zeros(m)
