"""The grid's active tiles (pmpm.core.grid, pmpm.core.kernels.grid_ops): the node passes of a
step visit only the tiles a particle's stencil reaches, and that changes nothing.

Against theory: the marked tiles cover every node where the independent NumPy basis
(pmpm.core.kernels.reference) of any shape is nonzero; the kernels equal their NumPy twins; a
whole run with tiles equals the same run over the whole window to the bit (the nodes are
visited in the same order, so every sum adds the same terms in the same order), and every node
outside the active tiles is zero after each step (a tile that emptied was cleared)."""
import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.core.grid import TILE, TILE_NODES_PER_PARTICLE, choose_tile
from pmpm.core.kernels import grid_ops
from pmpm.core.kernels.reference import basis_matrix
from pmpm.core.kernels.reference_tiles import mark_tiles_reference, tile_node_mask, zero_tiles_reference
from pmpm.core.shape import MAX_HALF_LENGTH, ghost_width
from pmpm.build import build_solver
from pmpm.scene.config import parse_scene

H = 0.25
ORIGIN = np.array([-0.5, 0.25])
CELLS = (13, 11)
NODES = (CELLS[0] + 1, CELLS[1] + 1)
ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}


def _points(n=60, seed=1):
    """Random positions over the grid, the outermost cells included (edge-modified supports)."""
    rng = np.random.default_rng(seed)
    return ORIGIN + rng.uniform(0.0, 1.0, (n, 2)) * np.array(CELLS) * H


def _mark(x, lo, shape, reach, tile, sort=False):
    if sort:
        c = np.floor((x - ORIGIN) / H).astype(int)
        x = x[np.lexsort((c[:, 1], c[:, 0]))]
    active = np.zeros((-(-shape[0] // tile), -(-shape[1] // tile)), dtype=np.bool_)
    K_shift = tile.bit_length() - 1
    grid_ops.mark_tiles(x, ORIGIN, 1 / H, lo[0], lo[1], shape[0], shape[1], reach, K_shift, active)
    return active


@pytest.mark.parametrize("reach", [1, 2, 3])
@pytest.mark.parametrize("tile", [1, 2, 4, 8])
@pytest.mark.parametrize("sort", [False, True])
def test_mark_tiles_matches_reference(reach, tile, sort):
    """The kernel (which skips a particle in its predecessor's cell) and the NumPy rule agree,
    on the whole grid and on a window starting at node (3, 0) that cuts the particles' stencils."""
    x = _points()
    for lo, shape in (((0, 0), NODES), ((3, 0), (7, NODES[1]))):
        got = _mark(x, lo, shape, reach, tile, sort)
        np.testing.assert_array_equal(got, mark_tiles_reference(x, ORIGIN, H, lo, shape, reach, tile))


@pytest.mark.parametrize("shape, interpolation", [("linear", "point"), ("quadratic", "point"),
                                                  ("cubic", "point"), ("cubic", "cpgimp")])
def test_marked_tiles_cover_every_node_the_basis_reaches(shape, interpolation):
    """Every node where a particle's weight or its gradient is nonzero (NumPy basis, GIMP with
    the largest half-length the solver allows) lies in a marked tile, with tile = 1 (each node
    its own tile, the strictest case): ``reach`` = ghost_width is the support of the basis."""
    x = _points(200, seed=3)
    domain = np.full((len(x), 2), MAX_HALF_LENGTH) if interpolation != "point" else None
    N, dN = basis_matrix(ORDER[shape], x, ORIGIN, H, CELLS, domain)
    reached = (N != 0).any(axis=0) | (dN != 0).any(axis=(0, 3))
    active = _mark(x, (0, 0), NODES, ghost_width(shape, interpolation), 1)
    assert reached.any() and not (reached & ~active).any()
    # and per particle: its own nodes are inside the tiles it alone marks
    for p in range(0, len(x), 37):
        mine = (N[p] != 0) | (dN[p] != 0).any(axis=-1)
        alone = _mark(x[p:p + 1], (0, 0), NODES, ghost_width(shape, interpolation), 1)
        assert not (mine & ~alone).any()


def test_zero_tiles_matches_reference():
    rng = np.random.default_rng(4)
    G = rng.normal(size=(*NODES, K.N_FIELDS))
    active = rng.random((-(-NODES[0] // 4), -(-NODES[1] // 4))) < 0.4
    want = zero_tiles_reference(G, active, 4)
    grid_ops.zero_tiles(G, active, 4)
    np.testing.assert_array_equal(G, want)


def _grid_with_mass_in(active, tile, seed=5):
    """A window whose nodes outside ``active`` are zero (the invariant the solver keeps), with
    empty nodes, light nodes and prescribed components inside and outside the active tiles."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(*NODES, K.N_FIELDS))
    G[..., 0] = np.where(rng.random(NODES) < 0.3, 0.0, rng.uniform(0.5, 2.0, NODES))
    G[0, 1, 0] = 1e-20
    G[~tile_node_mask(active, tile, NODES)] = 0.0
    mask = (rng.random((*NODES, 2)) < 0.3).astype(np.int8)
    vel = rng.normal(size=(*NODES, 2))
    ids = np.where(mask > 0, rng.integers(0, 2, (*NODES, 2)), -1).astype(np.int32)
    return G, mask, vel, ids


@pytest.mark.parametrize("tile", [2, 4])
def test_tiled_grid_update_and_velocity_equal_the_whole_window(tile):
    """grid_update (damping and reactions on) and momentum_to_velocity over the active tiles:
    every node the same to the bit, the damping work, the support work and the reaction sums
    too; a prescribed node outside the active tiles keeps velocity zero instead of its
    prescribed value (no particle reaches it)."""
    active = np.zeros((-(-NODES[0] // tile), -(-NODES[1] // tile)), dtype=np.bool_)
    active[1:3, :] = True
    active[:, 0] = True
    G, mask, vel, ids = _grid_with_mass_in(active, tile)
    owned = np.array([0, 1, NODES[0] - 2])
    out = []
    for tiles in (None, (active, tile)):
        g, sums = G.copy(), np.zeros((2, 3))
        work = K.grid_update(g, 1e-3, 1e-12, mask, vel, 0, NODES[0], 0, NODES[1], 0.7, owned,
                             (ids, sums, ORIGIN[0], ORIGIN[1], H), tiles)
        K.momentum_to_velocity(g, 5, 5, mask, vel, 0, NODES[0], 0, NODES[1], tiles)
        out.append((g, sums, work))
    (g0, s0, w0), (g1, s1, w1) = out
    inside = tile_node_mask(active, tile, NODES)
    assert w0 == w1 and w0[1] != 0.0 and w0[0] != 0.0
    np.testing.assert_array_equal(s0, s1)
    np.testing.assert_array_equal(g0[inside], g1[inside])
    np.testing.assert_array_equal(g0[~inside][..., :5], g1[~inside][..., :5])
    assert not g1[~inside].any()


# -- whole runs ---------------------------------------------------------------------------------

def _scene(shape, scheme, interpolation):
    """A block flying left into a fixed wall (reaction recorded), damped, under gravity, on a
    grid it occupies a small part of: tiles empty and fill as it moves; a moving lid no particle
    reaches (prescribed velocities outside the active tiles) and a roller floor."""
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": H, "cells": [16, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 10.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [1.25, 0.75], "upper": [2.25, 1.5],
                    "velocity": ["-8.0 + 0.5 * y", "0.3 * x"]}],
        "boundary": [{"name": "wall", "type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 2.5],
                      "reaction": True},
                     {"name": "floor", "type": "roller_x", "lower": [0.0, 0.0], "upper": [4.0, 0.0]},
                     {"name": "lid", "type": "velocity", "velocity": [0.5, 0.0], "lower": [0.0, 2.5],
                      "upper": [4.0, 2.5], "reaction": True}],
        "loads": {"gravity": [0.0, -9.8], "damping": 0.5},
        "solver": {"end_time": 1.0, "cfl": 0.4, "shape_function": shape, "scheme": scheme,
                   "interpolation": interpolation},
    }, "tiles.toml")


@pytest.mark.parametrize("shape, scheme, interpolation", [
    ("cubic", "musl", "point"), ("linear", "usl", "point"), ("quadratic", "usf", "point"),
    ("cubic", "musl", "cpgimp")])
def test_a_run_with_tiles_equals_the_whole_window_to_the_bit(shape, scheme, interpolation):
    scene = _scene(shape, scheme, interpolation)
    tiled, whole = build_solver(scene, MPI.COMM_SELF), build_solver(scene, MPI.COMM_SELF)
    tiled.window.use_tiles(2)
    whole.window.use_tiles(0)
    w = tiled.window
    seen_active = np.zeros_like(w.active)
    emptied = False
    for _ in range(40):
        before = w.active.copy()
        tiled.step()
        whole.step()
        seen_active |= w.active
        emptied |= bool((before & ~w.active).any())
        # nothing outside the active tiles: what an emptied tile held was cleared
        assert not w.G[~tile_node_mask(w.active, w.tile, w.shape)].any()
    assert emptied and not seen_active.all()  # the test exercised both
    for name in whole.particles.fields:
        np.testing.assert_array_equal(tiled.particles[name], whole.particles[name], err_msg=name)
    assert tiled.energies() == whole.energies()
    np.testing.assert_array_equal(tiled.effect("reactions").kernel_arg()[1], whole.effect("reactions").kernel_arg()[1])
    assert np.abs(whole.effect("reactions").kernel_arg()[1]).max() > 0  # the block reached the wall


def test_tiles_are_chosen_for_sparse_windows_only():
    """The solver's choice (pmpm.core.grid.choose_tile): tiles where the window holds more than
    TILE_NODES_PER_PARTICLE nodes per particle (an empty rank too), the whole window else."""
    assert choose_tile(10_000, 10_000 / TILE_NODES_PER_PARTICLE - 1) == TILE
    assert choose_tile(10_000, 10_000 / TILE_NODES_PER_PARTICLE) == 0
    assert choose_tile(100, 0) == TILE
    scene = _scene("cubic", "musl", "point")   # 17 x 11 nodes, 48 particles: 3.9 per particle
    dense = build_solver(scene, MPI.COMM_SELF)
    sparse = build_solver(dataclasses.replace(scene, grid=dataclasses.replace(scene.grid, cells=[32, 20])),
                    MPI.COMM_SELF)             # 33 x 21 nodes: 14 per particle
    assert dense.particles.n == sparse.particles.n == 48
    assert dense.window.tile == 0 and dense.window.tiles is None
    assert sparse.window.tile == TILE and sparse.window.tiles is not None
    # CPDI's corners are not bounded by the ghost width on one rank: never tiles
    sparse_scene = dataclasses.replace(scene, grid=dataclasses.replace(scene.grid, cells=[32, 20]))
    cpdi = dataclasses.replace(sparse_scene, solver=dataclasses.replace(sparse_scene.solver, interpolation="cpdi"))
    assert build_solver(cpdi, MPI.COMM_SELF).window.tiles is None
