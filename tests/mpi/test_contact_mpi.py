"""Contact between bodies gives the same answer on any rank count (scene ``[contact]``).

Run under ``mpirun -n K``: each scene runs on COMM_WORLD and, on rank 0, serially on COMM_SELF;
particle positions, velocities and stresses (by particle id) and the energies must agree to a
relative 1e-10, as in tests/mpi/test_same_answer.py. The per-body nodal fields, the mass
gradients that give the contact normals included, go through the halo sums; a normal or an
approach test computed from an incomplete sum would change the answer far above that.
"""
import dataclasses
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.scene.config import load_scene, parse_scene

comm = MPI.COMM_WORLD
RTOL = 1e-10

needs_ranks = pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more")


def _disks():
    scene = load_scene("cases/disks_contact.toml")[0]
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, end_time=1.5))


def _slide(mu=0.3, theta=30.0):
    th = math.radians(theta)
    block = lambda name, lo, hi: {"name": name, "shape": "rectangle", "material": "m",
                                  "lower": lo, "upper": hi}
    return parse_scene({
        "particles_per_cell": 2, "formulation": "plane_strain",
        "grid": {"cell_size": 0.05, "cells": [28, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.3, "density": 1000.0}},
        "bodies": [block("slab", [0.0, 0.0], [1.4, 0.2]), block("block", [0.2, 0.2], [0.4, 0.3])],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [1.4, 0.1]}],
        "loads": {"gravity": [10.0 * math.sin(th), -10.0 * math.cos(th)]},
        "solver": {"end_time": 0.15, "cfl": 0.5},
        "contact": {"friction": mu},
    }, "slide.toml")


@pytest.fixture(scope="module", autouse=True)
def warm_kernels():
    """Rank 0 compiles the contact kernels into numba's cache first, so that the ranks do not
    race writing the same cache entries (what ``python -m pmpm.warmup`` does for the others)."""
    if comm.rank == 0:
        for scene in (_disks(), _slide()):
            s = build_solver(scene, MPI.COMM_SELF)
            s.step()
            s.step()
    comm.Barrier()


def _run(scene, c):
    s = build_solver(scene, c)
    energies = []
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
        if s.step_count % 10 == 0:
            e = s.energies()
            energies.append([e["kinetic"], e["internal_work"], e["external_work"]])
    fields = {k: s.particles[k] for k in ("id", "x", "v", "stress")}
    gathered = c.gather(fields, root=0)
    corrections = c.reduce(s.grid_fields.corrections, root=0)
    result = None
    if c.Get_rank() == 0:
        cat = {k: np.concatenate([g[k] for g in gathered]) for k in fields}
        order = np.argsort(cat["id"])
        result = {k: v[order] for k, v in cat.items()}
        result["energy"] = np.array(energies)
        result["steps"], result["corrections"] = s.step_count, corrections
    return result, s


def _compare(scene):
    par, solver = _run(scene, comm)
    ok = True
    if comm.rank == 0:
        ref, _ = _run(scene, MPI.COMM_SELF)
        ok = par["steps"] == ref["steps"] and np.array_equal(par["id"], ref["id"])
        ok = ok and ref["corrections"] > 0
        for k in ("x", "v", "stress", "energy"):
            scale = max(np.abs(ref[k]).max(), 1e-300)
            err = np.abs(par[k] - ref[k]).max() / scale
            if err > RTOL:
                print(f"{k}: relative difference {err:.3g} > {RTOL}")
                ok = False
    return comm.allreduce(bool(ok), op=MPI.LAND), solver


@needs_ranks
def test_contact_disks_same_with_a_slab_boundary_through_the_contact():
    """The contact zone lies on the diagonal at the domain centre, where the slab boundaries
    (balanced by particle count) cut through it during the impact."""
    ok, s = _compare(_disks())
    cuts = s.decomp.bounds[1:-1] * s.grid.h
    assert ok
    assert np.any((cuts > 0.3) & (cuts < 0.7))


@needs_ranks
def test_sliding_block_with_friction_same_on_any_rank_count():
    """A block sliding with friction on a slab held by fixed nodes: supports, gravity and the
    Coulomb correction at the interface, which the slab boundaries cut."""
    ok, s = _compare(_slide())
    assert ok
