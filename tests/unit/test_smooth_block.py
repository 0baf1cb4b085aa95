"""The smooth model's two paths agree: the vectorised block path (single-sub-step increments,
integer N) against the scalar sub-stepped loop, which serves as its reference
(pmpm/physics/materials/smooth_vonmises.py)."""
import numpy as np
import pytest

from pmpm.physics.materials import smooth_vonmises as sv

E, NU, SY, ALPHA = 200e9, 0.3, 250e6, 0.05


def _states(n, rng, plane_strain):
    """Stresses from far below to beyond yield, back stresses, mixed loading and unloading
    increments up to 0.08 eps_y (one sub-step at N = 10: h = 0.1 eps_y)."""
    level = rng.uniform(0.0, 1.3, n)[:, None]
    stress = rng.normal(size=(n, 4)) * SY * level / 2
    back = rng.normal(size=(n, 4)) * SY * 0.05
    if not plane_strain:
        stress[:, 3] = 0.0
        back[:, 3] = 0.0
    de = rng.uniform(-1, 1, (n, 3)) * 0.08 * SY / E
    return stress, back, de


def _scalar_reference(stress, back, de, params, plane_strain):
    """The scalar path particle by particle (what every increment took before the block path)."""
    E_, nu, sy, alpha, N = params
    kint = int(N)
    out = [a.copy() for a in (stress, back)] + [np.zeros((len(de), 3)), np.zeros(len(de)), np.zeros(len(de))]
    mu = E_ / (2 * (1 + nu))
    for p in range(len(de)):
        sv._substepped_py(p, out[0], de, out[1], out[2], out[3], out[4], plane_strain, E_, nu,
                          E_ / (1 - nu * nu), mu, 1 / sy, N, kint, sv._power_floor_py(kint),
                          alpha * E_ / (1 - alpha), sy / E_ * min(0.1, 1 / N),
                          (sy * 2.0 ** (-53 / N)) ** 2)
    return out


@pytest.mark.parametrize("plane_strain", [False, True])
@pytest.mark.parametrize("N", [10.0, 3.0])
def test_block_path_matches_the_scalar_path(plane_strain, N):
    rng = np.random.default_rng(7)
    stress, back, de = _states(300, rng, plane_strain)
    params = np.array([E, NU, SY, ALPHA, N])
    ref = _scalar_reference(stress, back, de, params, plane_strain)
    s, b = stress.copy(), back.copy()
    eps_p, eq, work = np.zeros((300, 3)), np.zeros(300), np.zeros(300)
    sv._update_smooth(s, de, b, eps_p, eq, work, params, plane_strain, np.zeros(300, np.int32), -1)
    # round-off: the block path evaluates the model where the scalar one takes its exact elastic
    # shortcuts (H1 < 2^-53 there), and both sum the same terms in the same order otherwise
    scale = SY
    np.testing.assert_allclose(s, ref[0], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(b, ref[1], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(eps_p, ref[2], rtol=0, atol=1e-12 * SY / E)
    np.testing.assert_allclose(eq, ref[3], rtol=0, atol=1e-12 * SY / E)
    np.testing.assert_allclose(work, ref[4], rtol=0, atol=1e-12 * SY * SY / E)
    assert np.mean(eq > 0) > 0.2  # the sample does yield


def test_large_increments_and_other_materials_take_the_right_path():
    """Increments above one sub-step go through the scalar path inside the block loop; a
    particle of another material is left alone; ``eps_p`` None (not output) changes nothing."""
    rng = np.random.default_rng(3)
    stress, back, de = _states(200, rng, False)
    de[::7] *= 30.0  # 2.4 eps_y: 24 sub-steps
    mat = np.zeros(200, np.int32)
    mat[::5] = 1
    params = np.array([E, NU, SY, ALPHA, 10.0])
    ref = _scalar_reference(stress, back, de, params, False)
    s, b = stress.copy(), back.copy()
    eq, work = np.zeros(200), np.zeros(200)
    sv._update_smooth(s, de, b, None, eq, work, params, False, mat, 0)
    mine = mat == 0
    np.testing.assert_allclose(s[mine], ref[0][mine], rtol=0, atol=1e-12 * SY)
    np.testing.assert_allclose(eq[mine], ref[3][mine], rtol=0, atol=1e-12 * SY / E)
    assert np.array_equal(s[~mine], stress[~mine]) and not eq[~mine].any()
