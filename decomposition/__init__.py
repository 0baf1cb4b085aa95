"""Domain decomposition for pmpm: slabs of a 2-D node lattice over MPI.

This package knows a communicator, a node lattice, one split axis and the arrays it
is handed; it knows nothing of the physics.  The serial run is the 1-rank case of
the same code: every exchange becomes a no-op.

- :mod:`decomposition.slab`: pure slab rules (:func:`block_range`,
  :func:`balanced_bounds`, :func:`max_ranks`).
- :mod:`decomposition.decomp`: :class:`SlabDecomposition` (halo ``accumulate`` /
  ``fill``, neighbour ``migrate``, ``rebalance``, reductions, traffic counters).
- :mod:`decomposition.exchange`: :func:`alltoallv_fields`, the bulk any-to-any
  move of row-indexed arrays (one Alltoall of counts, one Alltoallv of packed rows).
- :mod:`decomposition.mpiutil`: ``get_comm``, ``install_abort_hook``, ``abort_all``.
- :mod:`decomposition.waiting`: :func:`wait_all`, completing requests without holding the
  core through a long wait (spin briefly, then sleep in short naps).
"""

import logging

from .decomp import PendingReduction, SlabDecomposition
from .exchange import alltoallv_fields
from .mpiutil import abort_all, get_comm, install_abort_hook
from .slab import balanced_bounds, block_range, max_ranks
from .waiting import wait_all

__all__ = [
    "SlabDecomposition",
    "PendingReduction",
    "wait_all",
    "alltoallv_fields",
    "block_range",
    "balanced_bounds",
    "max_ranks",
    "get_comm",
    "install_abort_hook",
    "abort_all",
]

logger = logging.getLogger(__name__)
