"""Section cuts (pmpm.results.sections): the band rule against closed forms on the particle
lattices pmpm's bodies make, and the bad-input rules of [[output.section]].

The closed forms are those of the point quadrature the strip's particles carry: a lattice of n
rows across a depth d integrates y^2 by the midpoint rule, sum y_i^2 dy = d^3/12 (1 - 1/n^2)
(exact for polynomials that rule integrates); an i_section strip's thicknesses are fitted so
that the same sums give the W shape's A and I exactly (pmpm.scene.bodies).
"""
import copy
import subprocess
import sys

import numpy as np
import pytest

from pmpm.core.grid import Grid
from pmpm.errors import ConfigError
from pmpm.results.sections import make_cuts, section_properties
from pmpm.scene.config import parse_scene
from pmpm.scene.setup_particles import place_points
from pmpm.physics.materials import make_material

#: a strip 2 x 0.2 (thickness 0.1), 0.05 cells, 2 particles per cell: 8 rows across
STRIP = {
    "thickness": 0.1,
    "grid": {"origin": [-0.2, -0.4], "cell_size": 0.05, "cells": [48, 16]},
    "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.0, "density": 1.0}},
    "bodies": [{"name": "strip", "shape": "rectangle", "material": "m",
                "lower": [0.0, -0.1], "upper": [2.0, 0.1]}],
    "solver": {"end_time": 0.01},
}
T, D, ROWS = 0.1, 0.2, 8


def _scene(sections, **extra):
    data = copy.deepcopy(STRIP)
    data.update(copy.deepcopy(extra))
    data.setdefault("output", {})["section"] = sections
    return parse_scene(data, "strip.toml")


def _setup(scene):
    grid = Grid(scene.grid.origin, scene.grid.cell_size, scene.grid.cells)
    mats = [make_material(scene.materials[k], k, scene.formulation) for k in scene.materials]
    points = place_points(scene, grid, mats, list(scene.materials))
    return make_cuts(scene, grid, points), points


def _vertical(name, x, **kw):
    return dict(name=name, segment=[[x, -0.3], [x, 0.3]], **kw)


def _resultants(cut, points, stress):
    phi = cut.weights(points["x"], points["body"])
    return cut.resultants(points["x"], stress, points["vol"], phi)


def test_uniform_stress_gives_force_per_depth():
    """sigma constant: N = sxx t d, V = -sxy t d, M = 0 (about the strip's axis)."""
    (cut,), pts = _setup(_scene([_vertical("a", 1.0)]))
    stress = np.zeros((len(pts["x"]), 4))
    stress[:, 0], stress[:, 1], stress[:, 2] = 3.0, 7.0, 2.0
    N, V, M = _resultants(cut, pts, stress)
    # tolerances: rounding only (sums of a few hundred terms)
    assert N == pytest.approx(3.0 * T * D, rel=1e-12)
    assert V == pytest.approx(-2.0 * T * D, rel=1e-12)
    assert M == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("width", [0.025, 0.05, 0.1, 0.2])
def test_linear_moment_along_member_is_exact_for_any_band(width):
    """sigma_xx = k y (L - x): M(x_c) = k (L - x_c) I_lattice for every band width (the band
    mean of a linear variation is its centre value); N = 0."""
    (cut,), pts = _setup(_scene([_vertical("a", 0.7, width=width)]))
    x, y = pts["x"][:, 0], pts["x"][:, 1]
    stress = np.zeros((len(x), 4))
    k, L = 5.0, 2.0
    stress[:, 0] = k * y * (L - x)
    N, V, M = _resultants(cut, pts, stress)
    I_lattice = T * D ** 3 / 12 * (1 - 1 / ROWS ** 2)   # midpoint rule of y^2 over 8 rows
    assert M == pytest.approx(k * (L - 0.7) * I_lattice, rel=1e-12)
    assert abs(N) < 1e-12 and abs(V) < 1e-12


def test_cut_off_the_lattice_rows_weights_by_fraction():
    """A band whose edges split particle domains still integrates a uniform field exactly:
    the fractions of each row add up to b / l."""
    (cut,), pts = _setup(_scene([_vertical("a", 1.01, width=0.037)]))
    stress = np.zeros((len(pts["x"]), 4))
    stress[:, 0] = 1.0
    assert _resultants(cut, pts, stress)[0] == pytest.approx(T * D, rel=1e-12)


def test_i_section_cut_recovers_the_w_shape():
    """Across an i_section strip: N = sigma A and, for sigma = k eta, M = k I of the W shape
    (the strip's thicknesses are fitted to A and I in the point quadrature)."""
    col = {"name": "col", "shape": "i_section", "material": "m", "start": [0.0, 0.0], "end": [0.0, 3.0],
           "depth": 0.33325, "flange_width": 0.31293, "flange_thickness": 0.028067,
           "web_thickness": 0.018034, "area": 0.022774, "inertia": 4.4537e-4}
    scene = _scene([{"name": "c", "body": "col", "position": 1.2}], bodies=[col],
                   grid={"origin": [-0.5, 0.0], "cell_size": 0.05, "cells": [20, 70]})
    (cut,), pts = _setup(scene)
    stress = np.zeros((len(pts["x"]), 4))
    stress[:, 1] = 2.0 + 3.0 * pts["x"][:, 0]   # syy = a + k x; the column's e = (-1, 0)
    N, V, M = _resultants(cut, pts, stress)
    A, I, S, Z, d = section_properties(scene.bodies[0])
    assert N == pytest.approx(2.0 * 0.022774, rel=1e-9)   # fitted to 1e-6 in bodies.py
    assert M == pytest.approx(-3.0 * 4.4537e-4, rel=1e-6)  # eta = -x
    assert Z == pytest.approx(3.048e-3, rel=0.01)  # design.md's tabulated Z (fillets left out)


BAD = {
    "misses": ([_vertical("a", 2.1)], "output.section[0].segment: misses every member"),
    "outside": ([dict(name="a", segment=[[1.0, -0.3], [1.0, 9.0]])], "output.section[0].segment: point"),
    "bad-name": ([_vertical("../a", 1.0)], "output.section[0].name: '../a' is not a valid file name"),
    "name-with-space": ([_vertical("left base", 1.0)], "not a valid file name"),
    "not-a-segment": ([dict(name="a", segment=[1.0, 2.0])], "output.section[0].segment: must be two [x, y] points"),
    "both-forms": ([dict(name="a", segment=[[1, 0], [1, 1]], body="strip", position=1.0)],
                   "output.section[0].segment: give either segment or body"),
    "band-off-the-end": ([_vertical("a", 0.01)], "output.section[0]: its band"),
    "duplicate": ([_vertical("a", 1.0), _vertical("a", 1.5)], "output.section: section names must be unique"),
    "not-an-i-section": ([dict(name="a", body="strip", position=1.0)], "is not an i_section"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_sections_name_their_key(case):
    sections, expected = BAD[case]
    with pytest.raises(ConfigError) as err:
        _setup(_scene(sections))
    assert expected in f"{err.value.key}: {err.value.reason}"


def test_cut_across_two_members():
    two = copy.deepcopy(STRIP["bodies"]) + [{"name": "other", "shape": "rectangle", "material": "m",
                                             "lower": [0.0, 0.15], "upper": [2.0, 0.3]}]
    with pytest.raises(ConfigError, match="crosses more than one member"):
        _setup(_scene([_vertical("a", 1.0)], bodies=two))


@pytest.mark.parametrize("value", ["[1.0]", '"centre"', "[1.0, true]"])
def test_moment_point_must_be_a_pair(value):
    data = copy.deepcopy(STRIP)
    data["boundary"] = [{"name": "wall", "type": "fixed", "lower": [-0.2, -0.4], "upper": [0.0, 0.4],
                         "reaction": True, "moment_about": eval(value, {"true": True})}]
    with pytest.raises(ConfigError) as err:
        parse_scene(data, "strip.toml")
    assert err.value.key == "boundary[0].moment_about"


def test_cli_bad_section_is_one_line_exit_2_nothing_written(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text("""\
thickness = 0.1
[grid]
origin = [-0.2, -0.4]
cell_size = 0.05
cells = [48, 16]
[materials.m]
type = "linear_elastic"
E = 1e6
nu = 0.0
density = 1.0
[[bodies]]
shape = "rectangle"
material = "m"
lower = [0.0, -0.1]
upper = [2.0, 0.1]
[solver]
end_time = 0.01
[[output.section]]
name = "cut"
segment = [[2.1, -0.3], [2.1, 0.3]]
""")
    proc = subprocess.run([sys.executable, "-m", "pmpm.cli", str(case)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == f"pmpm: error: {case}: output.section[0].segment: misses every member (no particle on the cut)\n"
    assert [p.name for p in tmp_path.iterdir()] == ["case.toml"]


def test_hysteresis_needs_recorded_reactions():
    data = copy.deepcopy(STRIP)
    data["output"] = {"track": [{"name": "tip", "point": [2.0, 0.0]}], "hysteresis": {"track": "tip"}}
    with pytest.raises(ConfigError, match="needs reactions"):
        parse_scene(data, "strip.toml")
    data["boundary"] = [{"name": "wall", "type": "fixed", "lower": [-0.2, -0.4], "upper": [0.0, 0.4], "reaction": True}]
    data["output"]["hysteresis"]["reactions"] = ["floor"]
    with pytest.raises(ConfigError, match="no recorded reaction 'floor'"):
        parse_scene(data, "strip.toml")
    data["output"]["hysteresis"]["reactions"] = ["wall"]
    assert parse_scene(data, "strip.toml").output.hysteresis["reactions"] == ["wall"]
