"""Compressible neo-Hookean hyperelasticity, from E and nu (the small-strain limit).

Strain energy per unit reference volume (Bonet & Wood, Nonlinear Continuum Mechanics for
Finite Element Analysis, 2nd ed., 2008, sec. 6.4.3)::

    W = mu / 2 (tr C - 3) - mu ln J + lambda / 2 (ln J)^2,   C = F^T F,  J = det F (3 x 3)

with mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)), and the Cauchy stress

    sigma = mu / J (b - I) + lambda ln J / J I,   b = F F^T.

The stress is computed from F at every step (no rate, no rotation: it is objective by
construction); the strain increment the solver passes is not read.

Formulations
------------
plane_strain
    F33 = 1; szz = lambda ln J / J is stored.
plane_stress
    F33 = s, the thickness stretch, solves szz = 0: mu (s^2 - 1) + lambda ln(J2 s) = 0 with
    J2 = det of the in-plane F. The left side increases monotonically in s > 0 (derivative
    2 mu s + lambda / s > 0), so the root is unique; Newton's method from the previous step's
    s converges in 1-2 iterations. s is kept in F[:, 4]. The particle's volume in pmpm is its
    area times the *initial* thickness (vol = vol0 J2), so the stored stress is the Cauchy
    stress times s (the in-plane force per unit length over the initial thickness): then
    vol * stress is the true V sigma, the internal forces and the internal work are exact,
    and szz is 0.
"""
import math

import numba as nb
import numpy as np

from pmpm.physics.materials.base import Material

__all__ = ["NeoHookean", "neo_hookean_stress", "neo_hookean_reference", "lame"]

#: Newton iterations for the plane-stress thickness stretch: from the previous step's value the
#: root is reached to round-off in 1-2; the cap only guards a pathological start
NEWTON_MAX = 30
#: stop after a Newton step smaller than this (relative): convergence is quadratic with a
#: constant of order 1 (f'' / 2 f' ~ 1 / s), so the error left is of order 1e-16, round-off
NEWTON_TOL = 1e-8


def lame(E, nu):
    """(mu, lambda) of the three-dimensional solid with Young's modulus E and Poisson's ratio nu."""
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


@nb.njit(cache=True, inline="always")
def _thickness_stretch(mu, lam, j2, s):
    """Root s > 0 of mu (s^2 - 1) + lam ln(j2 s) = 0 by Newton from ``s``."""
    if not s > 0.0:
        s = 1.0
    for _ in range(NEWTON_MAX):
        f = mu * (s * s - 1.0) + lam * math.log(j2 * s)
        ds = f / (2.0 * mu * s + lam / s)
        new = s - ds
        if new <= 0.0:  # Newton overshot below zero from far away: halve instead
            new = 0.5 * s
        if abs(new - s) <= NEWTON_TOL * new:
            return new
        s = new
    return s


@nb.njit(cache=True, inline="always")
def neo_hookean_stress(mu, lam, plane_strain, fxx, fxy, fyx, fyy, s):
    """Stored stress (sxx, syy, sxy, szz) and thickness stretch F33 of one particle with
    in-plane F ``(fxx, fxy, fyx, fyy)`` (``s``: the previous F33, the Newton start in plane
    stress). Non-finite when det F <= 0 (the solver stops such a run)."""
    j2 = fxx * fyy - fxy * fyx
    if plane_strain:
        s = 1.0
        J = j2
        p = lam * (math.log(J) if J > 0.0 else math.nan) / J
    else:
        s = _thickness_stretch(mu, lam, j2, s)
        J = j2 * s
        # at the root lam ln J = -mu (s^2 - 1): the same number to round-off, one log fewer,
        # and szz = mu / J (s^2 - 1) + p is exactly 0
        p = -mu * (s * s - 1.0) / J if J > 0.0 else math.nan
    bxx = fxx * fxx + fxy * fxy
    byy = fyx * fyx + fyy * fyy
    bxy = fxx * fyx + fxy * fyy
    a = mu / J
    sxx = a * (bxx - 1.0) + p
    syy = a * (byy - 1.0) + p
    sxy = a * bxy
    if plane_strain:
        return sxx, syy, sxy, p, 1.0
    # plane stress: the Cauchy stress times s, szz = 0 by the choice of s
    return s * sxx, s * syy, s * sxy, 0.0, s


@nb.njit(cache=True)
def _update_neo_hookean(stress, F, params, plane_strain, mat_ids, which):
    E, nu = params[0], params[1]
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        sxx, syy, sxy, szz, s = neo_hookean_stress(mu, lam, plane_strain, F[p, 0], F[p, 1],
                                                   F[p, 2], F[p, 3], F[p, 4])
        stress[p, 0] = sxx
        stress[p, 1] = syy
        stress[p, 2] = sxy
        stress[p, 3] = szz
        F[p, 4] = s


@nb.njit(cache=True)
def _energy_neo_hookean(F, vol0, params, mat_ids, which):
    """sum of vol0 W(F) over the particles of material ``which`` (-1: all)."""
    E, nu = params[0], params[1]
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    total = 0.0
    for p in range(F.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        s = F[p, 4]
        trC = F[p, 0] ** 2 + F[p, 1] ** 2 + F[p, 2] ** 2 + F[p, 3] ** 2 + s * s
        lnJ = math.log((F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2]) * s)
        total += vol0[p] * (0.5 * mu * (trC - 3.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ)
    return total


def neo_hookean_reference(F, E, nu, plane_strain, iterations=40):
    """NumPy twin of the stress update: stored stress (N, 4) and F33 (N,) for ``F`` (N, 5),
    with 3x3 matrices (b = F F^T, sigma = mu/J (b - I) + lambda ln J / J I) and, in plane
    stress, a vectorised Newton for F33 from s = 1 with a fixed iteration count."""
    mu, lam = lame(E, nu)
    n = len(F)
    j2 = F[:, 0] * F[:, 3] - F[:, 1] * F[:, 2]
    s = np.ones(n)
    if not plane_strain:
        for _ in range(iterations):
            s = np.maximum(s - (mu * (s * s - 1) + lam * np.log(j2 * s)) / (2 * mu * s + lam / s), 0.5 * s)
    F3 = np.zeros((n, 3, 3))
    F3[:, :2, :2] = F[:, :4].reshape(n, 2, 2)
    F3[:, 2, 2] = s
    J = np.linalg.det(F3)
    b = np.einsum("pij,pkj->pik", F3, F3)
    sigma = (mu / J)[:, None, None] * (b - np.eye(3)) + (lam * np.log(J) / J)[:, None, None] * np.eye(3)
    scale = np.ones(n) if plane_strain else s  # plane stress: force per initial thickness
    out = np.stack([sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 0, 1], sigma[:, 2, 2]], axis=1) * scale[:, None]
    if not plane_strain:
        out[:, 3] = 0.0  # zero to the Newton's round-off; stored as exactly 0 like the kernel
    return out, s


class NeoHookean(Material):
    """Compressible neo-Hookean solid (hyperelastic; reads the deformation gradient)."""

    name = "neo_hookean"
    needs_deformation_gradient = True
    stress_from_F = True   # no objective-rate rotation of its stress (see the module docs)

    def update_stress(self, stress, de, state, mat_ids, which):
        _update_neo_hookean(stress, state["F"], self.params, self.plane_strain, mat_ids, which)

    def strain_energy(self, F, vol0, mat_ids, which):
        """Stored energy sum vol0 W(F) (J) of this material's particles (``which``: -1 all)."""
        return _energy_neo_hookean(F, vol0, self.params, mat_ids, which)
