"""Shared pytest set-up.

Under ``mpirun -n K python -m pytest`` every rank runs the same tests; only rank 0 reports, so
the log holds one summary instead of K interleaved ones. The MPI tests combine their assertions
over all ranks, so a failure on any rank fails on rank 0 too.
"""
import os

import pytest


def _mpi_rank():
    for var in ("OMPI_COMM_WORLD_RANK", "PMI_RANK"):
        if var in os.environ:
            return int(os.environ[var])
    return 0


@pytest.hookimpl(trylast=True)
def pytest_configure(config):
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


#: test folders that are tiers CI must run (each test in them is marked ``required_tier``)
REQUIRED_TIER_DIRS = {"mpi": "mpi", "slurm": "slurm", "paraview": "paraview"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        parts = item.path.parts
        for folder, tier in REQUIRED_TIER_DIRS.items():
            if folder in parts[parts.index("tests") + 1:] if "tests" in parts else ():
                item.add_marker(pytest.mark.required_tier(tier))
