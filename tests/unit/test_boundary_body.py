"""Boundaries attached to a body's face (``[[boundary]] body = ..., face = ...``): the clamp
holding the face while the beam bends, its reaction, the domain interpolation's options and the one-line
errors for bad input."""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
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


def test_clamp_holds_the_face_while_the_beam_bends():
    """After 0.3 s of sudden gravity the tip has dropped, the clamped face has not: its particles
    are held by the velocity constraint, exactly up to rounding and the dependent rows dropped
    (the tolerance: 2% of the tip drop, the issue's bound)."""
    s = build_solver(_beam(0.125), MPI.COMM_SELF)
    while s.t < 0.3:
        s.step()
    p = s.particles
    u = p["x"] - p["x0"]
    face = p["x0"][:, 0] <= p["x0"][:, 0].min() + 1e-12
    tip_drop = -u[p["x0"][:, 0] >= p["x0"][:, 0].max() - 1e-12, 1].mean()
    assert tip_drop > 0.1
    assert np.abs(u[face]).max() < 0.02 * tip_drop


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
    s = build_solver(_beam(0.25, ppc=3, interpolation="ugimp"), MPI.COMM_SELF)
    np.testing.assert_allclose(s.particles["domain"], 1 / 6, rtol=1e-12)  # (h / 3) / 2 in cells


def test_cpgimp_domains_follow_the_stretch_and_ugimp_domains_do_not():
    """Under gravity the hanging beam's top fibres stretch along x: their cpGIMP half-lengths
    grow with 1 + de_xx each step; uGIMP's stay at their start."""
    for interp in ("ugimp", "cpgimp"):
        s = build_solver(_beam(0.125, interpolation=interp), MPI.COMM_SELF)
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
    s = build_solver(scene, MPI.COMM_SELF)
    s.effect("reactions").since = 0.0
    while s.t < 0.2:
        s.step()
    p = s.particles
    impulse = s.effect("reactions").take(s.t, lambda a: a)[0, :2] * s.t
    expected = (p["m"][:, None] * p["v"]).sum(axis=0) - p["m"].sum() * np.array([0.0, -9.8]) * s.t
    assert abs(expected[1]) > 0.1 * p["m"].sum() * 9.8 * s.t   # the clamp carries real load
    np.testing.assert_allclose(impulse, expected, rtol=1e-6)
    # the default moment point is the centroid of the held particles (the face layer, a quarter
    # cell inside the face at 2 particles per cell)
    np.testing.assert_allclose(s.effect("reactions").points[0], [0.25 / 4, 1.25], rtol=1e-12)
