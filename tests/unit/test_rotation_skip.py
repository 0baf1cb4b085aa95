"""With large rotations on, a material that computes its stress from F (neo-Hookean) gets no
objective-rate rotation of its stress: the rotation would be overwritten unread (pmpm.core.solver,
``Solver.rotates_stress``). So a neo-Hookean run is the same run with and without
``large_rotations`` (bit for bit, energies included: the rotated stress used to enter the first
half of the internal-work trapezoid), and the rotation kernels are never called; a rate-form
material (linear elastic) still gets them.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.build import build_solver
from pmpm.scene.config import parse_scene


def _scene(material, **solver):
    """A block spinning at 20 rad/s while stretching: rotation and strain every step."""
    return parse_scene({
        "grid": {"cell_size": 0.1, "cells": [20, 20]},
        "materials": {"m": {"type": material, "E": 1e6, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"name": "b", "shape": "rectangle", "material": "m", "lower": [0.6, 0.6],
                    "upper": [1.4, 1.4], "velocity": ["-20*(y-1) + 0.5*(x-1)", "20*(x-1)"]}],
        "solver": {"end_time": 0.05, **solver},
        "output": {"fields": ["x", "v", "stress"]}})


def _run(scene, monkeypatch=None):
    calls = {"jaumann_rotate": 0, "rotate": 0}
    if monkeypatch is not None:
        for name in calls:
            kernel = getattr(K, name)

            def counted(*args, _kernel=kernel, _name=name):
                calls[_name] += 1
                return _kernel(*args)
            monkeypatch.setattr(K, name, counted)
    s = build_solver(scene, MPI.COMM_SELF)
    while s.t < scene.solver.end_time * (1 - 1e-12):
        s.step()
    return s, calls


@pytest.mark.parametrize("rate", ["jaumann", "green_naghdi"])
def test_neo_hookean_stress_is_not_rotated(rate, monkeypatch):
    scene = _scene("neo_hookean", objective_rate=rate)
    on, calls = _run(scene, monkeypatch)
    assert scene.solver.large_rotations and not on.rotates_stress
    assert calls == {"jaumann_rotate": 0, "rotate": 0}
    off, _ = _run(_scene("neo_hookean", large_rotations=False))
    assert on.step_count == off.step_count > 10
    for name in ("x", "v", "stress", "F"):
        assert np.array_equal(on.particles[name], off.particles[name]), name
    assert on.energies() == off.energies()


@pytest.mark.parametrize("rate, kernel", [("jaumann", "jaumann_rotate"), ("green_naghdi", "rotate")])
def test_a_rate_form_material_is_still_rotated(rate, kernel, monkeypatch):
    """The control: without it the test above could pass with the rotation off for everyone."""
    s, calls = _run(_scene("linear_elastic", objective_rate=rate), monkeypatch)
    assert s.rotates_stress and calls[kernel] == s.step_count
