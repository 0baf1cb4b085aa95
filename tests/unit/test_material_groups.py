"""Materials of one law updated in one pass (pmpm.core.material_groups, Solver.update_stress).

The frame front end makes a copy of the steel per lumped mass, differing in density only (the
three-storey frame: ten materials of one law). The solver then runs one stress pass with
``which = -1`` instead of one per material. Against an independent computation: the same run
with the per-material passes forced (the code before the grouping) gives the same particles to
the bit (each row goes through the same kernel with the same parameters), and the strain
energy, now one sum instead of one per material, the same to round-off: the two sums add the
same n terms in another order, so they differ by at most n eps times the sum of |terms|
(Higham, Accuracy and Stability of Numerical Algorithms, 2002, eq. 4.4), n = the particles.

Shown to fail on the bug they guard (checked once by hand): with the single pass given
``which = 0`` (only the first material's particles updated) test_grouped_run_equals_per_material
fails on the stress; with the old loop that rotated the shared back stress once per material
test_back_stress_rotated_once fails by the second rotation.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.core import kernels as K
from pmpm.core.material_groups import same_elastic_energy, same_law, single_law
from pmpm.physics.materials import make_material
from pmpm.scene.config import parse_scene

STEEL = {"type": "smooth_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
         "yield_stress": 2e6, "hardening": 0.05, "smoothness": 10.0}


def _material(table, key="materials.m"):
    return make_material(dict(table), key, "plane_stress")


def test_same_law_ignores_density_and_key_only():
    a = _material(STEEL)
    assert same_law(a, _material(dict(STEEL, density=9000.0), "materials.m+c0_f1"))
    for change in ({"E": 210e9}, {"nu": 0.29}, {"yield_stress": 3e6}, {"hardening": 0.02},
                   {"smoothness": 8.0}):
        assert not same_law(a, _material(dict(STEEL, **change)))
    assert not same_law(a, _material({"type": "bilinear_vonmises", "E": 200e9, "nu": 0.3,
                                      "density": 7850.0, "yield_stress": 2e6, "hardening": 0.05}))
    assert not same_law(a, make_material(dict(STEEL), "materials.m", "plane_strain"))
    elastic = _material({"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0})
    assert not single_law([elastic, a]) and single_law([a, a])
    # the energy 1/2 sigma : C^-1 : sigma reads E and nu only
    assert same_elastic_energy([elastic, a])
    assert not same_elastic_energy([elastic, _material(dict(STEEL, E=100e9))])


def _scene(materials, large_rotations=False):
    """A clamped block in two halves (two bodies of two materials), sheared hard enough to
    yield at 2 MPa within the run."""
    h = 0.02
    data = {
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": [24, 16]},
        "materials": materials,
        "bodies": [{"shape": "rectangle", "material": name, "lower": [2 * h + k * 10 * h, 0.0],
                    "upper": [2 * h + (k + 1) * 10 * h, 12 * h], "velocity": ["1.0 * y", "0.3 * x"]}
                   for k, name in enumerate(materials)],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [24 * h, 0.0]}],
        "solver": {"shape_function": "cubic", "scheme": "musl", "end_time": 1.0, "cfl": 0.5,
                   "large_rotations": large_rotations},
    }
    return parse_scene(data, "groups.toml")


def _run(materials, per_material, steps=60):
    s = build_solver(_scene(materials), MPI.COMM_SELF)
    if per_material:   # the code before the grouping: one pass per material
        s._stress_passes = [(m, k) for k, m in enumerate(s.materials)]
        s._one_energy_sum = False
    energies = []
    for _ in range(steps):
        s.step()
        energies.append(s.energies()["strain"])
    return s, np.array(energies)


def test_grouped_run_equals_per_material():
    """Two copies of a steel differing in density: one pass, the same bits as two passes."""
    materials = {"a": STEEL, "b": dict(STEEL, density=3 * 7850.0)}
    grouped, e_grouped = _run(materials, per_material=False)
    assert grouped._stress_passes == [(grouped.materials[0], -1)] and grouped._one_energy_sum
    apart, e_apart = _run(materials, per_material=True)
    assert grouped.particles["eps_p_eq"].max() > 0   # it yielded: the plastic update ran
    assert np.any(grouped.particles["eps_p_eq"][grouped.particles["mat"] == 1] > 0)
    for name, a in apart.particles.fields.items():
        np.testing.assert_array_equal(grouped.particles[name], a, err_msg=name)
    p = grouped.particles
    n = p.n
    bound = n * np.finfo(float).eps * np.array([
        K.elastic_energy(p["stress"], p["vol"], 200e9, 0.3, p["mat"], -1)])  # all terms >= 0
    assert abs(e_grouped[-1] - e_apart[-1]) <= bound[0]
    np.testing.assert_allclose(e_grouped, e_apart, rtol=n * np.finfo(float).eps)


def test_different_laws_keep_one_pass_each():
    materials = {"a": STEEL, "b": dict(STEEL, yield_stress=4e6)}
    s = build_solver(_scene(materials), MPI.COMM_SELF)
    assert s._stress_passes == [(s.materials[0], 0), (s.materials[1], 1)]


@pytest.mark.parametrize("materials", [{"a": STEEL, "b": dict(STEEL, yield_stress=4e6)},
                                       {"a": STEEL, "b": dict(STEEL, density=9000.0)}])
def test_back_stress_rotated_once(materials):
    """With large rotations, the back stress (a field all the plastic materials share) turns by
    the step's spin once, whatever the number of materials: a zero strain increment and a
    given spin leave it rotated exactly as one Jaumann rotation does."""
    s = build_solver(_scene(materials, large_rotations=True), MPI.COMM_SELF)
    p = s.particles
    rng = np.random.default_rng(7)
    p["back_stress"][:] = rng.normal(scale=1e5, size=p["back_stress"].shape)
    p["back_stress"][:, 3] = 0.0
    expected = p["back_stress"].copy()
    dw = np.full(p.n, 0.01)
    K.jaumann_rotate(expected, dw)
    s._de = np.zeros((p.n, 3))
    s._dw, s._dq = dw, None
    s.update_stress()
    np.testing.assert_array_equal(p["back_stress"], expected)
