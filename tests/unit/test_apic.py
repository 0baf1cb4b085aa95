"""APIC (pmpm.core.kernels.affine, docs/accuracy.md "Transfers"): the numba kernels against
their NumPy twins, the exact transfer of an affine velocity field, and the conservation of
angular momentum about a point away from the origin and the body (Jiang et al. 2015, sec. 5)."""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.core.kernels.affine import g2p_affine, p2g_affine
from pmpm.core.kernels.reference_affine import apic_g2p_reference, apic_p2g_reference
from pmpm.core.shape import SHAPE_TAGS

ORDER = {"quadratic": 2, "cubic": 3}
CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])


def _particles(n=300, seed=3):
    rng = np.random.default_rng(seed)
    x = ORIGIN + rng.uniform(0, 1, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 0.05 * H      # near the edges: boundary-modified splines, D_p != h^2/3 I
    x[5:10, 1] = ORIGIN[1] + (CELLS[1] - 0.05) * H
    return {"x": x, "m": rng.uniform(0.5, 2, n), "v": rng.normal(size=(n, 2)),
            "C": rng.normal(size=(n, 4)), "vol": rng.uniform(0.1, 0.3, n), "stress": rng.normal(size=(n, 4))}


def _grid():
    return np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))


@pytest.mark.parametrize("name", list(ORDER))
def test_p2g_affine_matches_reference_and_p2g(name):
    p = _particles()
    G = _grid()
    p2g_affine(p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"], None, None, None, None,
               G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    mass, mom = apic_p2g_reference(ORDER[name], p["x"], p["m"], p["v"], p["C"], ORIGIN, H, CELLS)
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-11, atol=1e-11)
    # mass and forces are the point kernel's; with C = 0 the momentum too
    ref = _grid()
    K.p2g(p["x"], p["m"], p["v"], p["vol"], p["stress"], None, None, None, None,
          ref, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    np.testing.assert_allclose(G[..., [0, 3, 4]], ref[..., [0, 3, 4]], rtol=1e-13, atol=1e-13)
    zero = _grid()
    p2g_affine(p["x"], p["m"], p["v"], 0 * p["C"], p["vol"], p["stress"], None, None, None, None,
               zero, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    np.testing.assert_allclose(zero, ref, rtol=1e-13, atol=1e-13)
    # the affine part carries no net momentum (sum_i N_i (x_i - x_p) = 0, linear completeness)
    np.testing.assert_allclose(G[..., 1:3].sum((0, 1)), (p["m"][:, None] * p["v"]).sum(0), rtol=1e-12)


@pytest.mark.parametrize("name", list(ORDER))
def test_g2p_affine_matches_reference(name):
    p = _particles()
    G = _grid()
    G[..., 1:3] = np.random.default_rng(5).normal(size=G[..., 1:3].shape)
    vel = G[..., 1:3].copy()
    v, C, dx = p["v"].copy(), p["C"].copy(), np.empty_like(p["v"])
    vmax, bad = g2p_affine(p["x"], p["m"], v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1],
                           SHAPE_TAGS[name], True, dx, 0.5)
    vp, Cp = apic_g2p_reference(ORDER[name], p["x"], vel, ORIGIN, H, CELLS)
    np.testing.assert_allclose(v, vp, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(C, Cp, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(dx, 0.5 * vp, rtol=1e-12, atol=1e-12)
    assert vmax == pytest.approx(np.sqrt((vp ** 2).sum(1)).max(), rel=1e-12) and bad == 0
    _, remapped = apic_p2g_reference(ORDER[name], p["x"], p["m"], vp, Cp, ORIGIN, H, CELLS)
    np.testing.assert_allclose(G[..., 5:7], remapped, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("name", list(ORDER))
def test_an_affine_field_goes_through_unchanged(name):
    """Grid velocities v(x) = a + A x are reproduced exactly: v_p = a + A x_p and C_p = A at every
    particle, next to the edges as well (B-splines reproduce linear functions)."""
    p = _particles()
    a, A = np.array([0.3, -1.2]), np.array([[0.5, -2.0], [1.5, 0.25]])
    X = ORIGIN[0] + H * np.arange(CELLS[0] + 1)
    Y = ORIGIN[1] + H * np.arange(CELLS[1] + 1)
    XY = np.stack(np.meshgrid(X, Y, indexing="ij"), -1)
    G = _grid()
    G[..., 1:3] = a + XY @ A.T
    v, C, dx = p["v"].copy(), p["C"].copy(), np.empty_like(p["v"])
    g2p_affine(p["x"], p["m"], v, C, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name],
               False, dx, 0.1)
    np.testing.assert_allclose(v, a + p["x"] @ A.T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(C, np.tile(A.ravel(), (len(v), 1)), rtol=0, atol=1e-11)


def _spinning_block(scheme, transfer, shape="cubic"):
    """A free elastic block, spinning and drifting, far from the grid's origin and the point the
    angular momentum is taken about; no supports, no loads."""
    from pmpm.scene.config import parse_scene
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.3, -0.2], "cell_size": 0.1, "cells": [30, 30]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 100.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [1.0, 0.8], "upper": [1.8, 1.4],
                    "velocity": ["0.2 - 0.5 * (y - 1.1)", "0.1 + 0.5 * (x - 1.4)"]}],
        "solver": {"end_time": 1.0, "cfl": 0.5, "scheme": scheme, "transfer": transfer,
                   "shape_function": shape},
        "output": {"fields": ["x", "v"]},
    }, "block.toml")


def _grid_angular_momentum(s, o):
    """sum_i (x_i - o) x (m v)_i of a fresh particles-to-grid: the particles' angular momentum,
    affine part included (APIC's p2g conserves it)."""
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=False)
    w, g = s.window, s.grid
    X = g.origin[0] + g.h * (w.ox + np.arange(w.G.shape[0]))[:, None] - o[0]
    Y = g.origin[1] + g.h * (w.oy + np.arange(w.G.shape[1]))[None, :] - o[1]
    return float(np.sum(X * w.G[..., 2] - Y * w.G[..., 1]))


@pytest.mark.parametrize("scheme", ["musl", "usl", "usf"])
def test_apic_conserves_angular_momentum_off_the_origin(scheme):
    """Jiang et al. 2015, sec. 5: APIC transfers, the grid update (symmetric stress: no internal
    torque) and x_p += dt sum N v_i conserve the angular momentum, affine part included, to
    round-off. Taken about o = (-2, 3), away from the origin and the body (a term that vanishes
    at the body's centre would hide there). FLIP does not conserve it: the same run with FLIP
    drifts by orders of magnitude more, which shows the check can fail."""
    from pmpm.build import build_solver
    o = np.array([-2.0, 3.0])
    drift = {}
    for transfer in ("apic", "flip"):
        s = build_solver(_spinning_block(scheme, transfer), MPI.COMM_SELF)
        L0 = _grid_angular_momentum(s, o)
        worst = 0.0
        for _ in range(150):
            s.step()
            worst = max(worst, abs(_grid_angular_momentum(s, o) - L0))
        drift[transfer] = worst / abs(L0)
    # round-off: each step's sums lose ~1e-13 of L to the lever arms about o (3 to 5 m against a
    # 0.8 m body), 150 steps accumulate a few 1e-11; 1e-9 bounds that, FLIP's drift is ~1e-3
    assert drift["apic"] < 1e-9, drift
    assert drift["flip"] > 1e3 * drift["apic"], drift


def test_apic_loses_less_than_pic_on_the_bar(tmp_path, monkeypatch):
    """PIC drops every particle's sub-grid velocity each step; APIC keeps its affine part, so it
    dissipates much less (Jiang et al. 2015, fig. 3): the bar's numerical loss over 4 s."""
    import shutil
    from pathlib import Path
    import pmpm
    shutil.copy(Path(__file__).resolve().parents[2] / "cases" / "bar.toml", tmp_path)
    monkeypatch.chdir(tmp_path)
    loss = {}
    for name, over in (("pic", {"solver.pic_blend": 1.0}), ("apic", {"solver.transfer": "apic"})):
        res = pmpm.run("bar.toml", overrides={"solver.end_time": 4.0, **over}, dataframes=False)
        loss[name] = float(res.energies["numerical_loss"][-1])
    assert 0 < loss["apic"] < 0.5 * loss["pic"], loss


def test_an_unnamed_transfer_costs_nothing():
    """docs/effects.md: FLIP (the default) keeps no affine field and lists no transfer effect;
    naming APIC adds the field and says so at start."""
    from pmpm.build import build_solver
    from pmpm.runner import Run
    flip = build_solver(_spinning_block("musl", "flip"), MPI.COMM_SELF)
    assert "C" not in flip.particles.fields and flip.transfer.fields == {}
    run = Run(_spinning_block("musl", "apic"), MPI.COMM_SELF, write=False)
    assert run.solver.particles["C"].shape == (run.solver.particles.n, 4)
    assert any(line.startswith("APIC transfer") for line in run.effects())
    assert not any("transfer" in line for line in Run(_spinning_block("musl", "flip"), MPI.COMM_SELF,
                                                      write=False).effects())
