"""Smooth von Mises plasticity with Ziegler kinematic hardening (the paper's model, design.md section 5).

The plastic multiplier is extended over the whole stress space by two Heaviside-type factors,
so there is no elastic range and no return mapping; the stress rate is a tangent modulus,

    d_sigma = E_t d_eps,   E_t = D (I - H1 H2 R),   R = n n^T D / (n^T D n + n^T G),

with s = sigma - eta, Phi = von Mises of s, Phi0 = sigma_y, n = dPhi/dsigma, H1 = |Phi/Phi0|^N,
H2 = 1/2 + 1/2 sign(s . d_eps), G = c s / Phi0, c = alpha E / (1 - alpha), and

    d_lambda = H1 H2 (n^T D d_eps) / (n^T D n + n^T G),  d_eps_p = d_lambda n,  d_eta = d_lambda G.

Formulations
------------
plane_stress
    The paper's setting: 3-component Voigt (sxx, syy, sxy), plane-stress D and the plane-stress
    von Mises function; szz and the back stress's zz slot stay 0 (Ziegler's rule keeps eta in the
    plane because s has no zz part).
plane_strain
    The same equations with 4 components (sxx, syy, sxy, szz): 3D von Mises of s, 3D isotropic D
    restricted to d_eps_zz = 0, and s replaced by its deviator in H2 and in G. With the full s the
    pressure, to which von Mises is blind, dominates s . d_eps and switches plasticity off under
    confinement: a biaxial plane-strain path then drove Phi to almost 5 sigma_y. With dev(s),
    sign(dev(s) . d_eps) = sign(n^T D d_eps), the consistent loading test, and eta stays deviatoric
    (Ziegler on dev(s) is Prager's rule here). For a deviatoric n, D n = 2 mu n and
    n^T D n = 3 mu, so this version costs no more than plane stress.

Known properties of the model as written (not defects of the integration)
--------------------------------------------------------------------------
- Uniaxial stress reduces exactly to the 1D Bouc-Wen law only for nu -> 1/2 and alpha = 0:
  the reduction has n^T D n = E (5/4 - nu)/(1 - nu^2) instead of E, and n^T G = c Phi/Phi0
  instead of c. At steel values (nu = 0.3, alpha = 0.05, N = 10) the two laws differ by about
  0.1 % of the peak stress in the elastic-plastic transition; the yield plateau and the
  post-yield tangent alpha E are the same.
- In plane stress H2 tests s . d_eps (as design.md writes it), not n^T D d_eps, and the two
  can differ in sign on non-proportional paths: then d_lambda < 0, or Phi grows past Phi0
  elastically while H2 = 0 until a loading increment (H1 > 1) pulls it back. Proportional and
  shear-reversal paths are unaffected; tension, shear, then shear reversed with tension went
  0.8 % past Phi0 (the xfail test in tests/unit/test_plasticity_point.py), random 5-leg strain
  paths up to about 3 %. With a consistent H2, d Phi = (1 - H1) n^T D d_eps while loading, so
  Phi could not pass Phi0.

State
-----
back_stress (4,)  eta, same layout as stress (zz slot 0 in plane stress)
eps_p (3,)        plastic strain (exx, eyy, gxy), engineering shear; ezz_p = -(exx_p + eyy_p);
                  kept only when the output asks for it (None otherwise: nothing reads it)
eps_p_eq ()       sum of sqrt(2/3 d_eps_p : d_eps_p) (tensor shear, zz included); for the von Mises
                  flow direction sqrt(2/3 n : n) = 1, so this is sum |d_lambda|
plastic_work ()   integral of sigma . d_eps_p per unit volume, so that kinetic + elastic strain
                  energy + sum V plastic_work = external work (it includes the energy stored in the
                  back stress, which the elastic energy 1/2 sigma : C^-1 : sigma does not hold)

Integration
-----------
Each increment is cut into sub-steps whose largest strain component is at most
h = eps_y min(0.1, 1/N), eps_y = sigma_y / E, and each sub-step is advanced with the explicit
midpoint rule (RK2). The 1/N bound is there because near the surface 1 - Phi/Phi0 relaxes at a
rate of about N per eps_y of strain (and up to 1.5 N on biaxial paths), and RK2 is stable only for
rate * step <= 2; for the paper's N = 10 both bounds coincide at 0.1 eps_y. The error is second
order: a uniaxial +-4 eps_y cycle driven in steps of 0.1 / 0.05 / 0.01 eps_y is off by
3e-3 / 6e-4 / 2e-5 of the peak stress (explicit MPM steps are usually far smaller than 0.1 eps_y).
Plastic work uses the sub-step's mean stress, which makes (elastic energy + plastic work) increase
by exactly mean(sigma) . d_eps per sub-step, to round-off.

Cost: increments within one sub-step (nearly all in explicit MPM) of a model with an integer N
take the block path of _update_smooth: both RK2 stages evaluated for 64 particles at a time in
a branch-free loop the compiler vectorises: 19 ns per stress point for the kernel alone on
1,000,000 yielding points (13 ns within a step, docs/performance.md), whatever the stress
state; the scalar loop it replaced took 42 ns where the points yield. Other increments are sub-stepped by the
scalar path, where sub-steps along which H1 stays below 2^-53 (Phi under about 0.025 sigma_y
for N = 10) and unloading sub-steps are one elastic update, exactly; loading ones evaluate the
rate twice (one sqrt, one division, and an integer power when N is an integer, else one pow,
per evaluation).
"""
import math

import numba as nb
import numpy as np

from pmpm.physics.materials.base import KinematicHardening
from pmpm.physics.materials.linear_elastic import elastic_increment, elastic_matrix

__all__ = ["SmoothVonMises", "smooth_rate"]

# Phi below this fraction of sigma_y has no usable flow direction; H1 = (1e-12)^N is zero anyway.
_PHI_FLOOR = 1e-12
# A sub-step is taken as purely elastic when H1 < this bound everywhere along it: the plastic part
# of the stress increment is at most H1 times the elastic one (in the energy norm), so it is then
# below the rounding of the addition itself and the shortcut is exact to round-off.
_H1_ROUNDOFF = 2.0 ** -53
# beyond this use bilinear_vonmises (the sub-step count grows like N)
_MAX_SMOOTHNESS = 1000.0
# integer smoothness up to this value uses repeated squaring (a few multiplies) instead of pow
_MAX_INT_POWER = 1024


@nb.njit(cache=True, inline="always")
def _ipow(x, k, xfloor):
    """x**k for an integer 0 < k < 2048 by repeated squaring, over a fixed number of bits so
    that the loop unrolls into straight-line code (which the block path vectorises). x is
    floored where x**k would leave the normal numbers: subnormal arithmetic is a hundred times
    slower, and an H1 under 1e-300 is zero for every purpose here."""
    x = max(x, xfloor)  # xfloor = 1e-300 ** (1 / k), see _power_floor
    out = 1.0
    for bit in range(11):
        if (k >> bit) & 1:
            out *= x
        if k >> (bit + 1):  # no squaring past the highest bit of k
            x *= x
    return out


@nb.njit(cache=True, inline="always")
def _h1(phi2, phi, isy, N, kint, xfloor):
    """H1 = (Phi / sigma_y)^N; ``kint`` > 0 selects an exact integer power (N = kint).
    ``N`` None (the caller guarantees kint > 0) compiles the pow, which cannot be vectorised,
    out of the caller (see _rk2_block)."""
    if N is None or kint > 0:
        if kint % 2 == 0:
            return _ipow(phi2 * isy * isy, kint // 2, xfloor)
        return _ipow(phi * isy, kint, xfloor)
    return (phi2 * isy * isy) ** (0.5 * N)


@nb.njit(cache=True, inline="always")
def _power_floor(kint):
    """The floor of _ipow's base for H1 = _h1(...) with this kint (once per kernel call)."""
    if kint <= 0:
        return 0.0
    k = kint // 2 if kint % 2 == 0 else kint
    return 1e-300 ** (1.0 / k)


@nb.njit(cache=True, inline="always")
def _phi2(plane_strain, tx, ty, txy, tz):
    """Phi^2 of a relative stress (plane-stress von Mises, or 3D von Mises in plane strain)."""
    if plane_strain:
        return 0.5 * ((tx - ty) ** 2 + (ty - tz) ** 2 + (tz - tx) ** 2) + 3.0 * txy * txy
    return tx * tx - tx * ty + ty * ty + 3.0 * txy * txy


@nb.njit(cache=True, inline="always")
def _load(plane_strain, consistent, tx, ty, txy, tz, dexx, deyy, dgxy, dse):
    """The loading indicator of H2: s . d_eps (dev(s) . d_eps in plane strain); with
    ``consistent`` in plane stress, m . D d_eps (m = Phi n, ``dse`` = D d_eps): the sign of
    n^T D d_eps, the consistent loading test (plane strain's dev(s) . d_eps has that sign)."""
    if plane_strain:
        mean = (tx + ty + tz) / 3.0
        return (tx - mean) * dexx + (ty - mean) * deyy + txy * dgxy
    if consistent:
        return (tx - 0.5 * ty) * dse[0] + (ty - 0.5 * tx) * dse[1] + 3.0 * txy * dse[2]
    return tx * dexx + ty * deyy + txy * dgxy


@nb.njit(cache=True, inline="always")
def smooth_rate(plane_strain, consistent, cps, nu, mu, isy, N, kint, xfloor, c, dse,
                sxx, syy, sxy, szz, bxx, byy, bxy, bzz, dexx, deyy, dgxy):
    """Increments of stress, back stress and plastic strain for one strain increment.

    Parameters
    ----------
    plane_strain : bool
    consistent : bool
        Plane stress: H2 from the sign of n^T D d_eps instead of s . d_eps (the implicit
        integrator's update, continuous where the loading test switches: the plastic part is
        proportional to n^T D d_eps, which is then zero there; see SmoothVonMises.use_integrator).
    cps, nu, mu, isy, N, c : float
        E / (1 - nu^2), Poisson ratio, shear modulus, 1 / sigma_y, smoothness,
        Ziegler modulus alpha E / (1 - alpha).
    kint : int
        N as an integer when it is one (faster exact power), else 0.
    xfloor : float
        ``_power_floor(kint)``.
    dse : tuple of 4 float
        The elastic stress increment D d_eps (the same for both stages, so computed once).
    sxx, syy, sxy, szz, bxx, byy, bxy, bzz : float
        Stress and back stress where the rate is evaluated.
    dexx, deyy, dgxy : float
        Strain increment (engineering shear).

    Returns
    -------
    tuple of float
        (dsxx, dsyy, dsxy, dszz, dbxx, dbyy, dbxy, dbzz, dpxx, dpyy, dpxy, dlambda);
        the plastic zz strain is -(dpxx + dpyy).
    """
    ds = dse
    tx = sxx - bxx
    ty = syy - byy
    txy = sxy - bxy
    tz = szz - bzz
    if plane_strain:
        mean = (tx + ty + tz) / 3.0
        tx -= mean
        ty -= mean
        tz -= mean
        phi2 = 1.5 * (tx * tx + ty * ty + tz * tz) + 3.0 * txy * txy
    else:
        phi2 = tx * tx - tx * ty + ty * ty + 3.0 * txy * txy
    load = tx * dexx + ty * deyy + txy * dgxy  # s . d_eps (dev(s) in plane strain); d_eps_zz = 0
    if consistent and not plane_strain:
        load = (tx - 0.5 * ty) * ds[0] + (ty - 0.5 * tx) * ds[1] + 3.0 * txy * ds[2]   # m . D d_eps
    # no branches (the block path vectorises this): an unloading or stress-free point gets
    # beta = 0, which leaves exactly the elastic increment D d_eps
    active = load >= 0.0 and phi2 * isy * isy > _PHI_FLOOR * _PHI_FLOOR
    h2 = 1.0 if load > 0.0 else 0.5
    phi = math.sqrt(phi2)
    h1 = _h1(phi2, phi, isy, N, kint, xfloor)
    # Work with m = Phi n (no 1/Phi needed): with n = m / Phi,
    #   d_lambda n = beta m,  beta = H1 H2 (D m . d_eps) / (m . D m + c Phi^3 / sigma_y),
    # which is the design's d_lambda = H1 H2 (n.D d_eps)/(n.D n + n.G) with n.G = c Phi/sigma_y
    # (G = c s/sigma_y and n.s = Phi), multiplied through by Phi^2. One division per stage.
    if plane_strain:
        mxx = 1.5 * tx  # tx..tz hold dev(s) here, so G and eta stay deviatoric
        myy = 1.5 * ty
        mzz = 1.5 * tz
        mxy = 3.0 * txy
        dmxx = 2.0 * mu * mxx
        dmyy = 2.0 * mu * myy
        dmxy = mu * mxy
        dmzz = 2.0 * mu * mzz
        mdm = 3.0 * mu * phi2  # m deviatoric with sqrt(2/3 m:m) = Phi
    else:
        mxx = tx - 0.5 * ty
        myy = ty - 0.5 * tx
        mxy = 3.0 * txy
        mzz = 0.0
        dmxx = cps * (mxx + nu * myy)
        dmyy = cps * (myy + nu * mxx)
        dmxy = cps * 0.5 * (1.0 - nu) * mxy
        dmzz = 0.0
        mdm = mxx * dmxx + myy * dmyy + mxy * dmxy
    beta = h1 * h2 * (dmxx * dexx + dmyy * deyy + dmxy * dgxy) / (mdm + c * phi2 * phi * isy)
    beta = beta if active else 0.0  # (0/0 at a stress-free point is discarded here)
    dl = beta * phi
    g = dl * c * isy
    return (ds[0] - beta * dmxx, ds[1] - beta * dmyy, ds[2] - beta * dmxy, ds[3] - beta * dmzz,
            g * tx, g * ty, g * txy, g * tz,
            beta * mxx, beta * myy, beta * mxy, dl)


@nb.njit(cache=True, inline="always")
def _integrate(nsub, p, stress, de, back, plane_strain, consistent, E, nu, cps, mu, isy, N, kint,
               xfloor, c, phi_quiet2):
    """Particle p's increment ``de[p]`` in ``nsub`` equal RK2 sub-steps from its stored state.

    Returns the end state and the increment's plastic changes, (sxx, syy, sxy, szz, bxx, byy,
    bxy, bzz, dpxx, dpyy, dpxy, d_eps_p_eq, d_work, plastic), without storing them."""
    inv = 1.0 / nsub
    dexx = de[p, 0] * inv
    deyy = de[p, 1] * inv
    dgxy = de[p, 2] * inv
    sxx, syy, sxy, szz = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
    bxx, byy, bxy, bzz = back[p, 0], back[p, 1], back[p, 2], back[p, 3]
    pxx = pyy = pxy = eq = w = 0.0  # this increment's plastic changes
    plastic = False
    dse = elastic_increment(E, nu, plane_strain, dexx, deyy, dgxy)
    # growth of the loading indicator over an elastic half step: d_eps . D d_eps >= 0
    # (its deviatoric part 2 mu dev(d_eps) . d_eps >= 0 in plane strain)
    work_de = _load(plane_strain, consistent, dse[0], dse[1], dse[2], dse[3], dexx, deyy, dgxy, dse)
    quiet = -1.0  # Phi(D d_eps)^2 / 2, computed when first needed
    for _ in range(nsub):
        phi2 = _phi2(plane_strain, sxx - bxx, syy - byy, sxy - bxy, szz - bzz)
        if phi2 < phi_quiet2:
            if quiet < 0.0:
                quiet = 0.5 * _phi2(plane_strain, dse[0], dse[1], dse[2], dse[3])
            # Phi is a (semi)norm, so along the sub-step Phi <= Phi(start) + Phi(D d_eps)/2
            # (the plastic part is negligible by construction) and (a + b)^2 <= 2 a^2 + 2 b^2
            # gives a bound with no sqrt
            if 2.0 * phi2 + quiet < phi_quiet2:
                sxx += dse[0]
                syy += dse[1]
                sxy += dse[2]
                szz += dse[3]
                continue
        load = _load(plane_strain, consistent, sxx - bxx, syy - byy, sxy - bxy, szz - bzz, dexx, deyy,
                     dgxy, dse)
        if load + 0.5 * work_de < 0.0:
            # s . d_eps < 0 at the start and at the elastic midpoint (it grows by
            # 0.5 d_eps . D d_eps): both stages are elastic, so the step is exactly D d_eps.
            # This is the whole cost on unloading branches.
            sxx += dse[0]
            syy += dse[1]
            sxy += dse[2]
            szz += dse[3]
            continue
        k = smooth_rate(plane_strain, consistent, cps, nu, mu, isy, N, kint, xfloor, c, dse, sxx, syy, sxy, szz,
                        bxx, byy, bxy, bzz, dexx, deyy, dgxy)
        m = smooth_rate(plane_strain, consistent, cps, nu, mu, isy, N, kint, xfloor, c, dse,
                        sxx + 0.5 * k[0], syy + 0.5 * k[1], sxy + 0.5 * k[2], szz + 0.5 * k[3],
                        bxx + 0.5 * k[4], byy + 0.5 * k[5], bxy + 0.5 * k[6], bzz + 0.5 * k[7],
                        dexx, deyy, dgxy)
        plastic = True
        # plastic work with the sub-step's mean stress closes the energy balance exactly
        w += ((sxx + 0.5 * m[0]) * m[8] + (syy + 0.5 * m[1]) * m[9] + (sxy + 0.5 * m[2]) * m[10]
              - (szz + 0.5 * m[3]) * (m[8] + m[9]))
        sxx += m[0]
        syy += m[1]
        sxy += m[2]
        szz += m[3]
        bxx += m[4]
        byy += m[5]
        bxy += m[6]
        bzz += m[7]
        pxx += m[8]
        pyy += m[9]
        pxy += m[10]
        eq += abs(m[11])
    return sxx, syy, sxy, szz, bxx, byy, bxy, bzz, pxx, pyy, pxy, eq, w, plastic


@nb.njit(cache=True, inline="always")
def _store(p, r, stress, back, eps_p, eps_eq, work):
    """Store an ``_integrate`` result ``r`` as particle p's state."""
    stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3] = r[0], r[1], r[2], r[3]
    if r[13]:  # elastic points leave their state untouched (saves the stores)
        back[p, 0], back[p, 1], back[p, 2], back[p, 3] = r[4], r[5], r[6], r[7]
        if eps_p is not None:  # kept only when output (diagnostic_fields)
            eps_p[p, 0] += r[8]
            eps_p[p, 1] += r[9]
            eps_p[p, 2] += r[10]
        eps_eq[p] += r[11]
        work[p] += r[12]


@nb.njit(cache=True, inline="always")
def _substepped(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu, cps, mu, isy, N,
                kint, xfloor, c, h, phi_quiet2):
    """One particle's increment in sub-steps of at most ``h`` (any increment, any N)."""
    big = max(abs(de[p, 0]), abs(de[p, 1]), abs(de[p, 2]))
    nsub = 1
    if big > h:
        nsub = int(math.ceil(big / h))
    r = _integrate(nsub, p, stress, de, back, plane_strain, False, E, nu, cps, mu, isy, N, kint, xfloor, c,
                   phi_quiet2)
    _store(p, r, stress, back, eps_p, eps_eq, work)


@nb.njit(cache=True, inline="always")
def _substepped_continuous(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu, cps, mu,
                           isy, N, kint, xfloor, c, h, phi_quiet2):
    """The increment as a continuous function of ``de[p]`` (the implicit integrator's update).

    ``_substepped`` takes ceil(r) sub-steps, r = max|de| / h: where r crosses an integer the
    sub-step count jumps and the result with it, by the RK2 error (0.2 % of sigma_y from one
    sub-step to two near the yield surface). Newton's iterations on a step whose increments
    sit at such a jump cannot converge: the residual has no root there (issue 37: the
    Northridge record stalled at 8.82 s at the smallest step). Here, for r > 1,
    n = floor(r) and n + 1 sub-steps are blended with the weights 1 - (r - n) and r - n: equal
    to n sub-steps at r = n, to n + 1 at r -> n + 1, continuous in between, and as accurate as
    either (both integrate the same rate equation with sub-steps of at most h). Twice the cost
    of the explicit update for the points that need it; the explicit integrator keeps
    ``_substepped`` (the paper's update, bit for bit)."""
    r = _continuous(p, stress, de, back, plane_strain, E, nu, cps, mu, isy, N, kint, xfloor, c, h,
                    phi_quiet2)
    # an elastic pair (both False) stores the stress only: its back stress etc. are unchanged
    _store(p, r, stress, back, eps_p, eps_eq, work)


@nb.njit(cache=True, inline="always")
def _continuous(p, stress, de, back, plane_strain, E, nu, cps, mu, isy, N, kint, xfloor, c, h,
                phi_quiet2):
    """The result of ``_substepped_continuous`` (``_integrate``'s tuple), not stored."""
    big = max(abs(de[p, 0]), abs(de[p, 1]), abs(de[p, 2]))
    r = big / h
    if r <= 1.0:
        return _integrate(1, p, stress, de, back, plane_strain, True, E, nu, cps, mu, isy, N, kint,
                          xfloor, c, phi_quiet2)
    n = int(math.floor(r))
    theta = r - n
    a = _integrate(n, p, stress, de, back, plane_strain, True, E, nu, cps, mu, isy, N, kint, xfloor, c,
                   phi_quiet2)
    if theta == 0.0:
        return a
    b = _integrate(n + 1, p, stress, de, back, plane_strain, True, E, nu, cps, mu, isy, N, kint, xfloor,
                   c, phi_quiet2)
    wa = 1.0 - theta
    return (wa * a[0] + theta * b[0], wa * a[1] + theta * b[1], wa * a[2] + theta * b[2],
            wa * a[3] + theta * b[3], wa * a[4] + theta * b[4], wa * a[5] + theta * b[5],
            wa * a[6] + theta * b[6], wa * a[7] + theta * b[7], wa * a[8] + theta * b[8],
            wa * a[9] + theta * b[9], wa * a[10] + theta * b[10], wa * a[11] + theta * b[11],
            wa * a[12] + theta * b[12], a[13] or b[13])


@nb.njit(cache=True, inline="always")
def _rk2_block(X, Y, nq, plane_strain, consistent, E, nu, cps, mu, isy, kint, xfloor, c):
    """Both RK2 stages of a block's single-sub-step increments from X into Y (see
    _update_smooth); no branches on particle data, contiguous buffers: vectorised."""
    for q in range(nq):
        sxx, syy, sxy, szz = X[0, q], X[1, q], X[2, q], X[3, q]
        bxx, byy, bxy, bzz = X[4, q], X[5, q], X[6, q], X[7, q]
        dexx, deyy, dgxy = X[8, q], X[9, q], X[10, q]
        dse = elastic_increment(E, nu, plane_strain, dexx, deyy, dgxy)
        k1 = smooth_rate(plane_strain, consistent, cps, nu, mu, isy, None, kint, xfloor, c, dse, sxx, syy, sxy, szz,
                         bxx, byy, bxy, bzz, dexx, deyy, dgxy)
        m = smooth_rate(plane_strain, consistent, cps, nu, mu, isy, None, kint, xfloor, c, dse,
                        sxx + 0.5 * k1[0], syy + 0.5 * k1[1], sxy + 0.5 * k1[2],
                        szz + 0.5 * k1[3], bxx + 0.5 * k1[4], byy + 0.5 * k1[5],
                        bxy + 0.5 * k1[6], bzz + 0.5 * k1[7], dexx, deyy, dgxy)
        for k in range(12):
            Y[k, q] = m[k]
        Y[12, q] = ((sxx + 0.5 * m[0]) * m[8] + (syy + 0.5 * m[1]) * m[9]
                    + (sxy + 0.5 * m[2]) * m[10] - (szz + 0.5 * m[3]) * (m[8] + m[9]))


@nb.njit(cache=True)
def _substepped_py(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu, cps, mu, isy, N,
                   kint, xfloor, c, h, phi_quiet2):
    """_substepped callable from Python: the reference the block path is tested against."""
    _substepped(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu, cps, mu, isy, N,
                kint, xfloor, c, h, phi_quiet2)


@nb.njit(cache=True)
def _power_floor_py(kint):
    return _power_floor(kint)


@nb.njit(cache=True, inline="always")
def _constants(params):
    """The update's constants from ``params`` = [E, nu, yield_stress, hardening, N]:
    (E, nu, sigma_y, N, N as an integer or 0, _ipow's floor, the Ziegler modulus c, the
    sub-step bound h, E / (1 - nu^2), mu, 1 / sigma_y, the quiet bound of Phi^2)."""
    E, nu, sy, alpha, N = params[0], params[1], params[2], params[3], params[4]
    kint = 0
    if N == math.floor(N) and N <= _MAX_INT_POWER:
        kint = int(N)
    xfloor = _power_floor(kint)
    c = alpha * E / (1.0 - alpha)
    h = sy / E * min(0.1, 1.0 / N)
    cps = E / (1.0 - nu * nu)
    mu = E / (2.0 * (1.0 + nu))
    isy = 1.0 / sy
    phi_quiet2 = (sy * _H1_ROUNDOFF ** (1.0 / N)) ** 2  # H1 < _H1_ROUNDOFF below this Phi^2
    return E, nu, sy, N, kint, xfloor, c, h, cps, mu, isy, phi_quiet2


#: particles per block of the vectorised path (its ~20 buffers stay in the L1 cache)
_BLOCK = 64


# error_model="numpy": a float division by zero gives inf/nan instead of raising, so the
# division of each stage carries no exception branch and the block loop can be vectorised (the
# one 0/0, at a stress-free point, is discarded by smooth_rate)
@nb.njit(cache=True, error_model="numpy")
def _update_smooth(stress, de, back, eps_p, eps_eq, work, params, plane_strain, mat_ids, which,
                   continuous=False):
    """The particle loop of :meth:`SmoothVonMises.update_stress` (arrays updated in place).

    Two paths. Increments within one sub-step (nearly all of them in explicit MPM, whose
    strain increments are a small fraction of eps_y) of a model with an integer N go through
    the block path: a block's states are copied into contiguous buffers, both RK2 stages of
    every particle are evaluated in one branch-free loop that the compiler vectorises (8
    particles per AVX-512 instruction: the sqrt and the division of each stage no longer
    serialise the particles), and the results are copied back. It evaluates the model even
    where the scalar path would take its exact elastic shortcuts; with beta ~ H1 below 2^-53
    there, the two agree to round-off. Everything else takes the sub-stepped scalar path, or with
    ``continuous`` (the implicit integrator) its blend that is continuous in the increment
    (``_substepped_continuous``)."""
    E, nu, sy, N, kint, xfloor, c, h, cps, mu, isy, phi_quiet2 = _constants(params)
    n = stress.shape[0]
    if kint == 0:
        for p in range(n):
            if which >= 0 and mat_ids[p] != which:
                continue
            if continuous:
                _substepped_continuous(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E,
                                       nu, cps, mu, isy, N, kint, xfloor, c, h, phi_quiet2)
            else:
                _substepped(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu, cps,
                            mu, isy, N, kint, xfloor, c, h, phi_quiet2)
        return
    X = np.empty((11, _BLOCK))   # in: stress (0-3), back stress (4-7), strain increment (8-10)
    Y = np.empty((13, _BLOCK))   # out: the 12 increments of smooth_rate's second stage, work
    fast = np.empty(_BLOCK, np.bool_)
    for p0 in range(0, n, _BLOCK):
        nq = min(_BLOCK, n - p0)
        if which >= 0:  # several materials: skip blocks with none of this one's particles
            mine = 0
            for q in range(nq):
                mine += mat_ids[p0 + q] == which
            if mine == 0:
                continue
        for q in range(nq):
            p = p0 + q
            for k in range(4):
                X[k, q] = stress[p, k]
                X[4 + k, q] = back[p, k]
            for k in range(3):
                X[8 + k, q] = de[p, k]
            fast[q] = max(abs(de[p, 0]), abs(de[p, 1]), abs(de[p, 2])) <= h
        # the loop with constant formulation flags, so that no branch on them is left in it
        if plane_strain:
            _rk2_block(X, Y, nq, True, False, E, nu, cps, mu, isy, kint, xfloor, c)
        elif continuous:   # the implicit update's loading test (use_integrator)
            _rk2_block(X, Y, nq, False, True, E, nu, cps, mu, isy, kint, xfloor, c)
        else:
            _rk2_block(X, Y, nq, False, False, E, nu, cps, mu, isy, kint, xfloor, c)
        for q in range(nq):
            p = p0 + q
            if which >= 0 and mat_ids[p] != which:
                continue
            if not fast[q]:
                if continuous:
                    _substepped_continuous(p, stress, de, back, eps_p, eps_eq, work, plane_strain,
                                           E, nu, cps, mu, isy, N, kint, xfloor, c, h, phi_quiet2)
                else:
                    _substepped(p, stress, de, back, eps_p, eps_eq, work, plane_strain, E, nu,
                                cps, mu, isy, N, kint, xfloor, c, h, phi_quiet2)
                continue
            for k in range(4):
                stress[p, k] = X[k, q] + Y[k, q]
                back[p, k] = X[4 + k, q] + Y[4 + k, q]
            if eps_p is not None:  # kept only when output (diagnostic_fields)
                for k in range(3):
                    eps_p[p, k] += Y[8 + k, q]
            eps_eq[p] += abs(Y[11, q])
            work[p] += Y[12, q]


@nb.njit(cache=True)
def _smooth_tangent(D, stress, back, de, params, plane_strain, mat_ids, which):
    """The paper's tangent modulus E_t = D - H1 H2 (D n)(D n)^T / (n^T D n + n^T G) at the
    stress and back stress ``stress``, ``back`` (the end of the increment), H2 from the
    direction of the increment ``de`` (the loading test of ``smooth_rate``). Written with
    m = Phi n as ``smooth_rate`` does: D - H1 H2 (D m)(D m)^T / (m^T D m + c Phi^3 / sigma_y)."""
    E, nu, sy, alpha, N = params[0], params[1], params[2], params[3], params[4]
    c = E * alpha / (1.0 - alpha)   # (the Ziegler modulus of smooth_rate; spelled apart for tests/mutation)
    cps = E / (1.0 - nu * nu)
    mu = E / (2.0 * (1.0 + nu))
    isy = 1.0 / sy
    for p in range(D.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        elastic_matrix(E, nu, plane_strain, D, p)
        tx = stress[p, 0] - back[p, 0]
        ty = stress[p, 1] - back[p, 1]
        txy = stress[p, 2] - back[p, 2]
        tz = stress[p, 3] - back[p, 3]
        if plane_strain:
            mean = (tx + ty + tz) / 3.0
            tx -= mean
            ty -= mean
            tz -= mean
            phi2 = 1.5 * (tx * tx + ty * ty + tz * tz) + 3.0 * txy * txy
            dm0, dm1, dm2 = 3.0 * mu * tx, 3.0 * mu * ty, 3.0 * mu * txy
            mdm = 3.0 * mu * phi2
        else:
            phi2 = tx * tx - tx * ty + ty * ty + 3.0 * txy * txy
            mxx, myy, mxy = tx - 0.5 * ty, ty - 0.5 * tx, 3.0 * txy
            dm0, dm1 = cps * (mxx + nu * myy), cps * (myy + nu * mxx)
            dm2 = cps * 0.5 * (1.0 - nu) * mxy
            mdm = mxx * dm0 + myy * dm1 + mxy * dm2
        load = tx * de[p, 0] + ty * de[p, 1] + txy * de[p, 2]
        if load < 0.0 or phi2 * isy * isy <= _PHI_FLOOR * _PHI_FLOOR:
            continue  # unloading or stress-free: elastic
        h2 = 1.0 if load > 0.0 else 0.5
        phi = math.sqrt(phi2)
        h1 = (phi * isy) ** N
        f = h1 * h2 / (mdm + c * phi2 * phi * isy)
        dm = (dm0, dm1, dm2)
        for a in range(3):
            for b in range(3):
                D[p, a, b] -= f * dm[a] * dm[b]


#: the strain perturbation of the consistent tangent's differences, in yield strains: far above
#: round-off (the stress differences are then 1e-7 of sigma_y, whose rounding is 1e-16 of it)
#: and far below the strains over which the update's derivative changes (a sub-step, 0.1 eps_y)
_TANGENT_PROBE = 1e-6


# error_model="numpy": smooth_rate divides 0/0 at a stress-free point and discards the result
@nb.njit(cache=True, error_model="numpy")
def _consistent_tangent(D, stress0, back0, de, params, plane_strain, mat_ids, which):
    """The derivative of the implicit update (``_substepped_continuous`` from the step's start
    ``stress0``, ``back0`` by the increment ``de``) with respect to ``de``, by forward
    differences of the update itself: the tangent Newton's method converges with (Simo &
    Taylor 1985; by differences as Miehe 1996 and Perez-Foguet et al. 2000). Points whose update
    is elastic get the elastic matrix (the update is then exactly D de). Not symmetric in
    general (the loading test and the sub-steps): an LU factorisation takes it."""
    E, nu, sy, N, kint, xfloor, c, h, cps, mu, isy, phi_quiet2 = _constants(params)
    probe = _TANGENT_PROBE * sy / E
    s1 = np.empty((1, 4))
    b1 = np.empty((1, 4))
    d1 = np.empty((1, 3))
    for p in range(D.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        elastic_matrix(E, nu, plane_strain, D, p)
        for k in range(4):
            s1[0, k] = stress0[p, k]
            b1[0, k] = back0[p, k]
        for k in range(3):
            d1[0, k] = de[p, k]
        base = _continuous(0, s1, d1, b1, plane_strain, E, nu, cps, mu, isy, N, kint, xfloor, c, h,
                           phi_quiet2)
        if not base[13]:
            continue   # elastic: D
        for j in range(3):
            d1[0, j] = de[p, j] + probe
            r = _continuous(0, s1, d1, b1, plane_strain, E, nu, cps, mu, isy, N, kint, xfloor, c, h,
                            phi_quiet2)
            d1[0, j] = de[p, j]
            D[p, 0, j] = (r[0] - base[0]) / probe   # (a tuple of mixed types: no index loop)
            D[p, 1, j] = (r[1] - base[1]) / probe
            D[p, 2, j] = (r[2] - base[2]) / probe


class SmoothVonMises(KinematicHardening):
    """The paper's smooth von Mises plasticity with Ziegler kinematic hardening.

    TOML keys besides ``E``, ``nu``, ``density``: ``yield_stress`` (> 0), ``hardening``
    (alpha = post-yield tangent / E in uniaxial stress, 0 <= alpha < 1, required) and
    ``smoothness`` (0 < N <= 1000, default 10; N -> infinity is ``bilinear_vonmises``).
    Plane stress and plane strain (see the module docstring).
    """

    name = "smooth_vonmises"
    has_tangent = True

    def read_params(self, p):
        """Read ``yield_stress``, ``hardening`` and ``smoothness``.

        Parameters
        ----------
        p : Params
        """
        super().read_params(p)
        # sub-steps shrink like 1/N, so a huge N would quietly multiply the cost; the bilinear
        # model is the N -> infinity limit and costs nothing extra
        self.smoothness = p.number("smoothness", default=10.0, low=0.0, high=_MAX_SMOOTHNESS,
                                   low_open=True)

    @property
    def params(self):
        """Kernel parameters ``[E, nu, yield_stress, hardening, smoothness]`` (float64)."""
        return np.array([self.E, self.nu, self.yield_stress, self.hardening, self.smoothness],
                        dtype=np.float64)

    def describe(self):
        """One line for the start-up log."""
        return (f"{self.name} (E={self.E:g}, nu={self.nu:g}, density={self.density:g}, "
                f"yield_stress={self.yield_stress:g}, hardening={self.hardening:g}, "
                f"smoothness={self.smoothness:g}; {self.formulation})")

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
        _update_smooth(stress, de, state["back_stress"], state["eps_p"], state["eps_p_eq"],
                       state["plastic_work"], self.params, self.plane_strain, mat_ids, which,
                       self.continuous_in_increment)

    #: the update as a continuous function of the increment (``_substepped_continuous``): set
    #: for the implicit integrator, whose Newton iterations need it (use_integrator)
    continuous_in_increment = False

    def use_integrator(self, name):
        self.continuous_in_increment = name == "implicit"

    def tangent(self, stress0, state0, stress1, state1, de, D, mat_ids, which):
        """The derivative of the implicit update (``_consistent_tangent``, by differences), with
        which Newton converges where the points yield; as the increment shrinks it tends to the
        paper's tangent modulus E_t (``_smooth_tangent``, tests/unit/test_smooth_continuous.py).
        The rate form's E_t at the end of the increment, which the first implicit slice used,
        is not that derivative: Newton converged linearly with it and the Northridge record
        needed step halvings wherever the frame yielded. With the fracture option the points
        that soften take E_t (the fracture passes are not in the differenced update)."""
        if self.continuous_in_increment and self.fracture is None:
            _consistent_tangent(D, stress0, state0["back_stress"], de, self.params, self.plane_strain,
                                mat_ids, which)
            return
        _smooth_tangent(D, stress1, state1["back_stress"], de, self.params, self.plane_strain, mat_ids, which)
