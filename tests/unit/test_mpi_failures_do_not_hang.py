"""tests/conftest.py under ``mpirun -n 2 python -m pytest``: a failure on one rank fails the test
on every rank and never becomes a hang (docs/testing.md, "MPI failures never hang").

Checked on a generated tree (the real conftest.py copied beside a small test file with planted
failures) run by ``mpirun -n 2`` in a subprocess with a timeout, as CI meets it. Each rank logs
the outcomes it reports to its own file (a hook appended to the copied conftest), so the test
sees both ranks, not only rank 0's terminal:

* with ``-x``, a test that fails on rank 1 only fails on both ranks and both stop there: the
  next test, whose collective would have hung the rank that went on, is never started;
* without ``-x``, both ranks go on after that failure; a test that fails on rank 0 before a
  collective that rank 1 then blocks in ends in an abort of every rank within
  ``PMPM_MPI_AGREE_TIMEOUT`` (set to 3 s here) instead of a hang, rank 0's failure printed;
* a deadlock that no failure announces (the ranks in different collectives, as a rank-local
  decision to destroy a PETSc solver once did) ends within ``PMPM_MPI_TEST_TIMEOUT`` (set to
  5 s here) with the hung test's Python stack printed.
"""
import os
import pathlib
import shutil
import subprocess
import sys
import time

CONFTEST = pathlib.Path(__file__).resolve().parents[1] / "conftest.py"

PLANTED = '''
from mpi4py import MPI

comm = MPI.COMM_WORLD


def test_a_fails_on_rank_1_only():
    assert comm.rank != 1, "planted failure on rank 1"


def test_b_collective():
    # a rank that stopped after test_a would leave the other one blocked here
    assert comm.allreduce(1) == comm.size


def test_c_fails_on_rank_0_before_a_collective():
    assert comm.rank != 0, "planted failure on rank 0"
    comm.allreduce(1)  # rank 1 blocks here: rank 0 never comes


def test_d_after_the_abort():
    pass
'''

DEADLOCK = '''
from mpi4py import MPI

comm = MPI.COMM_WORLD


def test_ranks_in_different_collectives():
    if comm.rank == 0:
        comm.allreduce(1)
    else:
        comm.bcast(1, root=1)
'''

#: each rank writes "nodeid when outcome" lines to outcomes_<rank>.txt
LOG_HOOK = '''

def pytest_runtest_logreport(report):
    with open(f"outcomes_{_mpi_rank()}.txt", "a") as f:
        f.write(f"{report.nodeid.split('::')[-1]} {report.when} {report.outcome}\\n")
'''

#: the whole run must end well within this (a hang is stopped by the timeout and fails the test)
TIMEOUT_S = 60


def _env(agree_timeout, test_timeout=0):
    # a clean environment: no MPI variables of a parent that may itself be an MPI process
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_COMM", "PMIX", "PMI_", "OMPI_MCA_orte"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               PMPM_MPI_AGREE_TIMEOUT=str(agree_timeout), PMPM_MPI_TEST_TIMEOUT=str(test_timeout),
               PYTHONDONTWRITEBYTECODE="1")
    env.pop("PMPM_REQUIRE_TIERS", None)
    return env


def _run(tmp_path, *pytest_args, planted=PLANTED, test_timeout=0):
    tree = tmp_path / "tree"
    tree.mkdir(exist_ok=True)
    for f in tree.glob("outcomes_*.txt"):
        f.unlink()
    shutil.copy(CONFTEST, tree / "conftest.py")
    with open(tree / "conftest.py", "a") as f:
        f.write(LOG_HOOK)
    (tree / "test_planted.py").write_text(planted)
    cmd = ["mpirun", "-n", "2", "--oversubscribe", "--bind-to", "none", sys.executable, "-m", "pytest",
           "-q", "-p", "no:cacheprovider", "-o", "addopts=", "--rootdir", str(tree), *pytest_args, "test_planted.py"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=tree, env=_env(3, test_timeout), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          text=True, timeout=TIMEOUT_S)
    seconds = time.monotonic() - t0
    outcomes = {}
    for rank in (0, 1):
        path = tree / f"outcomes_{rank}.txt"
        lines = path.read_text().split("\n") if path.exists() else []
        outcomes[rank] = {(w[0], w[1]): w[2] for w in (ln.split() for ln in lines if ln)}
    return proc, seconds, outcomes


def test_with_x_a_failure_on_one_rank_stops_every_rank(tmp_path):
    proc, seconds, outcomes = _run(tmp_path, "-x")
    for rank in (0, 1):
        calls = {name: out for (name, when), out in outcomes[rank].items() if when == "call"}
        # test_a failed on both ranks (rank 0 had passed it), and nothing after it started
        assert calls == {"test_a_fails_on_rank_1_only": "failed"}, (rank, outcomes, proc.stdout)
    assert proc.returncode != 0
    # rank 0's report names the rank that failed and shows its message
    assert "failed on rank(s) [1] of 2" in proc.stdout and "planted failure on rank 1" in proc.stdout, proc.stdout
    # two interpreter start-ups and one collection: far below a hang (the timeout above)
    assert seconds < 40, seconds


def test_a_failure_before_a_collective_aborts_instead_of_hanging(tmp_path):
    proc, seconds, outcomes = _run(tmp_path)
    for rank in (0, 1):
        calls = {name: out for (name, when), out in outcomes[rank].items() if when == "call"}
        # without -x both ranks go on after test_a, and test_b's collective completes
        assert calls.get("test_a_fails_on_rank_1_only") == "failed", (rank, outcomes, proc.stdout)
        assert calls.get("test_b_collective") == "passed", (rank, outcomes, proc.stdout)
        # test_c aborted the run: no rank reports it, or anything after it
        assert "test_d_after_the_abort" not in calls, (rank, outcomes, proc.stdout)
    assert proc.returncode != 0
    assert "planted failure on rank 0" in proc.stdout and "Aborting every rank" in proc.stdout, proc.stdout
    # PMPM_MPI_AGREE_TIMEOUT is 3 s: the abort comes 3 s after the failure, not after a CI timeout
    assert seconds < 40, seconds


def test_a_deadlock_is_stopped_with_the_stack_of_the_hung_test(tmp_path):
    # rank 0 in an allreduce, rank 1 in a bcast: neither fails, both wait for ever
    proc, seconds, outcomes = _run(tmp_path, planted=DEADLOCK, test_timeout=5)
    assert proc.returncode != 0
    assert "Timeout" in proc.stdout and "test_ranks_in_different_collectives" in proc.stdout, proc.stdout
    # 5 + 10 s after the test started, not the subprocess timeout (60 s) nor CI's 90 minutes
    assert seconds < 40, seconds
