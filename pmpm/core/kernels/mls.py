"""MLS-MPM transfers of point particles (Hu, Fang, Ge, Qu, Zhu, Pradhana & Jiang 2018).

One particle-to-grid pass scatters mass, the APIC momentum and the force of the stress
together, one grid-to-particle pass gathers the velocity and the affine matrix C_p and takes
the strain increment from it (the velocity gradient is C_p itself):

    p2g   m_i = sum_p N_ip m_p,   (m v)_i = sum_p N_ip m_p (v_p + C_p (x_i - x_p)),
          f_i = sum_p -V_p sigma_p g_ip + N_ip f_ext,p,
    g2p   v_p = sum_i N_ip v_i,   C_p = sum_i v_i g_ip^T,   d_eps = dt sym C_p, F <- (I + dt C_p) F

with the MLS gradient g_ip = N_ip D_p^-1 (x_i - x_p), D_p = sum_i N_ip (x_i - x_p)(x_i - x_p)^T,
for quadratic and cubic B-splines (so C_p = B_p D_p^-1, APIC's matrix; D_p is the particle's own
sum, exact next to the grid's edges where the boundary-modified B-splines change the weights).
With linear B-splines D_p vanishes when a particle sits on a node, and N_ip D_p^-1 (x_i - x_p)
equals the B-spline gradient wherever D_p is regular (D_xx = f (1 - f) h^2 along an axis, at
fraction f of its cell): the kernels take the gradient itself there.

The force's torque about any point vanishes for a symmetric stress
(sum_i (x_i - x_p) (x) g_ip = I), so with the affine momentum the transfers conserve angular
momentum. The linear kernels' loops are pmpm.core.kernels.transfer's (``scatter_p2g``,
``gather2``, ``gather_gradient``); the quadratic and cubic ones are this module's, written for
speed (docs/performance.md, "The MLS step made faster"): D_p^-1 is the B-spline's constant
wherever the support is not boundary-modified (``_inverse_moments``), the gather sums by rows,
the scatter indexes a flat view of the grid, and both kernels let the compiler fuse multiplies
and adds (FMA; no fast-math assumption about NaN or infinity, so the non-finite checks hold).
The position update x += dx, the step-end count of strays and the first half of the internal
work are folded into the G2P when the scheme asks (``g2p_mls``'s last arguments), and so is
the stress update where the material hands it as one linear map (``stress_map``: a matrix,
so this module knows no material law and imports nothing of pmpm.physics).
"""
import math

import numba as nb
import numpy as np

from pmpm.core.kernels.affine import (D_FLOOR, affine_moments, affine_momentum, cell_position,
                                      store_velocity_update)
from pmpm.core.kernels.locate import stray
from pmpm.core.kernels.transfer import (_external_force, block_buffers, block_start, gather2, gather_gradient, move,
                                        particle_forces, scatter_p2g, strain_increment)
from pmpm.core.shape import _HUGE, BLOCK, _put, cubic, quadratic

__all__ = ["p2g_mls", "g2p_mls"]


@nb.njit(cache=True, inline="always")
def _axis_weights(x, p0, nq, axis, origin, inv_h, n, K, start, W):
    """The quadratic (K = 3) or cubic (K = 4) B-spline weights of the block's coordinates
    along ``axis`` into W[0 .. K-1] and their first nodes into ``start``: pmpm.core.shape's
    block kernels (_quadratic_block, _cubic_block; the same expressions, so the same floats)
    without the derivatives the MLS transfers do not read, the coordinates taken in the same
    loop, and the test for a support reaching a ghost node (or a non-finite coordinate) or'ed
    over the block in that loop, so that the scalar pass that owns the boundary modification
    (shape.quadratic, shape.cubic) runs only for a block that has one (measured: 5.9 against
    6.9 ns a particle and pass)."""
    edge = False
    for q in range(nq):
        s = (x[p0 + q, axis] - origin) * inv_h
        if K == 3:
            c = math.floor(s + 0.5)
            f = s - c
            a = 0.5 - f
            b = 0.5 + f
            W[0, q] = 0.5 * a * a
            W[1, q] = 0.75 - f * f
            W[2, q] = 0.5 * b * b
        else:
            c = math.floor(s)
            f = s - c
            e = 1.0 - f
            f2 = f * f
            f3 = f2 * f
            W[0, q] = e * e * e * (1.0 / 6.0)
            W[1, q] = 0.5 * f3 - f2 + 2.0 / 3.0
            W[2, q] = (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) * (1.0 / 6.0)
            W[3, q] = f3 * (1.0 / 6.0)
        start[q] = np.int64(c) - 1
        # start < 0 or start + K - 1 > n, in floats (c is a whole number), or not finite
        edge |= (c < 1.0) | (c + (K - 2) > n) | (not abs(s) < _HUGE)
    if edge:
        for q in range(nq):
            s = (x[p0 + q, axis] - origin) * inv_h
            if start[q] < 0 or start[q] + (K - 1) > n or not abs(s) < _HUGE:
                if K == 3:
                    i3, w3, g3 = quadratic(s, n)
                    _put(W, q, start, i3, w3, g3)
                else:
                    i4, w4, g4 = cubic(s, n)
                    _put(W, q, start, i4, w4, g4)


@nb.njit(cache=True, inline="always")
def _block_start(x, p0, origin, inv_h, ncx, ncy, shape, K, B, I0, J0, WX, WY):
    """The block of particles from p0: its weights evaluated (quadratic, cubic: ``_axis_weights``;
    linear: pmpm.core.kernels.transfer.block_start); returns its particle count."""
    if K == 2:
        return block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
    nq = min(BLOCK, x.shape[0] - p0)
    _axis_weights(x, p0, nq, 0, origin[0], inv_h, ncx, K, I0, WX)
    _axis_weights(x, p0, nq, 1, origin[1], inv_h, ncy, K, J0, WY)
    return nq


@nb.njit(cache=True, inline="always")
def _scatter_mls(Gf, nf, row, q, K, I0, J0, WX, WY, ox, oy, sx, sy, mp, mvx, mvy, k, force, fx, fy, A):
    """Particle q's MLS scatter (quadratic, cubic): node (i0 + a, j0 + b), at (ex_a, ey_b) =
    (i0 + a - sx, j0 + b - sy) cells from the particle, gets w_a w_b times m, m v + k (ex_a, ey_b)
    (``k`` = (kxx, kxy, kyx, kyy) of pmpm.core.kernels.affine.affine_momentum) and, with
    ``force``, f_ext + A (ex_a, ey_b) into fields 0 .. 4. ``Gf`` is the grid's fields
    flattened (``nf`` fields a node, ``row`` = nodes per window row times nf): one unsigned
    index per node, where G[ii, jj, f] cost each access the negative-index wraparound of three
    indices (the same sums to the bit)."""
    i0 = I0[q]   # in registers: the loop writes G, which the compiler cannot tell from I0
    j0 = J0[q]
    base = np.uint64((i0 - ox) * row + (j0 - oy) * nf)   # node (i0, j0)'s first field
    for a in range(K):
        wa = WX[a, q]
        ex = i0 + a - sx
        for b in range(K):
            n = base + np.uint64(a * row + b * nf)
            w = wa * WY[b, q]
            ey = j0 + b - sy
            Gf[n] += w * mp
            Gf[n + np.uint64(1)] += w * (mvx + k[0] * ex + k[1] * ey)
            Gf[n + np.uint64(2)] += w * (mvy + k[2] * ex + k[3] * ey)
            if force:
                Gf[n + np.uint64(3)] += w * (fx + A[0] * ex + A[1] * ey)
                Gf[n + np.uint64(4)] += w * (fy + A[2] * ex + A[3] * ey)


@nb.njit(cache=True, inline="always")
def _gather_mls(G, q, K, I0, J0, WX, WY, ox, oy, sx, sy):
    """v_p = sum_i N_i v_i and B_p = sum_i N_i v_i (x_i - x_p)^T (cells) of particle q, v the
    grid velocity in fields 1, 2: (vx, vy, bxx, bxy, byx, byy), as
    pmpm.core.kernels.affine.gather_affine, summed by rows: per row a the sums r = sum_b w_b v
    and t = sum_b w_b ey_b v, then v_p = sum_a w_a r, B_p = sum_a (w_a ex_a r, w_a t): four
    multiply-adds per node instead of eight (the sums differ in round-off only)."""
    vx = 0.0
    vy = 0.0
    bxx = 0.0
    bxy = 0.0
    byx = 0.0
    byy = 0.0
    i0 = I0[q]
    j0 = J0[q]
    for a in range(K):
        ii = i0 + a - ox
        rx = 0.0
        ry = 0.0
        tx = 0.0
        ty = 0.0
        for b in range(K):
            jj = j0 + b - oy
            wb = WY[b, q]
            wy = wb * (j0 + b - sy)
            gx = G[ii, jj, 1]
            gy = G[ii, jj, 2]
            rx += wb * gx
            ry += wb * gy
            tx += wy * gx
            ty += wy * gy
        wa = WX[a, q]
        wx = wa * (i0 + a - sx)
        vx += wa * rx
        vy += wa * ry
        bxx += wx * rx
        byx += wx * ry
        bxy += wa * tx
        byy += wa * ty
    return vx, vy, bxx, bxy, byx, byy


@nb.njit(cache=True, inline="always")
def _inside(s, K, n):
    """Whether the B-spline support of coordinate ``s`` (cells) on an axis of ``n`` cells is
    the plain one, not boundary-modified: the first node as pmpm.core.shape's block kernels
    find it (the same expressions, so the two agree on every float), its K nodes within
    0 .. n. False for a non-finite s."""
    c = math.floor(s + 0.5) if K == 3 else math.floor(s)
    return c - 1 >= 0 and c + K - 2 <= n


@nb.njit(cache=True, inline="always")
def _inverse_moments(q, K, I0, J0, WX, WY, sx, sy, ncx, ncy):
    """D_p^-1 of particle q in 1/cells^2, (ixx, ixy, iyy). Where the particle's support lies
    inside the grid (the B-splines not boundary-modified: pmpm.core.shape's block kernels)
    D_p is the B-spline's variance times I, 1/4 (quadratic) or 1/3 (cubic) cells^2, and its
    inverse is taken as that constant (the sum of the weights gives it to round-off, at the
    cost of a pass over the weights and a division per particle); next to the grid's edges
    D_p is summed from the particle's weights. A particle on the edge (D_p singular) gets
    zero: it exerts no stress force and keeps no affine velocity (APIC's rule)."""
    if _inside(sx, K, ncx) and _inside(sy, K, ncy):
        c = 4.0 if K == 3 else 3.0
        return c, 0.0, c
    dxx, dyy, dxy = affine_moments(q, K, I0, J0, WX, WY, sx, sy)
    det = dxx * dyy - dxy * dxy
    r = 1.0 / det if det > D_FLOOR else 0.0
    return dyy * r, -dxy * r, dxx * r


@nb.njit(cache=True, inline="always")
def _apply_stress_map(p, stress, e0, e1, e2, vol, D):
    """stress_p += D de_p, de_p = (e0, e1, e2) (``D`` the 12 entries of the (4, 3) map row by
    row, xx, yy, xy, zz from exx, eyy, gxy); returns V_p sigma_p : de_p with the new stress
    (the second half of the trapezoid internal work, pmpm.core.kernels.grid_ops.stress_power's
    terms)."""
    s0 = stress[p, 0] + (D[0] * e0 + D[1] * e1 + D[2] * e2)
    s1 = stress[p, 1] + (D[3] * e0 + D[4] * e1 + D[5] * e2)
    s2 = stress[p, 2] + (D[6] * e0 + D[7] * e1 + D[8] * e2)
    stress[p, 3] += D[9] * e0 + D[10] * e1 + D[11] * e2
    stress[p, 0] = s0
    stress[p, 1] = s1
    stress[p, 2] = s2
    return vol[p] * (s0 * e0 + s1 * e1 + s2 * e2)


@nb.njit(cache=True, inline="always")
def _settled(x, vol, p, origin, inv_h, ncx, ncy, owned):
    """Whether particle p is none of what pmpm.core.kernels.locate.stray counts: inside the
    grid, in the owned cell columns [c0, c1) of ``owned`` = (axis, c0, c1) and with a positive
    volume; False for a non-finite position. Float
    comparisons without branches (c0 <= s < c1 is c0 <= floor(s) < c1 for integers c0, c1),
    and'ed over a block: the G2P redoes the exact count (``stray``) only for a block where one
    particle is not settled (measured: 0.8 ns a particle less than ``stray`` for each)."""
    sx = (x[p, 0] - origin[0]) * inv_h
    sy = (x[p, 1] - origin[1]) * inv_h
    s, ns, t, nt = (sx, ncx, sy, ncy) if owned[0] == 0 else (sy, ncy, sx, ncx)
    return (max(owned[1], 0) <= s) & (s < min(owned[2], ns)) & (0.0 <= t) & (t < nt) & (vol[p] > 0.0)


@nb.njit(cache=True, inline="always")
def _move_by(p, x, ux, uy, m, gravity):
    """x_p += (ux, uy); returns the body force's work over the move (pmpm.core.kernels.transfer.
    move with the move in registers, not in an array)."""
    x[p, 0] += ux
    x[p, 1] += uy
    fx, fy = _external_force(p, m, gravity, None, None, None)
    return fx * ux + fy * uy


@nb.njit(cache=True, fastmath={"contract"})
def p2g_mls(x, m, v, C, vol, stress, gravity, load_id, load_w, load_vec,
            G, ox, oy, origin, inv_h, ncx, ncy, shape, impulse_dt=None):
    """Scatter mass, the APIC momentum m (v + C (x_i - x_p)) (``C`` (N, 4) in 1/s), the
    internal force -V sigma g_ip (MLS gradient; ``stress`` not None) and the external force
    N_ip f_ext into fields 0 .. 4 of ``G``.

    ``impulse_dt`` (the step's dt; None: not) scatters, with quadratic and cubic B-splines,
    the momentum and the force's impulse together, m v + dt f, into fields 1, 2 (fields 3, 4
    get nothing): Hu et al.'s P2G, three fields a node instead of five. The grid update's
    (m v + dt f) / m is then the same sum; what differs is a node lighter than the mass
    cutoff, which gets its particles' impulse (a weighted mean of their impulse over mass,
    bounded as their velocities are) where the separate force is held back. Linear B-splines
    scatter the force apart either way."""
    with_force = stress is not None or gravity is not None or load_id is not None
    K, B, I0, J0, WX, WY = block_buffers(shape)
    h = 1.0 / inv_h
    nf = G.shape[2]
    row = G.shape[1] * nf
    Gf = G.reshape(-1)   # a view (the window is C-contiguous): the scatter's flat node index
    for p0 in range(0, x.shape[0], BLOCK):
        nq = _block_start(x, p0, origin, inv_h, ncx, ncy, shape, K, B, I0, J0, WX, WY)
        for q in range(nq):
            p = np.uint64(p0 + q)   # unsigned: no negative-index wraparound in the many particle-array accesses
            mp, affine = affine_momentum(p, x, m, C, origin, inv_h, h)
            sx, sy = affine[4], affine[5]
            fx, fy, sxx, syy, sxy = particle_forces(p, m, vol, stress, gravity, load_id, load_w, load_vec, inv_h)
            if K == 2:   # linear: the B-spline gradient (the MLS gradient's value, defined on nodes)
                scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, True, mp, mp * v[p, 0], mp * v[p, 1], affine,
                            with_force, fx, fy, stress is not None, sxx, syy, sxy, None)
            else:
                ixx, ixy, iyy = _inverse_moments(q, K, I0, J0, WX, WY, sx, sy, ncx, ncy)
                # A = (-V sigma / h) D^-1: the force N_i A (x_i - x_p), the form of the momentum's
                A = (sxx * ixx + sxy * ixy, sxx * ixy + sxy * iyy, sxy * ixx + syy * ixy, sxy * ixy + syy * iyy)
                if impulse_dt is not None and with_force:   # m v + dt f into the momentum's fields
                    dt = impulse_dt
                    _scatter_mls(Gf, nf, row, q, K, I0, J0, WX, WY, ox, oy, sx, sy, mp,
                                 mp * v[p, 0] + dt * fx, mp * v[p, 1] + dt * fy,
                                 (affine[0] + dt * A[0], affine[1] + dt * A[1],
                                  affine[2] + dt * A[2], affine[3] + dt * A[3]), False, 0.0, 0.0, A)
                else:
                    _scatter_mls(Gf, nf, row, q, K, I0, J0, WX, WY, ox, oy, sx, sy, mp, mp * v[p, 0], mp * v[p, 1],
                                 affine, with_force, fx, fy, A)


@nb.njit(cache=True, fastmath={"contract"})
def g2p_mls(x, v, C, G, ox, oy, origin, inv_h, ncx, ncy, shape, dx, dt,
            strain, de, dw, F, vol, vol0, dq, m=None, gravity=None, stress=None, owned=None, stress_map=None):
    """v_p = sum N_ip v_i and C_p = sum v_i g_ip^T (1/s, into ``C``) from the grid velocities
    in fields 1, 2; ``dx`` receives dt v_p; the strain increment dt sym C_p into ``de``, its
    spin into ``dw``, ``strain``, the volume and F (``F``, ``vol0``, ``dq`` as
    pmpm.core.kernels.transfer.strain_increment's). ``dx`` and ``de`` may be None (not kept:
    two arrays fewer to write) where nothing reads them after the pass: ``dx`` with the move
    folded in (``m`` given), ``de`` with the stress map applied here (``stress_map``).

    The step's particle passes after the G2P, in the same pass when asked (``None``: not,
    compiled out; the scheme asks when nothing acts between them, pmpm.core.mls):

    * ``m`` given: the move x += dx with the work of the body force ``gravity`` (None: none)
      over it (pmpm.core.kernels.transfer.move), and the particle's place after it counted as
      pmpm.core.kernels.locate.count_strays counts it, ``owned`` = (axis, c0, c1) the owned
      cell columns (the particle's x is read for its
      weights before it moves; a block whose particles all stay settled is not counted
      particle by particle, ``_settled``);
    * ``stress`` given: the first half of the step's trapezoid internal work, sum_p V_p
      sigma_p : de_p with the stress before its update and the new volume
      (pmpm.core.kernels.grid_ops.stress_power, as the solver's update_stress takes it);
    * ``stress_map`` given (with ``stress``): the material's stress update, when it is one
      constant linear map d(sxx, syy, sxy, szz) = D d(exx, eyy, gxy) for every particle
      (pmpm.physics's Material.increment_matrix; the 12 entries of D row by row: the core
      applies a matrix the material hands it and knows no material law), and the second half
      of the internal work with the new stress. What the Taichi programs do in their G2P (Hu
      et al.'s G2P with the constitutive update): the materials' own pass over the particles,
      which reads the stress and the increment again, is left out.

    Returns (largest particle speed, number of particles whose velocity or C is not finite,
    work of the body force over the moves, the stress power sum, outside, leaving, inverted,
    the stress power sum after the update); the last six are 0 for a part not asked."""
    vmax2 = 0.0
    bad = 0
    work = 0.0
    power = 0.0
    outside = 0
    leaving = 0
    inverted = 0
    power_after = 0.0
    K, B, I0, J0, WX, WY = block_buffers(shape)
    for p0 in range(0, x.shape[0], BLOCK):
        nq = _block_start(x, p0, origin, inv_h, ncx, ncy, shape, K, B, I0, J0, WX, WY)
        fine = True   # every particle of the block moved to a place count_strays does not count
        for q in range(nq):
            p = np.uint64(p0 + q)   # unsigned: no negative-index wraparound in the many particle-array accesses
            if K == 2:
                vx, vy = gather2(G, 1, q, K, I0, J0, WX, WY, ox, oy)
                lxx, lxy, lyx, lyy = gather_gradient(G, 1, q, K, I0, J0, WX, WY, ox, oy)
                cxx = lxx * inv_h
                cxy = lxy * inv_h
                cyx = lyx * inv_h
                cyy = lyy * inv_h
            else:
                sx, sy = cell_position(x, p, origin, inv_h)
                ixx, ixy, iyy = _inverse_moments(q, K, I0, J0, WX, WY, sx, sy, ncx, ncy)
                vx, vy, bxx, bxy, byx, byy = _gather_mls(G, q, K, I0, J0, WX, WY, ox, oy, sx, sy)
                # C = B D^-1 / h
                cxx = (bxx * ixx + bxy * ixy) * inv_h
                cxy = (bxx * ixy + bxy * iyy) * inv_h
                cyx = (byx * ixx + byy * ixy) * inv_h
                cyy = (byx * ixy + byy * iyy) * inv_h
            vmax2, bad = store_velocity_update(p, v, C, dx, dt, vx, vy, cxx, cxy, cyx, cyy, vmax2, bad)
            strain_increment(p, dt, cxx, cxy, cyx, cyy, de, dw, strain, vol, F, vol0, dq)
            if stress is not None:
                # the increment as strain_increment computes it (the same expressions), from registers
                e0 = dt * cxx
                e1 = dt * cyy
                e2 = dt * (cxy + cyx)
                power += vol[p] * (stress[p, 0] * e0 + stress[p, 1] * e1 + stress[p, 2] * e2)
                if stress_map is not None:
                    power_after += _apply_stress_map(p, stress, e0, e1, e2, vol, stress_map)
            if m is not None:
                if dx is None:   # the move not kept: x += dt v_p directly (move's expressions)
                    work += _move_by(p, x, dt * vx, dt * vy, m, gravity)
                else:
                    work += move(p, x, dx, m, gravity, None, None, None)
                fine &= _settled(x, vol, p, origin, inv_h, ncx, ncy, owned)
        if m is not None and not fine:   # a particle of the block strayed: the block's counts exactly
            for q in range(nq):
                o, lv, inv = stray(x, vol, np.uint64(p0 + q), origin, inv_h, ncx, ncy, owned[0], owned[1], owned[2])
                outside += o
                leaving += lv
                inverted += inv
    return vmax2 ** 0.5, bad, work, power, outside, leaving, inverted, power_after
