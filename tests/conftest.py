"""Shared pytest set-up.

Under ``mpirun -n K python -m pytest`` every rank runs the same tests; only rank 0 reports, so
the log holds one summary instead of K interleaved ones.

The ranks agree on every test's outcome (:func:`_agree`, after each phase: set-up, call,
tear-down): a test that fails on one rank fails on every rank, naming the rank(s) where it
failed and their message, so rank 0 reports a failure on any rank and ``-x`` stops every rank at
the same test (before, the rank that failed stopped and the others hung in the next test's
collective until killed). A rank that failed waits at most ``PMPM_MPI_AGREE_TIMEOUT`` seconds
(default 60) for the others to finish the test; if they do not (they are blocked in a collective
of the test that the failed rank left), it prints its failure and aborts every rank, so a failure
never becomes a hang. docs/testing.md; tests/unit/test_mpi_failures_do_not_hang.py.
"""
import faulthandler
import math
import os
import signal
import sys
import time

import pytest


def _mpi_rank():
    for var in ("OMPI_COMM_WORLD_RANK", "PMI_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


def _mpi_size():
    for var in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE"):
        if var in os.environ:
            return int(os.environ[var])
    return 1


#: the communicator the ranks agree on outcomes with (a duplicate of COMM_WORLD, so that the
#: agreement can never match a collective of a test); None in a serial pytest
_AGREE = None
#: seconds a rank whose test failed waits for the others before aborting every rank
AGREE_TIMEOUT_S = float(os.environ.get("PMPM_MPI_AGREE_TIMEOUT", "60"))


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
    global _AGREE
    if _mpi_size() > 1:
        from mpi4py import MPI
        _AGREE = MPI.COMM_WORLD.Dup()
        _open_hang_report(config)
    if _mpi_rank() != 0:
        reporter = config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            config.pluginmanager.unregister(reporter)


#: set by .ci/run: a test marked ``required_tier`` that skips (Slurm that cannot be installed, a
#: real client that is missing, an MPI test run without ranks) fails instead, so CI can never
#: pass with a tier silently left out. Locally such tests still skip, with their reason.
REQUIRE_TIERS = os.environ.get("PMPM_REQUIRE_TIERS", "") not in ("", "0")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    marker = item.get_closest_marker("required_tier")
    if REQUIRE_TIERS and marker is not None and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        tier = marker.args[0] if marker.args else item.nodeid
        report.outcome = "failed"
        report.longrepr = (f"required tier '{tier}' skipped under PMPM_REQUIRE_TIERS (CI): {reason}")
    if _AGREE is not None:
        _agree(_AGREE, item, report)


def _status(report):
    """0 passed, 1 skipped (or an expected failure), 2 failed: the worst over the ranks wins."""
    return 2 if report.failed else 1 if report.skipped else 0


def _wait_for_the_others(comm, item, report, failed):
    """Block until every rank has finished this phase of the test; a rank whose test failed
    gives up after AGREE_TIMEOUT_S, prints its failure and aborts all ranks (the others are
    stuck in a collective of the test it left: waiting longer would be a hang)."""
    req = comm.Ibarrier()
    deadline = time.monotonic() + AGREE_TIMEOUT_S
    nap = 1e-4
    while not req.Test():
        if failed and time.monotonic() > deadline:
            sys.stderr.write(
                f"\n[rank {comm.rank}] {item.nodeid} ({report.when}) FAILED on this rank and the other "
                f"ranks did not finish it within {AGREE_TIMEOUT_S:g} s (PMPM_MPI_AGREE_TIMEOUT): they are "
                f"blocked in a collective this rank left. Aborting every rank.\n{report.longreprtext}\n")
            sys.stderr.flush()
            comm.Abort(1)
        time.sleep(nap)
        nap = min(2.0 * nap, 0.02)


def _agree(comm, item, report):
    """Make this phase's outcome the worst over all ranks (see the module docstring)."""
    mine = _status(report)
    _wait_for_the_others(comm, item, report, failed=mine == 2)
    text = report.longreprtext[-3000:] if mine else ""
    everyone = comm.allgather((mine, text))
    worst = max(s for s, _ in everyone)
    if worst <= mine:
        return
    ranks = [r for r, (s, _) in enumerate(everyone) if s == worst]
    first = everyone[ranks[0]][1]
    if worst == 2:
        report.outcome = "failed"
        report.longrepr = f"failed on rank(s) {ranks} of {comm.size} (rank {ranks[0]}'s report):\n{first}"
    elif report.when != "teardown":
        # a skip on another rank (a set-up that skipped there): skip here too, so every rank
        # runs the same phases and so the same collectives
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0, f"skipped on rank(s) {ranks}: {first}")


#: seconds one test may take under mpirun before every rank prints its Python stacks
#: (``PMPM_MPI_TEST_TIMEOUT``; 0 turns it off); ``MPI_KILL_AFTER_S`` later the ranks end (SIGALRM's
#: default action, which needs no interpreter: a rank blocked in a PETSc collective holds the
#: GIL) and mpirun stops the tier. A deadlock (ranks in different collectives) never fails by
#: itself: in CI it ran the 3-rank tier into the 90-minute limit with no word of which test
#: hung. The slowest MPI test (the portal on 3 ranks) took 522 s on this 2-core machine shared
#: with four other jobs (some 30 s on 2 ranks idle); 1200 s leaves room above that.
MPI_TEST_TIMEOUT_S = float(os.environ.get("PMPM_MPI_TEST_TIMEOUT", "1200"))
MPI_KILL_AFTER_S = 10


#: where a hung test's stacks go: the process's real stderr (pytest captures fd 2 while a test
#: runs, and a stack written there would be lost with the process)
_HANG_REPORT = None


def _open_hang_report(config):
    global _HANG_REPORT
    capman = config.pluginmanager.getplugin("capturemanager")
    if capman is not None:
        capman.suspend_global_capture(in_=False)
    try:
        _HANG_REPORT = os.fdopen(os.dup(2), "w")
    finally:
        if capman is not None:
            capman.resume_global_capture()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    armed = _HANG_REPORT is not None and MPI_TEST_TIMEOUT_S > 0 and \
        signal.getsignal(signal.SIGALRM) == signal.SIG_DFL
    if armed:
        faulthandler.dump_traceback_later(MPI_TEST_TIMEOUT_S, exit=False, file=_HANG_REPORT)
        signal.alarm(int(math.ceil(MPI_TEST_TIMEOUT_S)) + MPI_KILL_AFTER_S)
    try:
        yield
    finally:
        if armed:
            signal.alarm(0)
            faulthandler.cancel_dump_traceback_later()


#: test folders that are tiers CI must run (each test in them is marked ``required_tier``)
REQUIRED_TIER_DIRS = {"mpi": "mpi", "slurm": "slurm", "paraview": "paraview"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        parts = item.path.parts
        for folder, tier in REQUIRED_TIER_DIRS.items():
            if folder in parts[parts.index("tests") + 1:] if "tests" in parts else ():
                item.add_marker(pytest.mark.required_tier(tier))
