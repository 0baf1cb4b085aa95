"""Supports attached to a body (pmpm.physics.supports): the held particles' interpolation rows
against the reference basis, the projection against an independent solution of its
minimisation, and the clamp holding anywhere in the grid: the same beam clamped on the grid's
edge and inside the grid off the node lines gives the same tip history (issue 20, item 1)."""
import functools

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core.kernels.support import row_width, support_rows, support_rows_reference
from pmpm.core.shape import shape_argument
from pmpm.build import build_solver
from pmpm.scene.config import parse_scene

ORIGIN = np.array([-0.3, 0.2])
H = 0.25
CELLS = (12, 10)


def _dense(nodes, weights, n_nodes):
    out = np.zeros((len(nodes), n_nodes))
    for q in range(len(nodes)):
        ok = nodes[q] >= 0
        np.add.at(out[q], nodes[q][ok], weights[q][ok])
    return out


@pytest.mark.parametrize("interpolation", ["point", "ugimp", "cpdi"])
def test_rows_are_the_reference_basis_at_the_held_particles(interpolation):
    """Interior particles and particles whose support reaches a grid edge (the boundary-modified
    splines, CPDI corners clamped onto the grid), with a sheared and stretched F for CPDI."""
    rng = np.random.default_rng(3)
    x = ORIGIN + rng.uniform(0.02, 0.98, (40, 2)) * H * np.array(CELLS)
    domain = np.full((40, 2), 0.125) if interpolation != "point" else None
    F = None
    if interpolation == "cpdi":
        F = np.tile([1.3, 0.4, -0.2, 0.9, 1.0], (40, 1)) + rng.uniform(-0.1, 0.1, (40, 5)) * [1, 1, 1, 1, 0]
    shape = shape_argument("cubic", interpolation, domain, F)
    idx = np.arange(0, 40, 3)
    nodes = np.empty((len(idx), row_width(shape)), dtype=np.int64)
    weights = np.empty_like(nodes, dtype=np.float64)
    support_rows(idx, x, ORIGIN, 1 / H, CELLS[0], CELLS[1], shape, nodes, weights)
    n_nodes = (CELLS[0] + 1) * (CELLS[1] + 1)
    ref = support_rows_reference(3, x[idx], ORIGIN, H, CELLS, None if domain is None else domain[idx],
                                 None if F is None else F[idx])
    np.testing.assert_allclose(_dense(nodes, weights, n_nodes), ref, rtol=0, atol=1e-14)
    assert (weights[nodes < 0] == 0).all() and (weights[nodes >= 0] != 0).all()


def _beam(origin_x, h=0.125, end_time=0.6, interpolation="point", ppc=2, nu=0.3, cells_x=None):
    """A 2 m x 0.5 m beam at x in [0, 2], y in [1, 1.5], clamped at its left face, under sudden
    gravity. ``origin_x`` = 0 puts the face on the grid's left edge; a negative one puts it inside
    the grid (off the node lines unless -origin_x is a multiple of h)."""
    width = 2.5 - origin_x
    data = {
        "particles_per_cell": ppc,
        "grid": {"origin": [origin_x, 0.0], "cell_size": h,
                 "cells": [cells_x or int(round(width / h)), int(round(2.5 / h))]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e7, "nu": nu, "density": 1000.0}},
        "bodies": [{"name": "beam", "shape": "rectangle", "material": "m",
                    "lower": [0.0, 1.0], "upper": [2.0, 1.5]}],
        "boundary": [{"name": "clamp", "type": "fixed", "body": "beam", "face": "left"}],
        "loads": {"gravity": [0.0, -9.8]},
        "solver": {"end_time": end_time, "interpolation": interpolation},
        "output": {"track": [{"name": "tip", "point": [2.0, 1.25]}]},
    }
    return parse_scene(data, "beam.toml")


def test_projection_is_the_smallest_change_of_kinetic_energy_that_holds_the_face():
    """One grid update of the bending beam, the face inside the grid off the node lines: after
    the projection the held particles' interpolated velocity is zero, and the change of the
    nodal velocities is the one an independent solution of min 1/2 dv^T M dv subject to
    N (v + dv) = 0 gives (least squares on the KKT system); nodes a box fixes are not moved."""
    s = build_solver(_beam(-0.6 - 0.125 / 4), MPI.COMM_SELF)
    for _ in range(20):
        s.step()
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=True)
    s.exchange_halo(slice(0, 5))
    w = s.window
    G = w.G
    before = G.copy()
    supports, effects = s.effect("supports"), s.effects
    s.set_effects([e for e in effects if e is not supports])
    s.update_grid(s.dt)                       # the free grid update
    free = G.copy()
    G[...] = before
    s.set_effects(effects)
    s.update_grid(s.dt)                       # with the projection
    p = s.particles
    idx = np.nonzero((p["support"] >= 0).any(axis=1))[0]
    nodes = np.empty((len(idx), row_width(s.shape)), dtype=np.int64)
    weights = np.empty(nodes.shape)
    g = s.grid
    support_rows(idx, p["x"], g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape, nodes, weights)
    N = _dense(nodes, weights, g.nodes[0] * g.nodes[1])
    m = G[..., 0].reshape(-1)
    used = np.nonzero(np.abs(N).sum(axis=0) > 0)[0]
    Nu = N[:, used]
    for d in range(2):
        v_free = free[..., 1 + d].reshape(-1)[used]
        v_new = G[..., 1 + d].reshape(-1)[used]
        assert np.abs(Nu @ v_new).max() < 1e-12 * np.abs(v_free).max()
        assert np.abs(Nu @ v_free).max() > 1e-3 * np.abs(v_free).max()   # there was something to hold
        # KKT: [M N^T; N 0] [dv; lam] = [0; -N v_free], least squares (N's rows are dependent)
        M = np.diag(m[used])
        K = np.block([[M, Nu.T], [Nu, np.zeros((len(Nu), len(Nu)))]])
        rhs = np.concatenate([np.zeros(len(used)), -Nu @ v_free])
        dv = np.linalg.lstsq(K, rhs, rcond=None)[0][:len(used)]
        np.testing.assert_allclose(v_new - v_free, dv, rtol=0, atol=1e-9 * np.abs(v_free).max())
        # the velocity change FLIP hands to the particles moved with the velocity
        np.testing.assert_allclose(G[..., 3 + d].reshape(-1)[used] - free[..., 3 + d].reshape(-1)[used],
                                   v_new - v_free, atol=1e-15 * np.abs(v_free).max() + 1e-300)


def _history(scene):
    from pmpm.io.tracking import Tracker
    s = build_solver(scene, MPI.COMM_SELF)
    tr = Tracker(scene.output.track, s)
    t, uy, moved = [], [], 0.0
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
        t.append(s.t)
        uy.append(tr.sample()[0][1])
        p = s.particles
        face = (p["support"] >= 0).any(axis=1)      # (the particles are sorted now and then)
        moved = max(moved, float(np.abs(p["x"][face] - p["x0"][face]).max()))
    return np.array(t), np.array(uy), moved, s


@functools.lru_cache(maxsize=None)
def _edge_and_inner(h):
    """The same particles (the grid shifted by a whole number of particle spacings plus a
    quarter cell), the clamp on the grid's left edge and 0.77 m inside it, off the node lines;
    CPDI (the cantilever's interpolation), to 0.5 s: the first swing down and back up (the
    largest drop at 0.25 s)."""
    edge = _history(_beam(0.0, h=h, interpolation="cpdi", end_time=0.5))
    inner = _history(_beam(-0.75 - h / 4, h=h, interpolation="cpdi", end_time=0.5))
    return edge, inner


def _gap(edge, inner):
    """Largest |uy_edge(t) - uy_inner(t)| over the run, relative to the largest drop (the inner
    run interpolated at the edge run's times: the CFL step follows the particle speed, so the
    steps differ a little)."""
    (t0, e, _, _), (t1, i, _, _) = edge, inner
    return np.abs(e - np.interp(t0, t1, i)).max() / -e.min()


def test_a_clamp_inside_the_grid_off_the_node_lines_gives_the_edge_clamps_history():
    """Issue 20, item 1, on the beam 8 cells deep (0.0625 m): the face's particles move less
    than 2% of a cell (they are held exactly, their interpolated velocity zero up to the
    dependent rows dropped: measured 3e-6 cells) wherever the face lies, and the tip's uy
    histories of the edge and the interior clamp agree within 1% of the largest drop at every
    time (measured 0.69%). The clamp of before issue 20 fails the first check
    (test_the_old_clamp_would_have_torn_here)."""
    h = 0.0625
    edge, inner = _edge_and_inner(h)
    (t0, e, moved_edge, _), (t1, i, moved_inner, s) = edge, inner
    face_x = (0.0 - s.grid.origin[0]) / h
    assert abs(face_x - round(face_x)) > 0.2          # off the node lines
    assert -e.min() > 0.1                              # it bends (Euler-Bernoulli: 2 x 0.094 m)
    assert moved_edge < 0.02 * h and moved_inner < 0.02 * h, (moved_edge, moved_inner)
    assert _gap(edge, inner) < 0.01, f"tip histories differ by {100 * _gap(edge, inner):.2f}% of the drop"


@pytest.mark.xfail(strict=True, reason="on the beam 4 cells deep (0.125 m) the edge and the interior clamp "
                   "differ by 1.4% of the largest drop (0.69% at 0.0625 m: first order): the grid edge's "
                   "boundary-modified splines hold the root stiffer than the free nodes behind an "
                   "interior face (docs/scenes.md). Both 4-deep histories are 5.2-6.6% from the 8-deep "
                   "ones (the beam's own discretisation error); the interior clamp is the closer of the "
                   "two to the finer grid at both sizes (largest drops: edge 0.1771 / 0.1872 m, interior "
                   "0.1783 / 0.1879 m at 0.125 / 0.0625 m)")
def test_at_four_cells_deep_the_two_clamps_agree_within_1_percent():
    assert _gap(*_edge_and_inner(0.125)) < 0.01


def test_the_old_clamp_would_have_torn_here():
    """The check above can fail: holding only the nodes outside the face (the supports before
    issue 20), the particles at an interior face move by more than 2% of a cell in the same
    run (they interpolate from free nodes inside the body)."""
    h = 0.125
    scene = _beam(-0.75 - h / 4, h=h, end_time=0.3)
    s = build_solver(scene, MPI.COMM_SELF)
    # the old rule: fix the nodes the face's particles reach on the face's side of the layer
    p = s.particles
    face = (p["support"] >= 0).any(axis=1)
    layer_x = p["x"][face, 0].min()
    X, Y = s.window.node_coords()
    reach = (np.abs(X - layer_x) < 2 * h) & (X <= layer_x) & (Y > 1.0 - 2 * h) & (Y < 1.5 + 2 * h)
    s.set_effects([e for e in s.effects if e.name != "supports"])
    s.window.bc_mask[reach] = 1
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
    p = s.particles
    face = (p["support"] >= 0).any(axis=1)
    assert np.abs(p["x"][face] - p["x0"][face]).max() > 0.02 * h


@pytest.mark.parametrize("interpolation", ["point", "cpdi"])
def test_the_solve_kernel_and_its_numpy_twin_give_the_same_corrections(interpolation):
    """The kernel (loops) and its twin (matrix products, rank-one updates): the same corrections
    and impulses to 1e-9 of the largest (rounding, amplified by the kept pivots' conditioning:
    down to RANK_TOLERANCE = 1e-6 of the largest, a factor up to 1e6). A box
    fixes part of the nodes, so their columns drop out; a support holds one component only."""
    from pmpm.core.kernels.support import support_gather, support_solve, support_solve_reference
    from pmpm.physics.supports import RANK_TOLERANCE
    s = build_solver(_beam(-0.6 - 0.125 / 4, interpolation=interpolation), MPI.COMM_SELF)
    for _ in range(15):
        s.step()
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=True)
    s.exchange_halo(slice(0, 5))
    w = s.window
    if interpolation == "point":
        # a box fixing the nodes up to y = 0.875, under the face's lowest particles (with CPDI the
        # corners' rows on the few free nodes left are near-dependent, and the two solutions
        # part: a box overlapping an attached face is not a case the supports are made for)
        w.bc_mask[:, :8, :] = 1
    supports = s.effect("supports")
    s.set_effects([e for e in s.effects if e is not supports])
    s.update_grid(s.dt)
    _, ids, sup, nodes, weights = supports._local_rows(s)
    mass = np.empty(nodes.shape)
    vel = np.empty((*nodes.shape, 2))
    fixed = np.empty((*nodes.shape, 2), dtype=bool)
    support_gather(nodes, w.G, w.ox, w.oy, s.grid.nodes[1], 1, w.bc_mask, mass, vel, fixed)
    assert fixed.any() == (interpolation == "point") and not fixed.all()
    # a fixed clamp with part of its nodes fixed by the box, and a support prescribing vy = 0.01
    # alone with no box (with the box, vy = 0.01 would contradict it: no solution)
    free = np.zeros_like(fixed)
    only_y = np.where([[False, True]], sup, -1)
    for sup_d, vbc, fixed in ((sup, np.zeros((1, 2)), fixed), (only_y, np.array([[0.0, 0.01]]), free)):
        U, dv, J = support_solve(sup_d, nodes, weights, mass, vel, fixed, vbc, 1, RANK_TOLERANCE)
        U2, dv2, J2 = support_solve_reference(sup_d, nodes, weights, mass, vel, fixed, vbc, 1,
                                              RANK_TOLERANCE)
        np.testing.assert_array_equal(U, U2)
        assert np.abs(dv).max() > 0
        np.testing.assert_allclose(dv, dv2, rtol=0, atol=1e-9 * np.abs(dv2).max())
        np.testing.assert_allclose(J, J2, rtol=0, atol=1e-9 * np.abs(J2).max())
        # box-fixed nodes are not corrected
        valid = nodes >= 0
        fixed_U = np.zeros((len(U), 2), dtype=bool)
        fixed_U[np.searchsorted(U, nodes[valid])] = fixed[valid]
        assert (dv[fixed_U] == 0).all()


def test_two_faces_share_their_corner_particle_component_by_component():
    """A clamp on the left face and a roller (vy = 0, x free) on the bottom face of the beam:
    the corner particle's x is the clamp's, its y the later boundary's (the roller), as for
    overlapping boxes; after a few steps under gravity the left face has not moved and the bottom
    face has not moved vertically, while it slides along x (the beam's bending shortens it)."""
    data = {
        "particles_per_cell": 2,
        "grid": {"origin": [-0.5, 0.0], "cell_size": 0.125, "cells": [24, 20]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e7, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"name": "beam", "shape": "rectangle", "material": "m",
                    "lower": [0.0, 1.0], "upper": [2.0, 1.5]}],
        "boundary": [{"name": "clamp", "type": "fixed", "body": "beam", "face": "left"},
                     {"name": "roller", "type": "roller_x", "body": "beam", "face": "bottom"}],
        "loads": {"gravity": [0.0, -9.8]},
        "solver": {"end_time": 0.05},
    }
    s = build_solver(parse_scene(data, "beam.toml"), MPI.COMM_SELF)
    p = s.particles
    x0 = p["x0"]
    corner = np.argmin(x0[:, 0] + x0[:, 1])
    assert tuple(p["support"][corner]) == (0, 1)
    while s.t < 0.05 - 1e-12:
        s.step()
    p = s.particles
    u = p["x"] - p["x0"]
    left = p["support"][:, 0] == 0
    bottom = p["support"][:, 1] == 1
    assert left.sum() == 8 and bottom.sum() == 32         # 0.5 m and 2 m at 1/16 m spacing
    assert np.abs(u[left]).max() < 1e-6 * s.grid.h
    assert np.abs(u[bottom, 1]).max() < 1e-6 * s.grid.h
    assert np.abs(u[bottom & ~left, 0]).max() > 1e-4 * s.grid.h     # the roller lets it slide
