"""Sudden column loss: the same answer on 1 and 3 ranks (issue 23, item 3).

Run under ``mpirun -n 3 --oversubscribe python -m pytest -q tests/hard/mpi``. The scene is
cases/hard/column_loss.toml shortened as in tests/unit/test_events.py (0.1 m cells, load ramped
over 10 ms, the middle column removed at 12 ms over 5 ms, 22 ms in all), with the grid split
into three slabs along x, so the removed column lies inside the middle slab and its neighbours
hold none of it (the removal is collective all the same). Rank 0 runs the serial reference on
COMM_SELF; compared as tests/hard/mpi/test_hard_same_answer.py does (1e-10 of each quantity's
largest value, every 5 steps), plus the removed energy and the particle count after the event.
"""
import faulthandler
import os
import sys

import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from hard_cases import gather_particles, polite_barrier, run_case  # noqa: E402

from pmpm.scene.config import load_scene

comm = MPI.COMM_WORLD
RTOL = 1e-10
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
SHORT = {"grid.cell_size": 0.1, "grid.cells": [132, 42], "loads.forces.0.time_function.duration": 0.01,
         "events.0.time": 0.012, "events.0.duration": 0.005, "solver.end_time": 0.022,
         "output.section": [], "parallel.axis": "x"}

pytestmark = pytest.mark.skipif(comm.size < 2, reason="needs mpirun -n 2 or more (written for 3)")


@pytest.fixture(autouse=True)
def _watchdog():
    faulthandler.dump_traceback_later(600, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def _relative(a, b):
    scale = max(float(np.abs(b).max()) if b.size else 0.0, 1e-300)
    return float(np.abs(a - b).max()) / scale if b.size else 0.0


def test_column_loss_same_answer_on_one_and_several_ranks():
    scene = load_scene(os.path.join(ROOT, "cases", "hard", "column_loss.toml"), overrides=SHORT)[0]
    par = run_case(scene, comm, sample_every=5)
    fields = gather_particles(par.solver)
    removed = comm.allreduce(par.solver.effects.energy("removed_energy"))
    problems = []
    if comm.rank == 0:
        try:
            ref = run_case(scene, MPI.COMM_SELF, sample_every=5)
            ref_fields = gather_particles(ref.solver)
            if par.error is not None or ref.error is not None:
                problems.append(f"stopped: parallel {par.error}, serial {ref.error}")
            elif not np.array_equal(fields["id"], ref_fields["id"]):
                problems.append("different particles remain")
            else:
                pairs = {k: (fields[k], ref_fields[k]) for k in ("x", "v", "stress")}
                pairs["energies"] = (par.energy, ref.energy)
                pairs["tracks"] = (par.tracks, ref.tracks)
                problems += [f"{k}: relative difference {e:.3g}" for k, e in
                             ((k, _relative(a, b)) for k, (a, b) in pairs.items()) if not e <= RTOL]
                if not abs(removed - ref.solver.effects.energy("removed_energy")) <= RTOL * abs(ref.solver.effects.energy("removed_energy")):
                    problems.append(f"removed energy {removed} vs {ref.solver.effects.energy('removed_energy')}")
                if len(fields["id"]) >= par.solver.n_total:
                    problems.append("no particle was removed")
        except Exception as exc:  # reported on every rank below
            problems.append(f"serial reference failed: {exc!r}")
    polite_barrier(comm)
    ok = comm.allreduce(not problems, op=MPI.LAND)
    assert ok, "; ".join(problems)
    assert par.ranks_used >= 2
