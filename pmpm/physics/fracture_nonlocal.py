"""The nonlocal ductile fracture criterion: a point fails when the void growth index averaged
over the material's characteristic length reaches 1, and its own index too (docs/fracture.md,
"The nonlocal criterion").

An effect (pmpm.core.effects) that exists only when a material's ``[materials.<label>.fracture]``
names a ``characteristic_length`` l*. Kanvinde and Deierlein's void growth and SMCS criteria
carry such a length: the criterion must be exceeded over l*, not at a point. Taken at a
point, the index follows the strain of the single most strained point, which at a notch is a
surface point: its strain depends on how the surface is discretised (the staircase of the
particles' sub-cell centres in pmpm: docs/fracture.md measures it), so the displacement at
initiation does not converge under refinement. Averaged over l* it does, once the cell is
below l*.

The average is a smoothing on the grid, applied as many times as l* asks. One pass
particles -> grid -> particles with the linear hat functions N_j of the grid's nodes (whatever
basis the run's transfer uses: the hats reach the fewest nodes and spread the least per pass),

    u_p <- sum_j N_j(x_p) (sum_q N_j(x_q) m_q u_q) / (sum_q N_j(x_q) m_q),

is a mass-weighted average over the material's particles whose kernel has the variance
2 var(N) = h^2 / 3 per axis (the hat convolved with itself; plus s^2 / 6 on a particle lattice
of spacing s), normalised at free surfaces by the nodal mass (no weight outside the material).
The criterion's kernel has the variance of a uniform average over a segment of length l*,
l*^2 / 12 per axis: k = floor(r) passes and a blend (1 - f) P^k u + f P^(k+1) u, r = k + f =
l*^2 / (4 h^2), give exactly that variance at any cell size (the kernels of repeated passes
tend to a Gaussian; below one pass, k = 0, the blend mixes the point's own index with one
pass: l* is then not resolved). Each pass is one scatter, one halo sum and one gather: the
decomposition's halo of 2 node columns is all it needs, however wide l* is, and the passes
are the same on any number of ranks (tests/mpi/test_fracture_mpi.py).

When: at the start of each step's force pass (hook ``scatter_forces``: the particles are where
the step's grid window holds them, after the migration), and only once some point of the
material has a local index of 1: the average of a positive, normalised kernel never exceeds the
largest value averaged, so before that no point can fail and the passes are skipped (one
maximum over the ranks per step). A point that fails there fails with the stress at the end of
the previous step, exactly as the local criterion fails it in that step's update; the first
fracture record (pmpm.physics.fracture_record) notes it at the end of this step, one step
later. A point fails only where its own index has reached 1 as well (the criterion exceeded
at the point and over l*, :func:`pmpm.physics.materials.fracture.fail_where`): the average
alone would also fail the points beside a running crack, within about l* / 2 of its path,
whose own index is below 1, and the failed band, widening with l* / h, would dissipate more
than G_f per unit crack area. The intact points' ``damage`` is the smaller of the average and
their own index when last computed (0 before).
The failed points' index is frozen at failure (their plastic strain since is the crack's
opening, not void growth).
"""
import math

import numba as nb
import numpy as np

from pmpm.core.effects import Effect
from pmpm.physics.materials.fracture import fail_where

__all__ = ["NonlocalFracture", "smoothing_passes", "scatter_index", "gather_index", "nodal_average"]


def smoothing_passes(length, h):
    """(k, f): the passes of the grid's smoothing whose blend (1 - f) P^k + f P^(k+1) has the
    variance l*^2 / 12 per axis (module doc), for cell size ``h``."""
    r = length * length / (4.0 * h * h)
    k = int(math.floor(r))
    return k, r - k


@nb.njit(cache=True, inline="always")
def _hat(x, p, axis, origin, inv_h):
    """The first node of particle p's linear stencil along ``axis`` and its weight's complement."""
    t = (x[p, axis] - origin[axis]) * inv_h
    i = int(math.floor(t))
    return i, t - i


@nb.njit(cache=True)
def scatter_index(x, m, u, mat_ids, which, out, ox, oy, origin, inv_h):
    """out_j += N_j(x_p) (m_p u_p, m_p), N the linear hat functions, over the material's
    particles (``which``; -1: all): the mass-weighted index and the mass on the window's nodes."""
    for p in range(x.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        i, fx = _hat(x, p, 0, origin, inv_h)
        j, fy = _hat(x, p, 1, origin, inv_h)
        a, b = m[p] * u[p], m[p]
        for di in range(2):
            wx = fx if di else 1.0 - fx
            for dj in range(2):
                w = wx * (fy if dj else 1.0 - fy)
                out[i + di - ox, j + dj - oy, 0] += w * a
                out[i + di - ox, j + dj - oy, 1] += w * b


@nb.njit(cache=True)
def gather_index(x, mat_ids, which, G, u, ox, oy, origin, inv_h):
    """u_p = sum_j N_j(x_p) G_j[0] over the material's particles (G: the nodal averages)."""
    for p in range(x.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        i, fx = _hat(x, p, 0, origin, inv_h)
        j, fy = _hat(x, p, 1, origin, inv_h)
        v = 0.0
        for di in range(2):
            wx = fx if di else 1.0 - fx
            for dj in range(2):
                v += wx * (fy if dj else 1.0 - fy) * G[i + di - ox, j + dj - oy, 0]
        u[p] = v


def nodal_average(grid):
    """The nodes' mass-weighted averages in ``grid[..., 0]`` (the scattered m u over the
    scattered mass ``grid[..., 1]``; 0 where no mass), in place."""
    mass = grid[..., 1]
    grid[..., 0] = np.where(mass > 0.0, grid[..., 0] / np.where(mass > 0.0, mass, 1.0), 0.0)


class NonlocalFracture(Effect):
    """Failure decided by the void growth index averaged over l* (module doc)."""

    name = "fracture_nonlocal"

    @classmethod
    def create(cls, scene, setup):
        chosen = [(k, m) for k, m in enumerate(setup.materials)
                  if getattr(m, "fracture", None) and m.fracture.get("characteristic_length") is not None]
        if not chosen:
            return None
        several = len(setup.materials) > 1
        return cls([(k if several else -1, m) for k, m in chosen])

    def __init__(self, materials):
        self.materials = materials   # (which, material)
        self.passes_run = 0          # smoothing passes run on this rank (a cost figure)

    def describe(self):
        return ["nonlocal fracture criterion (the void growth index averaged over "
                + ", ".join(f"l* = {m.fracture['characteristic_length']:g} m" for _, m in self.materials) + ")"]

    def _smooth(self, s, u, which, passes):
        """``passes`` applications of the grid's smoothing to ``u`` (collective: one halo sum each)."""
        p = s.particles
        G, ox, oy, origin, inv_h, ncx, ncy, shape = s.geometry
        grid = np.zeros(G.shape[:2] + (2,))
        for _ in range(passes):
            grid[...] = 0.0
            scatter_index(p["x"], p["m"], u, p["mat"], which, grid, ox, oy, origin, inv_h)
            s.decomp.sum_halo(grid)
            nodal_average(grid)
            u = u.copy()
            gather_index(p["x"], p["mat"], which, grid, u, ox, oy, origin, inv_h)
            self.passes_run += 1
        return u

    def scatter_forces(self, s):
        p = s.particles
        for which, material in self.materials:
            index = p["vgm_index"]
            mine = slice(None) if which < 0 else (p["mat"] == which)
            local_max = float(index[mine].max()) if index[mine].size else 0.0
            if s.decomp.allreduce_max(local_max) < 1.0:
                continue   # no average can reach 1 yet (module doc): no pass
            k, f = smoothing_passes(material.fracture["characteristic_length"], s.grid.h)
            average = self._smooth(s, index, which, k)
            if f > 0.0:
                average = (1.0 - f) * average + f * self._smooth(s, average, which, 1)
            fp, damage, _, crack, eff = material.fracture_arguments(p.fields)
            fail_where(average, index, p["mat"], which, p["stress"], eff, crack, damage, fp)
