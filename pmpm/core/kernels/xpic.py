"""The grid-particle-grid smoothing of XPIC(m) (Hammerquist & Nairn 2017), for point particles.

XPIC(m) replaces PIC's velocity update v_p = S_p v^L by v_p = S_p (v^L - v^n + v*), where v^n
is the grid velocity the particles mapped at the step's start and

    v* = sum_{k=1..m} (-1)^(k+1) C(m, k) M^(k-1) v^n,    M u = S^+ S u,

M mapping a grid field to the particles and back, mass-weighted: (M u)_i = sum_p S_ip m_p
(sum_j S_jp u_j) / m_i. In terms of the particle-grid-particle map P = S S^+ the update
removes (I - P)^m v_p from the particle velocities, where PIC (m = 1) removes (I - P) v_p:
the null-space noise (P's eigenvalue 0) goes as with PIC, the modes the grid resolves
(eigenvalues near 1) lose (1 - lambda)^m of their velocity instead of (1 - lambda).
This module holds the particle pass of one application of M; the grid side (the halo sum,
the division by the mass, the boundary values) is pmpm.core.transfers.XPIC's.
"""
import numba as nb

from pmpm.core.kernels.transfer import block_buffers, block_start, gather2, scatter2
from pmpm.core.shape import BLOCK

__all__ = ["grid_particle_grid"]


@nb.njit(cache=True)
def grid_particle_grid(x, m, U, out, ox, oy, origin, inv_h, ncx, ncy, shape):
    """out_i += sum_p S_ip m_p (sum_j S_jp U_j): the momentum of the grid field ``U``
    (window nodes x 2, m/s) interpolated to the particles and scattered back (``out``: window
    nodes x 2, kg m/s; divided by the nodal mass it is M U)."""
    K, B, I0, J0, WX, WY = block_buffers(shape)
    for p0 in range(0, x.shape[0], BLOCK):
        nq = block_start(x, p0, origin, inv_h, ncx, ncy, shape, B)
        for q in range(nq):
            p = p0 + q
            ux, uy = gather2(U, 0, q, K, I0, J0, WX, WY, ox, oy)
            scatter2(out, 0, q, K, I0, J0, WX, WY, ox, oy, m[p] * ux, m[p] * uy, None)
