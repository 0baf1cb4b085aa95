"""Slow, plain NumPy twins of the transfer kernels, written from the equations for tests.

They build the full 2-D shape-function matrix N[p, i, j] from 1-D B-splines evaluated by the
Cox-de Boor-free closed forms below and the edge rule "ghost node -> 2x edge node, -1x inner
node", independently of the numba code paths.
"""
import numpy as np

__all__ = ["bspline_1d", "basis_matrix", "p2g_reference", "g2p_velocity_reference",
           "g2p_kinematics_reference", "reaction_reference"]


def _standard(order, xi):
    a = np.abs(xi)
    if order == 1:
        return np.clip(1 - a, 0, None), np.where(a < 1, -np.sign(xi), 0.0)
    if order == 2:
        w = np.where(a < 0.5, 0.75 - xi ** 2, np.where(a < 1.5, 0.5 * (1.5 - a) ** 2, 0.0))
        g = np.where(a < 0.5, -2 * xi, np.where(a < 1.5, -np.sign(xi) * (1.5 - a), 0.0))
        return w, g
    w = np.where(a < 1, 2 / 3 - a ** 2 + a ** 3 / 2, np.where(a < 2, (2 - a) ** 3 / 6, 0.0))
    g = np.where(a < 1, np.sign(xi) * (-2 * a + 1.5 * a ** 2), np.where(a < 2, -np.sign(xi) * 0.5 * (2 - a) ** 2, 0.0))
    return w, g


def bspline_1d(order, s, n):
    """Weights (P, n+1) and cell-unit gradients of every node for coordinates ``s`` (P,)."""
    s = np.asarray(s, dtype=float)
    nodes = np.arange(-1, n + 2)  # with one ghost node beyond each edge
    w, g = _standard(order, s[:, None] - nodes[None, :])
    if order > 1:
        # eliminate ghost nodes by linear extrapolation: v_-1 = 2 v_0 - v_1, v_n+1 = 2 v_n - v_n-1
        for arr in (w, g):
            arr[:, 1] += 2 * arr[:, 0]
            arr[:, 2] -= arr[:, 0]
            arr[:, -2] += 2 * arr[:, -1]
            arr[:, -3] -= arr[:, -1]
    return w[:, 1:-1], g[:, 1:-1]


def basis_matrix(order, x, origin, h, cells):
    """N (P, nx, ny) and grad N (P, nx, ny, 2) on the whole grid."""
    sx = (x[:, 0] - origin[0]) / h
    sy = (x[:, 1] - origin[1]) / h
    wx, gx = bspline_1d(order, sx, cells[0])
    wy, gy = bspline_1d(order, sy, cells[1])
    N = wx[:, :, None] * wy[:, None, :]
    dN = np.stack([gx[:, :, None] * wy[:, None, :], wx[:, :, None] * gy[:, None, :]], axis=-1) / h
    return N, dN


def p2g_reference(order, x, m, v, vol, stress, fext, origin, h, cells):
    """Nodal mass (nx, ny), momentum (nx, ny, 2) and force (nx, ny, 2) by paper eq. 2."""
    N, dN = basis_matrix(order, x, origin, h, cells)
    mass = np.einsum("pij,p->ij", N, m)
    mom = np.einsum("pij,p,pd->ijd", N, m, v)
    sig = np.stack([np.stack([stress[:, 0], stress[:, 2]], -1), np.stack([stress[:, 2], stress[:, 1]], -1)], 1)
    fint = -np.einsum("p,pde,pije->ijd", vol, sig, dN)
    force = fint + np.einsum("pij,pd->ijd", N, fext)
    return mass, mom, force


def g2p_velocity_reference(order, x, v, vel, dvel, pic, origin, h, cells):
    """New particle velocities from nodal velocities ``vel`` and changes ``dvel`` (nx, ny, 2)."""
    N, _ = basis_matrix(order, x, origin, h, cells)
    flip = v + np.einsum("pij,ijd->pd", N, dvel)
    return (1 - pic) * flip + pic * np.einsum("pij,ijd->pd", N, vel)


def g2p_kinematics_reference(order, x, vol, vel, dx, dt, origin, h, cells):
    """Strain increment, spin increment, new volume and new position by paper eq. 5-6.

    From the nodal velocities ``vel`` (nx, ny, 2): the velocity gradient
    L_p = sum_i v_i (grad N_i)^T, so L[d, e] = d v_d / d x_e; the strain increment
    de = dt (L_xx, L_yy, L_xy + L_yx) (engineering shear), the spin increment
    dw = dt (L_yx - L_xy) / 2 (the rotation rate of the Jaumann rate, W_yx), the volume
    V (1 + tr de) and the position x + dx.

    Returns
    -------
    de : (P, 3), dw : (P,), vol : (P,), x : (P, 2)
    """
    _, dN = basis_matrix(order, x, origin, h, cells)
    L = np.einsum("ijd,pije->pde", vel, dN)
    de = dt * np.stack([L[:, 0, 0], L[:, 1, 1], L[:, 0, 1] + L[:, 1, 0]], axis=-1)
    dw = 0.5 * dt * (L[:, 1, 0] - L[:, 0, 1])
    return de, dw, vol * (1.0 + de[:, 0] + de[:, 1]), x + dx


def reaction_reference(G, dt, bc_mask, bc_vel, ids, n, x0, y0, h):
    """Constraint impulses of the grid update per reaction: (n, 3) of (Jx, Jy, moment about
    (0, 0)), J = m (v_bc - v_free) with v_free = (mv + f dt) / m, for every node component that
    ``bc_mask`` constrains and ``ids[i, j, d]`` (>= 0) assigns to a reaction; node (i, j) at
    (x0 + i h, y0 + j h). No mass cutoff, no damping (as the kernel with those off)."""
    m = G[..., 0]
    heavy = m > 0
    v_free = np.where(heavy[..., None], (G[..., 1:3] + dt * G[..., 3:5]) / np.where(heavy, m, 1.0)[..., None], 0.0)
    J = np.where(bc_mask.astype(bool) & heavy[..., None], m[..., None] * (bc_vel - v_free), 0.0)
    X = x0 + h * np.arange(G.shape[0])[:, None] + 0.0 * np.arange(G.shape[1])[None, :]
    Y = y0 + h * np.arange(G.shape[1])[None, :] + 0.0 * np.arange(G.shape[0])[:, None]
    out = np.zeros((n, 3))
    for b in range(n):
        sx, sy = ids[..., 0] == b, ids[..., 1] == b
        out[b] = (J[sx, 0].sum(), J[sy, 1].sum(), np.sum(X[sy] * J[sy, 1]) - np.sum(Y[sx] * J[sx, 0]))
    return out
