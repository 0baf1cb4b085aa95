"""Plain NumPy twins of the MLS-MPM kernels (pmpm.core.kernels.mls), written from the equations
of Hu et al. 2018 on the whole grid's shape-function matrix (pmpm.core.kernels.reference)."""
import numpy as np

from pmpm.core.kernels.reference import basis_matrix
from pmpm.core.kernels.reference_affine import node_offsets

__all__ = ["mls_gradient", "mls_p2g_reference", "mls_g2p_reference"]


def mls_gradient(order, x, origin, h, cells):
    """N (P, nx, ny) and the MLS gradient g_ip = N_ip D_p^-1 (x_i - x_p) (P, nx, ny, 2; 1/m),
    D_p = sum_i N_ip (x_i - x_p)(x_i - x_p)^T; with linear B-splines the B-spline gradient,
    which it equals wherever D_p is regular."""
    N, dN = basis_matrix(order, x, origin, h, cells)
    if order == 1:
        return N, dN
    d = node_offsets(x, origin, h, cells)
    D = np.einsum("pij,pijd,pije->pde", N, d, d)
    return N, np.einsum("pij,pde,pije->pijd", N, np.linalg.inv(D), d)


def mls_p2g_reference(order, x, m, v, C, vol, stress, fext, origin, h, cells):
    """Nodal mass, APIC momentum sum_p N m (v + C (x_i - x_p)) and force
    sum_p -V sigma g + N f_ext (``C`` (P, 4) row-major, ``stress`` Voigt xx, yy, xy)."""
    N, g = mls_gradient(order, x, origin, h, cells)
    d = node_offsets(x, origin, h, cells)
    local = v[:, None, None, :] + np.einsum("pde,pije->pijd", C.reshape(-1, 2, 2), d)
    sig = np.stack([np.stack([stress[:, 0], stress[:, 2]], -1), np.stack([stress[:, 2], stress[:, 1]], -1)], 1)
    force = -np.einsum("p,pde,pije->ijd", vol, sig, g) + np.einsum("pij,pd->ijd", N, fext)
    return np.einsum("pij,p->ij", N, m), np.einsum("pij,p,pijd->ijd", N, m, local), force


def mls_g2p_reference(order, x, vol, vel, dt, origin, h, cells):
    """v_p = sum N v_i, C_p = sum v_i g_ip^T (P, 4 row-major), the strain increment
    dt (C_xx, C_yy, C_xy + C_yx) and the volume V (1 + tr d_eps), from nodal velocities
    ``vel`` (nx, ny, 2)."""
    N, g = mls_gradient(order, x, origin, h, cells)
    vp = np.einsum("pij,ijd->pd", N, vel)
    C = np.einsum("ijd,pije->pde", vel, g)
    de = dt * np.stack([C[:, 0, 0], C[:, 1, 1], C[:, 0, 1] + C[:, 1, 0]], axis=-1)
    return vp, C.reshape(-1, 4), de, vol * (1.0 + de[:, 0] + de[:, 1])
