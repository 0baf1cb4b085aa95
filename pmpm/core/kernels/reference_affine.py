"""Plain NumPy twins of the APIC kernels (pmpm.core.kernels.affine), written from the equations
of Jiang et al. 2015 on the whole grid's shape-function matrix (pmpm.core.kernels.reference)."""
import numpy as np

from pmpm.core.kernels.reference import basis_matrix

__all__ = ["node_offsets", "apic_p2g_reference", "apic_g2p_reference"]


def node_offsets(x, origin, h, cells):
    """x_i - x_p (P, nx, ny, 2) of every node i for the particles ``x`` (P, 2)."""
    X = origin[0] + h * np.arange(cells[0] + 1)
    Y = origin[1] + h * np.arange(cells[1] + 1)
    d = np.empty((len(x), cells[0] + 1, cells[1] + 1, 2))
    d[..., 0] = X[None, :, None] - x[:, 0, None, None]
    d[..., 1] = Y[None, None, :] - x[:, 1, None, None]
    return d


def apic_p2g_reference(order, x, m, v, C, origin, h, cells):
    """Nodal mass and APIC momentum sum_p N m (v + C (x_i - x_p)), ``C`` (P, 4) row-major."""
    N, _ = basis_matrix(order, x, origin, h, cells)
    d = node_offsets(x, origin, h, cells)
    Cm = C.reshape(-1, 2, 2)
    local = v[:, None, None, :] + np.einsum("pde,pije->pijd", Cm, d)
    return np.einsum("pij,p->ij", N, m), np.einsum("pij,p,pijd->ijd", N, m, local)


def apic_g2p_reference(order, x, vel, origin, h, cells):
    """v_p = sum N v_i, B_p = sum N v_i (x_i - x_p)^T, D_p = sum N (x_i - x_p)(x_i - x_p)^T and
    C_p = B_p D_p^-1 (P, 4 row-major), from nodal velocities ``vel`` (nx, ny, 2)."""
    N, _ = basis_matrix(order, x, origin, h, cells)
    d = node_offsets(x, origin, h, cells)
    vp = np.einsum("pij,ijd->pd", N, vel)
    B = np.einsum("pij,ijd,pije->pde", N, vel, d)
    D = np.einsum("pij,pijd,pije->pde", N, d, d)
    return vp, np.einsum("pde,pef->pdf", B, np.linalg.inv(D)).reshape(-1, 4)
