"""Reactions and section cuts are the same on any rank count.

Run under ``mpirun -n K`` (K = 2 or 3): a block standing on a floor of fixed nodes that spans
every slab (so one reaction is summed over ranks), pushed sideways by a load and pulled by
gravity; the histories of its floor reaction (mean impulses over each interval) and of two
section cuts on COMM_WORLD are compared, on rank 0, with the same run on COMM_SELF. Summation
order differs (halo sums, the reaction's allreduce), so 1e-10 relative to each quantity's
largest magnitude, as in test_same_answer.py.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.results.recorder import StructuralRecorder
from pmpm.scene.config import parse_scene

comm = MPI.COMM_WORLD
RTOL = 1e-10

SCENE = {
    "grid": {"origin": [-0.3, 0.0], "cell_size": 0.1, "cells": [26, 8]},
    "materials": {"m": {"type": "linear_elastic", "E": 1e4, "nu": 0.2, "density": 1.0}},
    "bodies": [{"name": "block", "shape": "rectangle", "material": "m", "lower": [0.0, 0.0], "upper": [2.0, 0.4]}],
    "boundary": [{"name": "floor", "type": "fixed", "lower": [-0.3, 0.0], "upper": [2.3, 0.0]},
                 {"name": "side", "type": "roller_x", "lower": [2.3, 0.0], "upper": [2.3, 0.8]}],
    "loads": {"gravity": [0.0, -9.81],
              "forces": [{"name": "push", "lower": [0.0, 0.3], "upper": [0.1, 0.4], "force": [2.0, 0.0]}]},
    "solver": {"end_time": 1.0},
    "parallel": {"axis": "x"},
    "output": {"reactions": True,
               "section": [{"name": "a", "segment": [[0.7, 0.0], [0.7, 0.5]]},
                           {"name": "b", "segment": [[1.45, 0.0], [1.45, 0.5]]}]},
}


def _histories(c):
    s = build_solver(parse_scene(SCENE, "block.toml"), c)
    rec = StructuralRecorder(s)
    rows = []
    for _ in range(12):
        for _ in range(25):
            s.step()
        sec, rea = rec.sample()
        rows.append(np.concatenate([sec.ravel(), rea.ravel()]))
    return np.array(rows), s


needs_ranks = pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")


@needs_ranks
def test_reactions_and_sections_do_not_depend_on_rank_count():
    par, solver = _histories(comm)
    assert solver.effect("reactions").names == ["floor", "side"]
    ok, message = True, ""
    if comm.rank == 0:
        ref, _ = _histories(MPI.COMM_SELF)
        scale = np.maximum(np.abs(ref).max(axis=0), 1e-300)
        err = (np.abs(par - ref) / scale).max()
        ok, message = err <= RTOL, f"relative difference {err:.3g}"
        # and the reaction is real: the floor carries the weight (and inertia) within reason
        weight = 9.81 * 2.0 * 0.4
        ok = ok and 0.5 * weight < ref[-1, 7] < 1.5 * weight
    assert comm.allreduce(bool(ok), op=MPI.LAND), message


if __name__ == "__main__":
    test_reactions_and_sections_do_not_depend_on_rank_count()
    print("ok")
