"""Tracked points: the particle nearest each requested point, sampled over time."""
import logging

import numpy as np

__all__ = ["Tracker", "HISTORY_COLUMNS"]
logger = logging.getLogger(__name__)

#: columns of each track's time history
HISTORY_COLUMNS = ("ux", "uy", "vx", "vy", "x", "y", "sxx", "syy", "sxy")


class Tracker:
    """Follows the particles nearest to the scene's ``[[output.track]]`` points.

    The nearest particle is chosen by initial position, so a restarted run follows the same
    particles. Sampling costs one small allreduce (the owner fills its rows, others add zeros).

    Parameters
    ----------
    tracks : sequence of TrackConfig
    solver : Solver
    """

    def __init__(self, tracks, solver):
        self.names = [t.name for t in tracks]
        self.points = [tuple(float(c) for c in t.point) for t in tracks]
        self.solver = solver
        self.ids = np.array([self._nearest(t.point) for t in tracks], dtype=np.int64)
        self._rows = np.full(len(self.ids), -1, dtype=np.int64)  # each one's row here, or -1

    def _nearest(self, point):
        p = self.solver.particles
        best = (np.inf, -1)
        if p.n:
            d = np.sum((p["x0"] - np.asarray(point)) ** 2, axis=1)
            k = int(np.argmin(d))
            best = (float(d[k]), int(p["id"][k]))
        return self.solver.comm.allreduce(best, op=_min_op())[1]

    def attrs(self):
        """Attributes of each track's history dataset: the followed particle's id, the point."""
        return {name: {"particle_id": int(pid), "point": list(point),
                       "point_units": "m"}
                for name, pid, point in zip(self.names, self.ids, self.points)}

    def _row(self, k, ids):
        """This rank's row of the k-th followed particle, or -1: the row found last time if it
        still holds that id (rows change only when particles are sorted or migrate), else one
        vectorised search."""
        r = self._rows[k]
        if not (0 <= r < len(ids) and ids[r] == self.ids[k]):
            hits = np.flatnonzero(ids == self.ids[k])
            r = self._rows[k] = hits[0] if hits.size else -1
        return r

    def sample(self):
        """(n_tracks, len(HISTORY_COLUMNS)) values, identical on every rank: the owner's row,
        zeros elsewhere, summed over the ranks (no reduction on one rank)."""
        out = self.local_rows()
        if not len(self.ids) or self.solver.comm.Get_size() == 1:
            return out
        return self.solver.decomp.allreduce_sum(out)

    def local_rows(self):
        """This rank's part of :meth:`sample`: the rows of the followed particles it owns, zeros
        for the others (a caller may sum it over the ranks with other figures in one reduction)."""
        out = np.zeros((len(self.ids), len(HISTORY_COLUMNS)))
        p = self.solver.particles
        if len(self.ids) and p.n:
            ids = p["id"]
            for k in range(len(self.ids)):
                r = self._row(k, ids)
                if r >= 0:
                    x, x0, v, s = p["x"][r], p["x0"][r], p["v"][r], p["stress"][r]
                    out[k] = (x[0] - x0[0], x[1] - x0[1], v[0], v[1], x[0], x[1], s[0], s[1], s[2])
        return out


def _min_op():
    from mpi4py import MPI
    return MPI.MIN
