"""F travels with its particle: a neo-Hookean block (which keeps F) sliding across the slab
boundaries gives, by particle id, the same F, stress and positions on K ranks as on one.

Run under ``mpirun -n K``. As in test_same_answer.py, halo sums are added in another order on K
ranks, so the comparison is to a relative 1e-10 (far above round-off growth over 60 steps, far
below any physical difference), not bitwise.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.scene.config import parse_scene

comm = MPI.COMM_WORLD
RTOL = 1e-10


def _scene():
    return parse_scene({
        "formulation": "plane_stress",
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.1, "cells": [40, 12]},
        "materials": {"m": {"type": "neo_hookean", "E": 1e5, "nu": 0.3, "density": 1000.0}},
        # moving right at 2 m/s and shearing: over 60 steps it crosses the slab boundaries
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.4, 0.3], "upper": [1.6, 0.9],
                    "velocity": ["2.0 + 1.0 * (y - 0.6)", "0.5 * (x - 1.0)"]}],
        "solver": {"end_time": 10.0, "sort_interval": 7},
        "parallel": {"axis": "x"},
    }, "slide.toml")


def _run(c, steps=60):
    s = build_solver(_scene(), c)
    start = set(s.particles["id"].tolist())
    for _ in range(steps):
        s.step()
    moved = len(set(s.particles["id"].tolist()) ^ start)  # ids that arrived or left this rank
    fields = {k: s.particles[k].copy() for k in ("id", "x", "stress", "F", "vol")}
    gathered = c.gather(fields, root=0)
    moved = c.allreduce(moved)
    if c.Get_rank() != 0:
        return None, moved
    cat = {k: np.concatenate([g[k] for g in gathered]) for k in fields}
    order = np.argsort(cat["id"])
    return {k: v[order] for k, v in cat.items()}, moved


@pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")
def test_F_migrates_with_its_particle():
    par, moved = _run(comm)
    ok = moved > 0
    if comm.rank == 0:
        ref, _ = _run(MPI.COMM_SELF)
        ok = ok and np.array_equal(par["id"], ref["id"])
        assert np.abs(ref["F"][:, :4] - [1, 0, 0, 1]).max() > 1e-2  # F really changed
        for k in ("x", "stress", "F", "vol"):
            err = np.abs(par[k] - ref[k]).max() / np.abs(ref[k]).max()
            if err > RTOL:
                print(f"{k}: relative difference {err:.3g} > {RTOL}")
                ok = False
    assert comm.allreduce(bool(ok), op=MPI.LAND)
