"""The smooth model's update under the implicit integrator is a continuous function of the
strain increment (pmpm/physics/materials/smooth_vonmises.py, ``_substepped_continuous``).

The explicit update takes ceil(max|de| / h) RK2 sub-steps, so where max|de| / h crosses an
integer its result jumps by the RK2 error: about 2e-3 sigma_y from one sub-step to two near the
yield surface. A Newton iteration whose increments sit at such a jump has no root to find; the
Northridge record under the implicit integrator stalled so at t = 8.82 s (issue 37). The
continuous update blends n and n + 1 sub-steps. Shown to fail on the bug: with
``continuous=False`` (the explicit update) the jump test fails at every crossing (measured 2e-3,
2e-3, 4e-4 sigma_y at r = 1, 2, 5 for a point at 0.95 sigma_y).
"""
import numpy as np
import pytest

from pmpm.physics.materials import smooth_vonmises as sv

E, NU, SY, ALPHA, N = 200e9, 0.3, 250e6, 0.03, 10.0
PARAMS = np.array([E, NU, SY, ALPHA, N])
H = SY / E * min(0.1, 1.0 / N)   # the sub-step bound of the update


def _update(stress, back, de, plane_strain, continuous):
    n = len(de)
    s, b = stress.copy(), back.copy()
    eps_p, eq, work = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
    sv._update_smooth(s, de, b, eps_p, eq, work, PARAMS, plane_strain, np.zeros(n, np.int32), -1,
                      continuous)
    return s, b, eq, work


def _states(plane_strain, rng, n=40):
    """Points from 0.5 to 1.1 sigma_y (relative stress) along random directions, with back
    stresses; increments in random directions whose largest component is exactly r h."""
    stress = rng.normal(size=(n, 4))
    back = rng.normal(size=(n, 4)) * 0.05 * SY
    if not plane_strain:
        stress[:, 3] = 0.0
        back[:, 3] = 0.0
    t = stress - back
    # scale the relative stress to the level wanted (the von Mises measure of the model)
    if plane_strain:
        dev = t[:, [0, 1, 3]] - t[:, [0, 1, 3]].mean(axis=1, keepdims=True)
        phi = np.sqrt(1.5 * (dev ** 2).sum(axis=1) + 3 * t[:, 2] ** 2)
    else:
        phi = np.sqrt(t[:, 0] ** 2 - t[:, 0] * t[:, 1] + t[:, 1] ** 2 + 3 * t[:, 2] ** 2)
    level = rng.uniform(0.5, 1.1, n)
    stress = back + t * (level * SY / phi)[:, None]
    if not plane_strain:
        stress[:, 3] = 0.0
    d = rng.uniform(-1, 1, (n, 3))
    d /= np.abs(d).max(axis=1, keepdims=True)
    return stress, back, d


@pytest.mark.parametrize("plane_strain", [False, True])
@pytest.mark.parametrize("r", [1.0, 2.0, 5.0, 13.0])
def test_no_jump_where_the_sub_step_count_changes(plane_strain, r):
    """Across max|de| = r h the update moves by no more than its slope times the change of
    the increment (E times it, with a factor 10 for the blend's kinks: it is continuous, not
    smooth), while the explicit update jumps by far more there."""
    rng = np.random.default_rng(int(r * 10) + plane_strain)
    stress, back, d = _states(plane_strain, rng)
    eps = 1e-9
    lo = _update(stress, back, d * r * H * (1 - eps), plane_strain, True)
    hi = _update(stress, back, d * r * H * (1 + eps), plane_strain, True)
    allowed = 10 * E * r * H * eps
    for a, b in zip(lo[:2], hi[:2]):
        assert np.abs(b - a).max() <= allowed
    assert np.abs(hi[3] - lo[3]).max() <= 10 * SY * r * H * eps   # the plastic work, J/m^3
    # the explicit update at the same increments jumps (the bug this guards)
    lo_x = _update(stress, back, d * r * H * (1 - eps), plane_strain, False)
    hi_x = _update(stress, back, d * r * H * (1 + eps), plane_strain, False)
    assert np.abs(hi_x[0] - lo_x[0]).max() > 1000 * allowed


@pytest.mark.parametrize("plane_strain", [False, True])
def test_as_accurate_as_the_sub_stepped_update(plane_strain):
    """The blend of n and n + 1 sub-steps integrates the same rate equation: against a
    reference with sub-steps a hundred times smaller, its error is no larger than the larger
    of its two parts' (it is their convex combination), and both are the RK2 error of steps of
    at most h; here checked against the explicit update's own error at the same increments,
    within a factor 2 (the blend may sit on either side of the reference)."""
    rng = np.random.default_rng(3)
    stress, back, d = _states(plane_strain, rng, n=60)
    de = d * rng.uniform(1.0, 20.0, (len(d), 1)) * H
    cont = _update(stress, back, de, plane_strain, True)[0]
    expl = _update(stress, back, de, plane_strain, False)[0]
    # the reference: the update over 100 equal pieces of each increment (the implicit one's:
    # in plane stress its loading test is n^T D d_eps, not s . d_eps, a slightly different
    # model on non-proportional paths; pieces below one sub-step take no blend)
    ref_s, ref_b = stress.copy(), back.copy()
    for _ in range(100):
        ref_s, ref_b, _, _ = _update(ref_s, ref_b, de / 100, plane_strain, True)
    err_c = np.abs(cont - ref_s).max(axis=1)
    err_x = np.abs(expl - ref_s).max(axis=1)
    assert np.all(err_c <= 2 * err_x.max())
    assert np.median(err_c) <= 2 * np.median(err_x)


def test_within_one_sub_step_both_updates_agree_in_plane_strain():
    """Increments of at most h (all of an explicit run's) take the same path either way in
    plane strain, whose loading test dev(s) . d_eps is already the consistent one:
    bit-identical."""
    rng = np.random.default_rng(11)
    stress, back, d = _states(True, rng)
    de = d * rng.uniform(0.0, 1.0, (len(d), 1)) * H
    a = _update(stress, back, de, True, True)
    b = _update(stress, back, de, True, False)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_no_jump_where_the_plane_stress_loading_test_switches():
    """Plane stress: the explicit update (the paper's H2 = sign(s . d_eps)) switches plastic
    flow on and off where s . d_eps changes sign, while the flow it switches is proportional to
    n^T D d_eps, not zero there: a jump. The implicit update tests n^T D d_eps, so its flow
    vanishes where it switches. Increments through each test's switch: the implicit update
    moves by no more than its slope, the explicit one jumps (the bug this guards: Newton's
    iterations cycled between two residuals at a load reversal of the Northridge record)."""
    rng = np.random.default_rng(21)
    stress, back, _ = _states(False, rng)
    t = stress - back
    m = np.stack([t[:, 0] - 0.5 * t[:, 1], t[:, 1] - 0.5 * t[:, 0], 3 * t[:, 2]], axis=1)
    Dmat = E / (1 - NU ** 2) * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
    eps = 1e-6
    for normal, continuous in ((m @ Dmat, True), (t[:, :3], False)):
        # increments of 3 h whose loading indicator (normal . de) is -eps, +eps of its scale
        base = rng.normal(size=(len(t), 3))
        unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
        base -= (base * unit).sum(axis=1, keepdims=True) * unit
        base *= 3 * H / np.abs(base).max(axis=1, keepdims=True)
        lo = _update(stress, back, base - eps * 3 * H * unit, False, continuous)[0]
        hi = _update(stress, back, base + eps * 3 * H * unit, False, continuous)[0]
        jump = np.abs(hi - lo).max()
        if continuous:
            assert jump <= 10 * E * 2 * eps * 3 * H
        else:
            assert jump > 1000 * E * 2 * eps * 3 * H


def _tangent(stress, back, de, plane_strain, consistent):
    n = len(de)
    D = np.zeros((n, 3, 3))
    ids = np.zeros(n, np.int32)
    if consistent:
        sv._consistent_tangent(D, stress, back, de, PARAMS, plane_strain, ids, -1)
    else:
        s1, b1, _, _ = _update(stress, back, de, plane_strain, True)
        sv._smooth_tangent(D, s1, b1, de, PARAMS, plane_strain, ids, -1)
    return D


@pytest.mark.parametrize("plane_strain", [False, True])
def test_consistent_tangent_is_the_updates_derivative(plane_strain):
    """The implicit integrator's tangent of the smooth model is the derivative of its update:
    against central differences of the update with a probe 30 times the tangent's (so that
    neither shares the other's rounding), to the forward difference's truncation error (the
    update's second derivative ~ E / eps_y times the probe: 1e-5 of E here)."""
    rng = np.random.default_rng(5)
    stress, back, d = _states(plane_strain, rng, n=30)
    de = d * rng.uniform(0.3, 12.0, (len(d), 1)) * H
    D = _tangent(stress, back, de, plane_strain, True)
    step = 30 * sv._TANGENT_PROBE * SY / E
    for j in range(3):
        up, down = de.copy(), de.copy()
        up[:, j] += step
        down[:, j] -= step
        central = (_update(stress, back, up, plane_strain, True)[0][:, :3]
                   - _update(stress, back, down, plane_strain, True)[0][:, :3]) / (2 * step)
        assert np.abs(D[:, :, j] - central).max() <= 1e-4 * E


@pytest.mark.parametrize("plane_strain", [False, True])
def test_consistent_tangent_tends_to_the_papers_modulus(plane_strain):
    """For increments that shrink (a hundredth of a sub-step, loading) the derivative of the
    update tends to the paper's tangent modulus E_t of the rate form (``_smooth_tangent``)."""
    rng = np.random.default_rng(9)
    stress, back, d = _states(plane_strain, rng, n=30)
    t = stress - back
    load = t[:, 0] * d[:, 0] + t[:, 1] * d[:, 1] + t[:, 2] * d[:, 2]
    d[load < 0] *= -1.0   # loading directions: the rate form's H2 = 1
    if not plane_strain:   # ... and the implicit update's (n^T D d_eps > 0), where they differ
        m = np.stack([t[:, 0] - 0.5 * t[:, 1], t[:, 1] - 0.5 * t[:, 0], 3 * t[:, 2]], axis=1)
        Dmat = E / (1 - NU ** 2) * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
        both = ((m @ Dmat) * d).sum(axis=1) > 0
        stress, back, d, t = stress[both], back[both], d[both], t[both]
        assert len(d) >= 15
    de = d * 1e-2 * H
    Dc = _tangent(stress, back, de, plane_strain, True)
    Dr = _tangent(stress, back, de, plane_strain, False)
    # E_t changes by about E/eps_y per unit strain: over 1e-3 eps_y, some 1e-3 of E
    assert np.abs(Dc - Dr).max() <= 5e-3 * E
    # and these points do yield: E_t is far from the elastic matrix
    De = np.zeros_like(Dr)
    for p in range(len(De)):
        sv.elastic_matrix(E, NU, plane_strain, De, p)
    assert np.abs(Dr - De).max() > 0.1 * E


@pytest.mark.parametrize("plane_strain", [False, True])
def test_consistent_tangent_of_a_stress_free_start(plane_strain):
    """A point with no stress yet (every point of a run's first step, e.g. gravity brought to
    equilibrium) and an elastic increment: the elastic matrix, no 0/0 from the flow direction
    (the model evaluates it and discards it there; it raised ZeroDivisionError once)."""
    n = 3
    zero = np.zeros((n, 4))
    de = np.array([[1e-5, -3e-6, 2e-6], [0.0, 0.0, 0.0], [-2e-5, 1e-5, 0.0]])
    D = _tangent(zero, zero, de, plane_strain, True)
    De = np.zeros_like(D)
    for p in range(n):
        sv.elastic_matrix(E, NU, plane_strain, De, p)
    assert np.array_equal(D, De)
