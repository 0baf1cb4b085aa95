"""Linear elastic material, incremental: d_sigma = D d_eps (paper eq. 6)."""
import numba as nb
import numpy as np

from pmpm.physics.materials.base import Material

__all__ = ["LinearElastic", "elastic_increment", "elastic_matrix"]


@nb.njit(cache=True, inline="always")
def elastic_increment(E, nu, plane_strain, dexx, deyy, dgxy):
    """Stress increment (dsxx, dsyy, dsxy, dszz) of an elastic strain increment."""
    if plane_strain:
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        tr = dexx + deyy
        return (lam * tr + 2 * mu * dexx, lam * tr + 2 * mu * deyy, mu * dgxy, lam * tr)
    c = E / (1 - nu * nu)
    return (c * (dexx + nu * deyy), c * (deyy + nu * dexx), c * 0.5 * (1 - nu) * dgxy, 0.0)


@nb.njit(cache=True, inline="always")
def elastic_matrix(E, nu, plane_strain, D, p):
    """D[p] = the in-plane elastic matrix d(sxx, syy, sxy) / d(exx, eyy, gxy) (engineering
    shear) of the formulation: the tangent of ``elastic_increment``."""
    if plane_strain:
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        a, b, g = lam + 2 * mu, lam, mu
    else:
        c = E / (1.0 - nu * nu)   # (the plane-stress modulus; spelled apart for tests/mutation)
        a, b, g = c, c * nu, c * 0.5 * (1 - nu)
    D[p, 0, 0] = a
    D[p, 0, 1] = b
    D[p, 0, 2] = 0.0
    D[p, 1, 0] = b
    D[p, 1, 1] = a
    D[p, 1, 2] = 0.0
    D[p, 2, 0] = 0.0
    D[p, 2, 1] = 0.0
    D[p, 2, 2] = g


@nb.njit(cache=True)
def _elastic_tangent(D, params, plane_strain, mat_ids, which):
    for p in range(D.shape[0]):
        if which < 0 or mat_ids[p] == which:
            elastic_matrix(params[0], params[1], plane_strain, D, p)


@nb.njit(cache=True)
def _update_elastic(stress, de, params, plane_strain, mat_ids, which):
    E, nu = params[0], params[1]
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        for k in range(4):
            stress[p, k] += ds[k]


@nb.njit(cache=True)
def _update_elastic_power(stress, de, vol, params, plane_strain, mat_ids, which):
    """``_update_elastic`` summing V sigma : de with the new stress as it goes (the solver's
    second half of the internal work, pmpm.core.kernels.grid_ops.stress_power's terms)."""
    E, nu = params[0], params[1]
    power = 0.0
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        for k in range(4):
            stress[p, k] += ds[k]
        power += vol[p] * (stress[p, 0] * de[p, 0] + stress[p, 1] * de[p, 1] + stress[p, 2] * de[p, 2])
    return power


class LinearElastic(Material):
    """Isotropic linear elasticity, plane stress or plane strain."""

    name = "linear_elastic"
    has_tangent = True

    sums_power = True

    def update_stress(self, stress, de, state, mat_ids, which):
        _update_elastic(stress, de, self.params, self.plane_strain, mat_ids, which)

    def update_stress_power(self, stress, de, vol, state, mat_ids, which):
        return _update_elastic_power(stress, de, vol, self.params, self.plane_strain, mat_ids, which)

    def increment_matrix(self):
        """``elastic_increment`` as the (4, 3) matrix of its linear map (rows sxx, syy, sxy,
        szz; szz's row is zero in plane stress)."""
        if self.plane_strain:
            lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
            mu = self.E / (2 * (1 + self.nu))
            rows = [[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu], [lam, lam, 0.0]]
        else:
            c = self.E / (1 - self.nu * self.nu)
            rows = [[c, c * self.nu, 0.0], [c * self.nu, c, 0.0], [0.0, 0.0, c * 0.5 * (1 - self.nu)],
                    [0.0, 0.0, 0.0]]
        return np.array(rows, dtype=np.float64)

    def tangent(self, stress0, state0, stress1, state1, de, D, mat_ids, which):
        """The elastic matrix (the update is linear: its tangent is exact)."""
        _elastic_tangent(D, self.params, self.plane_strain, mat_ids, which)
