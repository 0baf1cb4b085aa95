"""Plain NumPy twins of the implicit kernels, written from the equations for tests: the whole
grid at once with the dense shape-function matrices of pmpm.core.kernels.reference.

    f_p = I + sum_I u_I (x) G_pI,   E_p = (f_p^T f_p - I) / 2
    f_int,I = -sum_p V_p f_p S_p G_pI
    K_(Ia)(Jb) = sum_p V_p [ sum_rs B_pI[r, a] D_p[r, s] B_pJ[s, b] + delta_ab G_pI . S_p G_pJ ]
"""
import numpy as np

from pmpm.core.kernels.reference import basis_matrix

__all__ = ["deformation_reference", "internal_force_reference", "tangent_reference", "blocks_to_dense"]


def _tensor(S):
    return np.stack([np.stack([S[:, 0], S[:, 2]], -1), np.stack([S[:, 2], S[:, 1]], -1)], 1)


def deformation_reference(order, x, U, origin, h, cells):
    """(f (P, 2, 2), E (P, 3): Exx, Eyy, 2 Exy) of the nodal increments U (nx, ny, 2)."""
    _, dN = basis_matrix(order, x, origin, h, cells)
    f = np.eye(2)[None] + np.einsum("ija,pijb->pab", U, dN)
    C = np.einsum("pca,pcb->pab", f, f)
    E = np.stack([0.5 * (C[:, 0, 0] - 1), 0.5 * (C[:, 1, 1] - 1), C[:, 0, 1]], axis=1)
    return f, E


def internal_force_reference(order, x, vol, S, f, origin, h, cells):
    """-sum_p V_p (f_p S_p) G_pI on every node, (nx, ny, 2)."""
    _, dN = basis_matrix(order, x, origin, h, cells)
    P = np.einsum("pac,pcb->pab", f, _tensor(S))
    return -np.einsum("p,pab,pijb->ija", vol, P, dN)


def tangent_reference(order, x, vol, S, f, D, origin, h, cells):
    """The dense tangent (2 n_nodes, 2 n_nodes), dof 2 (i ny + j) + a."""
    _, dN = basis_matrix(order, x, origin, h, cells)
    P, nx, ny = len(x), cells[0] + 1, cells[1] + 1
    G = dN.reshape(P, nx * ny, 2)
    # B[p, node, r, a]
    B = np.zeros((P, nx * ny, 3, 2))
    B[:, :, 0, :] = G[:, :, 0, None] * f[:, None, :, 0]
    B[:, :, 1, :] = G[:, :, 1, None] * f[:, None, :, 1]
    B[:, :, 2, :] = G[:, :, 0, None] * f[:, None, :, 1] + G[:, :, 1, None] * f[:, None, :, 0]
    Kmat = np.einsum("p,pIra,prs,pJsb->IaJb", vol, B, D, B)
    geo = np.einsum("p,pIc,pcd,pJd->IJ", vol, G, _tensor(S), G)
    Kmat += geo[:, None, :, None] * np.eye(2)[None, :, None, :]
    return Kmat.reshape(2 * nx * ny, 2 * nx * ny)


def blocks_to_dense(Kb, lid, span):
    """The kernel's blocks (``assemble_blocks``) as the dense matrix ``tangent_reference``
    returns (nodes with ``lid`` < 0 left zero)."""
    nx, ny = lid.shape
    K = np.zeros((nx, ny, 2, nx, ny, 2))
    r = span // 2
    for i, j in zip(*np.nonzero(lid >= 0)):
        for off in range(span * span):
            ii, jj = i + off // span - r, j + off % span - r
            if 0 <= ii < nx and 0 <= jj < ny:
                K[i, j, :, ii, jj, :] += Kb[lid[i, j], off]
    return K.reshape(2 * nx * ny, 2 * nx * ny)
