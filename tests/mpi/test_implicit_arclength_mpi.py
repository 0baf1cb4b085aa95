"""Load-factor control of static analyses on several ranks (docs/implicit.md, "Load factor and
arc length"): displacement control and Crisfield's arc length give the same path on any rank
count.

Run under ``mpirun -n K`` (K = 2, 3: run_tests.sh): the beam-column of
tests/unit/test_implicit_arclength.py (pmpm.benchmarks.implicit_static.column_load_factor_scene:
elastic-perfectly-plastic J2, an axial load held, a lateral pattern scaled by the load factor)
with the slabs along x, so that the clamped base row, the load bands and the controlled
particle's stencil cross the slab boundaries; on COMM_WORLD and, on rank 0, alone. Compared:
the base's reactions (the load factor times the pattern, and the axial load), the controlled
and the other tracked particles' drifts, the load factor path of the run's summary. The unknowns
are numbered by the slabs and the solve is direct (MUMPS), so the runs differ by the order of
sums only; 1e-7 relative: Newton's residual tolerance (1e-8 of the force scale) carried through
the plastic path's steps, far above round-off and far below a physical difference (a ghost
node's share of the constraint vector or of the pattern counted twice moves lambda by a few %).

Shown to fail on a planted bug (restored): the constraint vector's halo sum left out
(DisplacementControl.weights without s.decomp.sum_halo): on 2 ranks the controlled particle's
stencil is cut by the slab boundary and its weights on the neighbour's nodes are lost, and the
displacement-control test fails on 2 ranks (base shear and lambda 2.9 % off, drifts 1.4 %).
"""
import numpy as np
import pytest
from mpi4py import MPI

import pmpm
from pmpm.benchmarks.implicit_static import column_load_factor_scene

comm = MPI.COMM_WORLD
RTOL = 1e-7


def _figures(r):
    out = {k: np.asarray(r.reactions["base"][k]) for k in ("Rx", "Ry", "M")}
    out.update({k: np.asarray(r.histories[k]["ux"]) for k in ("lateral", "axial", "low")})
    out["path"] = np.array([row[:2] for row in r.summary["load_factor_path"]])
    return out


def _compare(**kw):
    data = column_load_factor_scene(axis="x", axial=30e6, **kw)
    par = pmpm.run(data, comm=comm, dataframes=False)
    report = ""
    if comm.rank == 0:
        ref = pmpm.run(data, comm=MPI.COMM_SELF, dataframes=False)
        a, b = _figures(par), _figures(ref)
        for k in b:
            x, y = a[k][np.isfinite(a[k])], b[k][np.isfinite(b[k])]
            if x.shape != y.shape:
                report += f" {k}: {x.shape} vs {y.shape}"
                continue
            err = np.abs(x - y).max() / max(np.abs(y).max(), 1e-300)
            if not err <= RTOL:
                report += f" {k}: {err:.3g}"
        assert np.nanmax(b["Rx"]) < -1.5e6 or np.nanmin(b["Rx"]) < -1.5e6   # past first yield (~1 MN)
    return comm.bcast(report, root=0)


@pytest.mark.mpi(min_size=2)
def test_displacement_control_same_on_any_rank_count():
    report = _compare(control="displacement", steps=12, displacement=0.12)
    assert report == "", report


@pytest.mark.mpi(min_size=2)
def test_arc_length_same_on_any_rank_count():
    report = _compare(control="arc_length", steps=40, increment=0.5, stop_drift=0.15)
    assert report == "", report
