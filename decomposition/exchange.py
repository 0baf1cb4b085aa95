"""Bulk exchange of row-indexed arrays between ranks.

Protocol
--------
Particles (or any other row-indexed records) are stored as a structure of arrays: a
``dict`` mapping a name to an array whose first dimension is the row count ``N``.
To move rows between ranks, every rank computes ``dest``, the destination rank of
each row, and calls :func:`alltoallv_fields` collectively:

1. Rows are ordered by destination with a stable sort, so the rows sent to one rank
   keep their original relative order.
2. All fields are packed into ONE contiguous byte buffer of shape
   ``(N, row_nbytes)``: the bytes of one row of every field side by side, fields in
   sorted key order (so every rank packs identically whatever its dict order).
3. One ``Alltoall`` exchanges the per-destination row counts.
4. One ``Alltoallv`` moves the packed buffer; counts and displacements are in rows,
   with an MPI contiguous datatype of ``row_nbytes`` bytes (so large buffers do not
   overflow 32-bit byte counts).
5. The received buffer, grouped by source rank in rank order, is unpacked into
   arrays with the original keys, dtypes and trailing shapes.

Every rank must pass the same keys with the same dtypes and trailing shapes; a rank
with zero rows passes arrays of length 0 and still takes part.  With one rank no MPI
call is made.

:func:`pack_rows` and :func:`unpack_rows` are also used by the neighbour-only
particle migration of :class:`decomposition.SlabDecomposition`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

__all__ = [
    "FieldSpec",
    "field_layout",
    "pack_rows",
    "unpack_rows",
    "alltoallv_fields",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FieldSpec:
    """Placement of one field inside a packed row.

    Attributes
    ----------
    key : str
        Field name.
    dtype : numpy.dtype
        Element type.
    trailing : tuple of int
        Shape of one row (the array shape without its first dimension).
    offset : int
        Byte offset of the field inside a packed row.
    nbytes : int
        Bytes of one row of the field.
    """

    key: str
    dtype: np.dtype
    trailing: tuple
    offset: int
    nbytes: int


def field_layout(fields):
    """Describe how the rows of ``fields`` are packed side by side.

    Parameters
    ----------
    fields : dict of str to numpy.ndarray
        Arrays sharing their first dimension.

    Returns
    -------
    specs : list of FieldSpec
        One entry per field, in sorted key order.
    row_nbytes : int
        Bytes of one packed row.
    """
    specs, offset = [], 0
    for key in sorted(fields):
        arr = np.asarray(fields[key])
        if arr.ndim == 0:
            raise ValueError(f"field {key!r} is a scalar; fields need a row dimension")
        trailing = tuple(arr.shape[1:])
        nbytes = int(np.prod(trailing, dtype=np.int64)) * arr.dtype.itemsize
        specs.append(FieldSpec(key, arr.dtype, trailing, offset, nbytes))
        offset += nbytes
    return specs, offset


def _row_count(fields, n=None):
    """Return the common first dimension of ``fields`` (checked), or ``n``."""
    lengths = {key: np.shape(arr)[0] for key, arr in fields.items()}
    if n is not None:
        lengths["<dest>"] = n
    values = set(lengths.values())
    if len(values) > 1:
        raise ValueError(f"fields have different row counts: {lengths}")
    return values.pop() if values else 0


def pack_rows(fields, rows=None):
    """Pack selected rows of every field into one byte buffer.

    Parameters
    ----------
    fields : dict of str to numpy.ndarray
        Arrays sharing their first dimension ``N``.
    rows : numpy.ndarray of int or bool, optional
        Rows to pack, in this order (an index array or a boolean mask); all rows
        when omitted.

    Returns
    -------
    numpy.ndarray of uint8, shape (M, row_nbytes)
        Row ``j`` holds the bytes of row ``rows[j]`` of every field, laid out as
        :func:`field_layout` describes.
    """
    specs, row_nbytes = field_layout(fields)
    n = _row_count(fields)
    if rows is None:
        nrows = n
    else:
        rows = np.asarray(rows)
        nrows = int(np.count_nonzero(rows)) if rows.dtype == bool else len(rows)
    buf = np.empty((nrows, row_nbytes), dtype=np.uint8)
    for spec in specs:
        arr = np.asarray(fields[spec.key])
        sel = arr if rows is None else arr[rows]
        items = spec.nbytes // spec.dtype.itemsize
        sel = np.ascontiguousarray(sel).reshape(nrows, items)
        buf[:, spec.offset:spec.offset + spec.nbytes] = sel.view(np.uint8)
    return buf


def unpack_rows(buf, specs):
    """Unpack a byte buffer produced by :func:`pack_rows`.

    Parameters
    ----------
    buf : numpy.ndarray of uint8, shape (M, row_nbytes)
        Packed rows.
    specs : list of FieldSpec
        Layout from :func:`field_layout`.

    Returns
    -------
    dict of str to numpy.ndarray
        New contiguous arrays of shape ``(M,) + trailing`` with the original dtypes.
    """
    m = buf.shape[0]
    out = {}
    for spec in specs:
        raw = np.ascontiguousarray(buf[:, spec.offset:spec.offset + spec.nbytes])
        out[spec.key] = raw.view(spec.dtype).reshape((m,) + spec.trailing)
    return out


def _row_type(row_nbytes):
    """Return a committed MPI datatype of ``row_nbytes`` contiguous bytes."""
    return MPI.BYTE.Create_contiguous(max(row_nbytes, 1)).Commit()


def _exchange_buffers(comm, sendbuf, send_counts):
    """Alltoall the row counts, then Alltoallv the packed rows.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator.
    sendbuf : numpy.ndarray of uint8, shape (N, row_nbytes)
        Packed rows grouped by destination rank in rank order.
    send_counts : numpy.ndarray of int, shape (comm.size,)
        Rows for each destination.

    Returns
    -------
    numpy.ndarray of uint8, shape (M, row_nbytes)
        Received rows grouped by source rank in rank order.
    """
    size = comm.Get_size()
    row_nbytes = sendbuf.shape[1]
    scounts = np.ascontiguousarray(send_counts, dtype=np.int32)
    rcounts = np.empty(size, dtype=np.int32)
    comm.Alltoall([scounts, MPI.INT], [rcounts, MPI.INT])
    sdispls = np.zeros(size, dtype=np.int32)
    rdispls = np.zeros(size, dtype=np.int32)
    np.cumsum(scounts[:-1], out=sdispls[1:])
    np.cumsum(rcounts[:-1], out=rdispls[1:])
    recvbuf = np.empty((int(rcounts.sum(dtype=np.int64)), row_nbytes), dtype=np.uint8)
    if row_nbytes == 0:
        return recvbuf
    rowtype = _row_type(row_nbytes)
    try:
        comm.Alltoallv([sendbuf, (scounts, sdispls), rowtype],
                       [recvbuf, (rcounts, rdispls), rowtype])
    finally:
        rowtype.Free()
    return recvbuf


def alltoallv_fields(comm, fields, dest):
    """Send row ``i`` of every field to rank ``dest[i]`` (collective).

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator; every rank must call.
    fields : dict of str to numpy.ndarray
        Arrays sharing their first dimension ``N`` (any dtypes and trailing shapes,
        identical on every rank); ``N`` may be 0.
    dest : numpy.ndarray of int, shape (N,)
        Destination rank of each row, in ``[0, comm.size)``.

    Returns
    -------
    dict of str to numpy.ndarray
        The received rows with the same keys, dtypes and trailing shapes, grouped by
        source rank in rank order, each source's rows in their original order.
        Always new arrays (never views of the input).

    Raises
    ------
    ValueError
        If ``dest`` has the wrong length or names a rank outside the communicator.
    """
    size = comm.Get_size()
    dest = np.asarray(dest, dtype=np.int64).reshape(-1)
    n = _row_count(fields, len(dest))
    if n and (dest.min() < 0 or dest.max() >= size):
        raise ValueError(f"dest ranks must lie in [0, {size}); got [{dest.min()}, {dest.max()}]")
    if size == 1:
        return {key: np.array(arr, copy=True) for key, arr in fields.items()}
    specs, _ = field_layout(fields)
    order = np.argsort(dest, kind="stable")
    sendbuf = pack_rows(fields, order)
    counts = np.bincount(dest, minlength=size)
    recvbuf = _exchange_buffers(comm, sendbuf, counts)
    received = unpack_rows(recvbuf, specs)
    logger.debug("alltoallv_fields: sent %d rows, received %d rows", n, len(recvbuf))
    return {key: received[key] for key in fields}
