"""The grid's active tiles on slabs (pmpm.core.grid): on the same ranks, a run with tiles equals
the run whose node passes cover the whole window, to the bit (same nodes visited in the same
order, same halo sums). The halo strips are always active: a rank whose own particles do not
reach its ghost or borrowed columns must still update the nodes a neighbour's particles fill.

    mpirun -n 2 python -m pytest tests/mpi/test_grid_tiles_mpi.py -q
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.scene.config import parse_scene

comm = MPI.COMM_WORLD


def _scene(parallel):
    """A block crossing the slab boundary (migration, halo sums on both sides) into a fixed
    wall whose reaction is recorded, damped, on a grid it occupies a small part of."""
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.25, "cells": [24, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 1000.0, "nu": 0.3, "density": 10.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [3.5, 0.75], "upper": [4.5, 1.5],
                    "velocity": ["-8.0 + 0.5 * y", "0.3 * x"]}],
        "boundary": [{"name": "wall", "type": "fixed", "lower": [2.0, 0.0], "upper": [2.0, 2.5],
                      "reaction": True}],
        "loads": {"gravity": [0.0, -9.8], "damping": 0.5},
        "solver": {"end_time": 1.0, "cfl": 0.4, "shape_function": "cubic", "scheme": "musl"},
        "parallel": parallel,
    }, "tiles_mpi.toml")


@pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")
@pytest.mark.parametrize("parallel", [{}, {"rebalance_threshold": 1.05, "rebalance_interval": 5}])
def test_tiles_on_slabs_equal_the_whole_window_to_the_bit(parallel):
    scene = _scene(parallel)
    tiled, whole = build_solver(scene, comm), build_solver(scene, comm)
    tiled.window.use_tiles(2)
    whole.window.use_tiles(0)
    for _ in range(40):
        tiled.step()
        whole.step()
        if whole.window.active is not None:   # a rebalance rebuilt the window: tiles off again
            whole.window.use_tiles(0)
    ok = tiled.particles.n == whole.particles.n
    if ok:
        a, b = np.argsort(tiled.particles["id"]), np.argsort(whole.particles["id"])
        ok = all(np.array_equal(tiled.particles[k][a], whole.particles[k][b]) for k in whole.particles.fields)
        ok = ok and np.array_equal(tiled.effect("reactions").kernel_arg()[1], whole.effect("reactions").kernel_arg()[1])
    ok = ok and tiled.energies() == whole.energies()
    assert comm.allreduce(bool(ok), op=MPI.LAND)
    # the block moved across the slab boundary and hit the wall
    assert comm.allreduce(abs(whole.effect("reactions").kernel_arg()[1]).max(), op=MPI.MAX) > 0
