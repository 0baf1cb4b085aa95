"""Slow, plain NumPy twins of the transfer kernels, written from the equations for tests.

They build the full 2-D shape-function matrix N[p, i, j] from 1-D B-splines evaluated by the
Cox-de Boor-free closed forms below and the edge rule "ghost node -> 2x edge node, -1x inner
node", independently of the numba code paths.
"""
import numpy as np

__all__ = ["bspline_1d", "gimp_1d", "cpdi_basis_matrix", "basis_matrix", "p2g_reference", "g2p_velocity_reference",
           "g2p_kinematics_reference", "g2p_deformation_reference", "reaction_reference", "viscous_stress_reference"]


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


def gimp_1d(s, l, n, order=3):
    """B-spline GIMP by quadrature: the boundary-modified B-spline (``bspline_1d``) averaged over
    the particle domain [s - l, s + l] clamped to [0, n], with weights (P, n+1) and the
    derivative by s of that average (P, n+1) from the Leibniz rule,
    d/ds (1/(b-a) int_a^b N) = (N(b) b' - N(a) a') / (b-a) - S (b' - a') / (b-a).
    The integral is summed piece by piece between knots, 3-point Gauss-Legendre on each piece
    (exact for the cubic pieces)."""
    s = np.asarray(s, dtype=float)
    l = np.broadcast_to(np.asarray(l, dtype=float), s.shape)
    a = np.maximum(s - l, 0.0)
    b = np.minimum(s + l, float(n))
    da = (s - l > 0).astype(float)
    db = (s + l < n).astype(float)
    gx, gw = np.polynomial.legendre.leggauss(3)
    W = np.zeros((len(s), n + 1))
    for p in range(len(s)):
        knots = np.unique(np.concatenate([[a[p], b[p]], np.arange(np.ceil(a[p]), np.floor(b[p]) + 1)]))
        knots = knots[(knots >= a[p]) & (knots <= b[p])]
        for lo, hi in zip(knots[:-1], knots[1:]):
            xq = 0.5 * (lo + hi) + 0.5 * (hi - lo) * gx
            w, _ = bspline_1d(order, xq, n)
            W[p] += 0.5 * (hi - lo) * (gw @ w)
    length = (b - a)[:, None]
    W /= length
    Na, _ = bspline_1d(order, a, n)
    Nb, _ = bspline_1d(order, b, n)
    G = (Nb * db[:, None] - Na * da[:, None] - W * (db - da)[:, None]) / length
    return W, G


def cpdi_basis_matrix(order, x, origin, h, cells, domain, F):
    """CPDI1 (Sadeghirad, Brannon & Burghardt 2011, eq. 25-27) from the point B-splines at the
    corners of each particle's parallelogram, r1 = F (lx, 0), r2 = F (0, ly) (``domain`` (P, 2)
    the half-lengths in cell units, ``F`` (P, 5)), corners x_p -r1-r2, +r1-r2, +r1+r2, -r1+r2,
    each clamped onto the grid per axis: S_i = 1/4 sum_c N_i(x_c) and
    grad S_i = [(N_i(x_1) - N_i(x_3)) a + (N_i(x_2) - N_i(x_4)) b] / V,
    a = (r1y - r2y, r2x - r1x), b = (r1y + r2y, -r1x - r2x), V = 4 |r1 x r2|."""
    s = (np.asarray(x, dtype=float) - np.asarray(origin, dtype=float)) / h
    r1 = np.stack([F[:, 0], F[:, 2]], axis=1) * domain[:, :1]
    r2 = np.stack([F[:, 1], F[:, 3]], axis=1) * domain[:, 1:]
    N = []
    for corner in (s - r1 - r2, s + r1 - r2, s + r1 + r2, s - r1 + r2):
        cx = np.clip(corner[:, 0], 0, cells[0])
        cy = np.clip(corner[:, 1], 0, cells[1])
        wx, _ = bspline_1d(order, cx, cells[0])
        wy, _ = bspline_1d(order, cy, cells[1])
        N.append(wx[:, :, None] * wy[:, None, :])
    a = np.stack([r1[:, 1] - r2[:, 1], r2[:, 0] - r1[:, 0]], axis=1)
    b = np.stack([r1[:, 1] + r2[:, 1], -r1[:, 0] - r2[:, 0]], axis=1)
    V = 4.0 * np.abs(r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0])
    dN = ((N[0] - N[2])[..., None] * a[:, None, None, :]
          + (N[1] - N[3])[..., None] * b[:, None, None, :]) / (V[:, None, None, None] * h)
    return 0.25 * (N[0] + N[1] + N[2] + N[3]), dN


def basis_matrix(order, x, origin, h, cells, domain=None, F=None):
    """N (P, nx, ny) and grad N (P, nx, ny, 2) on the whole grid; with ``domain`` (P, 2), the
    particles' half-lengths in cell units, the B-spline GIMP (``gimp_1d``), or with ``F`` as
    well, CPDI (``cpdi_basis_matrix``)."""
    if F is not None:
        return cpdi_basis_matrix(order, x, origin, h, cells, domain, F)
    sx = (x[:, 0] - origin[0]) / h
    sy = (x[:, 1] - origin[1]) / h
    if domain is None:
        wx, gx = bspline_1d(order, sx, cells[0])
        wy, gy = bspline_1d(order, sy, cells[1])
    else:
        wx, gx = gimp_1d(sx, domain[:, 0], cells[0], order)
        wy, gy = gimp_1d(sy, domain[:, 1], cells[1], order)
    N = wx[:, :, None] * wy[:, None, :]
    dN = np.stack([gx[:, :, None] * wy[:, None, :], wx[:, :, None] * gy[:, None, :]], axis=-1) / h
    return N, dN


def p2g_reference(order, x, m, v, vol, stress, fext, origin, h, cells, domain=None, F=None):
    """Nodal mass (nx, ny), momentum (nx, ny, 2) and force (nx, ny, 2) by paper eq. 2."""
    N, dN = basis_matrix(order, x, origin, h, cells, domain, F)
    mass = np.einsum("pij,p->ij", N, m)
    mom = np.einsum("pij,p,pd->ijd", N, m, v)
    sig = np.stack([np.stack([stress[:, 0], stress[:, 2]], -1), np.stack([stress[:, 2], stress[:, 1]], -1)], 1)
    fint = -np.einsum("p,pde,pije->ijd", vol, sig, dN)
    force = fint + np.einsum("pij,pd->ijd", N, fext)
    return mass, mom, force


def g2p_velocity_reference(order, x, v, vel, dvel, pic, origin, h, cells, domain=None, F=None):
    """New particle velocities from nodal velocities ``vel`` and changes ``dvel`` (nx, ny, 2)."""
    N, _ = basis_matrix(order, x, origin, h, cells, domain, F)
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


def g2p_deformation_reference(order, x, vel, F, vol0, dt, origin, h, cells, domain=None):
    """The kinematics of the step from nodal velocities ``vel`` (nx, ny, 2), written from the
    equations as matrices: L = sum_i v_i (x) grad N_i, de = sym(L) dt (Voigt, engineering
    shear), spin dw = skew(L)_yx dt, F <- (I + dt L) F (the 2x2 block of ``F`` (P, 5); Fzz
    unchanged), vol = vol0 det F, and the change of the polar angle of F, dtheta, from the
    rotation R of F = R U found by an eigen-decomposition of U^2 = F^T F (independent of the
    kernel's closed form). Returns de (P, 3), dw (P,), F (P, 5), vol (P,), dtheta (P,).
    With ``domain`` (P, 2, cell units) the gradient is CPDI's, from the corners of F's
    parallelograms (``cpdi_basis_matrix``)."""
    _, dN = basis_matrix(order, x, origin, h, cells, domain, F if domain is not None else None)
    L = np.einsum("ijd,pije->pde", vel, dN)          # L[p, d, e] = d v_d / d x_e
    de = np.stack([L[:, 0, 0], L[:, 1, 1], L[:, 0, 1] + L[:, 1, 0]], axis=1) * dt
    dw = 0.5 * (L[:, 1, 0] - L[:, 0, 1]) * dt
    F2 = F[:, :4].reshape(-1, 2, 2)
    new2 = np.einsum("pde,pef->pdf", np.eye(2) + dt * L, F2)
    Fn = F.copy()
    Fn[:, :4] = new2.reshape(-1, 4)
    vol = vol0 * np.linalg.det(new2)

    def rotation_angle(A):
        lam, Q = np.linalg.eigh(np.einsum("pdi,pdj->pij", A, A))
        U_inv = np.einsum("pij,pj,pkj->pik", Q, 1.0 / np.sqrt(lam), Q)
        R = np.einsum("pij,pjk->pik", A, U_inv)
        return np.arctan2(R[:, 1, 0], R[:, 0, 0])

    dtheta = np.angle(np.exp(1j * (rotation_angle(new2) - rotation_angle(F2))))
    return de, dw, Fn, vol, dtheta


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


def viscous_stress_reference(sv, de, vol, dt, a1, E, nu, plane_strain):
    """NumPy twin of ``pmpm.physics.rayleigh.viscous_stress`` (one material): returns
    (new sv, work) with work = sum V sv : de and new sv = (a1 / dt) C de, C the elastic
    tangent matrix (plane stress, or the in-plane rows of plane strain)."""
    if plane_strain:
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        C = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    else:
        C = E / (1 - nu ** 2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    work = float(np.sum(vol * np.einsum("pk,pk->p", sv, de)))
    return (a1 / dt) * de @ C.T, work
