"""Stiffness-proportional (Rayleigh) damping: the viscous stress of the particles.

sigma_v = a1 C : D, with C the material's elastic tangent and D the rate of deformation (the
step's strain increment over its time step). It enters the internal force with the stress
(pmpm.physics.damping.RayleighDamping.force_stress); numba compiles this kernel only for scenes
that ask for Rayleigh damping. ``pmpm.core.kernels.reference.viscous_stress_reference`` is its
NumPy twin (tests/unit/test_damping.py compares the two).
"""
import numba as nb

from pmpm.physics.materials.linear_elastic import elastic_increment

__all__ = ["viscous_stress"]


@nb.njit(cache=True)
def viscous_stress(sv, de, vol, dt, a1, E, nu, plane_strain, mat_ids, which):
    """Advance the viscous stress ``sv`` (N, 3: sxx, syy, sxy) to this step's rate and return
    the work it did over the step.

    The viscous stress that acted during the step (in its internal force) is the one of the
    previous step; its work is V sv_old : de, de the step's strain increment (engineering
    shear: the product is the stress power times dt). Then sv = (a1 / dt) C de. Particles
    of other materials (``which`` >= 0 and ``mat_ids`` != which) are skipped.

    Returns
    -------
    float
        sum of V sv_old : de over the particles visited (J): the energy the stiffness part of
        the damping dissipated in the step.
    """
    work = 0.0
    c = a1 / dt
    for p in range(sv.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        work += vol[p] * (sv[p, 0] * de[p, 0] + sv[p, 1] * de[p, 1] + sv[p, 2] * de[p, 2])
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        sv[p, 0] = c * ds[0]
        sv[p, 1] = c * ds[1]
        sv[p, 2] = c * ds[2]
    return work


@nb.njit(cache=True)
def add_viscous(stress, sv, out):
    """out[:, :3] = stress[:, :3] + sv: the stress the internal force sees."""
    for p in range(sv.shape[0]):
        out[p, 0] = stress[p, 0] + sv[p, 0]
        out[p, 1] = stress[p, 1] + sv[p, 1]
        out[p, 2] = stress[p, 2] + sv[p, 2]
