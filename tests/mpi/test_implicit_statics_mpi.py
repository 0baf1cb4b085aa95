"""Implicit statics on several ranks (docs/implicit.md): displacement control gives the same
answer on any rank count, and an implicit run restarts on another rank count.

Run under ``mpirun -n K`` (K = 2, 3, 4: run_tests.sh): the pushed column (pmpm.benchmarks.implicit_static:
elastic-perfectly-plastic J2; slabs along x, so that the clamped base row and the pushed top
row cross the slab boundaries and their ghost nodes hold support forces too)
through its plastic mechanism on COMM_WORLD and, on rank 0, alone; the base and push reactions,
the cut's forces and the top's drift are compared. The unknowns are numbered by the slabs and
the default solve is direct (MUMPS), so the runs differ by the order of sums only: 1e-8
relative is Newton's residual tolerance (1e-8 of the force scale) on these small systems, far
above round-off and far below a physical difference (a ghost node's support force counted twice
doubles a reaction share).

Restart: rank 0 runs the first 6 of 12 steps alone and writes a checkpoint; every rank
continues from it on COMM_WORLD; the result equals the uninterrupted serial run's to the same
tolerance (the state of a static step is the particles' positions, stresses and plastic state,
and the pushover's profile depends on time only; the Newmark acceleration field is a particle
field, checkpointed with them).

Shown to fail on planted bugs (restored): the reactions' owned-node mask dropped in
Reactions._add_forces (ghost nodes counted by both ranks): test_pushover_same_on_any_rank_count
fails on 2 ranks (base 30 %, push 76 % off); the checkpoint's particle fields not restored
(runner's restore skipping its alltoallv: the restarted run starts from the undeformed state at
t = 0.5): test_restart_on_another_rank_count fails (shown with the test function called on one
process: every figure 50-70 % off).
"""
import os
import shutil
import tempfile

import numpy as np
import pytest
from mpi4py import MPI

import pmpm
from pmpm.benchmarks.implicit_static import column_pushover_scene
from pmpm.api import load_results
from pmpm.runner import Run

comm = MPI.COMM_WORLD
RTOL = 1e-8


def _curves(r):
    """The run's figures to compare (rank 0: the result is complete there)."""
    return {"base": np.asarray(r.reactions["base"]["Rx"]), "push": np.asarray(r.reactions["push"]["Rx"]),
            "moment": np.asarray(r.reactions["base"]["M"]), "cut": np.asarray(r.sections["base_cut"]["M"]),
            "drift": np.asarray(r.histories["top"]["ux"])}


def _differences(a, b):
    report = ""
    for k in b:
        x, y = a[k][np.isfinite(a[k])], b[k][np.isfinite(b[k])]
        if x.shape != y.shape:
            report += f" {k}: {x.shape} vs {y.shape}"
            continue
        err = np.abs(x - y).max() / max(np.abs(y).max(), 1e-300)
        if not err <= RTOL:
            report += f" {k}: {err:.3g}"
    return report


def _scene(**kw):
    return column_pushover_scene(displacement=0.2, steps=12, axis="x", **kw)


@pytest.mark.mpi(min_size=2)
def test_pushover_same_on_any_rank_count():
    par = pmpm.run(_scene(), comm=comm, dataframes=False)
    report = ""
    if comm.rank == 0:
        ref = pmpm.run(_scene(), comm=MPI.COMM_SELF, dataframes=False)
        report = _differences(_curves(par), _curves(ref))
        assert np.nanmax(np.abs(_curves(ref)["base"])) > 2e6   # past first yield (1.67 MN)
    report = comm.bcast(report, root=0)
    assert report == "", report


@pytest.mark.mpi(min_size=2)
def test_restart_on_another_rank_count():
    folder = comm.bcast(tempfile.mkdtemp(prefix="pmpm_implicit_restart_") if comm.rank == 0 else None, root=0)
    try:
        path = error = None
        if comm.rank == 0:   # the first half alone, ending with a checkpoint
            try:
                half = Run(_scene(checkpoint_interval=0.5, folder=folder, max_steps=6), MPI.COMM_SELF, write=True)
                half.execute()
                path = half.path
            except Exception as exc:   # every rank fails with it rather than wait for rank 0
                error = f"{type(exc).__name__}: {exc}"
        path, error = comm.bcast((path, error), root=0)
        assert error is None, error
        run = Run(_scene(checkpoint_interval=0.5, folder=folder), comm, write=True, restart=path)
        assert abs(run.solver.t - 0.5) < 1e-12
        run.execute()
        report = ""
        if comm.rank == 0:
            ref = pmpm.run(_scene(), comm=MPI.COMM_SELF, dataframes=False)
            report = _differences(_curves(load_results(path, dataframes=False)), _curves(ref))
        report = comm.bcast(report, root=0)
        assert report == "", report
    finally:
        comm.Barrier()
        if comm.rank == 0:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    for test in (test_pushover_same_on_any_rank_count, test_restart_on_another_rank_count):
        test()
        if comm.rank == 0:
            print(test.__name__, "passed on", comm.Get_size(), "ranks")
