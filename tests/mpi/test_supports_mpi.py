"""Supports attached to a body on several ranks (pmpm.physics.supports): the same answer as one
rank when the held particles and their nodes are split between slabs.

Run under ``mpirun -n K``. The beam of tests/unit/test_supports.py, clamped inside the grid off
the node lines, decomposed into slabs of rows (``parallel.axis = "y"``) so that the slab
boundaries cut the clamped face: its held particles sit on two ranks and their stencils reach
the neighbours' ghost nodes. Positions, velocities, the tip's history, the energies and the
clamp's reaction agree with the serial run to a relative 1e-10. Where from: the halo sums add in
another order (a rounding difference of 1e-16 relative, as in tests/mpi/test_same_answer.py),
and the projection solves A lambda = r keeping pivots down to RANK_TOLERANCE = 1e-6 of A's
largest, which can amplify such a difference by up to 1e6 (measured on 2 ranks: 4e-14); a node
or row missing on one rank is an order-one difference.
"""
import dataclasses
import os
import sys

import numpy as np
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.io.tracking import Tracker

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "unit"))
from test_supports import _beam  # noqa: E402

comm = MPI.COMM_WORLD
RTOL = 1e-10


def _scene():
    scene = _beam(-0.75 - 0.125 / 4, h=0.125, end_time=0.15, interpolation="cpdi")
    scene = dataclasses.replace(scene, parallel=dataclasses.replace(scene.parallel, axis="y"),
                                boundaries=tuple(dataclasses.replace(b, reaction=True) for b in scene.boundaries))
    return scene


def _run(c):
    scene = _scene()
    s = build_solver(scene, c)
    s.effect("reactions").since = 0.0
    tr = Tracker(scene.output.track, s)
    hist, energy, reaction = [], [], []
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
        if s.step_count % 10 == 0:
            hist.append(tr.sample()[0])
            e = s.energies()
            energy.append([e["kinetic"], e["internal_work"], e["external_work"]])
            reaction.append(s.effect("reactions").take(s.t, s.decomp.allreduce_sum)[0])
    held = np.count_nonzero((s.particles["support"] >= 0).any(axis=1))
    fields = c.gather({k: s.particles[k] for k in ("id", "x", "v")}, root=0)
    holders = c.allgather(held)
    out = None
    if c.Get_rank() == 0:
        cat = {k: np.concatenate([f[k] for f in fields]) for k in ("id", "x", "v")}
        order = np.argsort(cat["id"])
        out = {k: v[order] for k, v in cat.items()}
        out.update(hist=np.array(hist), energy=np.array(energy), reaction=np.array(reaction))
    return out, holders


def test_held_face_split_between_ranks_gives_the_serial_answer():
    par, holders = _run(comm)
    ok, report = True, ""
    if comm.Get_size() > 1 and sum(h > 0 for h in holders) < 2:
        ok, report = False, f"the face is not split between ranks: {holders}"
    if comm.rank == 0:
        ref, _ = _run(MPI.COMM_SELF)
        for k in ("x", "v", "hist", "energy", "reaction"):
            err = np.abs(par[k] - ref[k]).max() / max(np.abs(ref[k]).max(), 1e-300)
            if not err <= RTOL:
                ok, report = False, report + f" {k}: relative difference {err:.3g}"
    ok = comm.allreduce(bool(ok), op=MPI.LAND)
    assert ok, report
