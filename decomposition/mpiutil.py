"""Small MPI helpers: communicator default, abort-on-exception hook, abort helper.

A crash on one rank must never become a silent hang of the others (which would wait
forever in the next collective).  :func:`install_abort_hook` replaces
``sys.excepthook`` so that an uncaught exception on any rank prints its traceback once,
tagged with the rank, and then calls ``comm.Abort(1)``, which ends every rank (the
PyFR ``init_mpi`` pattern).  Call it once in the program's entry point, not in
library code or in tests.
"""

from __future__ import annotations

import logging
import sys
import traceback

from mpi4py import MPI

__all__ = ["get_comm", "install_abort_hook", "abort_all"]

logger = logging.getLogger(__name__)


def get_comm(comm=None):
    """Return ``comm``, or ``MPI.COMM_WORLD`` when it is None.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm, optional
        Communicator to use.

    Returns
    -------
    mpi4py.MPI.Comm
    """
    return MPI.COMM_WORLD if comm is None else comm


def _rank_tag(comm):
    """Return ``"[rank r/size]"`` for messages."""
    return f"[rank {comm.Get_rank()}/{comm.Get_size()}]"


def abort_all(comm, message, code=1):
    """Print ``message`` with the rank to stderr and abort every rank of ``comm``.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator whose processes are ended.
    message : str
        Reason, printed once by the calling rank.
    code : int, optional
        Exit code handed to ``MPI_Abort`` (default 1).
    """
    sys.stderr.write(f"{_rank_tag(comm)} aborting: {message}\n")
    sys.stderr.flush()
    comm.Abort(code)


class _AbortHook:
    """``sys.excepthook`` replacement: print the traceback once, then abort."""

    def __init__(self, comm, previous):
        self.comm = comm
        self.previous = previous
        self.fired = False

    def __call__(self, exc_type, exc, tb):
        if self.fired:
            return
        self.fired = True
        text = "".join(traceback.format_exception(exc_type, exc, tb))
        sys.stderr.write(f"{_rank_tag(self.comm)} uncaught exception, aborting all ranks:\n{text}")
        sys.stderr.flush()
        self.comm.Abort(1)


def install_abort_hook(comm=None):
    """Make any uncaught exception abort every rank instead of hanging the others.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm, optional
        Communicator to abort (default ``MPI.COMM_WORLD``).

    Returns
    -------
    callable
        The installed hook; its ``previous`` attribute is the replaced hook.
        Installing twice replaces the first hook rather than chaining it.
    """
    comm = get_comm(comm)
    previous = sys.excepthook
    if isinstance(previous, _AbortHook):
        previous = previous.previous
    hook = _AbortHook(comm, previous)
    sys.excepthook = hook
    logger.debug("installed MPI abort hook on %s", _rank_tag(comm))
    return hook
