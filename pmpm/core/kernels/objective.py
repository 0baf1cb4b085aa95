"""Objective (Jaumann) stress rate for large rotations."""
import numba as nb

__all__ = ["jaumann_rotate"]


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
