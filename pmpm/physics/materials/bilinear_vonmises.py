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
from pmpm.physics.materials.linear_elastic import elastic_increment, elastic_matrix

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


@nb.njit(cache=True, inline="always")
def _on_modes(v, fa, fb, fc):
    """The operator with eigenvalues fa, fb, fc on (1, 1, 0), (1, -1, 0), (0, 0, 1), applied to v."""
    sp = 0.5 * (v[0] + v[1]) * fa
    sm = 0.5 * (v[0] - v[1]) * fb
    return (sp + sm, sp - sm, v[2] * fc)


@nb.njit(cache=True, inline="always")
def _plane_stress_tangent(D, p, E, nu, sy, k, pa, pb, dl, xi, xt):
    """The consistent tangent of the projected return (plane stress) of particle p into D[p]:
    with A(dl) the return's scaling (1/(1 + pa dl) on (1, 1, 0), 1/(1 + pb dl) on (1, -1, 0)
    and (0, 0, 1), the eigenvectors D and the Mises matrix P share) and sigma = (1 + k dl) xi
    + eta0, xi = A xi_tr, differentiating the update and Phi(xi)^2 = sigma_y^2 gives

        C = (1 + k dl) A D - u v^T / w,  u = (1 + k dl) A' xi_tr + k xi,  v = D A P xi,
        w = xi^T P A' xi_tr,

    A' = dA/d dl. Not symmetric with Ziegler's rule (Prager's would make it so)."""
    ia = 1.0 / (1.0 + pa * dl)
    ib = 1.0 / (1.0 + pb * dl)
    da, db = -pa * ia * ia, -pb * ib * ib
    cps = E / (1.0 - nu * nu)
    # eigenvalues of D on (1, 1, 0), (1, -1, 0) and (0, 0, 1) (engineering shear: D_33 = G)
    ea, eb, eg = cps * (1.0 + nu), cps * (1.0 - nu), cps * 0.5 * (1.0 - nu)
    # P on the same vectors: 1/2, 3/2 and 3
    h = 1.0 + k * dl
    apt = _on_modes(xt, da, db, db)                       # A' xi_tr
    u = (h * apt[0] + k * xi[0], h * apt[1] + k * xi[1], h * apt[2] + k * xi[2])
    v = _on_modes(xi, ea * ia * 0.5, eb * ib * 1.5, eg * ib * 3.0)   # D A P xi
    pxi = _on_modes(xi, 0.5, 1.5, 3.0)
    w = pxi[0] * apt[0] + pxi[1] * apt[1] + pxi[2] * apt[2]
    for col in range(3):
        e = (1.0 if col == 0 else 0.0, 1.0 if col == 1 else 0.0, 1.0 if col == 2 else 0.0)
        adc = _on_modes(e, h * ia * ea, h * ib * eb, h * ib * eg)   # (1 + k dl) A D e_col
        for row in range(3):
            D[p, row, col] = adc[row] - u[row] * v[col] / w


@nb.njit(cache=True, inline="always")
def _plane_strain_tangent(D, p, E, nu, sy, c, s):
    """The consistent tangent of the radial return with Ziegler's rule on dev(xi) (plane
    strain) into D[p]: dev(sigma) = beta(Phi_tr) s_tr + dev(eta0), beta = (sigma_y / Phi)
    3 mu / (c + 3 mu) + c / (c + 3 mu), so C = K 1 (x) 1 + 2 mu beta I_dev
    + beta'(Phi_tr) 3 mu / Phi_tr s_tr (x) s_tr (in-plane rows and columns). ``s`` holds
    dev(xi_tr) (xx, yy, xy, zz)."""
    mu = E / (2.0 * (1.0 + nu))
    kb = E / (3.0 * (1.0 - 2.0 * nu))
    phi = math.sqrt(1.5 * (s[0] * s[0] + s[1] * s[1] + s[3] * s[3]) + 3.0 * s[2] * s[2])
    r = 3.0 * mu / (c + 3.0 * mu)
    beta = sy / phi * r + c / (c + 3.0 * mu)
    f = -(sy / (phi * phi)) * r * 3.0 * mu / phi
    D[p, 0, 0] = kb + 4.0 / 3.0 * mu * beta
    D[p, 1, 1] = D[p, 0, 0]
    D[p, 0, 1] = D[p, 1, 0] = kb - 2.0 / 3.0 * mu * beta
    D[p, 0, 2] = D[p, 1, 2] = D[p, 2, 0] = D[p, 2, 1] = 0.0
    D[p, 2, 2] = mu * beta
    sv = (s[0], s[1], s[2])
    for a in range(3):
        for b in range(3):
            D[p, a, b] += f * sv[a] * sv[b]


@nb.njit(cache=True)
def _bilinear_tangent(D, stress0, back0, stress1, back1, eq0, eq1, de, params, plane_strain, mat_ids, which):
    """The consistent tangent of ``_update_bilinear`` (its increment de from stress0, back0 to
    stress1, back1 with d_lambda = eq1 - eq0): the elastic matrix where the step stayed
    elastic, else the derivative of the return mapping."""
    E, nu, sy, alpha = params[0], params[1], params[2], params[3]
    c = alpha * E / (1.0 - alpha)
    k = c / sy
    mu = E / (2.0 * (1.0 + nu))
    pa = k + E / (2.0 * sy * (1.0 - nu))
    pb = k + 3.0 * mu / sy
    for p in range(D.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        dl = eq1[p] - eq0[p]
        if not dl > 0.0:
            elastic_matrix(E, nu, plane_strain, D, p)
            continue
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        xt = (stress0[p, 0] + ds[0] - back0[p, 0], stress0[p, 1] + ds[1] - back0[p, 1],
              stress0[p, 2] + ds[2] - back0[p, 2], stress0[p, 3] + ds[3] - back0[p, 3])
        if plane_strain:
            mean = (xt[0] + xt[1] + xt[3]) / 3.0
            _plane_strain_tangent(D, p, E, nu, sy, c, (xt[0] - mean, xt[1] - mean, xt[2], xt[3] - mean))
        else:
            xi = (stress1[p, 0] - back1[p, 0], stress1[p, 1] - back1[p, 1], stress1[p, 2] - back1[p, 2])
            _plane_stress_tangent(D, p, E, nu, sy, k, pa, pb, dl, xi, (xt[0], xt[1], xt[2]))


class BilinearVonMises(KinematicHardening):
    """Von Mises plasticity with linear (Ziegler) kinematic hardening, by return mapping.

    TOML keys besides ``E``, ``nu``, ``density``: ``yield_stress`` (> 0) and ``hardening``
    (alpha = post-yield tangent / E in uniaxial stress, 0 <= alpha < 1, required).
    Plane stress and plane strain (see the module docstring).
    """

    name = "bilinear_vonmises"
    has_tangent = True

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

    def tangent(self, stress0, state0, stress1, state1, de, D, mat_ids, which):
        """The consistent (algorithmic) tangent of the return mapping (``_bilinear_tangent``):
        Newton's method on a yielding structure converges quadratically with it."""
        _bilinear_tangent(D, stress0, state0["back_stress"], stress1, state1["back_stress"],
                          state0["eps_p_eq"], state1["eps_p_eq"], de, self.params, self.plane_strain,
                          mat_ids, which)
