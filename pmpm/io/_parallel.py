"""Private helpers shared by the HDF5 results writer and the checkpoints.

Three things every parallel writer here needs:

- agreeing on errors before any collective call (:func:`check_all`), so a bad input
  on one rank raises on every rank instead of leaving the others waiting inside an
  HDF5 collective;
- putting particle rows into id order (:func:`to_id_blocks`): rows move with ONE
  :func:`decomposition.alltoallv_fields` to the rank that owns their id block, which
  then holds a contiguous, gap-filled block ready for one hyperslab write;
- a hyperslab write that a rank with nothing to write still takes part in
  (:func:`write_rows`), because h5py's high-level ``dset[a:a] = x`` returns early on
  an empty selection and the other ranks then hang in the collective write
  (h5py issue 965; Dedalus ``evaluator.py`` does the same low-level call).
"""

from __future__ import annotations

import json
import logging

import h5py
import numpy as np
from mpi4py import MPI

from decomposition import alltoallv_fields
from decomposition.slab import block_bounds

__all__ = [
    "check_all",
    "fill_value",
    "owner_bounds",
    "to_id_blocks",
    "validate_rows",
    "write_rows",
    "json_dumps",
    "mpio_available",
]

logger = logging.getLogger(__name__)


def mpio_available():
    """Return True if h5py is built against parallel HDF5 (driver ``"mpio"``).

    Returns
    -------
    bool
    """
    return bool(h5py.get_config().mpi)


def check_all(comm, ok, message, exc=ValueError):
    """Raise ``exc`` on every rank if ``ok`` is False on any rank (collective).

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator; every rank must call.
    ok : bool
        This rank's verdict.
    message : str
        This rank's reason when ``ok`` is False (ignored otherwise).
    exc : type, optional
        Exception class raised (default ``ValueError``).

    Raises
    ------
    exc
        With the messages of all failing ranks.
    """
    if comm.allreduce(bool(ok), op=MPI.LAND):
        return
    # Only reached when some rank failed, and then by every rank: safe to gather
    reasons = comm.allgather(None if ok else message)
    text = "; ".join(f"rank {r}: {m}" for r, m in enumerate(reasons) if m is not None)
    raise exc(text)


def fill_value(dtype):
    """Return the value that marks a missing particle for ``dtype``.

    Parameters
    ----------
    dtype : numpy.dtype
        Field element type.

    Returns
    -------
    scalar
        NaN for floating types, -1 for signed integers, 0 otherwise.
    """
    dtype = np.dtype(dtype)
    if dtype.kind in "fc":
        return dtype.type(np.nan)
    if dtype.kind == "i":
        return dtype.type(-1)
    return dtype.type(0)


def owner_bounds(n_total, size, gather=False):
    """Return the first id of each rank's id block, plus ``n_total`` at the end.

    Parameters
    ----------
    n_total : int
        Number of particle ids.
    size : int
        Number of ranks.
    gather : bool, optional
        If True rank 0 owns every id (the ``gather`` mode).

    Returns
    -------
    numpy.ndarray of int64, shape (size + 1,)
        Rank ``r`` owns ids ``[bounds[r], bounds[r + 1])``; with ``gather=False``
        this is ``block_range(n_total, size, r)``.
    """
    if gather:
        return np.array([0] + [n_total] * size, dtype=np.int64)
    return block_bounds(n_total, size)


def _as_rows(arr, trailing, dtype):
    """Return ``arr`` as shape ``(N,) + trailing`` of ``dtype`` (empty arrays reshaped)."""
    arr = np.asarray(arr)
    if arr.size == 0:
        # An empty rank may hand (0,) for a (0, 2) field; only its row count matters
        return np.empty((0,) + tuple(trailing), dtype=dtype)
    return np.ascontiguousarray(arr, dtype=dtype)


def validate_rows(fields, specs, n_total):
    """Check one rank's rows against ``specs``; return an error message or None.

    Parameters
    ----------
    fields : dict of str to array_like
        The rank's particle arrays, including ``"id"``.
    specs : dict of str to (tuple, numpy.dtype)
        Expected trailing shape and dtype of each written field.
    n_total : int
        Ids must lie in ``[0, n_total)``.

    Returns
    -------
    str or None
    """
    if "id" not in fields:
        return "fields have no 'id' array"
    ids = np.asarray(fields["id"]).reshape(-1)
    missing = sorted(set(specs) - set(fields))
    if missing:
        return f"fields missing: {missing}"
    for name, (trailing, _) in specs.items():
        arr = np.asarray(fields[name])
        if arr.size and arr.shape != (len(ids),) + tuple(trailing):
            return f"field {name!r} has shape {arr.shape}, expected {(len(ids),) + tuple(trailing)}"
    if len(ids) and (ids.min() < 0 or ids.max() >= n_total):
        return f"ids outside [0, {n_total}): [{ids.min()}, {ids.max()}]"
    return None


def to_id_blocks(comm, fields, specs, bounds):
    """Move rows to the owner of their id and lay them out in id order (collective).

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator; every rank must call, also with zero rows.
    fields : dict of str to array_like
        This rank's particle arrays (``"id"`` plus every name in ``specs``), checked
        by :func:`validate_rows`.
    specs : dict of str to (tuple, numpy.dtype)
        Trailing shape and dtype of each field to lay out.
    bounds : numpy.ndarray of int64, shape (size + 1,)
        Id block of each rank (:func:`owner_bounds`).

    Returns
    -------
    blocks : dict of str to numpy.ndarray
        Shape ``(count,) + trailing`` with ``count = bounds[r+1] - bounds[r]``; row
        ``i`` holds id ``bounds[r] + i``, or the fill value when no rank has it.
    duplicates : int
        Ids of this block received more than once (a solver bug when non-zero).
    """
    rank = comm.Get_rank()
    ids = np.asarray(fields["id"], dtype=np.int64).reshape(-1)
    send = {name: _as_rows(fields[name], trailing, dtype) for name, (trailing, dtype) in specs.items()}
    send["id"] = ids
    dest = np.searchsorted(bounds, ids, side="right") - 1
    recv = alltoallv_fields(comm, send, dest)
    start, count = int(bounds[rank]), int(bounds[rank + 1] - bounds[rank])
    local = recv["id"] - start
    # bincount, not np.unique: linear, and a frame write should cost little beyond IO
    duplicates = len(local) - int(np.count_nonzero(np.bincount(local, minlength=count)))
    blocks = {}
    for name, (trailing, dtype) in specs.items():
        block = np.full((count,) + tuple(trailing), fill_value(dtype), dtype=dtype)
        block[local] = recv[name]
        blocks[name] = block
    return blocks, duplicates


def write_rows(dset, lead, start, block, collective):
    """Write ``block`` into rows ``[start, start + len(block))`` of ``dset``.

    The low-level call is made even when ``block`` is empty (the file and memory
    selections are then empty), so every rank takes part in a collective write.

    Parameters
    ----------
    dset : h5py.Dataset
        Target of shape ``lead_dims + (n_rows,) + trailing``.
    lead : tuple of int
        Fixed indices of the leading dimensions (``(frame,)`` or ``()``).
    start : int
        First row written.
    block : numpy.ndarray
        Shape ``(count,) + trailing``, already of the dataset's dtype.
    collective : bool
        Use MPI-IO collective transfer (only for files opened with ``"mpio"``).
    """
    data = np.ascontiguousarray(block, dtype=dset.dtype)
    fspace = dset.id.get_space()
    if data.shape[0] == 0:
        # A one-element dummy buffer keeps the memory dataspace non-degenerate
        data = np.zeros((1,) + data.shape[1:], dtype=dset.dtype)
        mspace = h5py.h5s.create_simple(data.shape)
        mspace.select_none()
        fspace.select_none()
    else:
        trailing = data.shape[1:]
        offset = tuple(lead) + (start,) + (0,) * len(trailing)
        count = (1,) * len(lead) + data.shape
        fspace.select_hyperslab(offset, count)
        mspace = h5py.h5s.create_simple(data.shape)
    dxpl = h5py.h5p.create(h5py.h5p.DATASET_XFER)
    if collective:
        dxpl.set_dxpl_mpio(h5py.h5fd.MPIO_COLLECTIVE)
    dset.id.write(mspace, fspace, data, dxpl=dxpl)


def _json_default(obj):
    """Convert numpy scalars and arrays for :func:`json.dumps`."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def json_dumps(obj):
    """Serialise ``obj`` to JSON, accepting numpy scalars and arrays.

    Parameters
    ----------
    obj : object
        Dicts, lists, strings, numbers, numpy scalars or arrays.

    Returns
    -------
    str
    """
    return json.dumps(obj, default=_json_default, sort_keys=True)
