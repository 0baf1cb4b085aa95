"""Numba kernels of the implicit step: the particles' deformation in the step, the internal
force, the tangent stiffness, and the Newmark update of the particles (docs/implicit.md).

Within a step the reference configuration is the step's start (updated Lagrangian): the
particles sit at ``x`` with volume ``vol``, the basis gradients G_I = grad N_I(x) are taken
there, and the grid carries the displacement increment ``U`` (window array ``[i, j, 2]``).
Per particle

    f = I + sum_I u_I (x) G_I                        (the step's deformation gradient)
    E = 1/2 (f^T f - I)                              (Green-Lagrange strain of the step)
    S = the material's update of the step-start stress by the increment E
    f_int,I = -V (f S) G_I                           (= -V' sigma' grad' N_I at the end)
    K_IJ = V [B_I^T D B_J + (G_I . S G_J) 1]         (material + initial-stress stiffness)

with B_I the derivative of E (Voigt, engineering shear) by u_I and D = dS/dE the material's
tangent. K is the exact derivative of -f_int whenever D is the exact derivative of the
material's update (elastic; bilinear J2): that is what makes Newton quadratic, and the
initial-stress term is what carries P-Delta and rotations within a step.

The grid is the rank's window (pmpm.core.grid); shapes are the point B-splines (the ``tag``
of pmpm.core.shape). A particle in cell c touches nodes c - K + 2 .. c + 1 per axis, so two
nodes it couples are at most K - 1 apart: the tangent is kept as blocks ``Kb[row, offset, a,
b]``, ``row`` the active-node number of I (``lid``), ``offset`` = (di + K - 1) (2K - 1) + dj + K
- 1 for J - I = (di, dj).
"""
import math

import numba as nb
import numpy as np

from pmpm.core.shape import weights

__all__ = ["scatter_inertia_and_gravity", "deformation_increment", "internal_force", "assemble_blocks",
           "newmark_particles", "push_forward", "stencil_span"]


def stencil_span(tag):
    """2K - 1: the offsets per axis between two nodes one particle couples."""
    return 2 * len(tag) - 1


@nb.njit(cache=True, inline="always")
def _basis(x, p, origin, inv_h, ncx, ncy, tag):
    """First nodes, weights and physical gradients of particle p along x and y."""
    i0, wx, gx = weights(tag, (x[p, 0] - origin[0]) * inv_h, ncx)
    j0, wy, gy = weights(tag, (x[p, 1] - origin[1]) * inv_h, ncy)
    return i0, wx, gx, j0, wy, gy


@nb.njit(cache=True)
def scatter_inertia_and_gravity(x, m, a, gravity, G, ox, oy, origin, inv_h, ncx, ncy, tag):
    """Add each particle's m a N_I to G[..., 5:7] (``a`` not None: the step's start
    accelerations, Newmark's a_n) and its weight m g N_I to G[..., 3:5] (``gravity`` not None)."""
    K = len(tag)
    for p in range(x.shape[0]):
        i0, wx, _, j0, wy, _ = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        for ia in range(K):
            for jb in range(K):
                w = wx[ia] * wy[jb] * m[p]
                ii = i0 + ia - ox
                jj = j0 + jb - oy
                if a is not None:
                    G[ii, jj, 5] += w * a[p, 0]
                    G[ii, jj, 6] += w * a[p, 1]
                if gravity is not None:
                    G[ii, jj, 3] += w * gravity[0]
                    G[ii, jj, 4] += w * gravity[1]


@nb.njit(cache=True)
def deformation_increment(x, U, ox, oy, origin, inv_h, ncx, ncy, tag, f, E):
    """The step's deformation gradient ``f`` (N, 4: fxx, fxy, fyx, fyy with f_ab = delta_ab +
    d u_a / d x_b) and Green-Lagrange strain ``E`` (N, 3: Exx, Eyy, 2 Exy) of every particle
    from the nodal displacement increments ``U``."""
    K = len(tag)
    for p in range(x.shape[0]):
        i0, wx, gx, j0, wy, gy = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        hxx = hxy = hyx = hyy = 0.0
        for ia in range(K):
            for jb in range(K):
                dx = gx[ia] * wy[jb] * inv_h
                dy = wx[ia] * gy[jb] * inv_h
                ux = U[i0 + ia - ox, j0 + jb - oy, 0]
                uy = U[i0 + ia - ox, j0 + jb - oy, 1]
                hxx += ux * dx
                hxy += ux * dy
                hyx += uy * dx
                hyy += uy * dy
        fxx, fxy, fyx, fyy = 1.0 + hxx, hxy, hyx, 1.0 + hyy
        f[p, 0], f[p, 1], f[p, 2], f[p, 3] = fxx, fxy, fyx, fyy
        E[p, 0] = 0.5 * (fxx * fxx + fyx * fyx - 1.0)
        E[p, 1] = 0.5 * (fxy * fxy + fyy * fyy - 1.0)
        E[p, 2] = fxx * fxy + fyx * fyy


@nb.njit(cache=True)
def internal_force(x, vol, S, f, R, ox, oy, origin, inv_h, ncx, ncy, tag):
    """Add f_int,I = -V (f S) G_I of every particle to R[..., 0:2]."""
    K = len(tag)
    for p in range(x.shape[0]):
        i0, wx, gx, j0, wy, gy = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        sxx, syy, sxy = S[p, 0], S[p, 1], S[p, 2]
        fxx, fxy, fyx, fyy = f[p, 0], f[p, 1], f[p, 2], f[p, 3]
        c = -vol[p] * inv_h
        # P = f S (first Piola-Kirchhoff stress of the step), times -V / h
        pxx = c * (fxx * sxx + fxy * sxy)
        pxy = c * (fxx * sxy + fxy * syy)
        pyx = c * (fyx * sxx + fyy * sxy)
        pyy = c * (fyx * sxy + fyy * syy)
        for ia in range(K):
            for jb in range(K):
                dx = gx[ia] * wy[jb]
                dy = wx[ia] * gy[jb]
                ii = i0 + ia - ox
                jj = j0 + jb - oy
                R[ii, jj, 0] += pxx * dx + pxy * dy
                R[ii, jj, 1] += pyx * dx + pyy * dy


@nb.njit(cache=True)
def assemble_blocks(x, vol, S, f, D, lid, Kb, ox, oy, origin, inv_h, ncx, ncy, tag):
    """Add every particle's V [B_I^T D B_J + (G_I . S G_J) 1] to the blocks ``Kb[lid[I],
    offset(J - I)]`` (module docstring). Nodes with ``lid`` < 0 (not in the solve) are skipped."""
    K = len(tag)
    span = 2 * K - 1
    n = K * K
    Gx = np.empty(n)
    Gy = np.empty(n)
    B = np.empty((n, 3, 2))
    DB = np.empty((n, 3, 2))
    rows = np.empty(n, np.int64)
    II = np.empty(n, np.int64)
    JJ = np.empty(n, np.int64)
    for p in range(x.shape[0]):
        i0, wx, gx, j0, wy, gy = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        fxx, fxy, fyx, fyy = f[p, 0], f[p, 1], f[p, 2], f[p, 3]
        v = vol[p]
        sxx, syy, sxy = S[p, 0], S[p, 1], S[p, 2]
        for ia in range(K):
            for jb in range(K):
                q = ia * K + jb
                dx = gx[ia] * wy[jb] * inv_h
                dy = wx[ia] * gy[jb] * inv_h
                Gx[q] = dx
                Gy[q] = dy
                II[q] = i0 + ia
                JJ[q] = j0 + jb
                rows[q] = lid[i0 + ia - ox, j0 + jb - oy]
                # dE / du_a: (dx f_ax, dy f_ay, dx f_ay + dy f_ax) for a = x, y
                B[q, 0, 0] = dx * fxx
                B[q, 1, 0] = dy * fxy
                B[q, 2, 0] = dx * fxy + dy * fxx
                B[q, 0, 1] = dx * fyx
                B[q, 1, 1] = dy * fyy
                B[q, 2, 1] = dx * fyy + dy * fyx
                for r in range(3):
                    for c in range(2):
                        DB[q, r, c] = v * (D[p, r, 0] * B[q, 0, c] + D[p, r, 1] * B[q, 1, c]
                                           + D[p, r, 2] * B[q, 2, c])
        for q in range(n):
            row = rows[q]
            if row < 0:
                continue
            for t in range(n):
                if rows[t] < 0:
                    continue
                off = (II[t] - II[q] + K - 1) * span + JJ[t] - JJ[q] + K - 1
                geo = v * (Gx[q] * (sxx * Gx[t] + sxy * Gy[t]) + Gy[q] * (sxy * Gx[t] + syy * Gy[t]))
                for a in range(2):
                    for b in range(2):
                        k = B[q, 0, a] * DB[t, 0, b] + B[q, 1, a] * DB[t, 1, b] + B[q, 2, a] * DB[t, 2, b]
                        if a == b:
                            k += geo
                        Kb[row, off, a, b] += k


@nb.njit(cache=True)
def newmark_particles(x, v, a, U, DV, A, ox, oy, origin, inv_h, ncx, ncy, tag, dx):
    """The converged step onto the particles: x += sum N_I u_I (also into ``dx``), and where
    ``v`` is not None (dynamics) v += sum N_I dv_I (``DV``, the nodal Newmark velocity change:
    FLIP's increment) and a = sum N_I a_I (``A``, the nodal accelerations at the step's end).
    Returns (largest speed, count of non-finite velocities or positions)."""
    K = len(tag)
    vmax = 0.0
    bad = 0
    for p in range(x.shape[0]):
        i0, wx, _, j0, wy, _ = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        ux = uy = dvx = dvy = ax = ay = 0.0
        for ia in range(K):
            for jb in range(K):
                w = wx[ia] * wy[jb]
                ii = i0 + ia - ox
                jj = j0 + jb - oy
                ux += w * U[ii, jj, 0]
                uy += w * U[ii, jj, 1]
                if v is not None:
                    dvx += w * DV[ii, jj, 0]
                    dvy += w * DV[ii, jj, 1]
                    ax += w * A[ii, jj, 0]
                    ay += w * A[ii, jj, 1]
        x[p, 0] += ux
        x[p, 1] += uy
        dx[p, 0] = ux
        dx[p, 1] = uy
        if v is not None:
            v[p, 0] += dvx
            v[p, 1] += dvy
            a[p, 0] = ax
            a[p, 1] = ay
            speed = math.sqrt(v[p, 0] ** 2 + v[p, 1] ** 2)
            if speed > vmax:
                vmax = speed
            if not math.isfinite(speed):
                bad += 1
        elif not (math.isfinite(ux) and math.isfinite(uy)):
            bad += 1
    return vmax, bad


@nb.njit(cache=True)
def push_forward(S, f, stress, vol, strain, E):
    """The step's end state of every particle: sigma = f S f^T / J in the plane (szz = S_zz /
    J), ``vol`` (not None) *= J with J = det f (in-plane, as the explicit step's volume), and
    ``strain`` (not None) += E. ``stress`` may be ``S`` itself (in place); the back stress of
    the plastic models is pushed forward the same way (``vol`` and ``strain`` None)."""
    for p in range(S.shape[0]):
        fxx, fxy, fyx, fyy = f[p, 0], f[p, 1], f[p, 2], f[p, 3]
        J = fxx * fyy - fxy * fyx
        sxx, syy, sxy = S[p, 0], S[p, 1], S[p, 2]
        # (f S)
        axx = fxx * sxx + fxy * sxy
        axy = fxx * sxy + fxy * syy
        ayx = fyx * sxx + fyy * sxy
        ayy = fyx * sxy + fyy * syy
        iJ = 1.0 / J
        stress[p, 0] = (axx * fxx + axy * fxy) * iJ
        stress[p, 1] = (ayx * fyx + ayy * fyy) * iJ
        stress[p, 2] = (axx * fyx + axy * fyy) * iJ
        stress[p, 3] = S[p, 3] * iJ
        if vol is not None:
            vol[p] *= J
        if strain is not None:
            strain[p, 0] += E[p, 0]
            strain[p, 1] += E[p, 1]
            strain[p, 2] += E[p, 2]
