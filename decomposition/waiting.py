"""Waiting for messages without holding the core: spin briefly, then sleep in short naps.

Open MPI waits by polling: a rank that waits for a late neighbour keeps its core busy the whole
time. On a machine with other work (a workstation's background jobs, an oversubscribed node)
that is the worst choice: the core the waiting rank holds is one the late rank, or the other
work that delays it, could use, and every wait for a descheduled rank lasts a full time slice
of the scheduler. :func:`wait_all` completes a set of requests by testing them in a loop: it
spins for ``SPIN_SECONDS`` (a neighbour that is on time answers within that, and spinning is
the fastest way to notice), then sleeps in naps of ``NAP_MIN_SECONDS`` growing to
``NAP_MAX_SECONDS``, which hand the core to whatever else is runnable and cost a few
microseconds of CPU each.

Sleeping needs a fine timer: Linux lets a sleep overrun by the thread's timer slack (50 us by
default, which would make the shortest nap ~65 us on the machine these figures come from); the
first wait sets this thread's slack to 1 us (``prctl(PR_SET_TIMERSLACK)``), after which a 10 us
nap takes ~25 us.

The policy is the module's ``POLICY`` (``"nap"``, or ``"spin"``: test without ever sleeping,
as Open MPI's own wait does); the environment variable ``PMPM_MPI_WAIT`` chooses it at start.
"""

from __future__ import annotations

import os
import time

from mpi4py import MPI

__all__ = ["wait_all", "POLICY", "SPIN_SECONDS", "NAP_MIN_SECONDS", "NAP_MAX_SECONDS"]

#: "nap" (spin, then sleep) or "spin" (never sleep)
POLICY = os.environ.get("PMPM_MPI_WAIT", "nap")
#: how long a wait spins before its first nap: a balanced neighbour's message arrives within this
#: (on an idle 2-core machine the main job's rendezvous often wait 50-300 us: 50 us made two ranks
#: 1.56x faster than one, 300 us 1.65-1.71x, and no slower under a background load; see
#: docs/performance.md, "The spin phase")
SPIN_SECONDS = 300e-6
#: the first nap, doubled after each one up to NAP_MAX_SECONDS (the latest a message is noticed)
NAP_MIN_SECONDS = 10e-6
NAP_MAX_SECONDS = 200e-6

_PR_SET_TIMERSLACK = 29
_slack_set = False


def _fine_timer():
    """Set this thread's timer slack to 1 us (Linux; elsewhere nothing happens)."""
    global _slack_set
    _slack_set = True
    try:
        import ctypes
        ctypes.CDLL(None).prctl(_PR_SET_TIMERSLACK, 1000, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def wait_all(requests, clock=time.perf_counter):
    """Complete every request of ``requests`` (a list of mpi4py requests), as
    ``MPI.Request.Waitall`` does, but without holding the core through a long wait."""
    if not requests or MPI.Request.Testall(requests):
        return
    deadline = clock() + SPIN_SECONDS
    while clock() < deadline or POLICY == "spin":
        if MPI.Request.Testall(requests):
            return
    if not _slack_set:
        _fine_timer()
    nap = NAP_MIN_SECONDS
    while not MPI.Request.Testall(requests):
        time.sleep(nap)
        nap = min(2.0 * nap, NAP_MAX_SECONDS)
