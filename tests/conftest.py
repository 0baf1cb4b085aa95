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
