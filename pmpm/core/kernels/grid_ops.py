"""Grid-node operations: explicit momentum update with essential BCs (paper eq. 4, step 8), and
the bookkeeping that limits the node passes to the grid's occupied tiles.

A small scene often occupies a fraction of its grid window (the portal frame: two columns and a
beam in a 143 x 85 window). The window is cut into square tiles of ``tile`` nodes; a tile is
*active* when a particle's stencil reaches one of its nodes (or the halo exchange writes into
it). Every other node is zero and nothing reads it, so the node passes skip it: each kernel
below takes ``tiles`` = ``(active, tile)``, or None for the whole range. Within a row the active
tiles are visited in increasing j, so the nodes are visited in the whole range's order and
every sum (damping work, reaction impulses) adds the same terms in the same order: results
are identical to the bit.
"""
import math

import numba as nb
from numba import types
from numba.extending import overload

__all__ = ["grid_update", "momentum_to_velocity", "mark_tiles", "zero_tiles", "span", "span_count"]


def span_count(tiles, j_lo, j_hi):
    """How many spans ``span`` cuts a row's [j_lo, j_hi) into: one for the whole range
    (``tiles`` None), else one per tile column the range meets."""
    if tiles is None:
        return 1
    return 0 if j_hi <= j_lo else (j_hi - 1) // tiles[1] - j_lo // tiles[1] + 1


def span(tiles, i, j_lo, j_hi, t):
    """Nodes [a, b) of row ``i`` to visit in its ``t``-th span: the whole range (``tiles``
    None), else the part of [j_lo, j_hi) in the t-th tile column it meets, empty when that
    tile is inactive."""
    if tiles is None:
        return j_lo, j_hi
    active, tile = tiles
    c = j_lo // tile + t
    if not active[i // tile, c]:
        return 0, 0
    return max(j_lo, c * tile), min(j_hi, (c + 1) * tile)


# the kernels call the two through these overloads: the choice between the whole range and the
# tiles is made when numba compiles a kernel for the type of ``tiles``, not per node
@overload(span_count, inline="always")
def _span_count_overload(tiles, j_lo, j_hi):
    if isinstance(tiles, types.NoneType):
        return lambda tiles, j_lo, j_hi: 1
    return span_count


@overload(span, inline="always")
def _span_overload(tiles, i, j_lo, j_hi, t):
    if isinstance(tiles, types.NoneType):
        return lambda tiles, i, j_lo, j_hi, t: (j_lo, j_hi)
    return span


@nb.njit(cache=True)
def grid_update(G, dt, mass_cutoff, bc_mask, bc_vel, i_lo, i_hi, j_lo, j_hi, damping, owned,
                reaction=None, tiles=None):
    """(mv) += f dt, then v = (mv)/m with the BCs imposed, over window rows [i_lo, i_hi) x
    [j_lo, j_hi). Afterwards fields 1, 2 hold the new velocity and 3, 4 the velocity change
    (what FLIP adds to the particles). Nodes lighter than ``mass_cutoff`` get no acceleration.

    ``damping`` (None: off) is the mass-proportional coefficient alpha: the nodal force gains
    -alpha m v. Returns the energy damping dissipated and the work of the support reactions
    (the impulses m (v_bc - v_free) that impose the BCs, times the prescribed velocity: exactly
    zero at fixed supports, a first-order estimate for moving ones),
    summed over the nodes in ``owned`` = (axis, lo, hi) (ghost nodes are summed by their owner).

    ``reaction`` (None: off, compiled out) is ``(ids, sums, x0, y0, h)``: ``ids`` (window
    shape x 2, int32) the reaction each node's component reports to (-1: none), ``sums`` (n, 3) to which the
    constraint impulses m (v_bc - v_free) of the owned nodes are added as (Jx, Jy, moment of
    J about the grid point (0, 0) of global coordinates), node (i, j) of the window lying at
    (x0 + i h, y0 + j h). Divided by the time over which they were summed they are the
    support reactions (pmpm.results.reactions).

    ``tiles`` (None: every node of the range) is ``(active, tile)``: only the nodes of active
    tiles are visited (the others are zero and stay so, see the module's docstring)."""
    dissipated = 0.0
    reactions = 0.0
    for i in range(i_lo, i_hi):
        for t in range(span_count(tiles, j_lo, j_hi)):
            j_a, j_b = span(tiles, i, j_lo, j_hi, t)
            for j in range(j_a, j_b):
                mi = G[i, j, 0]
                if mi <= 0.0:
                    for k in range(1, 5):
                        G[i, j, k] = 0.0
                    continue
                inv_m = 1.0 / mi
                # a node lighter than the cutoff keeps its velocity (a mass-weighted average of its
                # particles', always well defined) but gets no acceleration: f / m would be huge
                accelerate = mi > mass_cutoff
                for d in range(2):
                    v_old = G[i, j, 1 + d] * inv_m
                    v_new = v_old
                    if accelerate:
                        f = G[i, j, 3 + d]
                        if damping is not None:
                            f -= damping * G[i, j, 1 + d]
                        v_new = v_old + f * dt * inv_m
                    k = i if owned[0] == 0 else j
                    mine = owned[1] <= k < owned[2]
                    if bc_mask[i, j, d]:
                        v_free = v_new
                        v_new = bc_vel[i, j, d]
                        if mine:
                            # reaction impulse m (v_bc - v_free) times the support's own velocity:
                            # a support that does not move does no work
                            reactions += mi * (v_new - v_free) * v_new
                            if reaction is not None:
                                b = reaction[0][i, j, d]
                                if b >= 0:
                                    impulse = mi * (v_new - v_free)
                                    reaction[1][b, d] += impulse
                                    if d == 0:   # moment z of (Jx, 0) at (x, y): -y Jx
                                        reaction[1][b, 2] -= (reaction[3] + j * reaction[4]) * impulse
                                    else:        # moment z of (0, Jy): x Jy
                                        reaction[1][b, 2] += (reaction[2] + i * reaction[4]) * impulse
                    G[i, j, 1 + d] = v_new
                    G[i, j, 3 + d] = v_new - v_old
                    if damping is not None and mine and accelerate:
                        dissipated += damping * mi * v_old * 0.5 * (v_old + v_new) * dt
    return dissipated, reactions


@nb.njit(cache=True)
def momentum_to_velocity(G, src, dst, bc_mask, bc_vel, i_lo, i_hi, j_lo, j_hi, tiles=None):
    """v = (mv)/m from momentum fields ``src`` into fields ``dst`` (may be the same), with the
    BCs imposed (MUSL re-map; USF start-of-step velocity). No mass cutoff is needed here:
    a momentum over a mass is a weighted mean velocity, bounded however light the node.
    ``tiles`` as for ``grid_update`` (a prescribed node outside the active tiles keeps a zero
    velocity instead of its prescribed one: no particle reads it)."""
    for i in range(i_lo, i_hi):
        for t in range(span_count(tiles, j_lo, j_hi)):
            j_a, j_b = span(tiles, i, j_lo, j_hi, t)
            for j in range(j_a, j_b):
                mi = G[i, j, 0]
                for d in range(2):
                    if bc_mask[i, j, d]:
                        G[i, j, dst + d] = bc_vel[i, j, d]
                    elif mi <= 0.0:
                        G[i, j, dst + d] = 0.0
                    else:
                        G[i, j, dst + d] = G[i, j, src + d] / mi


@nb.njit(cache=True)
def zero_tiles(G, active, tile):
    """Zero every field of the nodes of the active tiles (the grid reset of step 1 when only
    those can hold anything)."""
    nx, ny = G.shape[0], G.shape[1]
    for ti in range(active.shape[0]):
        for tj in range(active.shape[1]):
            if active[ti, tj]:
                for i in range(ti * tile, min(nx, (ti + 1) * tile)):
                    for j in range(tj * tile, min(ny, (tj + 1) * tile)):
                        for k in range(G.shape[2]):
                            G[i, j, k] = 0.0


@nb.njit(cache=True)
def mark_tiles(x, origin, inv_h, ox, oy, nx, ny, reach, shift, active):
    """Set ``active`` for every tile (2**shift nodes a side) holding a node of some particle's
    stencil: with c the particle's cell along an axis (window-local), nodes c - reach + 1 ..
    c + reach (the B-splines' and GIMP's supports, ``reach`` = pmpm.core.shape.ghost_width),
    clipped to the window's ``nx`` x ``ny`` nodes. ``active`` is not cleared first. A particle
    in the same cell as the one before it (particles are sorted by cell) adds nothing."""
    last_x = last_y = -(1 << 62)
    for p in range(x.shape[0]):
        sx = (x[p, 0] - origin[0]) * inv_h
        sy = (x[p, 1] - origin[1]) * inv_h
        if not (abs(sx) < 1e15 and abs(sy) < 1e15):  # NaN or far away: the whole window
            active[:, :] = True
            return
        cx = int(math.floor(sx)) - ox
        cy = int(math.floor(sy)) - oy
        if cx == last_x and cy == last_y:
            continue
        last_x, last_y = cx, cy
        # shifts, not divisions: an integer division costs more than the rest of the loop
        for ti in range(max(cx - reach + 1, 0) >> shift, (min(cx + reach, nx - 1) >> shift) + 1):
            for tj in range(max(cy - reach + 1, 0) >> shift, (min(cy + reach, ny - 1) >> shift) + 1):
                active[ti, tj] = True


@nb.njit(cache=True)
def stress_power(stress, de, vol):
    """sum_p V_p sigma_p : de_p, the internal work of one half of a trapezoid step (called with
    the stress before and after the update, each weighted 1/2 by the caller)."""
    w = 0.0
    for p in range(stress.shape[0]):
        w += vol[p] * (stress[p, 0] * de[p, 0] + stress[p, 1] * de[p, 1] + stress[p, 2] * de[p, 2])
    return w


@nb.njit(cache=True)
def kinetic_energy(m, v):
    """sum_p 1/2 m_p |v_p|^2 without temporaries."""
    e = 0.0
    for p in range(m.shape[0]):
        e += m[p] * (v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1])
    return 0.5 * e


@nb.njit(cache=True)
def elastic_energy(stress, vol, E, nu, mat_ids, which):
    """sum_p V_p 1/2 sigma : C^-1 : sigma (isotropic C, 4-component stress) over the particles
    of material ``which`` (-1: all), without temporaries."""
    e = 0.0
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        sxx, syy, sxy, szz = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
        normal = sxx * sxx + syy * syy + szz * szz - 2 * nu * (sxx * syy + syy * szz + szz * sxx)
        e += vol[p] * (0.5 * normal / E + (1 + nu) / E * sxy * sxy)
    return e
