"""Boundaries attached to a body's face (``[[boundary]] body = ..., face = ...``): the nodes they
hold at several cell sizes against an independent derivation from the reference B-splines, the
clamp holding the face while the beam bends, the domain interpolation's options and the one-line
errors for bad input."""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core.kernels.reference import bspline_1d, gimp_1d
from pmpm.core.solver import Solver
from pmpm.errors import ConfigError
from pmpm.scene.config import parse_scene


def _beam(h, ppc=2, interpolation="point", face="left", extra_boundary=None, **solver):
    """A 2 m x 0.5 m elastic beam at y in [1, 1.5] whose left end sits on the grid's left edge."""
    cells = [int(round(2.5 / h)), int(round(2.5 / h))]
    data = {
        "particles_per_cell": ppc,
        "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": cells},
        "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"name": "beam", "shape": "rectangle", "material": "m",
                    "lower": [0.0, 1.0], "upper": [2.0, 1.5]}],
        "boundary": [{"name": "clamp", "type": "fixed", "body": "beam", "face": face},
                     *(extra_boundary or [])],
        "loads": {"gravity": [0.0, -9.8]},
        "solver": {"end_time": 1.0, "interpolation": interpolation, **solver},
    }
    return parse_scene(data, "beam.toml")


def _expected_left_clamp(s, interpolation):
    """Edge nodes (i = 0) at which some particle of the beam's first layer has a nonzero weight,
    from the reference basis (independent of the kernels)."""
    p = s.particles
    g = s.grid
    first = p["x"][:, 0] <= p["x"][:, 0].min() + 1e-12
    sx = (p["x"][first, 0] - g.origin[0]) / g.h
    sy = (p["x"][first, 1] - g.origin[1]) / g.h
    if interpolation == "point":
        wx, _ = bspline_1d(3, sx, g.cells[0])
        wy, _ = bspline_1d(3, sy, g.cells[1])
    else:
        wx, _ = gimp_1d(sx, p["domain"][first, 0], g.cells[0])
        wy, _ = gimp_1d(sy, p["domain"][first, 1], g.cells[1])
    touched = (np.abs(wx[:, :, None] * wy[:, None, :]) > 0).any(axis=0)
    expected = np.zeros(g.nodes, dtype=bool)
    expected[0] = touched[0]
    return expected


@pytest.mark.parametrize("interpolation", ["point", "ugimp"])
@pytest.mark.parametrize("h", [0.25, 0.125, 0.0625])
def test_clamp_takes_the_edge_nodes_its_face_reaches_at_every_cell_size(h, interpolation):
    s = Solver(_beam(h, interpolation=interpolation), MPI.COMM_SELF)
    mask = s.window.bc_mask
    held = (mask[..., 0] == 1) & (mask[..., 1] == 1)
    np.testing.assert_array_equal(held, _expected_left_clamp(s, interpolation))
    ys = s.grid.origin[1] + s.grid.h * np.nonzero(held[0])[0]
    # the whole face [1, 1.5] and, for the cubic reach, at least one node beyond each end
    assert ys.min() < 1.0 - 1e-9 and ys.max() > 1.5 + 1e-9
    assert not held[1:].any()  # nothing inside the body is constrained


def test_clamp_holds_the_face_while_the_beam_bends():
    """After 0.3 s of sudden gravity the tip has dropped, the clamped face has not: the grid
    velocity is zero on the face (edge nodes fixed, basis interpolatory there), so the face's
    particles move only by the interpolation of their free inner neighbours, a fraction of the
    deflection (the tolerance: 2% of the tip drop)."""
    s = Solver(_beam(0.125), MPI.COMM_SELF)
    while s.t < 0.3:
        s.step()
    p = s.particles
    u = p["x"] - p["x0"]
    face = p["x0"][:, 0] <= p["x0"][:, 0].min() + 1e-12
    tip_drop = -u[p["x0"][:, 0] >= p["x0"][:, 0].max() - 1e-12, 1].mean()
    assert tip_drop > 0.1
    assert np.abs(u[face]).max() < 0.02 * tip_drop


def test_attached_boundary_with_a_box_overlapping_keeps_both():
    """A roller wall over the whole left edge plus the clamp: fixed where the clamp is, vx only
    elsewhere on the edge."""
    wall = {"name": "wall", "type": "roller_y", "lower": [0.0, 0.0], "upper": [0.0, 2.5]}
    s = Solver(_beam(0.25, extra_boundary=[wall]), MPI.COMM_SELF)
    m = s.window.bc_mask
    assert m[0, :, 0].all()                       # the wall: vx = 0 on the whole edge
    assert m[0, :, 1].sum() < m.shape[1]          # vy only on the clamp's nodes
    assert not m[1:].any()


@pytest.mark.parametrize("change, key", [
    (lambda d: d["boundary"][0].update(body="nope"), "boundary[0].body"),
    (lambda d: d["boundary"][0].update(lower=[0.0, 0.0]), "boundary[0].lower"),
    (lambda d: d["boundary"][0].update(face="front"), "boundary[0].face"),
    (lambda d: d["solver"].update(shape_function="quadratic", interpolation="ugimp"), "solver.interpolation"),
    (lambda d: d["solver"].update(interpolation="cpdi2"), "solver.interpolation"),
])
def test_bad_input_is_one_config_error(change, key):
    data = {
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.25, "cells": [10, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"name": "beam", "shape": "rectangle", "material": "m", "lower": [0.0, 1.0], "upper": [2.0, 1.5]}],
        "boundary": [{"type": "fixed", "body": "beam", "face": "left"}],
        "solver": {"end_time": 1.0},
    }
    change(data)
    with pytest.raises(ConfigError) as err:
        parse_scene(data, "bad.toml")
    assert err.value.key == key


def test_gimp_domains_start_as_half_the_particle_spacing():
    s = Solver(_beam(0.25, ppc=3, interpolation="ugimp"), MPI.COMM_SELF)
    np.testing.assert_allclose(s.particles["domain"], 1 / 6, rtol=1e-12)  # (h / 3) / 2 in cells


def test_cpgimp_domains_follow_the_stretch_and_ugimp_domains_do_not():
    """Under gravity the hanging beam's top fibres stretch along x: their cpGIMP half-lengths
    grow with 1 + de_xx each step; uGIMP's stay at their start."""
    for interp in ("ugimp", "cpgimp"):
        s = Solver(_beam(0.125, interpolation=interp), MPI.COMM_SELF)
        d0 = s.particles["domain"].copy()
        while s.t < 0.2:
            s.step()
        d = s.particles["domain"]
        if interp == "ugimp":
            np.testing.assert_array_equal(d, d0)
        else:
            assert d[:, 0].max() > d0[:, 0].max() * 1.01 and d[:, 0].min() < d0[:, 0].min() * 0.99


def test_reaction_of_an_attached_clamp_closes_the_momentum_balance():
    """With the clamp the only support, its reaction impulse is the change of the beam's momentum
    minus the impulse of gravity: J = P(t) - P(0) - M g t (P(0) = 0). Tolerance 1e-6 relative:
    the transfers conserve momentum to rounding, but nodes lighter than ``mass_cutoff`` (1e-8 of
    a particle's mass) get no acceleration, so their share of gravity's impulse is not passed on
    (measured 4e-8); a reaction missing a node or a component is off by order 1."""
    scene = _beam(0.25)
    import dataclasses
    scene = dataclasses.replace(scene, boundaries=tuple(dataclasses.replace(b, reaction=True)
                                                        for b in scene.boundaries))
    s = Solver(scene, MPI.COMM_SELF)
    s.reactions.since = 0.0
    while s.t < 0.2:
        s.step()
    p = s.particles
    impulse = s.reactions.take(s.t, lambda a: a)[0, :2] * s.t
    expected = (p["m"][:, None] * p["v"]).sum(axis=0) - p["m"].sum() * np.array([0.0, -9.8]) * s.t
    assert abs(expected[1]) > 0.1 * p["m"].sum() * 9.8 * s.t   # the clamp carries real load
    np.testing.assert_allclose(impulse, expected, rtol=1e-6)
    # the default moment point is the centroid of the clamp's nodes (on the edge x = 0)
    assert s.reactions.points[0, 0] == 0.0 and 1.0 < s.reactions.points[0, 1] < 1.5
