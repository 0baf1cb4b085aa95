"""Open MPI settings pmpm chooses where the user has not set them, before MPI starts.

Open MPI's ranks wait for each other by polling, holding their core. On a machine with other
work, the core a waiting rank holds is one its late neighbour (or whatever delays it) could
use, so two ranks coupled every few hundred microseconds can run slower than one (issue 24,
docs/performance.md "Two ranks on a loaded machine"). pmpm's own exchanges wait without
holding the core (decomposition/waiting.py); for the MPI calls pmpm does not wait on itself
(collective I/O, broadcasts, barriers) it asks Open MPI to yield the processor while idle:
``OMPI_MCA_mpi_yield_when_idle=1`` (Debian's Open MPI 4.1 honours it: ``sched_yield`` in its
progress loop when nothing arrived; it is the value Open MPI itself picks when it knows a node
is oversubscribed).

The settings go into this process's environment when pmpm is imported, which is before MPI is
initialised in pmpm's entry points (the ``pmpm`` command, ``python -m pmpm``, the API, the
benchmarks); MPI reads them at initialisation. A value already in the environment (the user's
own, or one ``mpirun -x`` or ``--mca`` passed) is never replaced. A program that initialises MPI
itself before it imports pmpm keeps Open MPI's defaults.
"""
import os
import sys

__all__ = ["MPI_DEFAULTS", "choose_mpi_defaults"]

#: environment variable -> value pmpm sets when the variable is not set
MPI_DEFAULTS = {"OMPI_MCA_mpi_yield_when_idle": "1"}


def choose_mpi_defaults(environ=None):
    """Set every ``MPI_DEFAULTS`` variable that ``environ`` (default ``os.environ``) lacks,
    unless MPI is already initialised in this process. Returns {variable: value} of what it set."""
    environ = os.environ if environ is None else environ
    if "mpi4py.MPI" in sys.modules:  # too late: MPI has read its settings
        return {}
    chosen = {k: v for k, v in MPI_DEFAULTS.items() if k not in environ}
    environ.update(chosen)
    return chosen
