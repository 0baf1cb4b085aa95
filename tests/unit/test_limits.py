"""Limits refused before a run allocates or steps (pmpm/scene/limits.py, pmpm/scene/names.py):
the memory estimate against what a solver really allocates, the time-step checks against the
CFL rule written out, and the file-name rule."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.errors import ConfigError
from pmpm.scene.config import parse_scene
from pmpm.scene.limits import check_memory, check_time_step, estimate_bytes, estimate_particles
from pmpm.scene.names import check_name, check_output_files, run_files


def _data(cells=(40, 20), h=0.1, ppc=2, time_step=None, end_time=1.0, **solver):
    sv = {"end_time": end_time, **solver}
    if time_step is not None:
        sv["time_step"] = time_step
    return {"grid": {"cell_size": h, "cells": list(cells)},
            "materials": {"m": {"type": "smooth_vonmises", "E": 100.0, "nu": 0.3, "density": 1.0,
                                "yield_stress": 1.0, "hardening": 0.1}},
            "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.5, 0.5], "upper": [3.5, 1.5],
                        "particles_per_cell": ppc},
                       {"shape": "circle", "material": "m", "center": [2.0, 1.75], "radius": 0.2}],
            "solver": sv}


def test_memory_estimate_covers_what_the_solver_allocates():
    scene = parse_scene(_data())
    s = build_solver(scene, MPI.COMM_SELF)
    w = s.window
    window = w.G.nbytes + w.bc_mask.nbytes + w.bc_vel.nbytes
    particles = sum(a.nbytes for a in s.particles.fields.values())
    est_window, est_particles = estimate_bytes(scene, 1, sum(int(np.prod(f)) for m in s.materials
                                                              for f in m.state_fields.values()))
    # the estimate must not be below the arrays that live for the whole run; it counts the
    # scratch and copies on top (documented factors: 2 for the window, about 3 for particles)
    assert est_window >= window and est_particles >= particles
    assert est_window <= 2 * window  # one extra copy of G (halo scratch) on top: below twice
    n = s.n_total
    assert estimate_particles(scene.bodies[0], scene.grid.cell_size) == 30 * 10 * 4  # the lattice count
    assert sum(estimate_particles(b, scene.grid.cell_size) for b in scene.bodies) >= n


def test_memory_refusal_names_grid_cells():
    scene = parse_scene(_data())
    with pytest.raises(ConfigError) as info:
        check_memory(scene, available=1000.0)  # 1 KB cannot hold a 41 x 21 node window
    assert info.value.key == "grid.cells" and "would need about" in info.value.reason
    assert check_memory(scene, available=1e12) > 0


def test_time_step_checks_follow_the_cfl_rule():
    scene = parse_scene(_data())
    from pmpm.physics.materials import make_material
    mats = [make_material(scene.materials["m"], "materials.m", scene.formulation)]
    c = math.sqrt(100.0 / (1.0 * (1 - 0.3 ** 2)))  # plane stress dilatational speed
    assert check_time_step(scene, mats) == pytest.approx(0.5 * 0.1 / c, rel=1e-14)
    assert check_time_step(scene, mats, vmax=1.0) == pytest.approx(0.5 * 0.1 / (c + 1.0), rel=1e-14)
    # a fixed step just above h / (c + v) is refused, just below accepted
    stable = 0.1 / (c + 1.0)
    above = parse_scene(_data(time_step=stable * 1.01))
    with pytest.raises(ConfigError) as info:
        check_time_step(above, mats, vmax=1.0)
    assert info.value.key == "solver.time_step" and "allow_unstable_time_step" in info.value.reason
    assert check_time_step(parse_scene(_data(time_step=stable * 0.99)), mats, vmax=1.0) == stable * 0.99
    allowed = parse_scene(_data(time_step=stable * 3, allow_unstable_time_step=True))
    assert check_time_step(allowed, mats, vmax=1.0) == stable * 3
    # the step count: end_time / dt against max_estimated_steps, naming the material
    n = 1.0 / (0.5 * 0.1 / c)
    with pytest.raises(ConfigError) as info:
        parse_scene(_data(max_estimated_steps=int(n) - 1))
    assert info.value.key == "materials.m" and "wave speed" in info.value.reason
    parse_scene(_data(max_estimated_steps=int(n) + 1))


@pytest.mark.parametrize("name", ["a", "Tip_1", "x-2.5", "A" * 64, "9lives"])
def test_names_that_make_file_names(name):
    assert check_name(name, "k") == name


@pytest.mark.parametrize("name", ["", "a/b", "a\\b", "..", "a..b", ".h", "-x", "a b", "é", "A" * 65,
                                  "con", "NUL.txt", "com1", "lpt9.h5", "a\0b", "tip\n"])
def test_names_refused(name):
    with pytest.raises(ConfigError):
        check_name(name, "k")


def test_every_file_of_a_run_and_the_clash_check():
    data = _data()
    data["output"] = {"track": [{"name": "tip", "point": [3.4, 1.0]}]}
    scene = parse_scene(data, "/tmp/beam.toml")
    names = [n for _, n in run_files(scene)]
    assert names[:5] == ["beam.h5", "beam.xdmf", "beam.ckpt0.h5", "beam.ckpt1.h5", "beam.lastgood.h5"]
    assert "beam_history_tip.csv" in names and "beam_history_tip.png" in names
    check_output_files([scene])
    import dataclasses
    twin = dataclasses.replace(scene, output=dataclasses.replace(
        scene.output, track=scene.output.track + (dataclasses.replace(scene.output.track[0], name="TIP"),)))
    with pytest.raises(ConfigError, match="gives the file"):
        check_output_files([twin])
