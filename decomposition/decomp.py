"""Slab decomposition of a 2-D node lattice: halo exchange and particle migration.

Layout
------
The node columns ``0 .. ncols-1`` along ``axis`` are split into contiguous slabs
(``bounds``, see :mod:`decomposition.slab`).  Rank ``r`` owns node columns
``owned = [n0, n1)`` and stores a window ``[w0, w1) = [max(n0 - g, 0), min(n1 + g, ncols))``
where ``g = ghost`` is the reach of the shape function in node columns.  Every slab
is at least ``g`` columns wide, so each ghost column belongs to an immediate
neighbour (``lower`` or ``upper``) and all traffic goes to neighbours only.

Halo protocol (one message to and from each neighbour per call)
---------------------------------------------------------------
``accumulate``
    After a scatter (P2G) each rank has partial sums in its ghost columns.  It sends
    ``[w0, n0)`` to ``lower`` and ``[n1, w1)`` to ``upper``; each receiver adds them
    into its owned columns ``[n0, n0 + g)`` (from ``lower``) and ``[n1 - g, n1)``
    (from ``upper``).  Owned columns then hold the full sums; the sender's ghost
    columns are left unchanged.
``fill``
    The reverse: owners copy ``[n0, n0 + g)`` to ``lower`` and ``[n1 - g, n1)`` to
    ``upper``, which overwrite their ghost columns with them.
``sum_halo``
    Both in one round: each rank sends the partial sums of all the columns it shares with a
    neighbour (``[n1 - g, n1 + g)`` to ``upper``, ``[n0 - g, n0 + g)`` to ``lower``) and adds
    what it receives to the same columns. Where every shared column lies in exactly two
    windows (every slab but the end ones at least ``2 g`` wide) both holders then hold the
    owner's sum of ``accumulate``, bit for bit: the owner adds the same two numbers as
    ``accumulate`` does and the other holder adds them in the other order, and floating-point
    addition is commutative. Narrower slabs (a column in three windows) fall back to
    ``accumulate`` then ``fill``. One message each way instead of two: half the waits.

All use ``Irecv``/``Isend`` on contiguous copies; messages travelling to higher
ranks carry tag ``_TAG_UP`` and to lower ranks ``_TAG_DOWN``. They, the migration and the
reductions complete their requests with :func:`decomposition.waiting.wait_all`, which
sleeps through a long wait instead of holding the core. ``sum_halo`` can complete a pending
reduction (:meth:`start_allreduce`) in the same wait, so the two cost one rendezvous.

Migration protocol
------------------
Particles belong to the rank owning their base cell column.  After advection a
particle moves less than a cell, so its new owner is this rank or a neighbour.
``migrate`` exchanges one row count with each neighbour, then sends one packed byte
buffer per neighbour holding every field of the leaving rows
(:func:`decomposition.exchange.pack_rows`); empty buffers are not sent (both sides
know the count).  Rebalancing moves slab bounds; the caller then redistributes with
:func:`decomposition.exchange.alltoallv_fields`, which may send anywhere.

With one rank both neighbours are ``MPI.PROC_NULL``: no message is sent and every
operation is the identity.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager

import numpy as np
from mpi4py import MPI

from .exchange import field_layout, pack_rows, unpack_rows
from .slab import balanced_bounds, block_bounds, check_bounds
from .waiting import wait_all

__all__ = ["SlabDecomposition", "PendingReduction"]

logger = logging.getLogger(__name__)

_TAG_UP = 7101       # halo message travelling to rank + 1
_TAG_DOWN = 7102     # halo message travelling to rank - 1
_TAG_COUNT_UP = 7103
_TAG_COUNT_DOWN = 7104
_TAG_ROWS_UP = 7105
_TAG_ROWS_DOWN = 7106


class SlabDecomposition:
    """One-axis slab split of a 2-D node lattice over a communicator.

    Parameters
    ----------
    comm : mpi4py.MPI.Comm
        Communicator (``MPI.COMM_SELF`` or a 1-rank world gives the serial case).
    n_nodes : tuple of int
        Node counts ``(n_nodes[0], n_nodes[1])`` of the global lattice.
    axis : int
        Split axis (0 or 1); global node columns are ``0 .. n_nodes[axis] - 1``.
    ghost : int
        Ghost width in node columns (the shape function's reach).
    bounds : array_like of int, optional
        Column split (``size + 1`` entries); the :func:`block_range` split if None.

    Raises
    ------
    ValueError
        If a slab is narrower than ``max(ghost, 1)`` columns; the message gives the
        largest usable rank count.
    """

    def __init__(self, comm, n_nodes, axis, ghost, bounds=None):
        self.comm = comm
        self.rank = comm.Get_rank()
        self.size = comm.Get_size()
        self.n_nodes = tuple(int(n) for n in n_nodes)
        if axis not in (0, 1) or len(self.n_nodes) != 2:
            raise ValueError(f"need a 2-D lattice and axis 0 or 1; got {n_nodes}, axis {axis}")
        if ghost < 0:
            raise ValueError(f"ghost width must be >= 0; got {ghost}")
        self.axis = int(axis)
        self.ghost = int(ghost)
        self.ncols = self.n_nodes[self.axis]
        self.min_width = max(self.ghost, 1)
        if bounds is None:
            bounds = block_bounds(self.ncols, self.size)
        self._set_bounds(bounds)
        self.reset_counters()

    # ------------------------------------------------------------------ layout
    def _set_bounds(self, bounds):
        """Validate ``bounds`` and derive owned range, window and neighbours."""
        bounds = check_bounds(bounds, self.ncols, self.min_width)
        if len(bounds) != self.size + 1:
            raise ValueError(f"bounds need {self.size + 1} entries for {self.size} ranks; "
                             f"got {len(bounds)}")
        self.bounds = bounds
        n0, n1 = int(bounds[self.rank]), int(bounds[self.rank + 1])
        self.owned = (n0, n1)
        self.window = (max(n0 - self.ghost, 0), min(n1 + self.ghost, self.ncols))
        self.on_lower_boundary = n0 == 0
        self.on_upper_boundary = n1 == self.ncols
        self.lower = self.rank - 1 if self.rank > 0 else MPI.PROC_NULL
        self.upper = self.rank + 1 if self.rank < self.size - 1 else MPI.PROC_NULL
        # sum_halo's single round needs every shared column in two windows only: every slab
        # but the end ones 2 g wide (the same answer on every rank: the bounds are global)
        inner = np.diff(bounds)[1:-1]
        self.one_round_halo = bool(inner.size == 0 or inner.min() >= 2 * self.ghost)

    @property
    def window_shape(self):
        """tuple of int: node shape ``(m0, m1)`` of this rank's window array."""
        shape = list(self.n_nodes)
        shape[self.axis] = self.window[1] - self.window[0]
        return tuple(shape)

    def owner_of_columns(self, cols):
        """Return the rank owning each global node column.

        Parameters
        ----------
        cols : array_like of int
            Global node columns (a particle's base cell column ``c`` is owned with
            node column ``c``).

        Returns
        -------
        numpy.ndarray of int64
            Owning rank of each column; columns outside ``[0, ncols)`` get the
            nearest end rank.
        """
        cols = np.asarray(cols)
        owner = np.searchsorted(self.bounds, cols, side="right") - 1
        return np.clip(owner, 0, self.size - 1).astype(np.int64, copy=False)

    # ------------------------------------------------------------------- halo
    def _halo_slices(self):
        """Return window-local column slices of the four halo regions.

        Returns
        -------
        dict of str to slice
            ``ghost_lo``/``ghost_hi``: ghost columns owned by lower/upper;
            ``edge_lo``/``edge_hi``: owned columns that are lower's/upper's ghosts.
        """
        (n0, n1), (w0, w1), g = self.owned, self.window, self.ghost
        edge_lo_end = min(n0 + g, self.ncols) if self.lower != MPI.PROC_NULL else n0
        edge_hi_start = max(n1 - g, 0) if self.upper != MPI.PROC_NULL else n1
        return {"ghost_lo": slice(0, n0 - w0), "ghost_hi": slice(n1 - w0, w1 - w0),
                "edge_lo": slice(n0 - w0, edge_lo_end - w0),
                "edge_hi": slice(edge_hi_start - w0, n1 - w0)}

    def _columns(self, arr, cols):
        """Return the view of ``arr`` restricted to window columns ``cols``."""
        index = [slice(None)] * arr.ndim
        index[self.axis] = cols
        return arr[tuple(index)]

    def _check_window(self, arr):
        """Raise ValueError unless ``arr`` spans the window along ``axis``."""
        width = self.window[1] - self.window[0]
        if arr.ndim <= self.axis or arr.shape[self.axis] != width:
            raise ValueError(f"array of shape {arr.shape} does not span the window "
                             f"{self.window} ({width} columns) along axis {self.axis}")

    def _halo_exchange(self, arr, send, recv, also=()):
        """Send regions ``send`` and receive into copies shaped like ``recv``.

        Parameters
        ----------
        arr : numpy.ndarray
            Window array.
        send, recv : tuple of (slice, slice)
            (to/from lower, to/from upper) window-local column slices.
        also : sequence of mpi4py requests
            Completed in the same wait (a pending reduction).

        Returns
        -------
        list of numpy.ndarray or None
            Received buffers from (lower, upper), None where there is no neighbour.
        """
        requests, received = [], []
        peers = ((self.lower, _TAG_DOWN, _TAG_UP), (self.upper, _TAG_UP, _TAG_DOWN))
        for (peer, out_tag, in_tag), cols in zip(peers, recv):
            if peer == MPI.PROC_NULL or self.ghost == 0:
                received.append(None)
                continue
            buf = np.empty_like(self._columns(arr, cols), order="C")
            requests.append(self.comm.Irecv(buf, source=peer, tag=in_tag))
            received.append(buf)
        for (peer, out_tag, in_tag), cols in zip(peers, send):
            if peer == MPI.PROC_NULL or self.ghost == 0:
                continue
            buf = np.ascontiguousarray(self._columns(arr, cols))
            requests.append(self.comm.Isend(buf, dest=peer, tag=out_tag))
            self._count("halo", buf.nbytes)
        if requests:
            self.waits["halo"] += 1
        wait_all(requests + list(also))
        return received

    def accumulate(self, arr):
        """Add every rank's ghost-column values into the owners' columns, in place (collective).

        Parameters
        ----------
        arr : numpy.ndarray
            This rank's window array: ``arr.shape[self.axis] == w1 - w0``; any other
            and trailing dimensions; may be a non-contiguous view.  Afterwards each
            owned column holds the sum of all ranks' contributions; ghost columns are
            left as they were (call :meth:`fill` next).
        """
        with self._timed():
            self._check_window(arr)
            s = self._halo_slices()
            got = self._halo_exchange(arr, (s["ghost_lo"], s["ghost_hi"]),
                                      (s["edge_lo"], s["edge_hi"]))
            for buf, cols in zip(got, (s["edge_lo"], s["edge_hi"])):
                if buf is not None:
                    self._columns(arr, cols)[...] += buf

    def fill(self, arr):
        """Copy the owners' values into every rank's ghost columns, in place (collective).

        Parameters
        ----------
        arr : numpy.ndarray
            This rank's window array (as for :meth:`accumulate`).
        """
        with self._timed():
            self._check_window(arr)
            s = self._halo_slices()
            got = self._halo_exchange(arr, (s["edge_lo"], s["edge_hi"]),
                                      (s["ghost_lo"], s["ghost_hi"]))
            for buf, cols in zip(got, (s["ghost_lo"], s["ghost_hi"])):
                if buf is not None:
                    self._columns(arr, cols)[...] = buf

    def sum_halo(self, arr, pending=None):
        """:meth:`accumulate` then :meth:`fill`, in one round where the slabs allow it
        (``one_round_halo``): afterwards every window column holds the sum of every rank's
        contributions, owned and ghost columns alike, bit for bit as the two calls leave
        them (collective).

        Parameters
        ----------
        arr : numpy.ndarray
            This rank's window array (as for :meth:`accumulate`).
        pending : PendingReduction, optional
            A reduction started earlier, completed in the same wait (its ``result()`` is
            then ready without waiting).
        """
        also = pending.requests if pending is not None else ()
        if not self.one_round_halo:
            if pending is not None:
                pending.wait()
            self.accumulate(arr)
            self.fill(arr)
            return
        with self._timed():
            self._check_window(arr)
            s = self._halo_slices()
            # the shared columns: the ghosts and the owned columns the neighbour borrows
            lo = slice(s["ghost_lo"].start, s["edge_lo"].stop)
            hi = slice(s["edge_hi"].start, s["ghost_hi"].stop)
            got = self._halo_exchange(arr, (lo, hi), (lo, hi), also)
            for buf, shared in zip(got, (lo, hi)):
                if buf is not None:
                    self._columns(arr, shared)[...] += buf
        if pending is not None:
            pending.done = True

    # -------------------------------------------------------------- migration
    def _check_dest(self, dest):
        """Raise RuntimeError if a destination is not this rank or a neighbour."""
        allowed = [r for r in (self.lower, self.rank, self.upper) if r != MPI.PROC_NULL]
        ok = np.isin(dest, allowed)
        if not np.all(ok):
            bad = np.unique(dest[~ok]).tolist()
            raise RuntimeError(
                f"migrate: {int(np.count_nonzero(~ok))} rows on rank {self.rank} go to "
                f"ranks {bad}, which are not neighbours (lower {self.lower}, upper "
                f"{self.upper}); a particle moved more than a slab in one step")

    def _exchange_counts(self, send_counts):
        """Swap leaving-row counts with (lower, upper); return the incoming counts."""
        recv = [np.zeros(1, np.int64), np.zeros(1, np.int64)]
        peers = ((self.lower, _TAG_COUNT_DOWN, _TAG_COUNT_UP),
                 (self.upper, _TAG_COUNT_UP, _TAG_COUNT_DOWN))
        requests = []
        for (peer, out_tag, in_tag), buf, n in zip(peers, recv, send_counts):
            if peer == MPI.PROC_NULL:
                continue
            out = np.array([n], dtype=np.int64)
            requests.append(self.comm.Irecv(buf, source=peer, tag=in_tag))
            requests.append(self.comm.Isend(out, dest=peer, tag=out_tag))
            self._count("migration", out.nbytes)
        if requests:
            self.waits["migration"] += 1
        wait_all(requests)
        return [int(b[0]) for b in recv]

    def _exchange_rows(self, fields, masks, recv_counts):
        """Send packed leaving rows to (lower, upper); return the packed arrivals."""
        _, row_nbytes = field_layout(fields)
        peers = ((self.lower, _TAG_ROWS_DOWN, _TAG_ROWS_UP),
                 (self.upper, _TAG_ROWS_UP, _TAG_ROWS_DOWN))
        received = [np.empty((n, row_nbytes), np.uint8) for n in recv_counts]
        requests = []
        for (peer, out_tag, in_tag), buf in zip(peers, received):
            if peer != MPI.PROC_NULL and buf.size:
                requests.append(self.comm.Irecv(buf, source=peer, tag=in_tag))
        for (peer, out_tag, in_tag), mask in zip(peers, masks):
            if peer != MPI.PROC_NULL and row_nbytes and mask.any():
                out = pack_rows(fields, mask)
                requests.append(self.comm.Isend(out, dest=peer, tag=out_tag))
                self._count("migration", out.nbytes)
        if requests:
            self.waits["migration"] += 1
        wait_all(requests)
        return received

    def migrate(self, fields, dest):
        """Move rows to the neighbour ranks named by ``dest`` (collective).

        Parameters
        ----------
        fields : dict of str to numpy.ndarray
            Particle arrays sharing their first dimension ``N`` (may be 0); same keys,
            dtypes and trailing shapes on every rank.
        dest : numpy.ndarray of int, shape (N,)
            New owner of each row: this rank, ``lower`` or ``upper``.

        Returns
        -------
        dict of str to numpy.ndarray
            Staying rows in their original order, then rows from ``lower``, then
            from ``upper``.  When no row leaves or arrives the input arrays
            themselves are returned (no copy).

        Raises
        ------
        RuntimeError
            If a row's destination is farther than a neighbour (raised on that rank
            only; the abort hook ends the run).
        """
        with self._timed():
            dest = np.asarray(dest).reshape(-1)
            self._check_dest(dest)
            masks = (dest == self.lower, dest == self.upper)
            send_counts = [int(np.count_nonzero(m)) for m in masks]
            recv_counts = self._exchange_counts(send_counts)
            if sum(send_counts) + sum(recv_counts) == 0:
                return dict(fields)
            specs, _ = field_layout(fields)
            packed = self._exchange_rows(fields, masks, recv_counts)
            arrived = [unpack_rows(buf, specs) for buf in packed]
            stay = dest == self.rank
            return {key: np.concatenate([np.asarray(arr)[stay], arrived[0][key], arrived[1][key]])
                    for key, arr in fields.items()}

    # ------------------------------------------------------------ balancing
    def rebalance(self, column_weights):
        """Move slab bounds so each rank carries about the same column weight (collective).

        Parameters
        ----------
        column_weights : array_like, shape (ncols,)
            GLOBAL weight of every node column (identical on all ranks; rank 0's
            bounds are broadcast so rounding can never make ranks disagree).

        Returns
        -------
        bool
            True if the bounds (and so ``owned``, ``window``) changed.  The caller
            then redistributes its particles and rebuilds its grid window.
        """
        new = balanced_bounds(column_weights, self.size, self.min_width)
        if self.size > 1:
            self.comm.Bcast(new, root=0)
        if np.array_equal(new, self.bounds):
            return False
        logger.info("rebalance: bounds %s -> %s", self.bounds.tolist(), new.tolist())
        self._set_bounds(new)
        return True

    def imbalance(self, local_weight):
        """Return max over mean of a per-rank scalar, 1.0 when the mean is 0 (collective).

        Parameters
        ----------
        local_weight : float
            This rank's load (particle count or measured step time).

        Returns
        -------
        float
        """
        weights = np.empty(self.size, dtype=np.float64)
        self.comm.Allgather(np.array([local_weight], dtype=np.float64), weights)
        mean = weights.mean()
        return float(weights.max() / mean) if mean > 0 else 1.0

    # ------------------------------------------------------------ reductions
    def _allreduce(self, x, op):
        """Allreduce a scalar or small array; scalars come back as Python scalars."""
        return self.start_allreduce(x, op).result()

    def start_allreduce(self, x, op=MPI.MAX):
        """Start reducing ``x`` (scalar or small array) over all ranks; returns a
        :class:`PendingReduction` whose ``result()`` waits for it (collective: every rank
        starts the same reductions in the same order)."""
        send = np.array(x)
        recv = np.empty_like(send)
        if self.size == 1:
            recv[...] = send
            return PendingReduction(recv, [], isinstance(x, np.ndarray))
        self.waits["reduce"] += 1
        return PendingReduction(recv, [self.comm.Iallreduce(send, recv, op=op)],
                                isinstance(x, np.ndarray), keep=send)

    def allreduce_sum(self, x):
        """Return the sum of ``x`` (scalar or small array) over all ranks."""
        return self._allreduce(x, MPI.SUM)

    def allreduce_min(self, x):
        """Return the minimum of ``x`` (scalar or small array) over all ranks."""
        return self._allreduce(x, MPI.MIN)

    def allreduce_max(self, x):
        """Return the maximum of ``x`` (scalar or small array) over all ranks."""
        return self._allreduce(x, MPI.MAX)

    def exscan_sum(self, n):
        """Return the sum of ``n`` over lower ranks (0 on rank 0).

        Parameters
        ----------
        n : int or numpy.ndarray
            Local count (e.g. particles), used for file offsets.

        Returns
        -------
        int or numpy.ndarray
        """
        send = np.array(n, dtype=np.int64) if not isinstance(n, np.ndarray) else np.array(n)
        recv = np.zeros_like(send)
        self.comm.Exscan(send, recv, op=MPI.SUM)
        if self.rank == 0:
            recv[...] = 0
        return recv if isinstance(n, np.ndarray) else recv.item()

    # -------------------------------------------------------------- counters
    def reset_counters(self):
        """Zero ``bytes_sent``, ``messages_sent``, ``waits``, ``comm_time`` and ``comm_cpu``."""
        self.bytes_sent = {"halo": 0, "migration": 0}
        self.messages_sent = {"halo": 0, "migration": 0}
        #: rendezvous with other ranks by kind: halo rounds, migration rounds, reductions
        self.waits = {"halo": 0, "migration": 0, "reduce": 0}
        self.comm_time = 0.0
        self.comm_cpu = 0.0

    def _count(self, kind, nbytes):
        """Record one sent message of ``nbytes`` bytes under ``kind``."""
        self.bytes_sent[kind] += int(nbytes)
        self.messages_sent[kind] += 1

    #: also measure the CPU time of the exchanges (``comm_cpu``); off by default: reading the
    #: process CPU clock is a system call that took 6-16 us here, about 10% of a small scene's
    #: step at 8 readings per step (the scaling benchmark switches it on)
    measure_cpu = False

    @contextmanager
    def _timed(self):
        """Add the wall time of the block to ``comm_time`` and (``measure_cpu``) its CPU time to
        ``comm_cpu`` (Open MPI polls while it waits, so waiting costs CPU time too)."""
        start = time.perf_counter()
        cpu = time.process_time() if self.measure_cpu else 0.0
        try:
            yield
        finally:
            self.comm_time += time.perf_counter() - start
            if self.measure_cpu:
                self.comm_cpu += time.process_time() - cpu

    def __repr__(self):
        return (f"SlabDecomposition(rank={self.rank}/{self.size}, axis={self.axis}, "
                f"ghost={self.ghost}, owned={self.owned}, window={self.window})")


class PendingReduction:
    """A reduction on its way (:meth:`SlabDecomposition.start_allreduce`): ``result()`` waits
    for it and returns the reduced array (or scalar); :meth:`SlabDecomposition.sum_halo` can
    complete it in its own wait."""

    def __init__(self, recv, requests, as_array, keep=None):
        self._recv, self.requests, self._as_array = recv, requests, as_array
        self._keep = keep  # the send buffer must live until the reduction completes
        self.done = not requests

    def wait(self):
        if not self.done:
            wait_all(self.requests)
            self.done = True

    def result(self):
        self.wait()
        return self._recv if self._as_array else self._recv.item()
