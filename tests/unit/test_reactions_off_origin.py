"""Reactions and their moments on grids away from the origin, with supports that carry
horizontal force, against statics and against the NumPy twin with coordinates written out here
(tests/unit/test_reactions.py has the grid at the origin, where a moment taken about the wrong
origin, or node coordinates missing the grid's origin or the window's offset, go unseen)."""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.core.grid import Grid, GridWindow
from pmpm.core.kernels.reference import reaction_reference
from pmpm.build import build_solver
from pmpm.results.reactions import Reactions, node_centroid
from pmpm.results.recorder import StructuralRecorder
from pmpm.scene.config import BoundaryConfig, parse_scene


def _cross(d, f):
    return d[..., 0] * f[..., 1] - d[..., 1] * f[..., 0]


def test_a_held_body_reacts_with_minus_its_loads_and_their_moment():
    """A body whose every node is held (one fixed box over the whole grid): nothing moves, so
    each step the support takes exactly the loads, R = -(weight + set forces), and its moment
    about the chosen point is minus theirs, M = -[M (x_G - p) x g + (x_F - p) x F] with x_G the
    body's centroid and x_F the mass centroid of the force's particles (a set force is shared in
    proportion to mass). Gravity with a horizontal part and a sideways force: the support
    carries horizontal force; grid, body and point off the origin and off every symmetry.
    Tolerance: round-off of the sums over the particles (1e-12 of each quantity's scale)."""
    g = np.array([2.7, -9.81])
    F = np.array([-35.0, 12.0])
    p_m = np.array([3.05, -1.7])
    scene = parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [1.4, -2.2], "cell_size": 0.1, "cells": [24, 16]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 500.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [1.9, -1.8], "upper": [3.2, -1.2]}],
        "boundary": [{"name": "hold", "type": "fixed", "lower": [1.4, -2.2], "upper": [3.8, -0.6],
                      "reaction": True, "moment_about": list(p_m)}],
        "loads": {"gravity": list(g),
                  "forces": [{"name": "push", "lower": [2.75, -1.45], "upper": [3.2, -1.2], "force": list(F)}]},
        "solver": {"end_time": 1.0},
    }, "held.toml")
    s = build_solver(scene, MPI.COMM_SELF)
    rec = StructuralRecorder(s)
    rec.sample()  # the start: no interval yet
    for _ in range(7):
        s.step()
    _, R = rec.sample()
    p = s.particles
    m, x = p["m"], p["x"]
    in_box = (x[:, 0] >= 2.75) & (x[:, 0] <= 3.2) & (x[:, 1] >= -1.45) & (x[:, 1] <= -1.2)
    W = m.sum() * g
    x_G = (m[:, None] * x).sum(axis=0) / m.sum()
    x_F = (m[in_box, None] * x[in_box]).sum(axis=0) / m[in_box].sum()
    want = np.concatenate([-(W + F), [-(_cross(x_G - p_m, W) + _cross(x_F - p_m, F))]])
    scale = np.abs(W).max() + np.abs(F).max()
    np.testing.assert_allclose(R[0], want, rtol=0, atol=1e-12 * scale * 3.0)
    assert abs(R[0, 0]) > 10.0 and abs(R[0, 2]) > 10.0  # horizontal force and a moment to see


def test_kernel_moments_on_a_window_away_from_the_origin():
    """The grid update's bookkeeping on a rank's window (columns 3.. of a grid at (-2.35, 0.8))
    against the NumPy twin given the window's first node coordinates computed here, and the
    moment about each boundary's point (the wall's given, the floor's its node centroid)."""
    from pmpm.physics.boundary import apply_boundary_masks
    grid = Grid((-2.35, 0.8), 0.5, (8, 4))
    ox = 3
    w = GridWindow(grid, 0, (ox, 9))
    bcs = (BoundaryConfig("floor", "fixed", (-2.35, 0.8), (2.0, 0.8), (0.0, 0.0), reaction=True),
           BoundaryConfig("wall", "roller_y", (1.65, 0.8), (1.65, 2.8), (0.0, 0.0), reaction=True,
                          moment_about=(0.4, 1.9)))
    apply_boundary_masks(w, bcs)
    rng = np.random.default_rng(11)
    G0 = np.zeros((*w.shape, K.N_FIELDS))
    G0[..., 0] = rng.uniform(1.0, 2.0, w.shape)
    G0[..., 1:5] = rng.normal(size=(*w.shape, 4))
    dt = 0.1
    r = Reactions(bcs, grid)
    r.bind(w, bcs)
    r.since = 0.0
    G = G0.copy()
    K.grid_update(G, dt, 0.0, w.bc_mask, w.bc_vel, 0, w.shape[0], 0, w.shape[1], None,
                  np.array([0, 0, w.shape[0]]), r.kernel_arg())
    x0, y0 = -2.35 + ox * 0.5, 0.8  # the window's first node
    X = x0 + 0.5 * np.arange(w.shape[0])[:, None] + 0 * np.arange(w.shape[1])
    Y = y0 + 0.5 * np.arange(w.shape[1])[None, :] + 0 * np.arange(w.shape[0])[:, None]
    floor, wall = np.isclose(Y, 0.8), np.isclose(X, 1.65)
    ids = np.full((*w.shape, 2), -1)
    ids[floor, :] = 0
    ids[wall, 0] = 1  # the corner's x goes to the wall (the later box)
    ref = reaction_reference(G0, dt, w.bc_mask, w.bc_vel, ids, 2, x0, y0, 0.5)
    # the floor's point: the centroid of its nodes over the whole grid (x = -2.35 .. 1.65)
    points = np.array([[np.mean(-2.35 + 0.5 * np.arange(9)), 0.8], [0.4, 1.9]])
    ref[:, 2] -= points[:, 0] * ref[:, 1] - points[:, 1] * ref[:, 0]
    np.testing.assert_allclose(r.points, points, rtol=1e-14)
    R = r.take(dt, lambda a: a)
    np.testing.assert_allclose(R, ref / dt, rtol=1e-12, atol=1e-12)
    assert np.abs(R[:, 2]).min() > 0.1 and abs(R[1, 0]) > 0.1  # moments and the wall's push to see


def test_default_moment_point_off_the_origin():
    """The node centroid of a box on a grid at (0.35, -0.8), h = 0.5: the nodes inside
    x in [0.9, 2.6], y in [-1.0, 0.0] are x = 1.35, 1.85, 2.35 and y = -0.8, -0.3."""
    grid = Grid((0.35, -0.8), 0.5, (8, 4))
    bc = BoundaryConfig("b", "fixed", (0.9, -1.0), (2.6, 0.0), (0.0, 0.0), reaction=True)
    np.testing.assert_allclose(node_centroid(bc, grid), [(1.35 + 1.85 + 2.35) / 3, (-0.8 - 0.3) / 2])
