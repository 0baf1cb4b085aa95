"""A [[stop]] condition decides the same on every rank (pmpm.stop): 1 and K ranks stop at the
same step, with the same value.

Run under ``mpirun -n 2 --oversubscribe python -m pytest -q tests/mpi/test_stop_mpi.py``. The
free-falling block of tests/integration/test_stop.py, widened across the grid and cut in slabs
along x, so the tracked corner is owned by rank 0 while the other ranks hold the rest of the
block: only the owner sees the corner, and the stop must still end every rank's run at the same
step. Rank 0 also runs the scene alone (COMM_SELF) as the reference.
"""
import faulthandler
import os
import sys

import pytest
from mpi4py import MPI


sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "integration"))
from test_stop import SCENE  # noqa: E402  (the free-fall scene)

comm = MPI.COMM_WORLD
HANG_TIMEOUT = 300.0

WIDE = (SCENE.replace("cells = [8, 32]", "cells = [32, 32]")
        .replace("upper = [0.75, 3.5]", "upper = [3.75, 3.5]")
        + '\n[parallel]\naxis = "x"\n')


@pytest.fixture(autouse=True)
def hang_guard():
    faulthandler.dump_traceback_later(HANG_TIMEOUT, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def _run(data, on):
    from pmpm.runner import Run
    from pmpm.scene.config import parse_scene
    r = Run(parse_scene(data), on, write=False)
    summary = r.execute()
    owns = bool(r.solver.particles.n and (r.solver.particles["id"] == r.stop_check.tracker.ids[0]).any())
    return summary, owns, r.solver.particles.n


def test_every_rank_stops_at_the_step_of_the_serial_run():
    import tomllib
    data = tomllib.loads(WIDE)
    summary, owns, n = _run(data, comm)
    got = comm.allgather((summary["stopped"], owns, n))
    ok, message = True, ""
    if comm.rank == 0:
        ref = _run(data, MPI.COMM_SELF)[0]["stopped"]
        stops = [g[0] for g in got]
        ok = (ref is not None and all(st == stops[0] for st in stops)   # the same record everywhere
              and stops[0]["step"] == ref["step"] and stops[0]["time"] == ref["time"]
              # the corner falls freely on either rank count: the same value to rounding
              and abs(stops[0]["value"] - ref["value"]) <= 1e-12
              # the premise: one rank owns the corner, and another rank holds particles
              and sum(g[1] for g in got) == 1 and sum(g[2] > 0 for g in got) >= min(comm.size, 2))
        message = f"{comm.size} ranks: {got}; serial: {ref}"
    ok, message = comm.bcast((ok, message))
    assert ok, message
