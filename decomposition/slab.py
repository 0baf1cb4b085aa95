"""The slab rule: pure functions that split node columns into contiguous ranges.

A node lattice is split along one axis into contiguous column ranges, one per rank,
described by ``bounds`` (length ``size + 1``): rank ``r`` owns node columns
``[bounds[r], bounds[r + 1])``.  :func:`block_range` is the even split (the
mpi4py-fft ``_blockdist`` rule); :func:`balanced_bounds` splits by a per-column
weight (particles per column) so each rank carries about the same work.  No MPI here.
"""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["block_range", "block_bounds", "balanced_bounds", "max_ranks", "check_bounds"]

logger = logging.getLogger(__name__)


def block_range(n, size, rank):
    """Return the even share of ``n`` items held by ``rank`` of ``size``.

    The first ``n % size`` ranks hold one item more than the others.

    Parameters
    ----------
    n : int
        Number of items (node columns).
    size : int
        Number of ranks.
    rank : int
        This rank, ``0 <= rank < size``.

    Returns
    -------
    count : int
        Items held by ``rank``.
    start : int
        Index of its first item.
    """
    q, r = divmod(n, size)
    count = q + (1 if r > rank else 0)
    start = q * rank + min(rank, r)
    return count, start


def block_bounds(n, size):
    """Return the :func:`block_range` split as bounds.

    Parameters
    ----------
    n : int
        Number of columns.
    size : int
        Number of ranks.

    Returns
    -------
    numpy.ndarray of int64, shape (size + 1,)
        ``bounds[r]`` is the first column of rank ``r``; ``bounds[-1] == n``.
    """
    starts = [block_range(n, size, r)[1] for r in range(size)]
    return np.array(starts + [n], dtype=np.int64)


def max_ranks(ncols, min_width):
    """Return the largest rank count for which every slab is ``min_width`` wide.

    Parameters
    ----------
    ncols : int
        Number of node columns.
    min_width : int
        Minimum slab width in columns (at least 1 is used).

    Returns
    -------
    int
    """
    return int(ncols) // max(int(min_width), 1)


def check_bounds(bounds, ncols, min_width):
    """Raise ValueError unless ``bounds`` is a valid split of ``ncols`` columns.

    Parameters
    ----------
    bounds : array_like of int, shape (size + 1,)
        Proposed split.
    ncols : int
        Number of node columns.
    min_width : int
        Minimum slab width (at least 1 is enforced).

    Returns
    -------
    numpy.ndarray of int64
        The bounds as an array.
    """
    bounds = np.asarray(bounds, dtype=np.int64).reshape(-1)
    size = len(bounds) - 1
    min_width = max(int(min_width), 1)
    if size < 1 or bounds[0] != 0 or bounds[-1] != ncols:
        raise ValueError(f"bounds must run from 0 to {ncols}; got {bounds.tolist()}")
    widths = np.diff(bounds)
    if widths.min() < min_width:
        narrow = np.flatnonzero(widths < min_width).tolist()
        raise ValueError(
            f"slabs of ranks {narrow} are narrower than {min_width} node columns "
            f"(widths {widths.tolist()}); {ncols} columns allow at most "
            f"{max_ranks(ncols, min_width)} ranks")
    return bounds


def balanced_bounds(column_weights, size, min_width):
    """Split columns into ``size`` contiguous parts of about equal total weight.

    Boundary ``k`` is the column where the prefix sum of the weights comes nearest
    to ``k * total / size``; boundaries are then pushed apart so every part is at
    least ``min_width`` columns wide.  Without that push every part weighs at most
    ``total / size + max(column_weights)``.  Zero total weight gives the even split.

    Parameters
    ----------
    column_weights : array_like, shape (ncols,)
        Non-negative weight of each column (e.g. particles per node column).
    size : int
        Number of parts (ranks).
    min_width : int
        Minimum part width in columns (at least 1 is used).

    Returns
    -------
    numpy.ndarray of int64, shape (size + 1,)
        ``bounds[0] == 0``, ``bounds[-1] == ncols``, increasing.

    Raises
    ------
    ValueError
        If ``size * min_width > ncols`` or a weight is negative.
    """
    w = np.asarray(column_weights, dtype=np.float64).reshape(-1)
    ncols, min_width = len(w), max(int(min_width), 1)
    if size * min_width > ncols:
        raise ValueError(f"{size} parts of at least {min_width} columns do not fit in {ncols} "
                         f"columns; at most {max_ranks(ncols, min_width)} ranks")
    if np.any(w < 0):
        raise ValueError("column weights must be non-negative")
    prefix = np.concatenate(([0.0], np.cumsum(w)))
    if prefix[-1] <= 0:
        return block_bounds(ncols, size)
    # Interior boundary nearest to each target prefix value
    targets = prefix[-1] * np.arange(1, size) / size
    hi = np.clip(np.searchsorted(prefix, targets, side="left"), 1, ncols)
    lo = hi - 1
    inner = np.where(targets - prefix[lo] <= prefix[hi] - targets, lo, hi)
    # Push apart: with s_k = b_k - k * min_width the widths hold iff s is
    # non-decreasing within [0, ncols - size * min_width]
    k = np.arange(1, size)
    slack = np.clip(inner - k * min_width, 0, ncols - size * min_width)
    inner = np.maximum.accumulate(slack) + k * min_width
    return np.concatenate(([0], inner, [ncols])).astype(np.int64)
