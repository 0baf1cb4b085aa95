"""Single material point tests of the plasticity models (strain driven, no grid).

References are independent of the kernels: closed forms for the bilinear model, and for the smooth
model ODEs derived on paper and integrated here with a fine classical RK4 (scipy is not a
dependency of pmpm, so none is used).
"""
import math

import numpy as np
import pytest

from pmpm.errors import ConfigError
from pmpm.physics.materials import make_material

E = 200e9
NU = 0.3
SY = 400e6
EY = SY / E
ALPHA = 0.05
C_ZIEGLER = ALPHA * E / (1 - ALPHA)
MU = E / (2 * (1 + NU))
KEY = "materials.steel"

# The uniaxial driver solves for deyy until |syy| is below this: 100x under the tightest
# tolerance below (1e-8 sy on the bilinear paths), so the solve error is invisible in them.
SOLVE_TOL = 1e-10 * SY


def make(kind="smooth_vonmises", formulation="plane_stress", **over):
    """A material from a TOML-like table (steel-like defaults, ``over`` replaces keys)."""
    table = dict(type=kind, E=E, nu=NU, density=7850.0, yield_stress=SY, hardening=ALPHA)
    table.update(over)
    return make_material(table, KEY, formulation)


class Point:
    """One material point: stress, plastic state and the total strain driven so far."""

    def __init__(self, mat):
        self.mat = mat
        self.stress = np.zeros((1, 4))
        self.state = {k: np.zeros((1,) + shape) for k, shape in mat.state_fields.items()}
        self.ids = np.zeros(1, np.int32)
        self.strain = np.zeros(3)

    def trial(self, de):
        """Stress and state after increment ``de``, without committing them."""
        stress = self.stress.copy()
        state = {k: v.copy() for k, v in self.state.items()}
        self.mat.update_stress(stress, np.array([de], dtype=float), state, self.ids, -1)
        return stress, state

    def step(self, de):
        """Commit increment ``de`` (3 components)."""
        self.stress, self.state = self.trial(de)
        self.strain = self.strain + np.asarray(de, float)

    def step_uniaxial(self, dexx):
        """Increment exx by ``dexx`` with syy = sxy = 0: secant iteration on deyy."""
        x0 = -self.mat.nu * dexx  # exact when the increment is elastic
        result = self.trial((dexx, x0, 0.0))
        f0 = result[0][0, 1]
        if abs(f0) > SOLVE_TOL:
            x1 = x0 - f0 * (1 - self.mat.nu ** 2) / self.mat.E  # elastic d syy / d deyy
            for _ in range(50):
                result = self.trial((dexx, x1, 0.0))
                f1 = result[0][0, 1]
                if abs(f1) <= SOLVE_TOL:
                    break
                x0, f0, x1 = x1, f1, x1 - f1 * (x1 - x0) / (f1 - f0)
            else:
                raise AssertionError("uniaxial secant did not converge")
            x0 = x1
        self.stress, self.state = result
        self.strain = self.strain + np.array([dexx, x0, 0.0])

    def phi(self):
        """Von Mises of the relative stress sigma - eta (plane stress or 3D)."""
        s = self.stress[0] - self.state["back_stress"][0]
        if self.mat.plane_strain:
            return math.sqrt(0.5 * ((s[0] - s[1]) ** 2 + (s[1] - s[3]) ** 2 + (s[3] - s[0]) ** 2)
                             + 3 * s[2] ** 2)
        return math.sqrt(s[0] ** 2 - s[0] * s[1] + s[1] ** 2 + 3 * s[2] ** 2)


def legs(start, targets, inc):
    """Equal increments of at most ``inc`` from ``start`` through each target (scalar path)."""
    out = []
    for t in targets:
        n = max(1, math.ceil(abs(t - start) / inc - 1e-9))
        out += [(t - start) / n] * n
        start = t
    return out


def drive_uniaxial(point, targets, inc):
    """Uniaxial stress path through the exx ``targets``; returns arrays (exx, sxx, plastic_work)."""
    rec = []
    for d in legs(point.strain[0], targets, inc):
        point.step_uniaxial(d)
        rec.append((point.strain[0], point.stress[0, 0], point.state["plastic_work"][0]))
    return np.array(rec).T


def rk4_path(rhs, y0, increments, m):
    """Integrate dy/deps = rhs(y, direction) with ``m`` RK4 steps per increment; y[0] per increment."""
    y = np.array(y0, float)
    out = []
    for d in increments:
        h = d / m
        sgn = math.copysign(1.0, d)
        for _ in range(m):
            k1 = rhs(y, sgn)
            k2 = rhs(y + 0.5 * h * k1, sgn)
            k3 = rhs(y + 0.5 * h * k2, sgn)
            k4 = rhs(y + h * k3, sgn)
            y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(y[0])
    return np.array(out)


# RK4 steps per driving increment for the references: with increments of at most EY/50 and N <= 10
# a reference step is N h <= 0.05 in the relaxation rate of the law, where RK4's error (~(N h)^5
# per step) is below 1e-8 of the peak, far under the 1e-4 being tested.
REF_SUBSTEPS = 4
CYCLE = [4 * EY, -4 * EY, 4 * EY]


def bouc_wen_rhs(alpha, n):
    """docs/verification.md section 1: sigma = alpha E eps + (1-alpha) sy z, z' = (1 - |z|^n H2) / eps_y."""
    def rhs(y, sgn):
        z = y[1]
        h = abs(z) ** n if z * sgn > 0 else 0.0
        dz = (1 - h) / EY
        return np.array([alpha * E + (1 - alpha) * SY * dz, dz])
    return rhs


def smooth_uniaxial_rhs(nu, alpha, n):
    """Exact uniaxial-stress reduction of the smooth model as implemented (y = [sigma, s]).

    In uniaxial stress s = (s, 0, 0), n = sgn(s) (1, -1/2, 0), n.s = |s|, so with r = |s|/sy,
    H = r^n H2, m = n.D n / E = (5/4 - nu)/(1 - nu^2) and n.G = c r, eliminating d_eps_yy gives
        d_lambda (c r + (1 - H) E m) = H |d sigma|,   d eps = d sigma / E + sgn(s) d_lambda,
    i.e. tangent T = E d / (d + H E) with d = c r + (1 - H) E m, and d eta = c r d eps_p, so
    ds/d eps = T - c r (1 - T/E). This is Bouc-Wen only if m = 1 (nu = 1/2) and c r = c (alpha = 0).
    """
    c = alpha * E / (1 - alpha)
    m = (1.25 - nu) / (1 - nu * nu)

    def rhs(y, sgn):
        s = y[1]
        r = abs(s) / SY
        h = r ** n if s * sgn > 0 else 0.0
        d = c * r + (1 - h) * E * m
        t = E * d / (d + h * E)
        return np.array([t, t - c * r * (1 - t / E)])
    return rhs


def compare_to_reference(mat, rhs, inc):
    """Max |sigma - reference| / peak over the driving cycle CYCLE with increments ``inc``."""
    point = Point(mat)
    _, sxx, _ = drive_uniaxial(point, CYCLE, inc)
    ref = rk4_path(rhs, [0.0, 0.0], legs(0.0, CYCLE, inc), REF_SUBSTEPS)
    return np.max(np.abs(sxx - ref)) / np.max(np.abs(ref))


# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3.0, 10.0])
def test_smooth_uniaxial_is_bouc_wen_where_the_reduction_is_exact(n):
    # nu = 1/2 - 1e-4 makes m - 1 = delta^2/(3/4 + delta - delta^2) ~ 1.3e-8 and alpha = 0 removes
    # the c r vs c difference: the model's uniaxial law is then Bouc-Wen (see smooth_uniaxial_rhs).
    mat = make(nu=0.5 - 1e-4, hardening=0.0, smoothness=n)
    rhs = bouc_wen_rhs(0.0, n)
    coarse = compare_to_reference(mat, rhs, EY / 50)
    fine = compare_to_reference(mat, rhs, EY / 100)
    # the kernel is second order (midpoint sub-steps, piecewise-linear strain path): halving the
    # increment must cut the error about 4x (> 3 allows for the last digits of the reference)
    assert coarse / fine > 3.0
    assert fine < 1e-4


def test_smooth_uniaxial_matches_its_exact_reduction_at_steel_values():
    # the paper's N = 10 and 5 % hardening with nu = 0.3: the full plane-stress kernel, driven in
    # uniaxial stress, against the closed-form reduction of the same equations
    mat = make(smoothness=10.0)
    rhs = smooth_uniaxial_rhs(NU, ALPHA, 10.0)
    coarse = compare_to_reference(mat, rhs, EY / 50)
    fine = compare_to_reference(mat, rhs, EY / 100)
    assert coarse / fine > 3.0  # second order, as above
    assert fine < 1e-4


@pytest.mark.parametrize("kind", ["smooth_vonmises", "bilinear_vonmises"])
def test_post_yield_tangent_is_alpha_E(kind):
    point = Point(make(kind))
    drive_uniaxial(point, [20 * EY], EY / 10)
    s0 = point.stress[0, 0]
    drive_uniaxial(point, [30 * EY], EY / 10)
    slope = (point.stress[0, 0] - s0) / (10 * EY)
    # bilinear: exact. smooth: 1 - |s/sy|^N decays like exp(-N eps/eps_y) past the knee, so at
    # 20 eps_y the tangent is alpha E to far below 1e-6; the solve error (1e-10 sy over 10 eps_y
    # of strain) contributes ~1e-10 relative.
    assert slope == pytest.approx(ALPHA * E, rel=1e-6)


def bilinear_uniaxial_exact(path_strain):
    """Closed-form stress of linear kinematic hardening along a strain path (start 0, 0)."""
    et = ALPHA * E
    sigma, back, eps_prev = 0.0, 0.0, 0.0
    out = []
    for eps in path_strain:
        trial = sigma + E * (eps - eps_prev)
        # the elastic range is [back - sy, back + sy]; beyond it the stress follows slope alpha E
        if trial > back + SY:
            sigma = back + SY + et * (trial - back - SY) / E
        elif trial < back - SY:
            sigma = back - SY + et * (trial - back + SY) / E
        else:
            sigma = trial
        back = min(max(back, sigma - SY), sigma + SY)
        out.append(sigma)
        eps_prev = eps
    return np.array(out)


def test_bilinear_reyields_after_reversal_at_smax_minus_2sy():
    point = Point(make("bilinear_vonmises"))
    # 0.37 eps_y increments put the yield and re-yield points inside increments
    eps, sxx, _ = drive_uniaxial(point, [3 * EY, -3 * EY], 0.37 * EY)
    exact = bilinear_uniaxial_exact(eps)
    # backward Euler is exact for linear hardening along a fixed direction: only round-off and
    # the 1e-10 sy uniaxial solve remain
    assert np.max(np.abs(sxx - exact)) < 1e-8 * SY
    i_max = int(np.argmax(sxx))
    smax = sxx[i_max]
    unload = sxx[i_max + 1:]
    elastic = unload > smax - 2 * SY
    # every step above smax - 2 sy lies on the elastic line, the first one below it does not
    assert np.allclose(unload[elastic], smax - E * (eps[i_max] - eps[i_max + 1:][elastic]), rtol=0,
                       atol=1e-8 * SY)
    first_plastic = np.argmin(elastic)
    assert sxx[i_max + 1 + first_plastic] > smax - E * (eps[i_max] - eps[i_max + 1 + first_plastic])


def cycle_gap(n):
    """Max |sigma_smooth - sigma_bilinear| over one uniaxial cycle, for smoothness n."""
    paths = []
    for mat in (make(smoothness=n), make("bilinear_vonmises")):
        paths.append(drive_uniaxial(Point(mat), CYCLE, EY / 20)[1])
    return np.max(np.abs(paths[0] - paths[1]))


def test_smooth_approaches_bilinear_as_n_grows():
    gaps = [cycle_gap(n) for n in (5.0, 10.0, 20.0, 40.0)]
    assert all(b < a for a, b in zip(gaps, gaps[1:])), gaps
    # the transition has a width ~ eps_y / N, so the gap shrinks roughly like 1/N: demand at
    # least half of that rate over the factor 8 in N
    assert gaps[-1] < gaps[0] / 4, gaps


def shear_path(mat, gamma_max, inc):
    """Pure shear strain to ``gamma_max``: (point, tau per step, max |normal stress| per step)."""
    point = Point(mat)
    taus, normals = [], []
    for d in legs(0.0, [gamma_max], inc):
        point.step((0.0, 0.0, d))
        taus.append(point.stress[0, 2])
        normals.append(np.abs(point.stress[0, [0, 1, 3]]).max())
    return point, np.array(taus), np.array(normals)


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
def test_pure_shear_yields_at_sy_over_sqrt3(formulation):
    gy = SY / math.sqrt(3) / MU
    point, tau, normal = shear_path(make("bilinear_vonmises", formulation), 6 * gy, 0.3 * gy)
    gamma = np.arange(1, len(tau) + 1) * 0.3 * gy
    # in pure shear: tau = mu gamma up to sy/sqrt(3), then slope mu c / (c + 3 mu)
    # (d eta_xy = c d gamma_p / 3 on the surface, d tau = mu (d gamma - d gamma_p))
    ty = SY / math.sqrt(3)
    exact = np.where(gamma < gy, MU * gamma, ty + MU * C_ZIEGLER / (C_ZIEGLER + 3 * MU) * (gamma - gy))
    assert np.max(np.abs(tau - exact)) < 1e-9 * SY  # exact return, round-off only
    assert normal.max() < 1e-9 * SY  # no normal stress appears in pure shear
    # the smooth model approaches it: s_xy tends to sy/sqrt(3) (1 - |s/sy|^N relaxes like
    # exp(-N gamma/gamma_y)), and its distance to the bilinear path shrinks with N
    gaps = []
    for n in (10.0, 40.0):
        point, tau_s, _ = shear_path(make(smoothness=n, formulation=formulation), 6 * gy, 0.3 * gy)
        assert point.phi() == pytest.approx(SY, rel=1e-6)
        gaps.append(np.max(np.abs(tau_s - exact)))
    assert gaps[1] < gaps[0]


@pytest.mark.parametrize("kind", ["smooth_vonmises", "bilinear_vonmises"])
def test_elastic_unloading_slope_is_E(kind):
    point = Point(make(kind))
    drive_uniaxial(point, [3 * EY], EY / 20)
    eps, sxx, work = drive_uniaxial(point, [2.2 * EY], EY / 20)
    slopes = np.diff(sxx) / np.diff(eps)
    # H2 = 0 (smooth) / inside the surface (bilinear): exactly elastic; the 1e-10 sy solve error
    # over EY/20 increments bounds the slope error by ~4e-9 E
    assert np.allclose(slopes, E, rtol=1e-7, atol=0)
    assert np.ptp(work) == 0.0  # no plastic work while unloading


NONPROPORTIONAL = {
    "biaxial": [(4 * EY, 2 * EY, 0.0), (EY, 5 * EY, 0.0), (-3 * EY, -3 * EY, 0.0)],
    "shear_normal": [(2 * EY, 0.0, 0.0), (2 * EY, 0.0, 6 * EY), (2 * EY, 0.0, -4 * EY),
                     (-EY, 0.0, 0.0)],
}


def strain_path(point, targets, inc):
    """Drive all three strain components through ``targets``; yield (phi, d eps_p_eq) per step."""
    e = np.zeros(3)
    for t in targets:
        t = np.asarray(t, float)
        n = max(1, math.ceil(np.max(np.abs(t - e)) / inc - 1e-9))
        for _ in range(n):
            before = point.state["eps_p_eq"][0]
            point.step((t - e) / n)
            yield point.phi(), point.state["eps_p_eq"][0] - before
        e = t


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
@pytest.mark.parametrize("path", sorted(NONPROPORTIONAL))
def test_stress_stays_on_the_shifted_surface(path, formulation):
    plastic_steps = 0
    for phi, dq in strain_path(Point(make("bilinear_vonmises", formulation)),
                               NONPROPORTIONAL[path], EY / 20):
        # the return mapping converges to round-off (Newton's error squares each step)
        assert phi <= SY * (1 + 1e-12)
        if dq > 0:
            plastic_steps += 1
            assert phi == pytest.approx(SY, rel=1e-12)
    assert plastic_steps > 50  # the path really is plastic most of the way
    # smooth model: with a consistent loading test the continuous law has
    # d Phi = (1 - H1) n.D d_eps while loading, so Phi never passes sy; the discrete RK2 near the
    # attractor only adds its local error, O((N h)^3) of the tiny 1 - Phi/sy there
    worst = max(phi for phi, _ in strain_path(Point(make(formulation=formulation)),
                                              NONPROPORTIONAL[path], EY / 20))
    assert worst <= SY * (1 + 1e-6)


@pytest.mark.xfail(strict=True, reason="H2 = step(s . d_eps) (docs/verification.md section 1) is not the consistent "
                   "loading test n.D d_eps > 0 in plane stress; on this path they disagree and Phi "
                   "goes past sy elastically (about 1 %). Remove this marker if H2 is changed.")
def test_smooth_plane_stress_h2_quirk_on_shear_compression():
    # the last leg starts with s mostly shear and d_eps = (2, 0, -6): s . d_eps < 0 (H2 = 0)
    # while n.D d_eps > 0, so Phi rises elastically past sy
    targets = [(2 * EY, 0.0, 0.0), (2 * EY, 0.0, 6 * EY), (-2 * EY, 0.0, 2 * EY), (0.0, 0.0, -4 * EY)]
    worst = max(phi for phi, _ in strain_path(Point(make()), targets, EY / 20))
    assert worst <= SY * (1 + 1e-6)


@pytest.mark.parametrize("kind", ["smooth_vonmises", "bilinear_vonmises"])
def test_plastic_work_equals_hysteresis_area(kind):
    point = Point(make(kind))
    drive_uniaxial(point, [4 * EY, -4 * EY], EY / 50)  # settle onto the steady loop
    eps0, s0, w0 = point.strain[0], point.stress[0, 0], point.state["plastic_work"][0]
    eps, sxx, work = drive_uniaxial(point, [4 * EY, -4 * EY], EY / 50)
    eps = np.concatenate([[eps0], eps])
    sxx = np.concatenate([[s0], sxx])
    # the loop closes in strain; in stress too for the bilinear model and, once settled, to
    # round-off for the smooth one (the memory of the first loading decays like exp(-N ...))
    assert sxx[-1] == pytest.approx(s0, rel=1e-6)
    area = np.sum(0.5 * (sxx[1:] + sxx[:-1]) * np.diff(eps))  # cyclic integral of sigma d eps
    dissipated = work[-1] - w0
    # trapezoid error with EY/50 steps on a loop whose corners are smooth (smooth) or resolved
    # (bilinear: corners inside increments cost O(h^2) of the corner's share) is < 0.1 %;
    # 1 % is the brief's tolerance
    assert dissipated == pytest.approx(area, rel=0.01)
    assert area > 0


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
@pytest.mark.parametrize("kind", ["smooth_vonmises", "bilinear_vonmises"])
def test_energy_balance_per_increment(kind, formulation):
    # elastic energy + plastic work must grow by exactly mean(sigma) . d_eps per increment (plastic
    # work is taken with the step's mean stress): what the solver's energy check relies on.
    # Increments of EY/20 < 0.1 eps_y are one sub-step of the smooth model, where the identity is
    # exact; with several sub-steps it holds per sub-step, not for the increment's mean stress.
    mat = make(kind, formulation)
    point = Point(mat)
    strain_work = 0.0
    for targets in NONPROPORTIONAL.values():
        e = point.strain.copy()
        for t in targets:
            t = np.asarray(t, float)
            n = max(1, math.ceil(np.max(np.abs(t - e)) / (EY / 20) - 1e-9))
            for _ in range(n):
                before = point.stress[0].copy()
                de = (t - e) / n
                point.step(de)
                mid = 0.5 * (before + point.stress[0])
                strain_work += mid[0] * de[0] + mid[1] * de[1] + mid[2] * de[2]
            e = t
    stored = mat.elastic_energy_density(point.stress)[0] + point.state["plastic_work"][0]
    # ~600 increments each exact to round-off (1e-16 relative): 1e-10 leaves ample room
    assert stored == pytest.approx(strain_work, rel=1e-10)
    assert point.state["plastic_work"][0] > 0


def test_which_updates_only_that_material():
    mat = make()
    stress = np.zeros((3, 4))
    state = {k: np.zeros((3,) + shape) for k, shape in mat.state_fields.items()}
    ids = np.array([0, 1, 0], np.int32)
    de = np.tile([2 * EY, 0.0, 0.0], (3, 1))
    mat.update_stress(stress, de, state, ids, 0)
    assert np.all(stress[1] == 0) and state["eps_p_eq"][1] == 0
    assert np.array_equal(stress[0], stress[2]) and stress[0, 0] > 0


def test_describe_names_the_parameters():
    line = make(smoothness=12.0).describe()
    assert "smooth_vonmises" in line and "yield_stress=4e+08" in line and "smoothness=12" in line
    assert "hardening=0.05" in make("bilinear_vonmises").describe()


@pytest.mark.parametrize("kind", ["smooth_vonmises", "bilinear_vonmises"])
@pytest.mark.parametrize("over, key", [
    ({"yield_stress": -1.0}, "yield_stress"),
    ({"yield_stress": 0.0}, "yield_stress"),
    ({"hardening": 1.0}, "hardening"),
    ({"hardening": -0.1}, "hardening"),
    ({"hardening": None}, "hardening"),  # required
    ({"yield": 1e6}, "yield"),  # unknown key (typo)
])
def test_bad_parameters_name_the_key(kind, over, key):
    table = dict(type=kind, E=E, nu=NU, density=7850.0, yield_stress=SY, hardening=ALPHA)
    table.update(over)
    table = {k: v for k, v in table.items() if v is not None}
    with pytest.raises(ConfigError) as err:
        make_material(table, KEY, "plane_stress")
    assert err.value.key == f"{KEY}.{key}"
    assert str(err.value).count("\n") == 0


@pytest.mark.parametrize("bad", [0.0, -2.0, "ten", 1e4])
def test_bad_smoothness_names_the_key(bad):
    with pytest.raises(ConfigError) as err:
        make(smoothness=bad)
    assert err.value.key == f"{KEY}.smoothness"


def test_bilinear_has_no_smoothness():
    with pytest.raises(ConfigError) as err:
        make("bilinear_vonmises", smoothness=10.0)
    assert err.value.key == f"{KEY}.smoothness"
