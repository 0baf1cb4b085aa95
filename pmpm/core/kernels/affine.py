"""APIC transfers of point particles (Jiang, Schroeder, Selle, Teran & Stomakhin 2015): each
particle carries, beside its velocity v_p, an affine velocity C_p (the 2 x 2 matrix
B_p D_p^-1 of the paper, 1/s), so the grid sees the velocity field v_p + C_p (x - x_p) around
it instead of a constant:

    p2g   (m v)_i = sum_p w_ip m_p (v_p + C_p (x_i - x_p))
    g2p   v_p = sum_i w_ip v_i,   B_p = sum_i w_ip v_i (x_i - x_p)^T,   C_p = B_p D_p^-1,
          D_p = sum_i w_ip (x_i - x_p)(x_i - x_p)^T

D_p is summed from the particle's own weights rather than taken as h^2/3 I (cubic) or h^2/4 I
(quadratic): the two agree inside the grid, and the sum stays exact next to the edges, where the
boundary-modified B-splines (pmpm/core/shape.py) change the weights; the conservation of angular
momentum rests on D_p being that sum. The weights are tensor products, so
D_xx = sum_a wx_a dx_a^2, D_yy = sum_b wy_b dy_b^2 and D_xy = (sum_a wx_a dx_a)(sum_b wy_b dy_b).

The velocity update is PIC's (no FLIP increment): APIC keeps the affine part of the field a
particle sees, which PIC loses every step, and none of FLIP's null-space noise. The MUSL re-map
scatters the new m_p (v_p + C_p (x_i - x_p)), and the strain increment is the point kernel's
(pmpm.core.kernels.transfer.g2p_kinematics).

Point particles only (the CPDI and GIMP kernels are transfer.py's); linear B-splines are
refused by the scene (their D_p vanishes when a particle sits on a node).
"""
import numba as nb

from pmpm.core.kernels.transfer import (block_buffers, block_start, particle_forces, scatter2, scatter_p2g,
                                        speed_check)
from pmpm.core.shape import BLOCK

__all__ = ["p2g_affine", "g2p_affine", "D_FLOOR", "affine_momentum", "affine_moments", "gather_affine",
           "affine_matrix", "cell_position", "store_velocity_update"]

#: det D_p (cells^4) below which a particle keeps no affine velocity: D_p vanishes on a grid edge
#: (1e-12: D_xx ~ s^2 within s cells of the edge, so particles closer than ~1e-6 cells)
D_FLOOR = 1e-12


@nb.njit(cache=True, inline="always")
def cell_position(x, p, origin, inv_h):
    """Particle p's position in cells from the grid origin (sx, sy)."""
    return (x[p, 0] - origin[0]) * inv_h, (x[p, 1] - origin[1]) * inv_h


@nb.njit(cache=True, inline="always")
def affine_momentum(p, x, m, C, origin, inv_h, h):
    """(m_p, affine): particle p's mass and the affine part of its momentum for
    pmpm.core.kernels.transfer.scatter_p2g, m C in momentum per cell of offset with its
    position in cells (kxx, kxy, kyx, kyy, sx, sy)."""
    mp = m[p]
    sx, sy = cell_position(x, p, origin, inv_h)
    return mp, (mp * C[p, 0] * h, mp * C[p, 1] * h, mp * C[p, 2] * h, mp * C[p, 3] * h, sx, sy)


@nb.njit(cache=True, inline="always")
def _moments_1d(first, W, q, K, s):
    """(sum_a w_a d_a, sum_a w_a d_a^2) along one axis, d_a = first + a - s (cells)."""
    mean = 0.0
    second = 0.0
    for a in range(K):
        d = first + a - s
        mean += W[a, q] * d
        second += W[a, q] * d * d
    return mean, second


@nb.njit(cache=True, inline="always")
def affine_moments(q, K, I0, J0, WX, WY, sx, sy):
    """D_p = sum_i N_i (x_i - x_p)(x_i - x_p)^T of particle q in cells^2, (D_xx, D_yy, D_xy),
    from the 1-D weights (each axis' weights sum to 1, so D_xy is the product of the means)."""
    mx, dxx = _moments_1d(I0[q], WX, q, K, sx)
    my, dyy = _moments_1d(J0[q], WY, q, K, sy)
    return dxx, dyy, mx * my


@nb.njit(cache=True, inline="always")
def gather_affine(G, f, q, K, I0, J0, WX, WY, ox, oy, sx, sy):
    """v_p = sum_i N_i v_i and B_p = sum_i N_i v_i (x_i - x_p)^T (cells) of particle q, v the
    grid vector in fields f, f + 1: (vx, vy, bxx, bxy, byx, byy)."""
    vx = 0.0
    vy = 0.0
    bxx = 0.0
    bxy = 0.0
    byx = 0.0
    byy = 0.0
    i0 = I0[q]   # in registers: the loop writes G, which the compiler cannot tell from I0
    j0 = J0[q]
    for a in range(K):
        ii = i0 + a - ox
        wa = WX[a, q]
        ddx = i0 + a - sx
        for b in range(K):
            jj = j0 + b - oy
            w = wa * WY[b, q]
            ddy = j0 + b - sy
            gvx = w * G[ii, jj, f]
            gvy = w * G[ii, jj, f + 1]
            vx += gvx
            vy += gvy
            bxx += gvx * ddx
            bxy += gvx * ddy
            byx += gvy * ddx
            byy += gvy * ddy
    return vx, vy, bxx, bxy, byx, byy


@nb.njit(cache=True, inline="always")
def affine_matrix(bxx, bxy, byx, byy, dxx, dyy, dxy, scale):
    """C = B D^-1 times ``scale`` (inv_h: per metre). D is symmetric positive definite except
    for a particle on the grid's edge, whose edge node takes all its weight along that axis
    (D_xx or D_yy = 0): it sees no affine field and keeps none (PIC there)."""
    det = dxx * dyy - dxy * dxy
    r = scale / det if det > D_FLOOR else 0.0
    return ((bxx * dyy - bxy * dxy) * r, (bxy * dxx - bxx * dxy) * r,
            (byx * dyy - byy * dxy) * r, (byy * dxx - byx * dxy) * r)


@nb.njit(cache=True, inline="always")
def store_velocity_update(p, v, C, dx, dt, vx, vy, cxx, cxy, cyx, cyy, vmax2, bad):
    """Particle p's new velocity and affine matrix into ``v`` and ``C``, its move dt v into
    ``dx`` (None: not kept, the caller moves the particle itself); returns the running largest
    squared speed and count of non-finite particles."""
    C[p, 0] = cxx
    C[p, 1] = cxy
    C[p, 2] = cyx
    C[p, 3] = cyy
    if dx is not None:
        dx[p, 0] = dt * vx
        dx[p, 1] = dt * vy
    v[p, 0] = vx
    v[p, 1] = vy
    vmax2, bad = speed_check(vx, vy, vmax2, bad)
    if not abs(cxx) + abs(cxy) + abs(cyx) + abs(cyy) < 1e300:
        bad += 1
    return vmax2, bad


@nb.njit(cache=True)
def p2g_affine(x, m, v, C, vol, stress, gravity, load_id, load_w, load_vec,
               G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Scatter mass, the APIC momentum m (v + C (x_i - x_p)) (``C`` (N, 4): Cxx, Cxy, Cyx, Cyy
    in 1/s), the internal force (``stress`` not None) and the external force into ``G``, as
    pmpm.core.kernels.transfer.p2g with ``v`` given."""
    with_force = stress is not None or gravity is not None or load_id is not None
    K, B, I0, J0, WX, WY = block_buffers(shape)
    h = 1.0 / inv_h
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            mp, affine = affine_momentum(p, x, m, C, origin, inv_h, h)
            fx, fy, sxx, syy, sxy = particle_forces(p, m, vol, stress, gravity, load_id, load_w, load_vec, inv_h)
            scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, True, mp, mp * v[p, 0], mp * v[p, 1], affine,
                        with_force, fx, fy, stress is not None, sxx, syy, sxy, None)


@nb.njit(cache=True)
def g2p_affine(x, m, v, C, G, ox, oy, origin, inv_h, ncx, ncy, shape, remap, dx, dt):
    """APIC velocity update from the grid velocities in fields 1, 2: v_p = sum w v_i and
    C_p = B_p D_p^-1 (1/s, into ``C``); ``dx`` receives dt v_p (the move, eq. 5); with
    ``remap`` the new APIC momenta go into fields 5, 6 (MUSL). Returns the largest particle
    speed and the number of particles whose new velocity or affine matrix is not finite."""
    vmax2 = 0.0
    bad = 0
    K, B, I0, J0, WX, WY = block_buffers(shape)
    h = 1.0 / inv_h
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            sx, sy = cell_position(x, p, origin, inv_h)
            dxx, dyy, dxy = affine_moments(q, K, I0, J0, WX, WY, sx, sy)
            vx, vy, bxx, bxy, byx, byy = gather_affine(G, 1, q, K, I0, J0, WX, WY, ox, oy, sx, sy)
            cxx, cxy, cyx, cyy = affine_matrix(bxx, bxy, byx, byy, dxx, dyy, dxy, inv_h)
            vmax2, bad = store_velocity_update(p, v, C, dx, dt, vx, vy, cxx, cxy, cyx, cyy, vmax2, bad)
            if remap:
                mp = m[p]
                scatter2(G, 5, q, K, I0, J0, WX, WY, ox, oy, mp * vx, mp * vy,
                         (mp * cxx * h, mp * cxy * h, mp * cyx * h, mp * cyy * h, sx, sy))
    return vmax2 ** 0.5, bad
