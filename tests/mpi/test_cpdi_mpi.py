"""CPDI on slabs: a sheared neo-Hookean block sliding across the slab boundaries gives, by
particle id, the same positions, F and stress on K ranks as on one (the corners' supports stay
inside the ghost width), and a particle stretched across a slab boundary beyond the ghost
width stops every rank with one message naming it.

Run under ``mpirun -n K``; the tolerance is that of test_same_answer.py (halo sums in another
order: a relative 1e-10, far above round-off growth over the steps, far below any physical
difference)."""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core.shape import CPDI_REACH
from pmpm.build import build_solver
from pmpm.errors import UnstableRunError
from pmpm.scene.config import parse_scene

comm = MPI.COMM_WORLD
RTOL = 1e-10


def _scene(shape="cubic"):
    return parse_scene({
        "formulation": "plane_stress",
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.1, "cells": [40, 12]},
        "materials": {"m": {"type": "neo_hookean", "E": 1e5, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.4, 0.3], "upper": [1.6, 0.9],
                    "velocity": ["2.0 + 1.0 * (y - 0.6)", "0.5 * (x - 1.0)"]}],
        "solver": {"end_time": 10.0, "sort_interval": 7, "interpolation": "cpdi", "shape_function": shape},
        "parallel": {"axis": "x"},
    }, "slide.toml")


def _gather(c, s):
    fields = {k: s.particles[k].copy() for k in ("id", "x", "stress", "F")}
    gathered = c.gather(fields, root=0)
    if c.Get_rank() != 0:
        return None
    cat = {k: np.concatenate([g[k] for g in gathered]) for k in fields}
    order = np.argsort(cat["id"])
    return {k: v[order] for k, v in cat.items()}


@pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")
@pytest.mark.parametrize("shape", ["linear", "cubic"])
def test_cpdi_gives_the_same_answer_on_k_ranks_as_on_one(shape):
    runs = []
    for c in (MPI.COMM_SELF, comm):
        s = build_solver(_scene(shape), c)
        start = set(s.particles["id"].tolist())
        for _ in range(60):
            s.step()
        moved = len(set(s.particles["id"].tolist()) ^ start)  # ids that arrived or left this rank
        runs.append(_gather(c, s) if c is comm else (_gather(MPI.COMM_SELF, s) if comm.rank == 0 else None))
    assert comm.allreduce(moved) > 0          # the block crossed slab boundaries
    if comm.rank == 0:
        one, many = runs
        np.testing.assert_array_equal(one["id"], many["id"])
        for k in ("x", "F", "stress"):
            scale = np.abs(one[k]).max()
            np.testing.assert_allclose(many[k], one[k], rtol=0, atol=RTOL * scale)


@pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")
def test_a_domain_stretched_past_the_ghost_width_stops_every_rank_naming_the_particle():
    s = build_solver(_scene("linear"), comm)
    p = s.particles
    # rank 0's particle nearest its upper slab boundary, stretched along x by 3 cells more than
    # the reach the ghost width allows for
    target = -1
    if comm.rank == 0 and p.n:
        k = int(np.argmax(p["x"][:, 0]))
        p["F"][k, 0] = (CPDI_REACH + 3.0) / p["domain"][k, 0]
        target = int(p["id"][k])
    target = comm.bcast(target, root=0)
    with pytest.raises(UnstableRunError) as err:
        s.step()
    assert f"particle id {target} " in str(err.value)
    assert "beyond its slab's ghost nodes" in str(err.value) and "t = " in str(err.value)
    messages = comm.allgather(str(err.value))
    assert len(set(messages)) == 1          # every rank stops with the same one message
