"""Bodies read from a mesh file (meshio): particles placed per element carry its area."""
import meshio
import numpy as np
import pytest

from pmpm.scene.bodies import body_points
from pmpm.scene.config import parse_scene
from pmpm.core.grid import Grid


def _scene(tmp_path, ppe):
    points = np.array([[0.5, 0.5], [1.5, 0.5], [1.5, 1.5], [0.5, 1.5], [2.5, 0.5], [2.5, 1.5]])
    cells = [("triangle", np.array([[0, 1, 2], [0, 2, 3]])), ("quad", np.array([[1, 4, 5, 2]]))]
    meshio.write(str(tmp_path / "part.vtu"), meshio.Mesh(points, cells))
    return parse_scene({
        "thickness": 0.02,
        "grid": {"cell_size": 0.25, "cells": [16, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 1.0, "nu": 0.3, "density": 1.0}},
        "bodies": [{"shape": "mesh", "material": "m", "file": "part.vtu", "particles_per_element": ppe}],
        "solver": {"end_time": 1.0},
    }, str(tmp_path / "case.toml"))


@pytest.mark.parametrize("ppe", [1, 4])
def test_mesh_particles_carry_the_element_areas(tmp_path, ppe):
    scene = _scene(tmp_path, ppe)
    grid = Grid(scene.grid.origin, scene.grid.cell_size, scene.grid.cells)
    pts, vol = body_points(scene.bodies[0], grid, str(tmp_path))
    # two triangles of the unit square and one unit quad: area 2, times the thickness
    assert vol.sum() == pytest.approx(2.0 * 0.02, rel=1e-12)
    assert len(pts) == 3 * ppe
    # every point lies inside the mesh's outline [0.5, 2.5] x [0.5, 1.5]
    assert np.all((pts >= [0.5, 0.5]) & (pts <= [2.5, 1.5]))
    # and each element's points average to its centroid (symmetric placement)
    quad = pts[:, 0] > 1.5
    np.testing.assert_allclose(pts[quad].mean(axis=0), [2.0, 1.0], atol=1e-12)
