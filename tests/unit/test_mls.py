"""MLS-MPM (pmpm.core.mls, pmpm.core.kernels.mls; Hu et al. 2018): the numba kernels against
their NumPy twins, the conservation of momentum and angular momentum off the origin, the fixed-
free bar's period against its closed form (design.md section 7), and the scheme's refusals."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.core import kernels as K
from pmpm.core.solver import Solver
from pmpm.physics.materials.linear_elastic import LinearElastic, _update_elastic_power
from pmpm.core.schemes import make_scheme
from pmpm.core.kernels.mls import g2p_mls, p2g_mls
from pmpm.core.kernels.reference_mls import mls_g2p_reference, mls_p2g_reference
from pmpm.core.shape import SHAPE_TAGS
from pmpm.errors import ConfigError
from pmpm.scene.config import parse_scene

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}
CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])


def _particles(n=300, seed=4):
    rng = np.random.default_rng(seed)
    x = ORIGIN + rng.uniform(0.02, 0.98, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 0.05 * H      # near the edges: boundary-modified splines, D_p not h^2/3 I
    x[5:10, 1] = ORIGIN[1] + (CELLS[1] - 0.05) * H
    return {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
            "C": rng.normal(size=(n, 4)), "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4))}


def _grid():
    return np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))


@pytest.mark.parametrize("name", list(ORDER))
def test_p2g_mls_matches_reference(name):
    p = _particles()
    g = np.array([0.3, -9.81])
    G = _grid()
    p2g_mls(p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"], g, None, None, None,
            G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    mass, mom, force = mls_p2g_reference(ORDER[name], p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"],
                                         p["m"][:, None] * g, ORIGIN, H, CELLS)
    # tolerances: round-off of sums of ~300 terms of order one (the twin inverts D_p with LAPACK)
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("name", ["quadratic", "cubic"])
def test_p2g_mls_with_the_impulse_matches_reference(name):
    """With ``impulse_dt`` the P2G scatters m v + dt f into the momentum's fields and nothing
    into the force's (Hu et al.'s P2G, what the scheme runs without damping): against the twin's
    momentum plus dt times its force (internal and body force), mass unchanged. Tolerances as
    above (dt f is of the momentum's order here). Shown to fail: with the affine part of the
    impulse left out (k instead of k + dt A) the momentum differs at order one."""
    p = _particles()
    g = np.array([0.3, -9.81])
    dt = 0.7
    G = _grid()
    p2g_mls(p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"], g, None, None, None,
            G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name], dt)
    mass, mom, force = mls_p2g_reference(ORDER[name], p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"],
                                         p["m"][:, None] * g, ORIGIN, H, CELLS)
    assert np.abs(dt * force).max() > 0.5 * np.abs(mom).max()   # the impulse is not negligible
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom + dt * force, rtol=1e-10, atol=1e-10)
    assert not G[..., 3:5].any()


@pytest.mark.parametrize("name", list(ORDER))
def test_g2p_mls_matches_reference(name):
    p = _particles()
    G = _grid()
    G[..., 1:3] = np.random.default_rng(5).normal(size=G[..., 1:3].shape)
    vel = G[..., 1:3].copy()
    dt = 0.01
    v, C, dx, vol = p["v"].copy(), p["C"].copy(), np.empty_like(p["v"]), p["vol"].copy()
    de = np.empty((len(v), 3))
    vmax, bad, *tail = g2p_mls(p["x"], v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name],
                               dx, dt, None, de, None, None, vol, None, None)
    assert tail == [0.0, 0.0, 0, 0, 0, 0.0]   # no fused tail asked: none computed
    vp, Cp, de_ref, vol_ref = mls_g2p_reference(ORDER[name], p["x"], p["vol"], vel, dt, ORIGIN, H, CELLS)
    np.testing.assert_allclose(v, vp, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(C, Cp, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(de, de_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(vol, vol_ref, rtol=1e-12)
    np.testing.assert_allclose(dx, dt * vp, rtol=1e-12, atol=1e-14)
    assert vmax == pytest.approx(np.sqrt((vp ** 2).sum(1)).max(), rel=1e-12) and bad == 0


@pytest.mark.parametrize("name", ["quadratic", "cubic"])
@pytest.mark.parametrize("axis", [0, 1])
def test_mls_block_weights_are_the_shape_modules(name, axis):
    """The MLS kernels' own block weights (pmpm.core.kernels.mls._axis_weights: no derivatives,
    the edge test once per block) against pmpm.core.shape's block kernels: blocks
    of 64 interior coordinates, each with one coordinate where the boundary modification or the
    clamping must act (0, just inside each edge, on the last node, beyond the grid, 1e20,
    -1e20, NaN, inf) and one with none; the first nodes exactly, the weights to round-off.
    Shown to fail: with the edge test ``c < 0`` instead
    of ``c < 1`` the block with a support reaching node -1 keeps the plain weights."""
    from pmpm.core.kernels.mls import _axis_weights
    from pmpm.core.shape import block_weights
    order = ORDER[name]
    K = order + 1
    n = CELLS[axis]
    rng = np.random.default_rng(12)
    special = [None, 0.0, 0.3, 0.99, 1.2, n - 0.3, n - 1.2, n - 0.6, float(n), n + 0.7, -0.4,
               1e20, -1e20, np.nan, np.inf]
    for value in special:
        s = rng.uniform(2.0, n - 2.0, 64)
        if value is not None:
            s[17] = value
        x = np.zeros((64, 2))
        x[:, axis] = ORIGIN[axis] + s * H
        start, W = np.full(64, -7, np.int64), np.full((2 * K, 64), np.nan)
        _axis_weights(x, 0, 64, axis, ORIGIN[axis], 1 / H, n, K, start, W)
        ref_start, ref_W = np.empty(64, np.int64), np.empty((2 * K, 64))
        block_weights(SHAPE_TAGS[name], (x[:, axis] - ORIGIN[axis]) * (1 / H), None, 64, n, ref_start, ref_W)
        np.testing.assert_array_equal(start, ref_start, err_msg=f"coordinate {value}")
        # weights (at most 1) within 2 ulp of 1: the compiler may contract the polynomials'
        # multiply-adds (FMA) in one and not the other; the first nodes exactly
        np.testing.assert_allclose(W[:K], ref_W[:K], rtol=0, atol=4.5e-16, err_msg=f"coordinate {value}")


@pytest.mark.parametrize("name", ["quadratic", "cubic"])
def test_mls_kernels_at_the_edge_of_the_plain_supports(name):
    """The kernels take D_p^-1 as the B-spline's constant (4 or 3 / cells^2) where a support is
    not boundary-modified and sum D_p elsewhere: particles on either side of that limit on
    every edge (coordinates 0.5 and n - 0.5 cells quadratic, 1 and n - 1 cubic, and 1e-9
    cells to the edge's side of them, where the weights are boundary-modified and D_p is not
    the constant), against the NumPy twins (which always sum and invert D_p). Tolerances as
    in the two tests above. Shown to fail: with the plain support taken to start one node
    early (``c - 1 >= -1`` in pmpm.core.kernels.mls._inside) the forces differ by order one."""
    order = ORDER[name]
    limit = 0.5 if order == 2 else 1.0
    cells = np.array(CELLS)
    near = np.array([limit - 1e-9, limit, limit + 1e-9])
    s = np.array([[a, 2.7] for a in near] + [[cells[0] - a, 3.1] for a in near]
                 + [[4.3, a] for a in near] + [[5.6, cells[1] - a] for a in near])
    p = _particles(n=len(s), seed=7)
    p["x"] = ORIGIN + s * H
    G = _grid()
    p2g_mls(p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"], None, None, None, None,
            G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    mass, mom, force = mls_p2g_reference(order, p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"],
                                         np.zeros((len(s), 2)), ORIGIN, H, CELLS)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-10, atol=1e-10)
    G[..., 1:3] = np.random.default_rng(8).normal(size=G[..., 1:3].shape)
    vel = G[..., 1:3].copy()
    v, C, dx, vol = p["v"].copy(), p["C"].copy(), np.empty_like(p["v"]), p["vol"].copy()
    de = np.empty((len(v), 3))
    g2p_mls(p["x"], v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name],
            dx, 0.01, None, de, None, None, vol, None, None)
    vp, Cp, de_ref, vol_ref = mls_g2p_reference(order, p["x"], p["vol"], vel, 0.01, ORIGIN, H, CELLS)
    np.testing.assert_allclose(v, vp, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(C, Cp, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("name", list(ORDER))
@pytest.mark.parametrize("axis", [0, 1])
def test_g2p_mls_fused_tail_matches_reference(name, axis):
    """The G2P with the step's later particle passes folded in (``m``, ``gravity``, ``stress``,
    ``owned`` given; what the scheme runs when nothing acts between them): the same velocity,
    C, strain and volume as without, and the move x + dt v_p, the body force's work
    sum_p m_p g . dt v_p, the first half of the internal work sum_p V_p sigma_p : de_p (the new
    volume) and the counts of particles outside the grid, leaving the owned columns [3, 5) of
    ``axis`` and with an inverted volume, against the NumPy twin of the G2P and those
    definitions written here. dt = 0.08 s on 0.25 m cells of random nodal velocities moves
    particles by up to about a cell: some leave the grid, many the owned columns, and the
    largest velocity gradients turn some volumes inside out (each count is checked nonzero).
    Tolerances: the twins' above; the sums are of ~300 terms of order one. Shown to fail: with
    the strays counted before the move, the counts differ; with the work half taken with the
    volume before its update, the power differs (every shape, both axes)."""
    p = _particles()
    G = _grid()
    G[..., 1:3] = 3.0 * np.random.default_rng(5).normal(size=G[..., 1:3].shape)
    vel = G[..., 1:3].copy()
    dt = 0.08
    g = np.array([0.3, -9.81])
    owned = (axis, 3, 5)
    x, v, C, dx, vol = p["x"].copy(), p["v"].copy(), p["C"].copy(), np.empty_like(p["v"]), p["vol"].copy()
    de = np.empty((len(v), 3))
    vmax, bad, work, power, outside, leaving, inverted, after = g2p_mls(
        x, v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name],
        dx, dt, None, de, None, None, vol, None, None, p["m"], g, p["stress"], owned)
    vp, Cp, de_ref, vol_ref = mls_g2p_reference(ORDER[name], p["x"], p["vol"], vel, dt, ORIGIN, H, CELLS)
    np.testing.assert_allclose(v, vp, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(C, Cp, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(de, de_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(vol, vol_ref, rtol=1e-12)
    x_ref = p["x"] + dt * vp
    np.testing.assert_allclose(x, x_ref, rtol=1e-12, atol=1e-14)
    assert work == pytest.approx(np.sum(p["m"] * (dt * vp @ g)), rel=1e-10)
    assert power == pytest.approx(np.sum(vol_ref * np.sum(p["stress"][:, :3] * de_ref, axis=1)), rel=1e-10)
    s = (x_ref - ORIGIN) / H
    out_ref = ~((s[:, 0] >= 0) & (s[:, 0] < CELLS[0]) & (s[:, 1] >= 0) & (s[:, 1] < CELLS[1]))
    col = np.floor(s[:, axis])
    leaving_ref = ~out_ref & ((col < owned[1]) | (col >= owned[2]))
    assert (outside, leaving, inverted) == (out_ref.sum(), leaving_ref.sum(), (vol_ref <= 0).sum())
    assert outside > 0 and leaving > 0 and inverted > 0   # each count is exercised
    # and the solver's own count of the moved particles agrees with the kernel's
    assert K.count_strays(x, vol, ORIGIN, 1 / H, CELLS[0], CELLS[1], *owned) == (outside, leaving, inverted)
    assert bad == 0 and vmax == pytest.approx(np.sqrt((vp ** 2).sum(1)).max(), rel=1e-12)
    assert after == 0.0   # no stress map: the stress is not updated here


@pytest.mark.parametrize("name", list(ORDER))
def test_g2p_mls_applies_the_stress_map(name):
    """With ``stress_map`` (a material's update as one linear map D, (4, 3) row by row) the
    G2P adds D de_p to every particle's stress (szz included) and returns, besides the first
    half of the internal work with the stress before (V_new sigma_old : de), the second half
    V_new sigma_new : de, against the NumPy twin's de and volume and those sums written here.
    D is a full random matrix (every entry reaches the stress). Tolerances: the twins' above;
    the sums are of ~300 terms of order one. Shown to fail: with the szz row not applied, and
    with the second half summed with the stress before the increment."""
    p = _particles()
    G = _grid()
    G[..., 1:3] = np.random.default_rng(5).normal(size=G[..., 1:3].shape)
    vel = G[..., 1:3].copy()
    dt = 0.01
    D = np.random.default_rng(9).normal(size=(4, 3)) * 50.0
    owned = (0, 0, CELLS[0])
    x, v, C, dx, vol = p["x"].copy(), p["v"].copy(), p["C"].copy(), np.empty_like(p["v"]), p["vol"].copy()
    de = np.empty((len(v), 3))
    stress = p["stress"].copy()
    vmax, bad, work, power, outside, leaving, inverted, after = g2p_mls(
        x, v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name],
        dx, dt, None, de, None, None, vol, None, None, p["m"], None, stress, owned, tuple(D.ravel()))
    vp, Cp, de_ref, vol_ref = mls_g2p_reference(ORDER[name], p["x"], p["vol"], vel, dt, ORIGIN, H, CELLS)
    np.testing.assert_allclose(de, de_ref, rtol=1e-10, atol=1e-12)
    new = p["stress"] + de_ref @ D.T
    assert np.abs(de_ref @ D.T).min(axis=0).max() > 0 and np.abs(de_ref @ D.T)[:, 3].max() > 1e-3
    np.testing.assert_allclose(stress, new, rtol=1e-10, atol=1e-10)
    assert power == pytest.approx(np.sum(vol_ref * np.sum(p["stress"][:, :3] * de_ref, axis=1)), rel=1e-10)
    assert after == pytest.approx(np.sum(vol_ref * np.sum(new[:, :3] * de_ref, axis=1)), rel=1e-10)
    assert abs(after - power) > 1e-3 * abs(power)   # the two halves differ: each is checked


@pytest.mark.parametrize("axis", [0, 1])
def test_g2p_mls_counts_strays_block_by_block(axis):
    """The fused G2P recounts a block's strays one by one only where a particle of the block is
    not settled (pmpm.core.kernels.mls._settled): 640 particles at rest (zero grid velocities)
    in the owned columns [3, 5) of ``axis``, and in four blocks of 64 one particle each exactly
    on the limits: at column 5 (leaving), 1e-12 cells below column 3 (leaving), exactly on
    column 3 (not leaving), and one with a negative volume (inverted); the other six blocks
    settled. The counts against the solver's own pass (pmpm.core.kernels.locate.count_strays,
    floor and integer comparisons). Shown to fail: with ``s <= c1`` in _settled the particle on
    column 5 is not counted."""
    rng = np.random.default_rng(11)
    n = 640
    s = np.empty((n, 2))
    s[:, axis] = rng.uniform(3.2, 4.8, n)
    s[:, 1 - axis] = rng.uniform(1.5, 4.5, n)
    vol = rng.uniform(0.1, 0.3, n)
    s[70, axis] = 5.0
    s[200, axis] = 3.0 - 1e-12
    s[330, axis] = 3.0
    vol[460] = -0.1
    x = ORIGIN + s * H
    G = _grid()
    v, C, de = np.zeros((n, 2)), np.zeros((n, 4)), np.empty((n, 3))
    out = g2p_mls(x, v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS["quadratic"], None, 0.01,
                  None, de, None, None, vol, None, None, np.ones(n), None, None, (axis, 3, 5))
    assert out[4:7] == K.count_strays(x, vol, ORIGIN, 1 / H, CELLS[0], CELLS[1], axis, 3, 5) == (0, 2, 1)


@pytest.mark.parametrize("name", list(ORDER))
def test_g2p_mls_without_the_moves_and_increments_arrays(name):
    """With the move and the stress map folded in, ``dx`` and ``de`` may be None (the scheme
    leaves them out where nothing reads them after the pass): every other output is the same
    to the bit as with the arrays (the same expressions, from registers), under gravity (the
    body force's work over the move). Shown to fail: with the folded move taking dt v_y along x."""
    p = _particles()
    G = _grid()
    G[..., 1:3] = np.random.default_rng(5).normal(size=G[..., 1:3].shape)
    D = tuple(np.random.default_rng(9).normal(size=12) * 50.0)
    g = np.array([0.3, -9.81])
    runs = []
    for keep in (True, False):
        x, v, C, vol, stress = (p[k].copy() for k in ("x", "v", "C", "vol", "stress"))
        dx = np.empty_like(v) if keep else None
        de = np.empty((len(v), 3)) if keep else None
        out = g2p_mls(x, v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name], dx, 0.08, None, de,
                      None, None, vol, None, None, p["m"], g, stress, (1, 2, 5), D)
        runs.append((out, x, v, C, vol, stress))
    (out_a, *arrays_a), (out_b, *arrays_b) = runs
    assert out_a == out_b and out_a[2] != 0.0
    for a, b in zip(arrays_a, arrays_b):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("shape", ["quadratic", "cubic"])
def test_mls_step_with_the_fused_tail_is_the_step_without(shape, monkeypatch):
    """The solver's MLS step with the move, the strays count and the first work half in the
    G2P's pass, the force's impulse scattered with the momentum and the second work half in
    the elastic update's pass, against the same step with separate passes and the force apart
    (``tail_fusable``, ``impulse_fusable`` and ``sums_power`` forced False): the particles' state and the balance's internal and external work agree to
    round-off over 60 steps of the bar under gravity along it, towards its held end (the body
    force works over the moves),
    (no objective rate). Round-off: the fused passes contract multiply-adds (FMA) and add the
    impulse to the momentum before the nodal sums, ~1e-16 relative per step over 60 steps
    (1e-14 measured). No mass cutoff: with the default one (1e-8 of the largest particle
    mass) the nodes below it take their particles' impulse when it is fused and hold it back
    when apart, 1e-11 to 1e-10 of the fields here (pmpm.core.kernels.mls.p2g_mls).
    Shown to fail: with take_tail dropping the body force's work, the fused run's energy
    check stops it at step 10 (energy above the initial energy plus the external work); with
    update_stress taking its own first half as well as the fused one, internal_work is 140 J
    against 94 J; with the elastic update summing its half with the stress before the
    increment, internal_work differs too."""
    def run():
        data = _bar_data(shape, v0=0.05)
        data["solver"]["mass_cutoff"] = 0.0   # (a node below the cutoff gets the impulse when fused)
        scene = parse_scene({**data, "loads": {"gravity": [-9.81, 0.0]}}, "bar.toml")
        s = build_solver(scene, MPI.COMM_SELF)
        for _ in range(60):
            s.step()
        return s
    updates = []
    monkeypatch.setattr(LinearElastic, "update_stress_power",
                        lambda self, *a: updates.append(1) or _update_elastic_power(*a[:3], self.params,
                                                                                   self.plane_strain, *a[4:]))
    fused = run()
    assert fused.tail_fusable and fused.impulse_fusable and fused._stress_map is not None
    assert not updates   # the G2P applied the elastic map: the material's pass did not run
    monkeypatch.setattr(Solver, "tail_fusable", property(lambda self: False))
    monkeypatch.setattr(Solver, "impulse_fusable", property(lambda self: False))
    monkeypatch.setattr(LinearElastic, "sums_power", False)   # the second work half in its own pass too
    apart = run()
    for name in ("x", "v", "stress", "C", "vol"):
        ref = apart.particles[name]   # (round-off relative to the field's own scale)
        np.testing.assert_allclose(fused.particles[name], ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert abs(apart.external_work) > 0 and abs(apart.internal_work) > 0
    assert fused.external_work == pytest.approx(apart.external_work, rel=1e-12)
    assert fused.internal_work == pytest.approx(apart.internal_work, rel=1e-12)


@pytest.mark.parametrize("loads", ["forces", "rayleigh"])
def test_mls_step_keeps_the_arrays_its_effects_read(loads, monkeypatch):
    """The fused G2P leaves out the moves (``dx``) and increments (``de``) only where nothing
    reads them after it: a point load's work reads the moves (``after_move``), Rayleigh
    damping's viscous stress the increments (``after_stress_update``). Against the same step
    with every fusion off (tail_fusable, impulse_fusable False), 40 steps of the bar with the
    point load on its free end or Rayleigh damping: the state, the works and the damping's
    work agree to round-off (tolerance as in the test above). Shown to fail: with the moves
    or the increments left out regardless (the last two flags of Solver.tail_arguments
    False), the external work (point load) or the viscous damping work (Rayleigh) differ."""
    def run():
        data = _bar_data("quadratic", v0=0.05)
        data["solver"]["mass_cutoff"] = 0.0
        h = L_BAR / 50
        data["loads"] = ({"forces": [{"lower": [L_BAR - h, 0.0], "upper": [L_BAR, h], "force": [0.05, 0.0]}]}
                         if loads == "forces" else {"damping": {"ratio": 0.05, "periods": [PERIOD, PERIOD / 3]}})
        s = build_solver(parse_scene(data, "bar.toml"), MPI.COMM_SELF)
        for _ in range(40):
            s.step()
        return s
    fused = run()
    assert fused.tail_fusable and fused._stress_map is not None
    assert fused.tail_arguments()[-2:] == ((True, False) if loads == "forces" else (False, True))
    monkeypatch.setattr(Solver, "tail_fusable", property(lambda self: False))
    monkeypatch.setattr(Solver, "impulse_fusable", property(lambda self: False))
    apart = run()
    for name in ("x", "v", "stress"):
        ref = apart.particles[name]
        np.testing.assert_allclose(fused.particles[name], ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    ef, ea = fused.energies(), apart.energies()
    for key in ("external_work", "internal_work", "viscous_damping_work"):
        if key in ea:
            assert ef[key] == pytest.approx(ea[key], rel=1e-10, abs=1e-12 * abs(ea["internal_work"]))
    assert abs(ea["external_work" if loads == "forces" else "viscous_damping_work"]) > 0


def _spinning_block(scheme, shape, transfer="flip"):
    """A free elastic L-shaped body, spinning, drifting and stretching, far from the grid's
    origin and from the point the angular momentum is taken about; no supports, no loads, no
    mass cutoff (a node dropped by it would take momentum away)."""
    vel = ["0.2 - 0.5 * (y - 1.1) + 0.3 * (x - 1.4)", "0.1 + 0.5 * (x - 1.4) - 0.1 * (y - 1.1)"]
    body = {"shape": "rectangle", "material": "m", "velocity": vel}
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.3, -0.2], "cell_size": 0.1, "cells": [30, 30]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 100.0}},
        "bodies": [{**body, "name": "a", "lower": [1.0, 0.8], "upper": [1.8, 1.2]},
                   {**body, "name": "b", "lower": [1.0, 1.2], "upper": [1.3, 1.6]}],
        "solver": {"end_time": 1.0, "cfl": 0.5, "scheme": scheme, "transfer": transfer,
                   "shape_function": shape, "mass_cutoff": 0.0},
        "output": {"fields": ["x", "v"]},
    }, "block.toml")


def _grid_momenta(s, o):
    """(P_x, P_y, L about o) of a fresh particles-to-grid of momentum: the particles' momentum
    and angular momentum, affine part included (the affine p2g conserves both)."""
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=False)
    w, g = s.window, s.grid
    X = g.origin[0] + g.h * (w.ox + np.arange(w.G.shape[0]))[:, None] - o[0]
    Y = g.origin[1] + g.h * (w.oy + np.arange(w.G.shape[1]))[None, :] - o[1]
    G = w.G
    return np.array([G[..., 1].sum(), G[..., 2].sum(), np.sum(X * G[..., 2] - Y * G[..., 1])])


@pytest.mark.parametrize("shape", ["quadratic", "cubic"])
def test_mls_conserves_momentum_and_angular_momentum_off_the_origin(shape):
    """The affine transfers, the grid update with the MLS force (its torque vanishes for a
    symmetric stress: sum_i (x_i - x_p) (x) g_ip = I) and x_p += dt v_p conserve the momentum and
    the angular momentum to round-off (Hu et al. 2018, sec. 4; Jiang et al. 2015, sec. 5), while
    the body deforms (the stresses are not small: E = 1e5 against rho v^2 ~ 10). About
    o = (-2, 3): away from the origin and the body, which is not symmetric. Shown to fail: with
    the affine part left out of p2g (PIC momentum) the angular momentum drifts by ~1e-1."""
    o = np.array([-2.0, 3.0])
    s = build_solver(_spinning_block("mls", shape), MPI.COMM_SELF)
    M0 = _grid_momenta(s, o)
    worst = np.zeros(3)
    for _ in range(150):
        s.step()
        worst = np.maximum(worst, np.abs(_grid_momenta(s, o) - M0))
    assert np.abs(s.particles["stress"]).max() > 1.0   # the body really is stressed
    scale = np.abs(M0).max()
    # round-off: each step's sums lose ~1e-13 of the momenta to the lever arms about o (3 to 5 m
    # against a 0.8 m body); 150 steps accumulate a few 1e-11; 1e-9 bounds that
    assert worst.max() / scale < 1e-9, worst / scale


def test_mls_linear_conserves_momentum():
    """With linear B-splines the MLS force is the B-spline gradient's (sum_i grad N_i = 0):
    the momentum is conserved to round-off. 40 steps: this stretching body's particles cross
    cells by step ~50, where linear MPM's cell-crossing error inverts a volume (USL too).
    Shown to fail: with the velocity gathered from the grid's velocity change (fields 3, 4,
    FLIP's) instead of the velocity, the momentum drifts at order one."""
    o = np.array([-2.0, 3.0])
    s = build_solver(_spinning_block("mls", "linear"), MPI.COMM_SELF)
    M0 = _grid_momenta(s, o)
    worst = np.zeros(3)
    for _ in range(40):
        s.step()
        worst = np.maximum(worst, np.abs(_grid_momenta(s, o) - M0))
    assert worst[:2].max() / np.abs(M0[:2]).max() < 1e-10, worst


# -- the fixed-free bar (design.md section 7): u = (v0 / omega) sin(omega t) sin(beta x) ------
L_BAR, E_BAR, RHO_BAR = 25.0, 100.0, 1.0
BETA = math.pi / (2 * L_BAR)
OMEGA = BETA * math.sqrt(E_BAR / RHO_BAR)
PERIOD = 2 * math.pi / OMEGA   # 10 s


def _bar(shape, cells=50, v0=1e-3):
    return parse_scene(_bar_data(shape, cells, v0), "bar.toml")


def _bar_data(shape, cells=50, v0=1e-3):
    h = L_BAR / cells
    return {
        "particles_per_cell": 2,
        "grid": {"cell_size": h, "cells": [cells + 4, 3]},
        "materials": {"bar": {"type": "linear_elastic", "E": E_BAR, "nu": 0.0, "density": RHO_BAR}},
        "bodies": [{"shape": "rectangle", "material": "bar", "lower": [0.0, 0.0], "upper": [L_BAR, h],
                    "velocity": [f"{v0} * sin({BETA} * x)", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 3 * h]}],
        "solver": {"shape_function": shape, "scheme": "mls", "end_time": 1.3 * PERIOD, "cfl": 0.5},
    }


@pytest.mark.parametrize("shape", ["linear", "quadratic", "cubic"])
def test_mls_bar_period_and_amplitude(shape):
    """The bar's free end crosses zero downwards at T/2 and upwards at T (T = 10 s): the
    measured period within 1% (the bar case's accuracy standard, docs/verification.md; the
    semi-discrete dispersion at 50 cells is ~(beta h)^2 / 12 ~ 1e-5 for B-splines), and the
    displacement of every particle within 2% of the amplitude over 1.3 periods (APIC's velocity
    update is PIC's plus its affine part: it loses a little energy that FLIP keeps).
    Shown to fail: with the cubic MLS force scaled by 3/4 (D_p taken as quadratic's h^2/4 I)
    the first crossing moves from 5 s to 5.8 s."""
    v0 = 1e-3
    s = build_solver(_bar(shape, v0=v0), MPI.COMM_SELF)
    amp = v0 / OMEGA
    x0 = s.particles["x0"][:, 0].copy()
    end = x0 > 0.9 * L_BAR
    t_prev, u_prev, crossings, err = 0.0, 0.0, [], 0.0
    while s.t < 1.3 * PERIOD - 1e-12:
        s.step()
        p = s.particles
        u = p["x"][:, 0] - p["x0"][:, 0]
        err = max(err, float(np.abs(u - amp * math.sin(OMEGA * s.t) * np.sin(BETA * p["x0"][:, 0])).max()) / amp)
        ue = float(u[p["x0"][:, 0] > 0.9 * L_BAR].mean())
        if s.t > 0.25 * PERIOD and (ue > 0) != (u_prev > 0):
            crossings.append(t_prev + (s.t - t_prev) * u_prev / (u_prev - ue))   # linear interpolation
        t_prev, u_prev = s.t, ue
    assert end.any()
    assert len(crossings) == 2, crossings
    period = 2 * (crossings[1] - crossings[0])
    assert crossings[0] == pytest.approx(PERIOD / 2, rel=0.01)
    assert period == pytest.approx(PERIOD, rel=0.01), period
    assert err < 0.02, err


def test_mls_refuses_what_it_cannot_run():
    """Point particles only, its own transfer, one grid field: a scene asking otherwise gets a
    ConfigError naming the key."""
    base = _bar("cubic")
    import dataclasses
    for change, key in (({"interpolation": "gimp"}, "solver.scheme"), ({"transfer": "apic"}, "solver.transfer"),
                        ({"pic_blend": 0.5}, "solver.pic_blend")):
        with pytest.raises(ConfigError) as e:
            make_scheme("mls", dataclasses.replace(base.solver, **change))
        assert e.value.key == key
    make_scheme("mls", base.solver)   # the bar as it is: accepted
    # and the scene check says so before anything runs (pmpm run --check)
    with pytest.raises(ConfigError) as e:
        parse_scene({"grid": {"cell_size": 0.5, "cells": [4, 4]},
                     "materials": {"m": {"type": "linear_elastic", "E": 1.0, "nu": 0.0, "density": 1.0}},
                     "solver": {"scheme": "mls", "transfer": "apic", "end_time": 1.0}}, "s.toml")
    assert e.value.key == "solver.transfer"


def test_mls_keeps_its_affine_field_and_says_so():
    """The scheme brings its transfer: the particles keep C (4 numbers), and the run header's
    transfer line says MLS-MPM."""
    s = build_solver(_bar("quadratic"), MPI.COMM_SELF)
    assert s.particles["C"].shape == (s.particles.n, 4)
    assert any("MLS-MPM" in line for line in s.transfer.describe())
