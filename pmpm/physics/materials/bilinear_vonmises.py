"""Classical von Mises plasticity with linear Ziegler kinematic hardening, by return mapping.

The rate-independent (N -> infinity) limit of ``smooth_vonmises``: the same yield function
Phi(sigma - eta) = sigma_y, associative flow d_eps_p = d_lambda n, and the same hardening rule
d_eta = d_lambda c (sigma - eta) / sigma_y with c = alpha E / (1 - alpha), so that the uniaxial
post-yield tangent is alpha E. Ziegler's rule (rather than Prager's d_eta ~ d_eps_p) is used because
in plane stress it keeps eta in the plane (eta_zz = 0), as the smooth model does.

Each increment is one backward-Euler step (unconditionally stable, exact for proportional
uniaxial and pure-shear paths), with the flow direction and hardening at the end of the step.

Formulations
------------
plane_stress
    The projected algorithm of Simo and Taylor (IJNME 22, 1986; Simo and Hughes, Computational
    Inelasticity, 1998, ch. 3):
    D and the plane-stress projection P share the eigenvectors (1, 1, 0), (1, -1, 0), (0, 0, 1),
    so the relative stress xi = sigma - eta at the end of the step is the trial one scaled
    component-wise in that basis:

        (xi_xx + xi_yy)  = (xi_xx + xi_yy)_tr / (1 + d_lambda (k + E / (2 sigma_y (1 - nu))))
        (xi_xx - xi_yy), xi_xy  scaled by  1 / (1 + d_lambda (k + 3 mu / sigma_y)),   k = c / sigma_y

    and the consistency condition Phi(xi(d_lambda)) = sigma_y is one scalar equation. It is
    solved by Newton's method on q = 1/Phi(xi(d_lambda)) - 1/sigma_y: 1/Phi is a power mean of
    order -2 of functions linear in d_lambda, hence concave, so Newton from d_lambda = 0
    increases monotonically to the root (no overshoot, d_lambda never negative) and, q being
    nearly linear, converges in 2-4 iterations; the stress lands on the surface to round-off.
plane_strain
    Classical radial return in 4 components (sxx, syy, sxy, szz): the deviatoric part of xi
    scales by sigma_y / Phi_tr and d_lambda = (Phi_tr - sigma_y) / (c + 3 mu) in closed form.
    As in ``smooth_vonmises``, Ziegler's rule acts on dev(xi) here, so eta stays deviatoric and
    the pressure passes through unchanged.

State: as ``smooth_vonmises`` (back_stress, eps_p, eps_p_eq = sum d_lambda, plastic_work =
integral of sigma . d_eps_p, taken with the mean of the start and end stress of the increment,
which makes elastic energy + plastic work grow by exactly mean(sigma) . d_eps).
"""
import math

import numba as nb
import numpy as np

from pmpm.physics.materials.base import KinematicHardening
from pmpm.physics.materials.linear_elastic import elastic_increment

__all__ = ["BilinearVonMises"]

# below this Phi/sigma_y - 1 one more Newton step lands at round-off (the error squares each step)
_LAST_STEP = 1e-7
_MAXIT = 50


@nb.njit(cache=True)
def _update_bilinear(stress, de, back, eps_p, eps_eq, work, params, plane_strain, mat_ids, which):
    """The particle loop of :meth:`BilinearVonMises.update_stress` (arrays updated in place)."""
    E, nu, sy, alpha = params[0], params[1], params[2], params[3]
    c = alpha * E / (1.0 - alpha)
    k = c / sy
    mu = E / (2.0 * (1.0 + nu))
    pa = k + E / (2.0 * sy * (1.0 - nu))
    pb = k + 3.0 * mu / sy
    sy2 = sy * sy
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        oxx, oyy, oxy, ozz = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
        txx, tyy, txy, tzz = oxx + ds[0], oyy + ds[1], oxy + ds[2], ozz + ds[3]
        bxx, byy, bxy, bzz = back[p, 0], back[p, 1], back[p, 2], back[p, 3]
        xx, yy, xy, zz = txx - bxx, tyy - byy, txy - bxy, tzz - bzz
        if plane_strain:
            phi2 = 0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) + 3.0 * xy * xy
        else:
            phi2 = xx * xx - xx * yy + yy * yy + 3.0 * xy * xy
        if phi2 <= sy2:
            stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3] = txx, tyy, txy, tzz
            continue
        if plane_strain:
            phi_tr = math.sqrt(phi2)
            dl = (phi_tr - sy) / (c + 3.0 * mu)
            mean = (xx + yy + zz) / 3.0
            fd = sy / phi_tr
            xx = (xx - mean) * fd
            yy = (yy - mean) * fd
            zz = (zz - mean) * fd
            xy = xy * fd
            f = 1.5 * dl / sy
            dpxx, dpyy, dpxy, dpzz = f * xx, f * yy, 2.0 * f * xy, f * zz
        else:
            # invariants of the trial relative stress in the common eigenbasis of D and P
            a2 = 0.25 * (xx + yy) ** 2
            b2 = 0.75 * (xx - yy) ** 2 + 3.0 * xy * xy
            # first Newton step from d_lambda = 0 reuses the trial Phi^2 (= f2 there)
            excess = math.sqrt(phi2) / sy - 1.0
            dl = phi2 * excess / (a2 * pa + b2 * pb)
            for _ in range(_MAXIT):
                if excess <= _LAST_STEP:
                    # quadratic convergence: the error after the step just taken is O(excess^2),
                    # at round-off, so skip the evaluation that would only confirm it
                    break
                u = 1.0 + pa * dl
                v = 1.0 + pb * dl
                iuv = 1.0 / (u * v)  # one division for both scale factors
                ia = v * iuv
                ib = u * iuv
                f2 = a2 * ia * ia + b2 * ib * ib
                excess = math.sqrt(f2) / sy - 1.0  # Phi / sigma_y - 1 >= 0 (decreases to 0)
                # Newton on q = 1/Phi - 1/sigma_y:  q / q' = 2 f2 (1 - Phi/sigma_y) / (-d f2/d dl)
                dl += f2 * excess / (a2 * pa * ia * ia * ia + b2 * pb * ib * ib * ib)
            u = 1.0 + pa * dl
            v = 1.0 + pb * dl
            iuv = 1.0 / (u * v)
            ia = v * iuv
            ib = u * iuv
            sp = (xx + yy) * ia
            sm = (xx - yy) * ib
            xx = 0.5 * (sp + sm)
            yy = 0.5 * (sp - sm)
            xy = xy * ib
            zz = 0.0
            # n = 3 P xi / (2 sigma_y): the same n the projection above was built with, so
            # sigma = sigma_tr - D d_eps_p holds to round-off whatever the Newton residual
            f = dl / sy
            dpxx, dpyy, dpxy = f * (xx - 0.5 * yy), f * (yy - 0.5 * xx), 3.0 * f * xy
            dpzz = -(dpxx + dpyy)
            mean = 0.0
        # xx..zz hold dev(xi) in plane strain (the pressure is added back below), xi in plane stress
        g = k * dl
        bxx += g * xx
        byy += g * yy
        bxy += g * xy
        bzz += g * zz
        nxx, nyy, nxy, nzz = xx + bxx + mean, yy + byy + mean, xy + bxy, zz + bzz + mean
        work[p] += 0.5 * ((oxx + nxx) * dpxx + (oyy + nyy) * dpyy + (oxy + nxy) * dpxy
                          + (ozz + nzz) * dpzz)
        stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3] = nxx, nyy, nxy, nzz
        back[p, 0], back[p, 1], back[p, 2], back[p, 3] = bxx, byy, bxy, bzz
        if eps_p is not None:  # kept only when output (diagnostic_fields)
            eps_p[p, 0] += dpxx
            eps_p[p, 1] += dpyy
            eps_p[p, 2] += dpxy
        eps_eq[p] += dl


class BilinearVonMises(KinematicHardening):
    """Von Mises plasticity with linear (Ziegler) kinematic hardening, by return mapping.

    TOML keys besides ``E``, ``nu``, ``density``: ``yield_stress`` (> 0) and ``hardening``
    (alpha = post-yield tangent / E in uniaxial stress, 0 <= alpha < 1, required).
    Plane stress and plane strain (see the module docstring).
    """

    name = "bilinear_vonmises"
    def read_params(self, p):
        """Read ``yield_stress`` and ``hardening``.

        Parameters
        ----------
        p : Params
        """
        super().read_params(p)

    @property
    def params(self):
        """Kernel parameters ``[E, nu, yield_stress, hardening]`` (float64)."""
        return np.array([self.E, self.nu, self.yield_stress, self.hardening], dtype=np.float64)

    def describe(self):
        """One line for the start-up log."""
        return (f"{self.name} (E={self.E:g}, nu={self.nu:g}, density={self.density:g}, "
                f"yield_stress={self.yield_stress:g}, hardening={self.hardening:g}; {self.formulation})")

    def plastic_update(self, stress, de, state, mat_ids, which):
        """Advance ``stress`` and the plastic state in place by the strain increments ``de``
        (the plain kernel; :meth:`KinematicHardening.update_stress` adds the fracture option).

        Parameters
        ----------
        stress : ndarray (N, 4)
        de : ndarray (N, 3)
        state : dict of ndarray
            ``back_stress`` (N, 4), ``eps_p`` (N, 3), ``eps_p_eq`` (N,), ``plastic_work`` (N,).
        mat_ids : ndarray (N,) int32
        which : int
            Update only particles with ``mat_ids == which``; -1 updates all.
        """
        _update_bilinear(stress, de, state["back_stress"], state["eps_p"], state["eps_p_eq"],
                         state["plastic_work"], self.params, self.plane_strain, mat_ids, which)
