"""Scene parsing: defaults are resolved, and every bad input names its key (docs/scenes.md).

``parse_scene`` checks the scene file alone; a body outside the grid, a boundary box with no node,
a load box with no particle and a bad mesh file are found when the solver builds the particles
(``build_solver(scene, comm)``), before any kernel is compiled.
"""
import copy
import json
import math
import re
from pathlib import Path

import pytest
from mpi4py import MPI

from pmpm.scene.config import load_scene, parse_scene
from pmpm.errors import ConfigError

BASE = {
    "grid": {"cell_size": 0.5, "cells": [8, 4]},
    "materials": {"steel": {"type": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0}},
    "bodies": [{"shape": "rectangle", "material": "steel", "lower": [0.0, 0.0], "upper": [2.0, 1.0]}],
    "solver": {"end_time": 0.01},
}

BASE_TOML = """\
[grid]
cell_size = 0.5
cells = [8, 4]

[materials.steel]
type = "linear_elastic"
E = 100.0
nu = 0.3
density = 1.0

[[bodies]]
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]

[solver]
end_time = 0.01
"""


def scene_data(**changes):
    """A deep copy of BASE with top-level keys replaced."""
    data = copy.deepcopy(BASE)
    data.update(copy.deepcopy(changes))
    return data


def with_(path, value):
    """BASE with the dotted ``path`` (list indices as numbers) set to ``value``; None deletes."""
    data = copy.deepcopy(BASE)
    node = data
    parts = path.split(".")
    for part in parts[:-1]:
        node = node[int(part)] if isinstance(node, list) else node.setdefault(part, {})
    if value is None:
        del node[parts[-1]]
    else:
        node[parts[-1]] = value
    return data


def error_of(data, path="case.toml"):
    with pytest.raises(ConfigError) as info:
        parse_scene(data, path)
    return info.value


def solver_error(data, tmp_path):
    """The ConfigError raised while the solver sets the scene up on one rank."""
    from pmpm.build import build_solver
    scene = parse_scene(data, str(tmp_path / "case.toml"))
    with pytest.raises(ConfigError) as info:
        build_solver(scene, MPI.COMM_SELF)
    return info.value


# -- a valid scene and its defaults ---------------------------------------------------------------

def test_defaults_are_resolved():
    s = parse_scene(scene_data(), "/somewhere/beam.toml")
    assert s.path == "/somewhere/beam.toml" and s.stem == "beam"
    assert s.title == "beam.toml"
    assert s.formulation == "plane_stress" and s.thickness == 1.0
    assert s.grid.origin == (0.0, 0.0) and s.grid.cell_size == 0.5 and s.grid.cells == (8, 4)
    assert s.materials == {"steel": BASE["materials"]["steel"]}
    (b,) = s.bodies
    assert (b.name, b.shape, b.material, b.particles_per_cell, b.thickness, b.velocity) == \
        ("body0", "rectangle", "steel", 2, 1.0, (0.0, 0.0))
    assert b.geometry == {"lower": (0.0, 0.0), "upper": (2.0, 1.0)}
    assert s.boundaries == ()
    assert s.loads.gravity is None and s.loads.forces == ()
    sv = s.solver
    assert (sv.shape_function, sv.scheme, sv.pic_blend, sv.cfl, sv.end_time) == ("cubic", "musl", 0.0, 0.5, 0.01)
    assert (sv.time_step, sv.mass_cutoff, sv.large_rotations, sv.sort_interval) == (None, 1e-8, False, 20)
    assert (sv.on_particle_exit, sv.max_steps) == ("error", None)
    out = s.output
    assert out.directory == "beam_results"
    assert math.isclose(out.interval, 0.01 / 20) and math.isclose(out.history_interval, 0.01 / 1000)
    assert out.fields == ("x", "v", "stress") and out.track == ()
    assert (out.checkpoint_interval, out.deformed_plot, out.progress_interval) == (None, None, 2.0)
    p = s.parallel
    assert (p.axis, p.rebalance_threshold, p.rebalance_interval, p.io) == ("auto", None, 50, "mpio")
    assert s.variants == {} and s.variant == ""
    json.dumps(s.to_dict(), default=str)  # the resolved scene goes into every output file


def test_top_level_defaults_reach_the_bodies():
    s = parse_scene(scene_data(thickness=0.02, particles_per_cell=3, title="t", formulation="plane_strain"))
    assert (s.title, s.formulation) == ("t", "plane_strain")
    assert (s.bodies[0].thickness, s.bodies[0].particles_per_cell) == (0.02, 3)
    data = with_("bodies.0.thickness", 0.5)
    data["bodies"][0]["particles_per_cell"] = 4
    assert (parse_scene(data).bodies[0].thickness, parse_scene(data).bodies[0].particles_per_cell) == (0.5, 4)


def test_full_scene_is_accepted():
    data = scene_data(
        boundary=[{"name": "left", "type": "fixed", "lower": [0, 0], "upper": [0, 2]},
                  {"type": "roller_x", "lower": [0, 0], "upper": [4, 0]},
                  {"type": "roller_y", "lower": [4, 0], "upper": [4, 2]},
                  {"type": "velocity", "lower": [0, 2], "upper": [4, 2], "velocity": [0.1, 0]}],
        loads={"gravity": [0, -9.81],
               "forces": [{"lower": [1.5, 0], "upper": [2, 1], "force": [0, -1],
                           "time_function": {"type": "ramp", "duration": 0.001}},
                          {"lower": [0, 0], "upper": [0.5, 1], "force": [1, 0],
                           "time_function": {"type": "table", "t": [0, 1], "value": [0, 2]}}]},
        output={"directory": "res", "interval": 0.001, "history_interval": 1e-4,
                "fields": ["x", "x0", "v", "m", "vol", "stress", "strain", "mat", "body", "id"],
                "track": [{"name": "tip", "point": [2, 1]}], "checkpoint_interval": 0.005,
                "deformed_plot": {"track": "tip", "component": "uy"}, "progress_interval": 0},
        parallel={"axis": "x", "rebalance_threshold": 1.2, "rebalance_interval": 10, "io": "gather"})
    data["solver"].update(shape_function="quadratic", scheme="usl", pic_blend=0.01, cfl=1.0,
                          time_step=1e-4, mass_cutoff=0.0, large_rotations=True, sort_interval=0,
                          on_particle_exit="remove", max_steps=5)
    s = parse_scene(data)
    assert [b.type for b in s.boundaries] == ["fixed", "roller_x", "roller_y", "velocity"]
    assert s.boundaries[0].name == "left" and s.boundaries[1].name == "boundary1"
    assert s.boundaries[3].velocity == (0.1, 0.0) and s.boundaries[0].velocity == (0.0, 0.0)
    assert s.loads.gravity == (0.0, -9.81)
    assert s.loads.forces[0].time_function == {"type": "ramp", "start": 0.0, "duration": 0.001}
    assert s.loads.forces[1].name == "force1"
    assert s.output.deformed_plot == {"track": "tip", "component": "uy", "color": "eps_p_eq", "scale": 10.0}
    assert s.solver.time_step == 1e-4 and s.solver.max_steps == 5


def test_default_time_function_is_a_step_at_zero():
    data = scene_data(loads={"forces": [{"lower": [0, 0], "upper": [1, 1], "force": [0, 1]}]})
    assert parse_scene(data).loads.forces[0].time_function == {"type": "step", "start": 0.0}


@pytest.mark.parametrize("kind,extra", [
    ("smooth_vonmises", {"yield_stress": 2.0, "hardening": 0.05}),
    ("smooth_vonmises", {"yield_stress": 2.0, "hardening": 0.0, "smoothness": 25}),
    ("bilinear_vonmises", {"yield_stress": 2.0, "hardening": 0.05}),
])
def test_plastic_materials_accepted(kind, extra):
    data = with_("materials.steel.type", kind)
    data["materials"]["steel"].update(extra)
    data["output"] = {"fields": ["x", "eps_p_eq", "back_stress", "eps_p", "plastic_work"]}
    assert parse_scene(data).output.fields[1] == "eps_p_eq"


# -- unknown keys (typos never pass silently) -----------------------------------------------------

@pytest.mark.parametrize("path,key", [
    ("titel", "titel"),
    ("grid.cellsize", "grid.cellsize"),
    ("materials.steel.young", "materials.steel.young"),
    ("bodies.0.colour", "bodies[0].colour"),
    ("solver.endtime", "solver.endtime"),
    ("solver.shape", "solver.shape"),
    ("output.intervall", "output.intervall"),
    ("parallel.ranks", "parallel.ranks"),
    ("loads.graviti", "loads.graviti"),
])
def test_unknown_key(path, key):
    err = error_of(with_(path, 1))
    assert err.key == key and "unknown key" in err.reason


def test_unknown_key_in_nested_tables():
    bc = scene_data(boundary=[{"type": "fixed", "lower": [0, 0], "upper": [0, 2], "velocity": [1, 0]}])
    assert error_of(bc).key == "boundary[0].velocity"  # only type = "velocity" takes a velocity
    force = scene_data(loads={"forces": [{"lower": [0, 0], "upper": [1, 1], "force": [0, 1], "forse": 1}]})
    assert error_of(force).key == "loads.forces[0].forse"
    tf = scene_data(loads={"forces": [{"lower": [0, 0], "upper": [1, 1], "force": [0, 1],
                                       "time_function": {"type": "step", "duration": 1.0}}]})
    assert error_of(tf).key == "loads.forces[0].time_function.duration"
    track = scene_data(output={"track": [{"point": [1, 1], "pont": [0, 0]}]})
    assert error_of(track).key == "output.track[0].pont"
    shape_key = with_("bodies.0.radius", 1.0)  # a circle key on a rectangle
    assert error_of(shape_key).key == "bodies[0].radius"


def test_unknown_material_parameter_names_the_material():
    err = error_of(with_("materials.steel.yield_stress", 250.0))  # not a linear_elastic parameter
    assert err.key == "materials.steel.yield_stress" and "unknown key" in err.reason


# -- wrong types ----------------------------------------------------------------------------------

@pytest.mark.parametrize("path,value,key", [
    ("grid.cell_size", "0.5", "grid.cell_size"),
    ("grid.cells", [8.0, 4], "grid.cells"),
    ("grid.cells", [8, 4, 2], "grid.cells"),
    ("grid.origin", [0.0], "grid.origin"),
    ("materials.steel.E", "200e9", "materials.steel.E"),
    ("materials.steel.nu", True, "materials.steel.nu"),
    ("materials.steel", 5, "materials.steel"),
    ("materials", [1], "materials"),
    ("bodies", {"shape": "rectangle"}, "bodies"),
    ("bodies.0.lower", [0, "a"], "bodies[0].lower"),
    ("bodies.0.velocity", [1.0], "bodies[0].velocity"),
    ("bodies.0.particles_per_cell", 2.5, "bodies[0].particles_per_cell"),
    ("solver.end_time", "1", "solver.end_time"),
    ("solver.end_time", math.inf, "solver.end_time"),
    ("solver.large_rotations", 1, "solver.large_rotations"),
    ("solver.scheme", 3, "solver.scheme"),
    ("solver.max_steps", 10.0, "solver.max_steps"),
    ("title", 5, "title"),
    ("thickness", "1", "thickness"),
    ("loads", 9.81, "loads"),
    ("loads.gravity", -9.81, "loads.gravity"),
    ("output.fields", "x", "output.fields"),
    ("output.track", {"point": [1, 1]}, "output.track"),
])
def test_wrong_type(path, value, key):
    assert error_of(with_(path, value)).key == key


@pytest.mark.parametrize("path,value,key", [
    ("formulation", "3d", "formulation"),
    ("solver.shape_function", "quartic", "solver.shape_function"),
    ("solver.scheme", "flip", "solver.scheme"),
    ("solver.on_particle_exit", "ignore", "solver.on_particle_exit"),
    ("bodies.0.shape", "square", "bodies[0].shape"),
    ("materials.steel.type", "elastic", "materials.steel.type"),
    ("parallel.axis", "z", "parallel.axis"),
    ("parallel.io", "posix", "parallel.io"),
])
def test_value_not_among_choices(path, value, key):
    err = error_of(with_(path, value))
    assert err.key == key and ("one of" in err.reason)


# -- missing sections and keys --------------------------------------------------------------------

@pytest.mark.parametrize("path,key", [
    ("grid", "grid"),
    ("grid.cell_size", "grid.cell_size"),
    ("grid.cells", "grid.cells"),
    ("materials", "materials"),
    ("materials.steel.type", "materials.steel.type"),
    ("materials.steel.E", "materials.steel.E"),
    ("materials.steel.density", "materials.steel.density"),
    ("bodies", "bodies"),
    ("bodies.0.shape", "bodies[0].shape"),
    ("bodies.0.material", "bodies[0].material"),
    ("bodies.0.upper", "bodies[0].upper"),
    ("solver", "solver"),
    ("solver.end_time", "solver.end_time"),
])
def test_missing(path, key):
    err = error_of(with_(path, None))
    assert err.key == key and "missing" in err.reason


def test_empty_materials_and_no_bodies():
    assert error_of(scene_data(materials={})).key == "materials"
    assert error_of(scene_data(bodies=[])).key == "bodies"


def test_plastic_material_needs_its_parameters():
    data = with_("materials.steel.type", "bilinear_vonmises")
    data["materials"]["steel"]["yield_stress"] = 2.0
    err = error_of(data)
    assert err.key == "materials.steel.hardening" and "missing" in err.reason
    data["materials"]["steel"]["hardening"] = 1.0
    assert error_of(data).key == "materials.steel.hardening"


# -- physical ranges ------------------------------------------------------------------------------

@pytest.mark.parametrize("name,value", [("E", -1), ("E", 0), ("density", 0), ("density", -7850.0)])
def test_modulus_and_density_must_be_positive(name, value):
    err = error_of(with_(f"materials.steel.{name}", value))
    assert err.key == f"materials.steel.{name}" and "must be > 0" in err.reason
    assert str(err) == f"materials.steel.{name}: must be > 0 (got {value:g})"


@pytest.mark.parametrize("nu,reason", [(0.5, "must be < 0.5"), (0.7, "must be < 0.5"),
                                       (-1.0, "must be > -1"), (-1.2, "must be > -1")])
def test_poisson_ratio_out_of_range(nu, reason):
    err = error_of(with_("materials.steel.nu", nu))
    assert err.key == "materials.steel.nu" and reason in err.reason


@pytest.mark.parametrize("nu", [0.0, 0.499, -0.99])
def test_poisson_ratio_in_range(nu):
    parse_scene(with_("materials.steel.nu", nu))


@pytest.mark.parametrize("cfl", [1.5, 0.0, -0.5])
def test_cfl_out_of_range(cfl):
    assert error_of(with_("solver.cfl", cfl)).key == "solver.cfl"


def test_cfl_of_one_is_allowed():
    assert parse_scene(with_("solver.cfl", 1.0)).solver.cfl == 1.0


@pytest.mark.parametrize("path,value,key", [
    ("grid.cell_size", 0.0, "grid.cell_size"),
    ("grid.cells", [2, 4], "grid.cells"),
    ("solver.end_time", 0.0, "solver.end_time"),
    ("solver.time_step", -1e-3, "solver.time_step"),
    ("solver.pic_blend", 1.5, "solver.pic_blend"),
    ("solver.mass_cutoff", 2.0, "solver.mass_cutoff"),
    ("solver.sort_interval", -1, "solver.sort_interval"),
    ("solver.max_steps", 0, "solver.max_steps"),
    ("particles_per_cell", 0, "particles_per_cell"),
    ("particles_per_cell", 9, "particles_per_cell"),
    ("thickness", 0.0, "thickness"),
    ("bodies.0.thickness", -1.0, "bodies[0].thickness"),
    ("output.interval", 0.0, "output.interval"),
    ("parallel.rebalance_threshold", 1.0, "parallel.rebalance_threshold"),
    ("materials.steel.density", math.nan, "materials.steel.density"),
])
def test_out_of_range(path, value, key):
    assert error_of(with_(path, value)).key == key


def test_material_that_is_not_defined():
    err = error_of(with_("bodies.0.material", "stel"))
    assert err.key == "bodies[0].material"
    assert "'stel'" in err.reason and "steel" in err.reason


def test_bad_geometry_in_the_scene_file():
    assert error_of(with_("bodies.0.upper", [-1.0, 1.0])).key == "bodies[0].upper"
    poly = [{"shape": "polygon", "material": "steel", "vertices": [[0, 0], [1, 0]]}]
    assert error_of(scene_data(bodies=poly)).key == "bodies[0].vertices"
    poly[0]["vertices"] = [[0, 0], [1, 0], ["1", 1]]
    assert error_of(scene_data(bodies=poly)).key == "bodies[0].vertices"
    circle = [{"shape": "circle", "material": "steel", "center": [1, 1], "radius": 0}]
    assert error_of(scene_data(bodies=circle)).key == "bodies[0].radius"
    isec = {"shape": "i_section", "material": "steel", "start": [0.5, 1], "end": [3.5, 1], "depth": 0.3,
            "flange_width": 0.15, "flange_thickness": 0.15, "web_thickness": 0.01}
    assert error_of(scene_data(bodies=[isec])).key == "bodies[0].flange_thickness"
    isec.update(flange_thickness=0.01, end=[0.5, 1])
    assert error_of(scene_data(bodies=[isec])).key == "bodies[0].end"
    mesh = [{"shape": "mesh", "material": "steel", "file": "m.msh", "particles_per_element": 17}]
    assert error_of(scene_data(bodies=mesh)).key == "bodies[0].particles_per_element"


def test_bad_time_functions():
    def force(tf):
        return scene_data(loads={"forces": [{"lower": [0, 0], "upper": [1, 1], "force": [0, 1],
                                             "time_function": tf}]})
    key = "loads.forces[0].time_function"
    assert error_of(force({"type": "sine"})).key == f"{key}.type"
    assert error_of(force({"type": "ramp"})).key == f"{key}.duration"
    assert error_of(force({"type": "harmonic", "frequency": 0})).key == f"{key}.frequency"
    assert error_of(force({"type": "step", "start": -1})).key == f"{key}.start"
    assert error_of(force({"type": "table", "t": [0, 1], "value": [0]})).key == f"{key}.t"
    assert error_of(force({"type": "table", "t": [0, 0], "value": [0, 1]})).key == f"{key}.t"
    assert error_of(force({"type": "table", "t": [0, 1], "value": [0, math.nan]})).key == f"{key}.t"


def test_bad_output_settings():
    err = error_of(with_("output.fields", ["x", "stres"]))
    assert err.key == "output.fields" and "'stres'" in err.reason
    # plastic state fields exist only when a plastic material is in the scene
    assert error_of(with_("output.fields", ["eps_p_eq"])).key == "output.fields"
    twice = {"track": [{"name": "a", "point": [0, 0]}, {"name": "a", "point": [1, 1]}]}
    assert error_of(scene_data(output=twice)).key == "output.track"
    plot = {"track": [{"name": "a", "point": [0, 0]}], "deformed_plot": {"track": "b"}}
    assert error_of(scene_data(output=plot)).key == "output.deformed_plot.track"


# -- found while the solver places the particles ---------------------------------------------------

def test_body_outside_the_grid(tmp_path):
    err = solver_error(with_("bodies.0.upper", [5.0, 1.0]), tmp_path)  # grid is 4 x 2
    assert err.key == "bodies[0]" and "outside the grid" in err.reason


def test_circle_partly_outside_the_grid(tmp_path):
    circle = [{"shape": "circle", "material": "steel", "center": [3.8, 1.0], "radius": 0.5}]
    assert solver_error(scene_data(bodies=circle), tmp_path).key == "bodies[0]"


def test_boundary_box_that_selects_no_node(tmp_path):
    data = scene_data(boundary=[{"type": "fixed", "lower": [0.1, 0.1], "upper": [0.2, 0.2]}])
    err = solver_error(data, tmp_path)
    assert err.key == "boundary[0]" and "no grid node" in err.reason


def test_load_box_that_selects_no_particle(tmp_path):
    data = scene_data(loads={"forces": [{"lower": [3.0, 0.0], "upper": [4.0, 2.0], "force": [0, -1]}]})
    err = solver_error(data, tmp_path)
    assert err.key == "loads.forces[0]" and "no particle" in err.reason


def test_overlapping_load_boxes(tmp_path):
    box = {"lower": [0.0, 0.0], "upper": [1.0, 1.0], "force": [0, -1]}
    err = solver_error(scene_data(loads={"forces": [box, dict(box, name="second")]}), tmp_path)
    assert err.key == "loads.forces[1]" and "overlaps" in err.reason


def test_bad_velocity_expression():
    # refused while the scene is parsed (so also by --check), naming the unknown name
    err = error_of(with_("bodies.0.velocity", ["0.1 * sin(z)", 0.0]))
    assert err.key == "bodies[0].velocity" and "'z'" in err.reason


@pytest.mark.parametrize("depth,ppc", [(0.6, 1),    # one point row: singular
                                       (1.5, 1)])   # three rows: the web would need negative mass
def test_i_section_too_coarse_for_its_particles(tmp_path, depth, ppc):
    isec = {"shape": "i_section", "material": "steel", "start": [0.25, 1.0], "end": [3.75, 1.0],
            "depth": depth, "flange_width": 0.8, "flange_thickness": 0.1, "web_thickness": 0.05,
            "particles_per_cell": ppc}
    err = solver_error(scene_data(bodies=[isec]), tmp_path)
    assert err.key == "bodies[0].depth" and "positive thicknesses" in err.reason


def test_i_section_matches_area_and_second_moment():
    import numpy as np
    from pmpm.scene.bodies import body_points
    from pmpm.core.grid import Grid
    isec = {"shape": "i_section", "material": "steel", "start": [0.25, 1.0], "end": [3.75, 1.0],
            "depth": 1.5, "flange_width": 0.8, "flange_thickness": 0.1, "web_thickness": 0.05,
            "particles_per_cell": 2}
    body = parse_scene(scene_data(bodies=[isec])).bodies[0]
    pts, vol = body_points(body, Grid((0, 0), 0.5, (8, 4)), ".")
    A = 2 * 0.8 * 0.1 + 1.3 * 0.05
    I = (0.8 * 1.5 ** 3 - 0.75 * 1.3 ** 3) / 12
    assert np.all(vol > 0)
    assert np.isclose(vol.sum() / 3.5, A) and np.isclose(np.sum(vol * (pts[:, 1] - 1.0) ** 2) / 3.5, I)


@pytest.mark.parametrize("name,content", [
    ("garbage.msh", b"this is not a mesh\n$MeshFormat\nnonsense\n"),
    ("garbage.vtk", b"\x00\x01\x02 binary junk"),
    ("garbage.xyz", b"1 2 3\n"),
    ("missing.msh", None),
])
def test_unreadable_mesh_names_the_file(tmp_path, capfd, name, content):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    data = scene_data(bodies=[{"shape": "mesh", "material": "steel", "file": name}])
    err = solver_error(data, tmp_path)
    assert err.key == str(tmp_path / name) and "cannot read mesh" in err.reason
    assert "\n" not in str(err)
    out, errs = capfd.readouterr()
    assert out == "" and errs == ""  # meshio's own messages do not leak


def test_mesh_without_area_cells(tmp_path):
    meshio = pytest.importorskip("meshio")
    import numpy as np
    meshio.write(str(tmp_path / "lines.vtk"),
                 meshio.Mesh(np.array([[0.5, 0.5, 0.0], [1.5, 0.5, 0.0]]), [("line", np.array([[0, 1]]))]))
    data = scene_data(bodies=[{"shape": "mesh", "material": "steel", "file": "lines.vtk"}])
    err = solver_error(data, tmp_path)
    assert err.key == str(tmp_path / "lines.vtk") and "no triangle or quad" in err.reason


# -- files and variants (load_scene) ---------------------------------------------------------------

def test_load_scene_reads_a_file(tmp_path):
    case = tmp_path / "plate.toml"
    case.write_text(BASE_TOML)
    (scene,) = load_scene(str(case))
    assert scene.path == str(case) and scene.output.directory == "plate_results"


@pytest.mark.parametrize("text", [
    BASE_TOML + "\n[solver]\ncfl = 0.3\n",   # a table defined twice
    BASE_TOML.replace("E = 100.0", "E = 100.0.0"),
    BASE_TOML.replace('type = "linear_elastic"', "type = linear_elastic"),
    BASE_TOML.replace("cells = [8, 4]", "cells = [8, 4"),
])
def test_malformed_toml_names_the_file(tmp_path, text):
    case = tmp_path / "case.toml"
    case.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scene(str(case))
    assert info.value.key == str(case) and "not valid TOML" in info.value.reason


def test_missing_scene_file(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_scene(str(tmp_path / "nope.toml"))
    assert info.value.key == str(tmp_path / "nope.toml") and "cannot read" in info.value.reason


VARIANTS = BASE_TOML + """
[[output.track]]
name = "tip"
point = [2.0, 1.0]

[variants.base]

[variants.soft]
"materials.steel.E" = 50.0
solver.cfl = 0.25
"bodies.0.upper" = [3.0, 1.0]
output.interval = 0.002
"""


def test_variants_overrides_applied(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(VARIANTS)
    base, soft = load_scene(str(case))
    assert (base.variant, soft.variant) == ("base", "soft")
    assert base.materials["steel"]["E"] == 100.0 and soft.materials["steel"]["E"] == 50.0
    assert base.solver.cfl == 0.5 and soft.solver.cfl == 0.25
    assert soft.bodies[0].geometry["upper"] == (3.0, 1.0)
    # a bare dotted key overrides one key, the rest of its table stays
    assert soft.solver.end_time == 0.01
    assert soft.output.interval == 0.002 and [t.name for t in soft.output.track] == ["tip"]
    (only,) = load_scene(str(case), "soft")
    assert only.variant == "soft" and only.solver.cfl == 0.25


def test_quoted_dotted_key_replaces_a_whole_table(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(BASE_TOML + """
[variants.plastic]
"materials.steel" = { type = "bilinear_vonmises", E = 200.0, nu = 0.3, density = 2.0, yield_stress = 1.0, hardening = 0.01 }
[variants.merged]
materials.steel = { E = 300.0 }
[variants.typo]
"solvr.cfl" = 0.3
""")
    plastic = load_scene(str(case), "plastic")[0]
    assert plastic.materials["steel"] == {"type": "bilinear_vonmises", "E": 200.0, "nu": 0.3, "density": 2.0,
                                          "yield_stress": 1.0, "hardening": 0.01}
    merged = load_scene(str(case), "merged")[0]
    assert merged.materials["steel"] == dict(BASE["materials"]["steel"], E=300.0)
    with pytest.raises(ConfigError) as info:
        load_scene(str(case), "typo")
    assert info.value.key == "solvr" and "unknown key" in info.value.reason


def test_variant_errors(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(VARIANTS)
    with pytest.raises(ConfigError) as info:
        load_scene(str(case), "hard")
    assert info.value.key == "variants" and "'hard'" in info.value.reason
    case.write_text(VARIANTS + '"materials.steel.nu" = 0.5\n')
    with pytest.raises(ConfigError) as info:
        load_scene(str(case))
    assert info.value.key == "materials.steel.nu"
    case.write_text(VARIANTS + '"bodies.3.upper" = [1.0, 1.0]\n')
    with pytest.raises(ConfigError) as info:
        load_scene(str(case))
    assert info.value.key == "variants.soft.bodies.3.upper"
    case.write_text(VARIANTS + '"solver.end_time.x" = 1.0\n')
    with pytest.raises(ConfigError) as info:
        load_scene(str(case))
    assert info.value.key == "variants.soft.solver.end_time.x" and "not a table" in info.value.reason
    case.write_text(BASE_TOML)
    with pytest.raises(ConfigError) as info:
        load_scene(str(case), "soft")
    assert info.value.key == "variants"


# -- the examples of docs/scenes.md ----------------------------------------------------------------

DOC = Path(__file__).resolve().parents[2] / "docs" / "scenes.md"


def _doc_blocks():
    return re.findall(r"```toml\n(.*?)```", DOC.read_text(), re.S)


@pytest.mark.skipif(not DOC.exists(), reason="docs/scenes.md not present")
def test_documented_examples_are_valid(tmp_path):
    blocks = _doc_blocks()
    (complete,) = [b for b in blocks if b.startswith("# complete example")]
    case = tmp_path / "block.toml"
    case.write_text(complete)
    (scene,) = load_scene(str(case))
    assert scene.output.directory == "block_results"
    (variants,) = [b for b in blocks if "[variants." in b]
    case.write_text(BASE_TOML + "\n" + variants)
    base, soft, plastic = load_scene(str(case))
    assert (base.variant, soft.variant, plastic.variant) == ("base", "soft", "plastic")
    assert soft.materials["steel"]["E"] == 100.0e9 and soft.solver.cfl == 0.3
    assert soft.bodies[0].geometry["upper"] == (3.0, 0.5)
    assert plastic.materials["steel"]["type"] == "bilinear_vonmises"
