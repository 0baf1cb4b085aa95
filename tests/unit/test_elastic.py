"""Linear elastic update against D of docs/verification.md section 1 (plane stress) and Lame (plane strain)."""
import math

import numpy as np
import pytest

from pmpm.errors import ConfigError
from pmpm.physics.materials import make_material

E, NU, RHO = 210e9, 0.3, 7800.0


def _mat(formulation):
    return make_material({"type": "linear_elastic", "E": E, "nu": NU, "density": RHO}, "materials.s", formulation)


def test_plane_stress_increment_is_D_de():
    m = _mat("plane_stress")
    D = E / (1 - NU ** 2) * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
    de = np.random.default_rng(0).normal(scale=1e-4, size=(50, 3))
    stress = np.zeros((50, 4))
    m.update_stress(stress, de, {}, np.zeros(50, np.int32), -1)
    np.testing.assert_allclose(stress[:, :3], de @ D.T, rtol=1e-13)
    assert not stress[:, 3].any()


def test_plane_strain_increment_has_out_of_plane_stress():
    m = _mat("plane_strain")
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    de = np.array([[1e-4, -2e-4, 3e-4]])
    stress = np.zeros((1, 4))
    m.update_stress(stress, de, {}, np.zeros(1, np.int32), -1)
    tr = de[0, 0] + de[0, 1]
    np.testing.assert_allclose(stress[0], [lam * tr + 2 * mu * de[0, 0], lam * tr + 2 * mu * de[0, 1],
                                           mu * de[0, 2], NU * (stress[0, 0] + stress[0, 1])], rtol=1e-12)


def test_only_the_selected_material_is_updated():
    m = _mat("plane_stress")
    stress = np.zeros((4, 4))
    m.update_stress(stress, np.full((4, 3), 1e-4), {}, np.array([0, 1, 0, 1], np.int32), 1)
    assert not stress[[0, 2]].any() and stress[[1, 3]].any()


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
def test_update_with_power_is_the_update_and_the_power_of_its_particles(formulation):
    """``update_stress_power`` (the update with the second half of the step's internal work in
    its pass): the stress of ``update_stress`` (D de, docs/verification.md section 1) and
    sum_p V_p sigma_new : de_p over the particles of material ``which`` only, off the origin
    (nonzero starting stresses). Tolerance: round-off of 50 terms. Shown to fail: with the
    power summed with the stress before the increment, or over every particle."""
    m = _mat(formulation)
    rng = np.random.default_rng(3)
    de = rng.normal(scale=1e-4, size=(50, 3))
    vol = rng.uniform(0.5, 2.0, 50)
    ids = (rng.uniform(size=50) < 0.5).astype(np.int32)
    start = rng.normal(scale=1e6, size=(50, 4))
    expected = start.copy()
    m.update_stress(expected, de, {}, ids, 1)
    stress = start.copy()
    power = m.update_stress_power(stress, de, vol, {}, ids, 1)
    np.testing.assert_array_equal(stress, expected)
    mine = ids == 1
    ref = np.sum(vol[mine] * np.sum(expected[mine, :3] * de[mine], axis=1))
    assert m.sums_power and power == pytest.approx(ref, rel=1e-12)


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
def test_increment_matrix_is_the_update(formulation):
    """``increment_matrix`` (the map a transfer applies in its own pass, pmpm.core.kernels.mls)
    against D of docs/verification.md section 1 (plane stress) and Lame's constants (plane
    strain, szz = lam tr de) written out here, and against ``update_stress`` itself.
    Tolerance: round-off (the update computes c (dexx + nu deyy), the map c dexx + c nu deyy).
    Shown to fail: with the plane-strain szz row left zero, or mu in place of lam + 2 mu."""
    m = _mat(formulation)
    if formulation == "plane_stress":
        c = E / (1 - NU ** 2)
        D = c * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2], [0, 0, 0]])
    else:
        lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
        D = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu], [lam, lam, 0]])
    M = m.increment_matrix()
    assert M.shape == (4, 3) and M.dtype == np.float64
    np.testing.assert_allclose(M, D, rtol=1e-14, atol=0)
    de = np.random.default_rng(4).normal(scale=1e-4, size=(50, 3))
    stress = np.zeros((50, 4))
    m.update_stress(stress, de, {}, np.zeros(50, np.int32), -1)
    np.testing.assert_allclose(de @ M.T, stress, rtol=1e-13, atol=1e-13 * np.abs(stress).max())


def test_only_a_linear_law_hands_a_matrix():
    """The plastic and hyperelastic models hand no map (the solver runs their update)."""
    table = {"E": E, "nu": NU, "density": RHO}
    assert make_material({"type": "bilinear_vonmises", **table, "yield_stress": 250e6,
                          "hardening": 0.01}, "materials.s",
                         "plane_stress").increment_matrix() is None
    assert make_material({"type": "neo_hookean", **table}, "materials.s", "plane_strain").increment_matrix() is None


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
def test_elastic_energy_density_is_half_sigma_epsilon(formulation):
    m = _mat(formulation)
    de = np.array([[2e-4, -1e-4, 5e-5]])
    stress = np.zeros((1, 4))
    m.update_stress(stress, de, {}, np.zeros(1, np.int32), -1)
    work = 0.5 * (stress[0, 0] * de[0, 0] + stress[0, 1] * de[0, 1] + stress[0, 2] * de[0, 2])
    assert m.elastic_energy_density(stress)[0] == pytest.approx(work, rel=1e-12)


def test_wave_speeds():
    assert _mat("plane_stress").wave_speed() == pytest.approx(math.sqrt(E / (RHO * (1 - NU ** 2))))
    lam_2mu = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    assert _mat("plane_strain").wave_speed() == pytest.approx(math.sqrt(lam_2mu / RHO))


@pytest.mark.parametrize("key,value", [("E", -1.0), ("density", 0.0), ("nu", 0.5), ("nu", -1.0)])
def test_bad_parameters_name_the_key(key, value):
    table = {"type": "linear_elastic", "E": E, "nu": NU, "density": RHO, key: value}
    with pytest.raises(ConfigError) as err:
        make_material(table, "materials.s", "plane_stress")
    assert err.value.key == f"materials.s.{key}"
