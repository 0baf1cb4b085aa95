"""The diagonal of the step's tangent without assembling it (``newton = "accelerated"``: the
Jacobi step a kept factorisation gives the rows it does not have, pmpm.core.implicit.
kept_factorisation).

Per particle and node I of its stencil, the diagonal entries of the block K_II of
pmpm.core.implicit.kernels.assemble_blocks:

    K_II,aa = V [B_I,a^T D B_I,a + G_I . S G_I]          (a = x, y)

a sixteenth of the assembly's work with cubic splines (one node of the particle's stencil
against itself instead of against all). Its twin is the centre block of ``assemble_blocks``
(tests/unit/test_implicit_accelerated.py).
"""
import numba as nb
import numpy as np

from pmpm.core.implicit.kernels import _basis

__all__ = ["diagonal_entries"]


@nb.njit(cache=True)
def diagonal_entries(x, vol, S, f, D, out, ox, oy, origin, inv_h, ncx, ncy, tag):
    """Add every particle's K_II,xx and K_II,yy to out[i, j, 0:2] (window array)."""
    K = len(tag)
    for p in range(x.shape[0]):
        i0, wx, gx, j0, wy, gy = _basis(x, p, origin, inv_h, ncx, ncy, tag)
        fxx, fxy, fyx, fyy = f[p, 0], f[p, 1], f[p, 2], f[p, 3]
        v = vol[p]
        sxx, syy, sxy = S[p, 0], S[p, 1], S[p, 2]
        for ia in range(K):
            for jb in range(K):
                dx = gx[ia] * wy[jb] * inv_h
                dy = wx[ia] * gy[jb] * inv_h
                geo = dx * (sxx * dx + sxy * dy) + dy * (sxy * dx + syy * dy)
                ii = i0 + ia - ox
                jj = j0 + jb - oy
                # B_I for the x and the y component (kernels.assemble_blocks)
                b0, b1, b2 = dx * fxx, dy * fxy, dx * fxy + dy * fxx
                c0, c1, c2 = dx * fyx, dy * fyy, dx * fyy + dy * fyx
                kx = (b0 * (D[p, 0, 0] * b0 + D[p, 0, 1] * b1 + D[p, 0, 2] * b2)
                      + b1 * (D[p, 1, 0] * b0 + D[p, 1, 1] * b1 + D[p, 1, 2] * b2)
                      + b2 * (D[p, 2, 0] * b0 + D[p, 2, 1] * b1 + D[p, 2, 2] * b2))
                ky = (c0 * (D[p, 0, 0] * c0 + D[p, 0, 1] * c1 + D[p, 0, 2] * c2)
                      + c1 * (D[p, 1, 0] * c0 + D[p, 1, 1] * c1 + D[p, 1, 2] * c2)
                      + c2 * (D[p, 2, 0] * c0 + D[p, 2, 1] * c1 + D[p, 2, 2] * c2))
                out[ii, jj, 0] += v * (kx + geo)
                out[ii, jj, 1] += v * (ky + geo)
