"""Ductile fracture on several ranks (pmpm.physics.materials.fracture): the bar of
tests/unit/test_fracture_bar.py, decomposed into slabs along its length (the longer axis), so
the weak band where it fractures and the damage, crack and effective-stress fields migrate and
the first-fracture record is reduced over the ranks. The fracture energy, the energies' balance,
the damage field and the first fracture time agree with the serial run to a relative 1e-10
(the halo sums add in another order: 1e-16 relative per step, as in tests/mpi/test_same_answer.py,
grown over the run's 3,400 steps; measured on 2 ranks: 3e-16 for the fracture energy). A field
that did not migrate with its particle, or a rank's first fracture left out, is an order-one
difference.

Run under ``mpirun -n K python -m pytest tests/mpi/test_fracture_mpi.py`` (or as a script).
With a reaction recorded, the structural tables' failed points per body (summed over the ranks
in the recorder's one reduction) equal the serial counts.
The nonlocal criterion (pmpm.physics.fracture_nonlocal): the round-notched specimen of
studies/fracture_specimen.py at 10/3 mm with a characteristic length of 4 mm, on several ranks
(slabs along x: on 2 ranks the slab boundary crosses the notches, at x = 53 mm), gives the serial
first fracture time, fracture energy and damage field to 1e-10: the averages' passes sum their
halos like the transfer's, so a pass whose halo sum were left out (each rank's partial nodal
sums) changes the averages at the slab boundary by O(1) and the failures with them.
Planted bug: the passes' halo sum left out (fracture_nonlocal.NonlocalFracture._smooth) -> on
2 ranks the fracture work differs from the serial run's by 10%: fails.
Planted bug: FractureRecord.summary without its allgather (each rank its own first fractures)
-> on 2 ranks rank 0 does not hold the weak band and the run's summary misses it: fails.
"""
import os
import sys

import numpy as np
from mpi4py import MPI

from pmpm.api import run
from studies import fracture_specimen as study

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "unit"))
from test_fracture_bar import bar_scene  # noqa: E402

comm = MPI.COMM_WORLD
RTOL = 1e-10


def _run(c):
    sc = bar_scene(20)
    sc["output"]["fields"] = ["x", "damage"]
    sc["boundary"][0]["reaction"] = True   # structural tables: each body's failed points, reduced
    r = run(sc, dataframes=False, comm=c)
    if c.Get_rank() != 0:
        return None
    e = r.energies
    failed = np.concatenate([np.asarray(r.fractures[b]["failed"]) for b in sorted(r.fractures)])
    return {"fracture_work": np.asarray(e["fracture_work"]), "numerical_loss": np.asarray(e["numerical_loss"]),
            "damage": np.asarray(r.frames["damage"][-1]), "first": np.array([r.summary["first_fracture"]["weak"]]),
            "failed": failed}


def test_fracture_on_several_ranks_gives_the_serial_answer():
    par = _run(comm)
    ok, report = True, ""
    if comm.rank == 0:
        ref = _run(MPI.COMM_SELF)
        # the failed points per body (the structural tables' sum over the ranks): the same counts
        if par["failed"].shape != ref["failed"].shape or not np.array_equal(par["failed"], ref["failed"]):
            ok, report = False, report + " failed points per body differ"
        for k in ("fracture_work", "damage", "first"):
            err = np.abs(par[k] - ref[k]).max() / max(np.abs(ref[k]).max(), 1e-300)
            if not err <= RTOL:
                ok, report = False, report + f" {k}: relative difference {err:.3g}"
        # the loss is a small difference of large terms: compared to the external work's scale
        if not np.abs(par["numerical_loss"] - ref["numerical_loss"]).max() <= 1e-10 * 5.0:
            ok, report = False, report + " numerical_loss differs"
    ok = comm.allreduce(bool(ok), op=MPI.LAND)
    assert ok, report


def _run_specimen(c):
    sp = dict(study.fe_module().SPECIMEN, characteristic_length=0.004)
    r = run(study.scene(0.1 / 30, 1.8e-3, sp), dataframes=False, comm=c)
    if c.Get_rank() != 0:
        return None
    return {"fracture_work": np.asarray(r.energies["fracture_work"]), "damage": np.asarray(r.frames["damage"][-1]),
            "first": np.array([r.summary["first_fracture"]["plate"]])}


def test_nonlocal_criterion_on_several_ranks_gives_the_serial_answer():
    par = _run_specimen(comm)
    ok, report = True, ""
    if comm.rank == 0:
        ref = _run_specimen(MPI.COMM_SELF)
        for k in ("fracture_work", "damage", "first"):
            err = np.abs(par[k] - ref[k]).max() / max(np.abs(ref[k]).max(), 1e-300)
            if not err <= RTOL:
                ok, report = False, report + f" {k}: relative difference {err:.3g}"
        if not ref["fracture_work"][-1] > 0.0:
            ok, report = False, report + " no fracture energy: the crack did not start"
    ok = comm.allreduce(bool(ok), op=MPI.LAND)
    assert ok, report


if __name__ == "__main__":
    test_fracture_on_several_ranks_gives_the_serial_answer()
    test_nonlocal_criterion_on_several_ranks_gives_the_serial_answer()
    if comm.rank == 0:
        print("ok")
