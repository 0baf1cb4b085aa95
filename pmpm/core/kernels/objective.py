"""Objective stress rates for large rotations: Jaumann (the spin) and Green-Naghdi (the
rotation of the polar decomposition of F).

Both rotate the stress (and the tensor state of the material) before the material adds its
increment, sigma <- Q sigma Q^T + C : de: Jaumann with the linearised Q = I + W dt of the spin
W = skew(L), Green-Naghdi with the exact rotation Q = R_{n+1} R_n^T between the polar
rotations of F at the step's end and start (in 2-D a rotation by the change of the polar angle,
see pmpm.core.kernels.transfer.polar_angle; the kinematics kernel gives its cosine and sine).
"""
import numba as nb

__all__ = ["jaumann_rotate", "rotate"]


@nb.njit(cache=True)
def jaumann_rotate(t, dw):
    """Rotate Voigt tensors ``t`` (N, >=3: xx, yy, xy) by the spin increments ``dw`` (N,):
    t += W t - t W with W = [[0, -dw], [dw, 0]] (dw = 0.5 (dvy/dx - dvx/dy) dt)."""
    for p in range(t.shape[0]):
        w = dw[p]
        txx = t[p, 0]
        tyy = t[p, 1]
        txy = t[p, 2]
        t[p, 0] = txx - 2.0 * w * txy
        t[p, 1] = tyy + 2.0 * w * txy
        t[p, 2] = txy + w * (txx - tyy)


@nb.njit(cache=True)
def rotate(t, dq):
    """Rotate Voigt tensors ``t`` (N, >=3: xx, yy, xy) exactly, t <- Q t Q^T with Q the
    counter-clockwise rotation whose cosine and sine are ``dq`` (N, 2) (the Green-Naghdi
    update)."""
    for p in range(t.shape[0]):
        c = dq[p, 0]
        s = dq[p, 1]
        txx = t[p, 0]
        tyy = t[p, 1]
        txy = t[p, 2]
        t[p, 0] = c * c * txx - 2.0 * c * s * txy + s * s * tyy
        t[p, 1] = s * s * txx + 2.0 * c * s * txy + c * c * tyy
        t[p, 2] = c * s * (txx - tyy) + (c * c - s * s) * txy
