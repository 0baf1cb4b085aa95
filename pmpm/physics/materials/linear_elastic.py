"""Linear elastic material, incremental: d_sigma = D d_eps (paper eq. 6)."""
import numba as nb

from pmpm.physics.materials.base import Material

__all__ = ["LinearElastic", "elastic_increment"]


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


@nb.njit(cache=True)
def _update_elastic(stress, de, params, plane_strain, mat_ids, which):
    E, nu = params[0], params[1]
    for p in range(stress.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        for k in range(4):
            stress[p, k] += ds[k]


class LinearElastic(Material):
    """Isotropic linear elasticity, plane stress or plane strain."""

    name = "linear_elastic"

    def update_stress(self, stress, de, state, mat_ids, which):
        _update_elastic(stress, de, self.params, self.plane_strain, mat_ids, which)
