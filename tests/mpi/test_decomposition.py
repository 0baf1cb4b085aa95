"""MPI tests of decomposition: halo sums, migration, alltoallv, rebalance, counters.

Run under several rank counts, e.g.::

    mpirun -n 2 python -m pytest tests/mpi/test_decomposition.py -q
    mpirun -n 4 --oversubscribe python tests/mpi/test_decomposition.py

Every assertion is reduced over all ranks first (``everywhere``), so a failure on one
rank fails the test on all of them instead of leaving the others waiting in the next
collective.
"""

import numpy as np
import pytest
from mpi4py import MPI

from decomposition import SlabDecomposition, alltoallv_fields

comm = MPI.COMM_WORLD
parallel_only = pytest.mark.skipif(comm.size < 2,
                                   reason="meaningless on one rank; run under mpirun -n >= 2")
pytestmark = pytest.mark.mpi(min_size=1)


def everywhere(ok):
    """Return True only if ``ok`` holds on every rank (collective)."""
    return comm.allreduce(bool(ok), op=MPI.LAND)


def _neighbours(decomp):
    """Number of neighbour ranks (0, 1 or 2)."""
    return int(decomp.lower != MPI.PROC_NULL) + int(decomp.upper != MPI.PROC_NULL)


def _same_layout(got, fields):
    """True if ``got`` has the keys, dtypes and trailing shapes of ``fields``."""
    return list(got) == list(fields) and all(
        got[k].dtype == fields[k].dtype and got[k].shape[1:] == fields[k].shape[1:] for k in fields)


# ---------------------------------------------------------------------------- halo
def _value(col, row, rank, comp):
    """Deterministic contribution of ``rank`` to node (col, row), component ``comp``."""
    return 1000.0 * col + 10.0 * row + 3.0 * comp + rank + 1.0


def _window_nodes(decomp):
    """Global column and row index arrays of the window nodes."""
    idx = np.indices(decomp.window_shape)
    return idx[decomp.axis] + decomp.window[0], idx[1 - decomp.axis]


def _full_sum(decomp, cols, rows, comps):
    """Sum over all ranks whose window touches each column, from ``bounds`` alone."""
    total = np.zeros(np.broadcast(cols, comps).shape)
    b, g, ncols = decomp.bounds, decomp.ghost, decomp.ncols
    for r in range(decomp.size):
        lo, hi = max(b[r] - g, 0), min(b[r + 1] + g, ncols)
        touches = (cols >= lo) & (cols < hi)
        total += np.where(touches, _value(cols, rows, r, comps), 0.0)
    return total


def _tight_bounds(ncols, size, ghost):
    """Every slab exactly ``ghost`` wide except the last."""
    return np.array([ghost * r for r in range(size)] + [ncols])


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("ghost", [1, 2])
@pytest.mark.parametrize("layout", ["block", "tight"])
@pytest.mark.parametrize("dtype", [np.float64, np.int64])
def test_halo_sums_equal_serial_sums(axis, ghost, layout, dtype):
    n_nodes = (11, 5) if axis == 0 else (4, 11)
    bounds = _tight_bounds(11, comm.size, ghost) if layout == "tight" else None
    decomp = SlabDecomposition(comm, n_nodes, axis=axis, ghost=ghost, bounds=bounds)
    cols, rows = _window_nodes(decomp)
    cols, rows = cols[..., None], rows[..., None]
    comps = np.arange(3)
    # A non-contiguous view of a wider node-interleaved array
    storage = np.zeros(decomp.window_shape + (5,), dtype=dtype)
    view = storage[..., 1:4]
    view[...] = _value(cols, rows, decomp.rank, comps)
    original = view.copy()
    expected = _full_sum(decomp, cols, rows, comps)
    owned = (cols[..., 0] >= decomp.owned[0]) & (cols[..., 0] < decomp.owned[1])

    decomp.accumulate(view)
    assert everywhere(np.array_equal(view[owned], expected[owned]))
    assert everywhere(np.array_equal(view[~owned], original[~owned]))
    decomp.fill(view)
    assert everywhere(np.array_equal(view, expected))
    assert everywhere(not storage[..., 0].any() and not storage[..., 4].any())


def _double_bounds(ncols, size, ghost):
    """Every slab exactly ``2 ghost`` wide except the last: the narrowest one-round layout."""
    return np.array([2 * ghost * r for r in range(size)] + [ncols])


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("ghost", [1, 2])
@pytest.mark.parametrize("layout", ["block", "tight", "double"])
def test_one_round_halo_equals_accumulate_then_fill_bit_for_bit(axis, ghost, layout):
    """sum_halo (one message each way, a pending reduction completed in the same wait) leaves
    every window column as accumulate + fill do, to the bit: random values of mixed
    magnitudes, so a sum in another order or with a contribution missing would differ."""
    n_nodes = (17, 5) if axis == 0 else (4, 17)
    bounds = {"tight": _tight_bounds, "double": _double_bounds}.get(layout, lambda *a: None)(17, comm.size, ghost)
    decomp = SlabDecomposition(comm, n_nodes, axis=axis, ghost=ghost, bounds=bounds)
    # a column lies in three windows only where an inner slab is narrower than 2 ghost
    widths = np.diff(decomp.bounds)[1:-1]
    assert everywhere(decomp.one_round_halo == bool(widths.size == 0 or widths.min() >= 2 * ghost))
    rng = np.random.default_rng(100 + decomp.rank)
    storage = np.zeros(decomp.window_shape + (6,))
    storage[..., 1:5] = rng.standard_normal(decomp.window_shape + (4,)) * 10.0 ** rng.integers(-8, 8, decomp.window_shape + (4,))
    two = storage.copy()
    decomp.accumulate(two[..., 1:5])
    decomp.fill(two[..., 1:5])
    cols, rows = _window_nodes(decomp)
    cols, rows = cols[..., None], rows[..., None]
    one = storage.copy()
    one[..., 1:5] = _value(cols, rows, decomp.rank, np.arange(4))
    decomp.sum_halo(one[..., 1:5])   # the exact serial sums first (the deterministic values)
    assert everywhere(np.array_equal(one[..., 1:5], _full_sum(decomp, cols, rows, np.arange(4))))
    one = storage.copy()
    waits = decomp.waits["halo"]
    pending = decomp.start_allreduce(np.array([float(decomp.rank), -float(decomp.rank)]), MPI.MAX)
    decomp.sum_halo(one[..., 1:5], pending=pending)
    assert everywhere(pending.done and np.array_equal(pending.result(), [comm.size - 1.0, 0.0]))
    assert everywhere(np.array_equal(one, two))
    rounds = 0 if decomp.size == 1 else (1 if decomp.one_round_halo else 2)
    assert everywhere(decomp.waits["halo"] - waits == rounds)


@parallel_only
def test_a_wait_for_a_late_neighbour_sleeps_instead_of_polling(monkeypatch):
    """A rank whose neighbour is 0.2 s late waits in naps (decomposition/waiting.py), not by
    polling: it sleeps, at least the 5 growing naps (10 + 20 + 40 + 80 + 160 us) a wait longer
    than 0.15 s must pass through whatever the machine's load (a nap lasts at least its
    length; a loaded machine makes them longer, so fewer), and the exchange completes with the
    right sums. Polling (PMPM_MPI_WAIT=spin) naps never."""
    import time
    from decomposition import waiting
    decomp = SlabDecomposition(comm, (11, 4), axis=0, ghost=2)
    decomp.sum_halo(np.ones(decomp.window_shape))  # connections set up
    naps = []
    real_sleep = time.sleep

    def counted(seconds):
        naps.append(seconds)
        real_sleep(seconds)

    monkeypatch.setattr(waiting, "time", type("clock", (), {"sleep": staticmethod(counted),
                                                             "perf_counter": time.perf_counter}))
    comm.Barrier()
    late = decomp.rank == 0
    if late:
        real_sleep(0.2)
    arr = np.ones(decomp.window_shape)
    wall0 = time.perf_counter()
    decomp.sum_halo(arr)
    wall = time.perf_counter() - wall0
    cols = np.arange(*decomp.window)
    shared = np.array([sum(lo <= c < hi for lo, hi in zip(np.maximum(decomp.bounds[:-1] - 2, 0),
                                                           np.minimum(decomp.bounds[1:] + 2, 11)))
                       for c in cols], dtype=float)
    assert everywhere(np.array_equal(arr, np.broadcast_to(shared[:, None], arr.shape)))
    waited = decomp.rank == 1 and wall > 0.15
    assert everywhere(not waited or len(naps) >= 5)
    assert everywhere(decomp.rank != 1 or wall > 0.15)  # rank 1 did wait for rank 0


# ----------------------------------------------------------------------- migration
def _particles(decomp, n_local, rng):
    """Particles in this rank's owned cells, with ids unique over all ranks."""
    first = decomp.exscan_sum(n_local)
    ids = first + np.arange(n_local, dtype=np.int64)
    n0, n1 = decomp.owned
    x = rng.uniform(n0, min(n1, decomp.ncols - 1), n_local)
    return {
        "id": ids,
        "x": np.stack([x, rng.uniform(0, 4, n_local)], axis=1),
        "F": np.tile(np.eye(2), (n_local, 1, 1)) * ids[:, None, None],
        "mat": (ids % 3).astype(np.int8),
        "src": np.full(n_local, decomp.rank, dtype=np.int32),
        "chk": np.sin(ids.astype(np.float64)),
    }


def _migration_setup(seed):
    decomp = SlabDecomposition(comm, (16, 5), axis=0, ghost=2)
    rng = np.random.default_rng(seed + decomp.rank)
    n_local = 0 if decomp.rank == 1 else 20 + 3 * decomp.rank
    fields = _particles(decomp, n_local, rng)
    # Advect by less than a cell and hand each particle to its base cell's owner
    fields["x"][:, 0] = np.clip(fields["x"][:, 0] + rng.uniform(-0.99, 0.99, n_local), 0, 14.999)
    dest = decomp.owner_of_columns(np.floor(fields["x"][:, 0]).astype(np.int64))
    fields["dest"] = dest.astype(np.int32)
    return decomp, fields, dest


@parallel_only
def test_migrate_conserves_and_moves_to_neighbours_only():
    decomp, fields, dest = _migration_setup(seed=11)
    n_before = decomp.allreduce_sum(len(fields["id"]))
    id_sum = decomp.allreduce_sum(int(fields["id"].sum()))
    out = decomp.migrate(fields, dest)
    rank = decomp.rank

    assert decomp.allreduce_sum(len(out["id"])) == n_before
    assert decomp.allreduce_sum(int(out["id"].sum())) == id_sum
    assert everywhere(_same_layout(out, fields))
    # Every row intact, at its destination, from this rank or a neighbour
    assert everywhere(np.array_equal(out["chk"], np.sin(out["id"].astype(float))))
    assert everywhere(np.array_equal(out["F"][:, 1, 1], out["id"].astype(float)))
    assert everywhere(np.all(out["dest"] == rank) and np.all(np.abs(out["src"] - rank) <= 1))
    cells = np.floor(out["x"][:, 0]).astype(np.int64)
    assert everywhere(np.all(decomp.owner_of_columns(cells) == rank))
    # Staying rows first, then from lower, then from upper; each group in original order
    group = np.select([out["src"] == rank, out["src"] == rank - 1], [0, 1], 2)
    assert everywhere(np.all(np.diff(group) >= 0))
    for g in range(3):
        assert everywhere(np.all(np.diff(out["id"][group == g]) > 0))


@parallel_only
def test_migrate_into_and_out_of_empty_ranks():
    decomp = SlabDecomposition(comm, (16, 5), axis=0, ghost=2)
    rank, n = decomp.rank, 0 if decomp.rank == 1 else 5
    fields = {"id": decomp.exscan_sum(n) + np.arange(n), "v": np.ones((n, 2))}
    # Everything neighbouring rank 1 goes to rank 1; rank 1 had nothing
    dest = np.full(n, 1 if abs(rank - 1) <= 1 else rank)
    out = decomp.migrate(fields, dest)
    total = decomp.allreduce_sum(n)
    assert decomp.allreduce_sum(len(out["id"])) == total
    # Ranks 0 and 2 emptied themselves into rank 1; ranks above 2 kept theirs
    expect_here = {0: 0, 1: 5 * (1 + (decomp.size > 2)), 2: 0}.get(rank, 5)
    assert everywhere(len(out["id"]) == expect_here)
    # And back out: rank 1 sends everything to rank 0
    back = decomp.migrate(out, np.full(len(out["id"]), 0 if rank == 1 else rank))
    assert decomp.allreduce_sum(len(back["id"])) == total
    assert everywhere(rank != 1 or len(back["id"]) == 0)


@parallel_only
def test_migrate_without_movement_returns_inputs():
    decomp = SlabDecomposition(comm, (16, 5), axis=0, ghost=1)
    fields = {"x": np.arange(6.0).reshape(3, 2)}
    out = decomp.migrate(fields, np.full(3, decomp.rank))
    assert everywhere(out["x"] is fields["x"])
    assert everywhere(decomp.bytes_sent["migration"] == 8 * _neighbours(decomp))


def test_migrate_rejects_far_destination():
    decomp = SlabDecomposition(comm, (16, 5), axis=0, ghost=1)
    with pytest.raises(RuntimeError, match="not neighbours"):
        decomp.migrate({"x": np.zeros(2)}, np.array([decomp.rank, comm.size + 3]))


# ---------------------------------------------------------------------- alltoallv
def _mixed_fields(rank, n):
    idx = np.arange(n, dtype=np.int64)
    return {
        "pos": np.stack([idx + 0.5, rank + 0.25 * idx], axis=1),
        "idx": idx,
        "src": np.full(n, rank, dtype=np.int32),
        "nbr": (idx[:, None] * 3 + np.arange(3)).astype(np.int32),
        "flag": (idx % 2).astype(np.int8),
        "F": idx[:, None, None] * np.ones((n, 2, 2)) + rank,
        "mass": 1.0 + idx * rank,
    }


def test_alltoallv_round_trip_mixed_dtypes():
    rank, size = comm.rank, comm.size
    n = 0 if rank == 1 else 7 + 2 * rank
    fields = _mixed_fields(rank, n)
    dest = np.random.default_rng(3 + rank).integers(0, size, n)
    got = alltoallv_fields(comm, fields, dest)

    assert comm.allreduce(len(got["idx"])) == comm.allreduce(n)
    assert everywhere(list(got) == list(fields))
    assert everywhere(_same_layout(got, fields))
    # Grouped by source in rank order, each source's rows in original order
    src, idx = got["src"].astype(np.int64), got["idx"]
    key = src * 10**6 + idx
    assert everywhere(np.all(np.diff(key) > 0))
    for k, arr in got.items():
        expected = np.concatenate([_mixed_fields(s, 40)[k][idx[src == s]] for s in range(size)])
        assert everywhere(np.array_equal(arr, expected))
    # every row arrived where its source sent it, and every row sent here arrived
    for s in range(size):
        n_s = 0 if s == 1 else 7 + 2 * s
        dest_s = np.random.default_rng(3 + s).integers(0, size, n_s)
        assert everywhere(np.array_equal(np.sort(idx[src == s]), np.nonzero(dest_s == rank)[0]))
    # Send everything home again and restore the original order
    back = alltoallv_fields(comm, got, got["src"].astype(np.int64))
    order = np.argsort(back["idx"], kind="stable")
    assert everywhere(all(np.array_equal(back[k][order], fields[k]) for k in fields))


def test_alltoallv_all_empty():
    fields = {"x": np.empty((0, 2)), "i": np.empty(0, dtype=np.int8)}
    got = alltoallv_fields(comm, fields, np.empty(0, dtype=int))
    assert everywhere(got["x"].shape == (0, 2) and got["i"].dtype == np.int8)


# ---------------------------------------------------------------------- rebalance
@parallel_only
def test_rebalance_improves_imbalance_and_redistributes():
    ncols = 40
    decomp = SlabDecomposition(comm, (ncols, 6), axis=0, ghost=2)
    weights = np.where(np.arange(ncols) < 8, 100, 1).astype(np.int64)
    # One particle per unit of weight, held by the current owner of its column
    n0, n1 = decomp.owned
    cols = np.repeat(np.arange(n0, n1), weights[n0:n1])
    before = decomp.imbalance(len(cols))

    assert everywhere(decomp.rebalance(weights))
    n0, n1 = decomp.owned
    after = decomp.imbalance(weights[n0:n1].sum())
    assert everywhere(after < before)
    assert everywhere(after <= 1.0 + weights.max() / weights.mean() / ncols * decomp.size)
    assert everywhere(np.diff(decomp.bounds).min() >= decomp.ghost)
    assert everywhere(decomp.window == (max(n0 - 2, 0), min(n1 + 2, ncols)))
    assert everywhere(not decomp.rebalance(weights))

    moved = alltoallv_fields(comm, {"col": cols}, decomp.owner_of_columns(cols))
    assert everywhere(np.all((moved["col"] >= n0) & (moved["col"] < n1)))
    assert everywhere(len(moved["col"]) == weights[n0:n1].sum())


def test_imbalance_and_reductions():
    decomp = SlabDecomposition(comm, (8, 3), axis=0, ghost=1)
    size, rank = decomp.size, decomp.rank
    assert everywhere(decomp.imbalance(0.0) == 1.0)
    expected = (size - 1 + 1.0) / ((size - 1) / 2 + 1.0)
    assert everywhere(np.isclose(decomp.imbalance(rank + 1.0), expected))
    assert everywhere(decomp.allreduce_sum(rank) == size * (size - 1) // 2)
    assert everywhere(decomp.allreduce_max(float(rank)) == size - 1)
    assert everywhere(np.array_equal(decomp.allreduce_min(np.array([rank, -rank])), [0, 1 - size]))
    assert everywhere(decomp.exscan_sum(2) == 2 * rank)


# ----------------------------------------------------------------------- counters
@parallel_only
def test_counters_count_halo_and_migration_bytes():
    decomp = SlabDecomposition(comm, (12, 4), axis=0, ghost=2)
    arr = np.zeros(decomp.window_shape + (3,))
    (n0, n1), (w0, w1) = decomp.owned, decomp.window
    neighbours = _neighbours(decomp)
    row = 4 * 3 * 8  # bytes of one node column

    decomp.accumulate(arr)
    ghost_cols = (n0 - w0) + (w1 - n1)
    assert everywhere(decomp.bytes_sent["halo"] == ghost_cols * row)
    assert everywhere(decomp.messages_sent["halo"] == neighbours)
    decomp.fill(arr)
    edge_cols = 2 * neighbours  # slabs are at least ghost wide
    assert everywhere(decomp.bytes_sent["halo"] == (ghost_cols + edge_cols) * row)
    assert everywhere(decomp.messages_sent["halo"] == 2 * neighbours)
    assert everywhere(decomp.comm_time > 0)

    # Rank 0 sends two rows of 16 + 1 bytes up; everyone swaps one count per neighbour
    n = 4 if decomp.rank == 0 else 0
    fields = {"x": np.zeros((n, 2)), "f": np.zeros(n, np.int8)}
    dest = np.array([0, 1, 1, 0])[:n]
    decomp.migrate(fields, dest)
    extra = 2 * 17 if decomp.rank == 0 else 0
    assert everywhere(decomp.bytes_sent["migration"] == 8 * neighbours + extra)
    assert everywhere(decomp.messages_sent["migration"] == neighbours + (decomp.rank == 0))

    decomp.reset_counters()
    assert everywhere(decomp.bytes_sent == {"halo": 0, "migration": 0})
    assert everywhere(decomp.messages_sent == {"halo": 0, "migration": 0})
    assert everywhere(decomp.comm_time == 0.0)


if __name__ == "__main__":
    import sys

    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
