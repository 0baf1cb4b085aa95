"""The implicit integrator gives the same answer on any rank count (docs/implicit.md).

Run under ``mpirun -n K`` (run_tests.sh: 2, 3 and 4 ranks): each test runs a scene on
COMM_WORLD and, on rank 0, the same scene serially, and compares the particles by id. The
unknowns are numbered by the slabs and the ghost rows summed by PETSc, and the default linear
solve is direct (MUMPS) on any rank count, so the answers differ only by the order of sums:
the tolerance 1e-9 relative is Newton's residual tolerance (1e-8 of the force scale) times the
condition of these small systems' solution, far above round-off and far below any physical
difference (a ghost row lost, or a node numbered twice, moves the answer by O(1)).

Shown to fail on a planted bug (restored): the owners' numbers not filled into the ghost
columns (``decomp.fill`` skipped in StepDofs): the matrix couples the wrong unknowns across a
slab boundary and both tests fail on 2 ranks (Newton diverges).
Also runs as a script: ``mpirun -n 3 python tests/mpi/test_implicit_mpi.py``.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.benchmarks.implicit import bar_scene, cantilever_scene
from pmpm.build import build_solver

comm = MPI.COMM_WORLD
RTOL = 1e-9


def _run(scene, c):
    s = build_solver(scene, c)
    start = {}   # (all ranks': a particle may change rank during the run)
    for part in c.allgather(dict(zip(s.particles["id"].tolist(), s.particles["x"].copy()))):
        start.update(part)
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
    fields = {k: s.particles[k] for k in ("id", "x", "v", "stress")}
    fields["u"] = s.particles["x"] - np.array([start[i] for i in s.particles["id"].tolist()]).reshape(-1, 2)
    gathered = c.gather(fields, root=0)
    if c.Get_rank() != 0:
        return None, s
    cat = {k: np.concatenate([g[k] for g in gathered]) for k in fields}
    order = np.argsort(cat["id"])
    return {k: v[order] for k, v in cat.items()}, s


def _compare(scene):
    par, s = _run(scene, comm)
    ok, report = True, ""
    if comm.rank == 0:
        ref, _ = _run(scene, MPI.COMM_SELF)
        ok = np.array_equal(par["id"], ref["id"])
        for k in ("u", "v", "stress"):   # displacements, not positions: their differences count
            a, b = par[k], ref[k]
            err = np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)
            if not err <= RTOL:
                ok = False
                report += f" {k}: {err:.3g}"
    return comm.allreduce(bool(ok), op=MPI.LAND), comm.bcast(report, root=0), s


@pytest.mark.mpi(min_size=2)
def test_bar_dynamics_same_on_any_rank_count():
    """The bar in free vibration, 6 implicit steps of 50 explicit ones (slabs along the bar)."""
    ok, report, s = _compare(bar_scene(1.25, 7.5, v0=0.01))
    assert ok, report
    assert s.decomp.size == comm.Get_size()


@pytest.mark.mpi(min_size=2)
def test_static_cantilever_same_on_any_rank_count():
    """The cantilever under 100 g, one static step: geometric nonlinearity, 4-5 Newton
    iterations, the clamped slab on rank 0 only."""
    ok, report, s = _compare(cantilever_scene(gravity=981.0))
    assert ok, report
    assert s.scheme.stats["newton_iterations"] >= 3


@pytest.mark.mpi(min_size=2)
def test_krylov_newton_same_on_any_rank_count():
    """newton = "krylov" (GMRES on a kept factorisation, pmpm/core/implicit/kept_factorisation.py)
    on the bar swinging 0.8 m at its free end, more than a cell: the active nodes change from
    step to step, so the kept factorisation's rows are mapped onto new unknowns on every rank
    (its rank-local map) and, where the GMRES stalls, refactored (a decision every rank must
    take together). The GMRES's tolerance tightened to 1e-12 and Newton's to 1e-10 so that the
    rank counts' answers differ by round-off, within RTOL. Written against two bugs it caught
    on 2 ranks while the mode was built (fixed): the current diagonal fetched (a collective
    PETSc call) only on the ranks whose rows had changed (PETSc error "Global size overflow",
    then a hang), and the identity map applying the kept factorisation to the current
    operator's vectors on a rank whose rows had not changed while another's had (PETSc error
    "Nonconforming object sizes"). A wrong map on one rank costs GMRES iterations, never the
    answer: that is tests/unit/test_implicit_kept_factorisation.py's to catch."""
    implicit = {"newton": "krylov", "krylov_tolerance": 1e-12, "residual_tolerance": 1e-10}
    ok, report, s = _compare(bar_scene(1.25, 7.5, v0=0.5, implicit=implicit))
    assert ok, report
    assert s.scheme.stats["remapped_tangents"] >= 1       # the unknowns did change
    assert s.scheme.stats["factorisations"] < s.scheme.stats["newton_iterations"]


@pytest.mark.mpi(min_size=2)
@pytest.mark.parametrize("v0", [0.01, 0.5])
def test_accelerated_newton_same_on_any_rank_count(v0):
    """newton = "accelerated" (modified Newton with Anderson mixing on a kept factorisation,
    pmpm/core/implicit/accelerated.py) on the bar in free vibration: at v0 = 0.01 m/s its rows
    stay the same, so the steps start on the kept factorisation rescaled to the current
    diagonal (computed on every rank together, a halo sum) without a new tangent; at 0.5 m/s
    (0.8 m of swing, more than a cell) the rows change and the steps refactor (a collective
    decision). The least squares of the mixing use global sums, so every rank count takes the
    same corrections; Newton's tolerance at 1e-10 so that the answers differ by round-off,
    within RTOL, and the iteration counts are the one-rank run's. Fails with the Gram matrix left
    rank-local (other iterations on 2 ranks) and with the rows' comparison taken per rank (a hang: the watchdog of
    tests/conftest.py)."""
    implicit = {"newton": "accelerated", "residual_tolerance": 1e-10}
    scene = bar_scene(1.25, 7.5, v0=v0, implicit=implicit)
    ok, report, s = _compare(scene)
    assert ok, report
    _, alone = _run(scene, MPI.COMM_SELF)   # the same iterations, not only the same answer
    for key in ("newton_iterations", "tangents", "refits"):
        assert s.scheme.stats.get(key) == alone.scheme.stats.get(key), (key, s.scheme.stats, alone.scheme.stats)
    if v0 < 0.1:
        assert s.scheme.stats["refits"] >= 1                          # steps on the kept factorisation
        assert s.scheme.stats["tangents"] < s.scheme.stats["steps"]


if __name__ == "__main__":
    for test in (test_bar_dynamics_same_on_any_rank_count, test_static_cantilever_same_on_any_rank_count,
                 test_krylov_newton_same_on_any_rank_count):
        test()
        if comm.rank == 0:
            print(test.__name__, "passed on", comm.Get_size(), "ranks")
