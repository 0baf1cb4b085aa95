"""The Jaumann (objective) stress rate used for large rotations."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.scene.config import parse_scene
from pmpm.core.kernels import jaumann_rotate
from pmpm.build import build_solver


def test_many_small_spins_rotate_the_stress_like_the_rotation_matrix():
    """Integrating t += W t - t W over n steps of spin theta / n converges to R t R^T at first
    order in the step (forward Euler of an exact rotation)."""
    sigma = np.array([[3.0, -1.0], [-1.0, 0.5]])
    theta = math.pi / 3
    R = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    exact = R @ sigma @ R.T
    errors = []
    for n in (1000, 2000):
        t = np.array([[sigma[0, 0], sigma[1, 1], sigma[0, 1], 0.0]])
        for _ in range(n):
            jaumann_rotate(t, np.array([theta / n]))
        got = np.array([[t[0, 0], t[0, 2]], [t[0, 2], t[0, 1]]])
        errors.append(np.abs(got - exact).max())
    assert errors[0] < 5e-3 * np.abs(sigma).max()
    assert errors[1] == pytest.approx(errors[0] / 2, rel=0.05)  # first order in the step
    # invariants of the rotation are kept to the same order
    assert t[0, 0] + t[0, 1] == pytest.approx(np.trace(sigma), abs=1e-9)


def test_rigid_rotation_makes_no_strain():
    """A spinning square: the velocity gradient of a rigid rotation is skew, so the strain
    increment is zero where every node of a particle's support is surrounded by material
    (there the nodal velocities are the linear field itself, which B-splines reproduce exactly;
    near free edges the nodal velocity is a mass-weighted mean, not the field's value). The
    physics of large rotations is checked by the cantilever of tests/hard."""
    w = 0.5
    scene = parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [-2.0, -2.0], "cell_size": 0.2, "cells": [20, 20]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e9, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [-1.2, -1.2], "upper": [1.2, 1.2],
                    "velocity": [f"-{w} * y", f"{w} * x"]}],
        "solver": {"end_time": 1.0, "cfl": 0.5, "large_rotations": True},
    }, "spin.toml")
    s = build_solver(scene, MPI.COMM_SELF)
    s.step()
    deep = np.abs(s.particles["x"]).max(axis=1) < 1.2 - 3 * 0.2  # support far from the edges
    assert deep.sum() > 10
    assert np.abs(s._de[deep]).max() < 1e-12
