"""The numba transfer kernels agree with their plain NumPy twins (pmpm.core.kernels.reference),
on the whole grid and on a window of it (the rank-local grid of a slab)."""
import numpy as np
import pytest

from pmpm.core import kernels as K
from pmpm.core.kernels.reference import g2p_kinematics_reference, g2p_velocity_reference, p2g_reference
from pmpm.core.shape import SHAPE_TAGS, SHAPES

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}
CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])


def _particles(n=300, seed=1):
    rng = np.random.default_rng(seed)
    x = ORIGIN + rng.uniform(0, 1, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 1e-9          # on the lower edge: boundary-modified splines
    x[5:10, 1] = ORIGIN[1] + CELLS[1] * H - 1e-9
    return {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
            "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4)),
            "load_id": rng.integers(-1, 2, n).astype(np.int32), "load_w": rng.uniform(0, 1, n)}


@pytest.mark.parametrize("name", list(SHAPES))
def test_p2g_matches_reference(name):
    p = _particles()
    gravity = np.array([0.3, -9.8])
    load_vec = np.array([[1.0, 2.0], [-3.0, 0.5]])
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], gravity, p["load_id"], p["load_w"], load_vec,
          G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    fext = p["m"][:, None] * gravity + np.where(p["load_id"][:, None] >= 0,
                                                p["load_w"][:, None] * load_vec[p["load_id"]], 0.0)
    mass, mom, force = p2g_reference(ORDER[name], p["x"], p["m"], p["v"], p["vol"], p["stress"], fext,
                                     ORIGIN, H, CELLS)
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-11, atol=1e-11)
    assert G[..., 0].sum() == pytest.approx(p["m"].sum(), rel=1e-13)  # partition of unity: mass kept


@pytest.mark.parametrize("name", list(SHAPES))
def test_p2g_on_a_window_equals_the_slice_of_the_full_grid(name):
    """Particles whose cells lie in columns [3, 6) touch only the window [3-g, 6+g)."""
    p = _particles()
    keep = (p["x"][:, 0] - ORIGIN[0]) / H
    keep = (keep >= 3) & (keep < 6)
    p = {k: v[keep] for k, v in p.items()}
    full = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    win = np.zeros((6 + 2 - 1 + 1, CELLS[1] + 1, K.N_FIELDS))  # columns 1 .. 8
    for G, ox in ((full, 0), (win, 1)):
        K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
              G, ox, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    np.testing.assert_array_equal(full[1:9], win)
    assert not full[:1].any() and not full[9:].any()


@pytest.mark.parametrize("name", list(SHAPES))
@pytest.mark.parametrize("pic", [0.0, 0.3])
def test_g2p_velocity_matches_reference(name, pic):
    p = _particles()
    rng = np.random.default_rng(7)
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    G[..., 1:5] = rng.normal(size=G[..., 1:5].shape)
    vel, dvel = G[..., 1:3].copy(), G[..., 3:5].copy()
    v = p["v"].copy()
    dx = np.empty_like(v)
    vmax, bad = K.g2p_velocity(p["x"], p["m"], v, pic, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1],
                               SHAPE_TAGS[name], True, dx, 0.5)
    ref = g2p_velocity_reference(ORDER[name], p["x"], p["v"], vel, dvel, pic, ORIGIN, H, CELLS)
    np.testing.assert_allclose(v, ref, rtol=1e-12, atol=1e-12)
    assert vmax == pytest.approx(np.sqrt((ref ** 2).sum(1)).max(), rel=1e-12) and bad == 0
    pic_only = g2p_velocity_reference(ORDER[name], p["x"], p["v"], vel, dvel, 1.0, ORIGIN, H, CELLS)
    np.testing.assert_allclose(dx, 0.5 * pic_only, rtol=1e-12, atol=1e-12)  # the move, eq. 5
    # the MUSL re-map scattered the new momenta: total momentum is conserved exactly
    np.testing.assert_allclose(G[..., 5:7].sum(axis=(0, 1)), (p["m"][:, None] * v).sum(0), rtol=1e-12)


@pytest.mark.parametrize("name", list(SHAPES))
@pytest.mark.parametrize("field", [K.MOM, K.REMAP])
def test_g2p_kinematics_matches_reference(name, field):
    """Strain increment, spin, volume update and move against the twin written from eq. 5-6.
    A random nodal velocity field has every gradient component, so a wrong component, a
    wrong sign of the spin or a volume update missing a term shows at order one; the
    tolerance is round-off of sums of at most 16 O(1) terms."""
    p = _particles()
    rng = np.random.default_rng(11)
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    G[..., 1:] = rng.normal(size=G[..., 1:].shape)
    other = K.REMAP if field == K.MOM else K.MOM
    vel = G[..., field:field + 2].copy()
    dt = 0.01
    dx = 1e-3 * rng.normal(size=(len(p["m"]), 2))
    x, vol = p["x"].copy(), p["vol"].copy()
    strain = rng.normal(size=(len(p["m"]), 3))
    strain0 = strain.copy()
    de, dw = np.empty((len(p["m"]), 3)), np.empty(len(p["m"]))
    gravity = np.array([0.3, -9.8])
    work = K.g2p_kinematics(x, p["m"], vol, strain, de, dw, None, None, None, field, dx, dt, gravity,
                            None, None, None,
                            G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    de_ref, dw_ref, vol_ref, x_ref = g2p_kinematics_reference(ORDER[name], p["x"], p["vol"], vel, dx, dt,
                                                             ORIGIN, H, CELLS)
    assert np.abs(de_ref).max() > 1e-3 and np.abs(dw_ref).max() > 1e-3  # the check is not vacuous
    np.testing.assert_allclose(de, de_ref, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(dw, dw_ref, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(vol, vol_ref, rtol=1e-12, atol=0)
    np.testing.assert_allclose(strain, strain0 + de_ref, rtol=1e-12, atol=1e-13)
    np.testing.assert_array_equal(x, x_ref)  # x + dx: one addition, exact
    # the work of the body force over the moves, sum m g . dx
    assert work == pytest.approx(float(np.sum(p["m"][:, None] * gravity * dx)), rel=1e-12)
    # the other velocity field is not read: changing it changes nothing
    G[..., other:other + 2] += 1.0
    de2 = np.empty_like(de)
    K.g2p_kinematics(p["x"].copy(), p["m"], p["vol"].copy(), None, de2, None, None, None, None, field, None,
                     dt, None, None, None, None, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    np.testing.assert_array_equal(de2, de)


def test_g2p_kinematics_point_load_work():
    """The work returned with per-particle loads (load_id/load_w, the kernel's own load path)
    is sum_p (m_p g + w_p F_k) . dx_p."""
    p = _particles()
    rng = np.random.default_rng(5)
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    dx = 1e-3 * rng.normal(size=(len(p["m"]), 2))
    load_vec = np.array([[1.0, 2.0], [-3.0, 0.5]])
    gravity = np.array([0.0, -9.8])
    work = K.g2p_kinematics(p["x"].copy(), p["m"], p["vol"].copy(), None, None, None, None, None, None,
                            K.MOM, dx, 0.01,
                            gravity, p["load_id"], p["load_w"], load_vec,
                            G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS["cubic"])
    f = p["m"][:, None] * gravity + np.where(p["load_id"][:, None] >= 0,
                                             p["load_w"][:, None] * load_vec[p["load_id"]], 0.0)
    assert work == pytest.approx(float(np.sum(f * dx)), rel=1e-12)


def test_grid_update_applies_bcs_and_mass_cutoff():
    """v = (p + f dt)/m; prescribed components; nodes below the cutoff get no acceleration."""
    G = np.zeros((3, 3, K.N_FIELDS))
    G[..., 0] = 2.0
    G[..., 1:3] = 4.0   # momentum
    G[..., 3:5] = 2.0   # force
    G[0, 0, 0] = 1e-20  # below the cutoff: keeps its (mean) velocity, no acceleration
    G[0, 0, 1:3] = 1e-20 * 3.0
    mask = np.zeros((3, 3, 2), np.int8)
    vel = np.zeros((3, 3, 2))
    mask[1, 1, 0] = 1
    vel[1, 1, 0] = 0.5
    K.grid_update(G, 0.1, 1e-12, mask, vel, 0, 3, 0, 3, None, np.array([0, 0, 3]))
    assert G[2, 2, 1] == pytest.approx(2.0 + 0.1)      # v = (p + f dt) / m
    assert G[2, 2, 3] == pytest.approx(0.1)            # dv = f dt / m
    assert G[1, 1, 1] == 0.5 and G[1, 1, 3] == pytest.approx(0.5 - 2.0)  # prescribed component
    assert G[1, 1, 2] == pytest.approx(2.1)            # the free component is untouched
    np.testing.assert_allclose(G[0, 0, 1:3], 3.0)
    assert not G[0, 0, 3:5].any()


def test_none_effects_compile_out_and_match_zero_effects():
    """Passing None (effect off) gives the same grid as passing zero gravity and no load."""
    p = _particles()
    a = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    b = np.zeros_like(a)
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
          a, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS["cubic"])
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], np.zeros(2), np.full(len(p["m"]), -1, np.int32),
          p["load_w"], np.zeros((1, 2)), b, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS["cubic"])
    np.testing.assert_array_equal(a, b)


def test_cell_order_sorts_by_cell_and_is_a_permutation():
    p = _particles(500)
    order = K.cell_order(p["x"], ORIGIN, 1 / H, 0, CELLS[0], 0, CELLS[1])
    assert sorted(order) == list(range(500))
    cells = np.floor((p["x"][order] - ORIGIN) / H).astype(int)
    key = cells[:, 0] * CELLS[1] + cells[:, 1]
    assert np.all(np.diff(key) >= 0)


def test_reorder_in_place_equals_fancy_indexing():
    from pmpm.core.particles import Particles
    rng = np.random.default_rng(3)
    n = 257
    fields = {"id": np.arange(n, dtype=np.int64), "x": rng.normal(size=(n, 2)),
              "stress": rng.normal(size=(n, 4)), "mat": rng.integers(0, 3, n).astype(np.int32)}
    order = rng.permutation(n)
    expected = {k: v[order].copy() for k, v in fields.items()}
    p = Particles({k: v.copy() for k, v in fields.items()})
    p.reorder(order)
    for k in fields:
        np.testing.assert_array_equal(p[k], expected[k])
