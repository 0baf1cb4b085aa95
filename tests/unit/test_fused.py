"""The fused strain-and-stress pass (pmpm/core/kernels/fused.py, a measured prototype the solver
does not call: docs/performance.md) against the kernels it fuses:
g2p_kinematics, the elastic update, and the two stress_power halves (the reference twins).

The arithmetic per particle is the same in the same order, so positions, volumes, strains and
stresses agree to the bit; the internal work is a sum over particles taken in a different
grouping (one running sum instead of two), so it agrees to round-off: relative 1e-12, many
orders above the ~n * 1e-16 a sum of n = 3,000 terms can differ by, many below any physics.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.benchmarks.block import block_scene
from pmpm.core import kernels as K
from pmpm.core.kernels.fused import kinematics_stress
from pmpm.core.solver import Solver
from pmpm.physics.materials.linear_elastic import _update_elastic

#: relative round-off allowed on the internal work (see the module docstring)
WORK_RTOL = 1e-12


def _state(material="elastic", steps=3):
    """A sheared block a few steps in, stopped after its grid velocity (MUSL re-map) of the next step."""
    s = Solver(block_scene(3000, material=material, extra_solver={"sort_interval": 0}), MPI.COMM_SELF)
    for _ in range(steps):
        s.step()
    s._dt_step = dt = s.dt
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=True)
    s.exchange_halo(slice(0, 5))
    s.update_grid(dt)
    s.grid_to_particles(remap=True)
    s.exchange_halo(slice(5, 7))
    s.grid_velocity(source=K.REMAP, target=K.REMAP)
    return s, dt


def _copies(s):
    p = s.particles
    return {k: p[k].copy() for k in ("x", "vol", "stress")}


@pytest.mark.parametrize("with_strain", [False, True])
def test_fused_elastic_pass_matches_the_reference_kernels(with_strain):
    s, dt = _state()
    p = s.particles
    strain = np.zeros((p.n, 3)) if with_strain else None
    strain_ref = None if strain is None else strain.copy()
    start = _copies(s)
    geo = s._geometry()
    mat = s.materials[0]
    # reference: the unfused phases
    x, vol, stress = start["x"].copy(), start["vol"].copy(), start["stress"].copy()
    de = np.empty((p.n, 3))
    work_ref = K.g2p_kinematics(x, p["m"], vol, strain_ref, de, None, None, None, None, K.REMAP, s._dx, dt,
                                None, None, None, None, *geo)
    power_ref = 0.5 * K.stress_power(stress, de, vol)
    _update_elastic(stress, de, mat.params, mat.plane_strain, p["mat"], -1)
    power_ref += 0.5 * K.stress_power(stress, de, vol)
    # fused
    work, power = kinematics_stress(p["x"], p["m"], p["vol"], strain, p["stress"], None, K.REMAP,
                                      s._dx, dt, (mat.E, mat.nu, mat.plane_strain), None, None, None,
                                      None, *geo)
    assert np.array_equal(p["x"], x)
    assert np.array_equal(p["vol"], vol)
    assert np.array_equal(p["stress"], stress)
    if with_strain:
        assert np.array_equal(strain, strain_ref)
    assert not np.array_equal(stress, start["stress"])  # the pass did update something
    assert work == work_ref
    assert power == pytest.approx(power_ref, rel=WORK_RTOL) and power_ref != 0


def test_fused_generic_pass_leaves_the_stress_to_the_material():
    s, dt = _state("smooth_vonmises", steps=5)
    p = s.particles
    start = _copies(s)
    geo = s._geometry()
    x, vol = start["x"].copy(), start["vol"].copy()
    de_ref = np.empty((p.n, 3))
    K.g2p_kinematics(x, p["m"], vol, None, de_ref, None, None, None, None, K.REMAP, s._dx, dt, None, None, None, None, *geo)
    power_ref = 0.5 * K.stress_power(start["stress"], de_ref, vol)
    de = np.empty((p.n, 3))
    _, power = kinematics_stress(p["x"], p["m"], p["vol"], None, p["stress"], de, K.REMAP, s._dx, dt,
                                   None, None, None, None, None, *geo)
    assert np.array_equal(de, de_ref)
    assert np.array_equal(p["x"], x) and np.array_equal(p["vol"], vol)
    assert np.array_equal(p["stress"], start["stress"])
    assert power == pytest.approx(power_ref, rel=WORK_RTOL) and power_ref != 0
