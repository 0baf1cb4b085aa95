"""Kernels of the deformation gradient outside the transfers: its health check and the plane
stress thickness stretch of the hypoelastic models (F itself is advanced in the kinematics
tail, pmpm.core.kernels.transfer.strain_increment)."""
import math

import numba as nb

__all__ = ["check_deformation", "in_plane_trace", "advance_thickness_stretch"]


@nb.njit(cache=True)
def check_deformation(F):
    """Number of particles whose deformation gradient ``F`` (N, 5: Fxx, Fxy, Fyx, Fyy, Fzz) is
    not finite or has det F <= 0 (in-plane determinant times Fzz), and the index of the first
    of them (-1 if none)."""
    bad = 0
    first = -1
    for p in range(F.shape[0]):
        det = (F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2]) * F[p, 4]
        if not (det > 0.0 and det < math.inf):  # also NaN: every comparison with it is False
            bad += 1
            if first < 0:
                first = p
    return bad, first


@nb.njit(cache=True)
def in_plane_trace(stress, out):
    """out = sxx + syy of every particle."""
    for p in range(stress.shape[0]):
        out[p] = stress[p, 0] + stress[p, 1]


@nb.njit(cache=True)
def advance_thickness_stretch(F, de, stress, trace_before, E, nu, mat_ids, which):
    """F33 *= 1 + d_ezz for the particles of material ``which`` (-1: all) of a hypoelastic
    model in plane stress, where szz = 0 with isotropic elasticity and plastic
    incompressibility (von Mises flow is deviatoric) gives
    d_ezz = -(d_exx + d_eyy) + (1 - 2 nu) / E d(sxx + syy)
    (for linear elasticity -nu / (1 - nu) (d_exx + d_eyy))."""
    c = (1.0 - 2.0 * nu) / E
    for p in range(F.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        dezz = -(de[p, 0] + de[p, 1]) + c * (stress[p, 0] + stress[p, 1] - trace_before[p])
        F[p, 4] *= 1.0 + dezz
