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
momentum. The loops are pmpm.core.kernels.transfer's (``scatter_p2g``, ``gather2``,
``gather_gradient``) and the APIC module's (``affine_moments``, ``gather_affine``,
``affine_matrix``). The position update x += dx and the stress update are the step's later
passes (no grid visit).
"""
import numba as nb

from pmpm.core.kernels.affine import (D_FLOOR, affine_matrix, affine_moments, affine_momentum, cell_position,
                                      gather_affine, store_velocity_update)
from pmpm.core.kernels.transfer import (block_buffers, block_start, gather2, gather_gradient, particle_forces,
                                        scatter_p2g, strain_increment)
from pmpm.core.shape import BLOCK

__all__ = ["p2g_mls", "g2p_mls"]


@nb.njit(cache=True)
def p2g_mls(x, m, v, C, vol, stress, gravity, load_id, load_w, load_vec,
            G, ox, oy, origin, inv_h, ncx, ncy, shape):
    """Scatter mass, the APIC momentum m (v + C (x_i - x_p)) (``C`` (N, 4) in 1/s), the
    internal force -V sigma g_ip (MLS gradient; ``stress`` not None) and the external force
    N_ip f_ext into fields 0 .. 4 of ``G``."""
    with_force = stress is not None or gravity is not None or load_id is not None
    K, B, I0, J0, WX, WY = block_buffers(shape)
    h = 1.0 / inv_h
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            mp, affine = affine_momentum(p, x, m, C, origin, inv_h, h)
            sx, sy = affine[4], affine[5]
            fx, fy, sxx, syy, sxy = particle_forces(p, m, vol, stress, gravity, load_id, load_w, load_vec, inv_h)
            if K == 2:   # linear: the B-spline gradient (the MLS gradient's value, defined on nodes)
                scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, True, mp, mp * v[p, 0], mp * v[p, 1], affine,
                            with_force, fx, fy, stress is not None, sxx, syy, sxy, None)
            else:
                dxx, dyy, dxy = affine_moments(q, K, I0, J0, WX, WY, sx, sy)
                det = dxx * dyy - dxy * dxy
                # D^-1 in 1/cells^2; a particle on the grid's edge (D singular) exerts no stress
                # force (APIC keeps no affine velocity there either)
                r = 1.0 / det if det > D_FLOOR else 0.0
                ixx = dyy * r
                ixy = -dxy * r
                iyy = dxx * r
                # A = (-V sigma / h) D^-1: the force N_i A (x_i - x_p), the form of the momentum's
                scatter_p2g(G, q, K, I0, J0, WX, WY, ox, oy, True, mp, mp * v[p, 0], mp * v[p, 1], affine,
                            with_force, fx, fy, stress is not None, 0.0, 0.0, 0.0,
                            (sxx * ixx + sxy * ixy, sxx * ixy + sxy * iyy,
                             sxy * ixx + syy * ixy, sxy * ixy + syy * iyy))


@nb.njit(cache=True)
def g2p_mls(x, v, C, G, ox, oy, origin, inv_h, ncx, ncy, shape, dx, dt,
            strain, de, dw, F, vol, vol0, dq):
    """v_p = sum N_ip v_i and C_p = sum v_i g_ip^T (1/s, into ``C``) from the grid velocities
    in fields 1, 2; ``dx`` receives dt v_p (the move, applied later); the strain increment
    dt sym C_p into ``de``, its spin into ``dw``, ``strain``, the volume and F (``F``, ``vol0``,
    ``dq`` as pmpm.core.kernels.transfer.strain_increment's). Returns the largest particle speed
    and the number of particles whose velocity or C is not finite."""
    vmax2 = 0.0
    bad = 0
    K, B, I0, J0, WX, WY = block_buffers(shape)
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            if K == 2:
                vx, vy = gather2(G, 1, q, K, I0, J0, WX, WY, ox, oy)
                lxx, lxy, lyx, lyy = gather_gradient(G, 1, q, K, I0, J0, WX, WY, ox, oy)
                cxx = lxx * inv_h
                cxy = lxy * inv_h
                cyx = lyx * inv_h
                cyy = lyy * inv_h
            else:
                sx, sy = cell_position(x, p, origin, inv_h)
                dxx, dyy, dxy = affine_moments(q, K, I0, J0, WX, WY, sx, sy)
                vx, vy, bxx, bxy, byx, byy = gather_affine(G, 1, q, K, I0, J0, WX, WY, ox, oy, sx, sy)
                cxx, cxy, cyx, cyy = affine_matrix(bxx, bxy, byx, byy, dxx, dyy, dxy, inv_h)
            vmax2, bad = store_velocity_update(p, v, C, dx, dt, vx, vy, cxx, cxy, cyx, cyy, vmax2, bad)
            strain_increment(p, dt, cxx, cxy, cyx, cyy, de, dw, strain, vol, F, vol0, dq)
    return vmax2 ** 0.5, bad
