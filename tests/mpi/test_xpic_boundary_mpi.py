"""XPIC(3) with a moving boundary gives the same answer on any rank count (issue 38): the block of
tests/unit/test_transfers_blind.py, carried by a prescribed-velocity box of nodes on its left part
while an elastic wave runs into the free part, through the Python API (pmpm.run with ``comm``) on
every rank of COMM_WORLD, against the same scene run on rank 0 alone (COMM_SELF). The slab
boundaries cut the block (the grid's 30 columns split over the ranks), so each smoothing pass's
halo sum crosses them, and on 3 and 4 ranks one of them runs through the prescribed box.

Tolerance: 1e-10 of each quantity's scale (the sums differ across ranks only in their order).
Shown to fail on its bug: ``mutate.py --only xpic_smoothing_not_summed_across_ranks`` (the
smoothing pass's halo sum skipped) fails it on 2, 3 and 4 ranks."""
import os
import sys

import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), "unit"))
from test_transfers_blind import xpic_moving_boundary  # noqa: E402

import pmpm  # noqa: E402

comm = MPI.COMM_WORLD
RTOL = 1e-10


def _fields(res):
    return {"x": res.frames["x"][-1], "v": res.frames["v"][-1],
            "energy": np.column_stack([np.asarray(res.energies[k]) for k in ("kinetic", "internal_work",
                                                                             "external_work")]),
            "track": np.asarray(res.histories["probe"]["vx"])}


def test_xpic_with_a_moving_boundary_same_on_any_rank_count():
    scene = xpic_moving_boundary(end=0.03)
    scene["output"]["track"] = [{"name": "probe", "point": [0.85, 0.45]}]   # in the free part, beside the box
    par = pmpm.run(scene, comm=comm, dataframes=False)
    ok, why = True, ""
    if comm.rank == 0:
        ref = _fields(pmpm.run(scene, comm=MPI.COMM_SELF, dataframes=False))
        got = _fields(par)
        for k in ref:
            scale = max(np.abs(ref[k]).max(), 1e-300)
            err = np.abs(got[k] - ref[k]).max() / scale
            if not err <= RTOL:
                ok, why = False, f"{k}: relative difference {err:.3g} > {RTOL}"
                break
        # the probe moves: the wave from the carried part reached the free part
        if ok and not np.abs(ref["track"]).max() > 0.01:
            ok, why = False, "the probe in the free part never moved"
        if ok and comm.size > 1 and not par.summary["steps"] > 10:
            ok, why = False, "too few steps"
    ok, why = comm.bcast((ok, why), root=0)
    assert ok, why
