"""Serial tests of the slab rule and of the 1-rank decomposition (exchanges are identities)."""

import numpy as np
import pytest
from mpi4py import MPI

from decomposition import (SlabDecomposition, alltoallv_fields, balanced_bounds, block_range,
                           max_ranks)
from decomposition.slab import block_bounds


@pytest.mark.parametrize("n", [0, 1, 2, 7, 10, 64, 101])
@pytest.mark.parametrize("size", [1, 2, 3, 4, 7, 16])
def test_block_range_covers_contiguously(n, size):
    parts = [block_range(n, size, r) for r in range(size)]
    counts = [c for c, _ in parts]
    assert sum(counts) == n
    assert max(counts) - min(counts) <= 1
    assert counts == sorted(counts, reverse=True)
    start = 0
    for count, s in parts:
        assert s == start
        start += count
    assert block_bounds(n, size).tolist() == [s for _, s in parts] + [n]


def test_block_range_matches_blockdist():
    # mpi4py-fft's _blockdist(10, 4, r): counts 3, 3, 2, 2
    assert [block_range(10, 4, r) for r in range(4)] == [(3, 0), (3, 3), (2, 6), (2, 8)]


def _part_weights(weights, bounds):
    prefix = np.concatenate(([0.0], np.cumsum(weights)))
    return np.diff(prefix[bounds])


def _assert_valid(bounds, ncols, size, min_width):
    assert bounds.shape == (size + 1,)
    assert bounds[0] == 0 and bounds[-1] == ncols
    assert np.diff(bounds).min() >= min_width


@pytest.mark.parametrize("size", [1, 2, 3, 4, 8])
def test_balanced_bounds_balances_skewed_weights(size):
    rng = np.random.default_rng(size)
    ncols = 60
    # Skewed: most weight in the first fifth, some noise elsewhere
    weights = rng.integers(0, 5, ncols).astype(float)
    weights[:12] += rng.integers(50, 150, 12)
    bounds = balanced_bounds(weights, size, 1)
    _assert_valid(bounds, ncols, size, 1)
    parts = _part_weights(weights, bounds)
    assert parts.sum() == pytest.approx(weights.sum())
    # Each boundary is within half a column weight of its target
    assert parts.max() <= weights.sum() / size + weights.max() + 1e-9
    # And far better than the even split for this skew
    if size > 1:
        even = _part_weights(weights, block_bounds(ncols, size))
        assert parts.max() < even.max()


def test_balanced_bounds_respects_min_width():
    weights = np.zeros(20)
    weights[0] = 1000.0          # everything in one column
    for size, min_width in [(2, 2), (4, 3), (5, 4), (10, 2), (1, 20)]:
        bounds = balanced_bounds(weights, size, min_width)
        _assert_valid(bounds, 20, size, min_width)


def test_balanced_bounds_zero_weight_is_even_split():
    assert balanced_bounds(np.zeros(10), 4, 1).tolist() == block_bounds(10, 4).tolist()


def test_balanced_bounds_uniform_weight_is_near_even():
    bounds = balanced_bounds(np.ones(12), 4, 1)
    assert bounds.tolist() == [0, 3, 6, 9, 12]


def test_balanced_bounds_too_many_parts():
    with pytest.raises(ValueError, match="at most 3 ranks"):
        balanced_bounds(np.ones(7), 4, 2)


def test_max_ranks():
    assert max_ranks(10, 2) == 5
    assert max_ranks(11, 2) == 5
    assert max_ranks(10, 1) == 10
    assert max_ranks(10, 0) == 10
    assert max_ranks(3, 4) == 0


def test_too_many_ranks_message_gives_largest_count():
    # 4 ranks on 7 columns with ghost 2: the block split gives widths 2, 2, 2, 1
    with pytest.raises(ValueError, match="at most 3 ranks"):
        SlabDecomposition(MPI.COMM_SELF, (7, 5), axis=0, ghost=2, bounds=[0, 2, 4, 6, 7])
    with pytest.raises(ValueError, match="at most 0 ranks"):
        SlabDecomposition(MPI.COMM_SELF, (9, 3), axis=1, ghost=4)


@pytest.fixture(params=[(0, 1), (1, 2), (0, 0)])
def serial(request):
    axis, ghost = request.param
    return SlabDecomposition(MPI.COMM_SELF, (9, 6), axis=axis, ghost=ghost)


def test_serial_layout(serial):
    ncols = serial.n_nodes[serial.axis]
    assert serial.owned == (0, ncols) and serial.window == (0, ncols)
    assert serial.on_lower_boundary and serial.on_upper_boundary
    assert serial.lower == MPI.PROC_NULL and serial.upper == MPI.PROC_NULL
    assert serial.bounds.tolist() == [0, ncols]
    assert serial.owner_of_columns(np.arange(ncols)).tolist() == [0] * ncols


def test_serial_halo_is_identity(serial):
    grid = np.random.default_rng(0).random(serial.window_shape + (3,))
    before = grid.copy()
    view = grid[..., 0:2]
    serial.accumulate(view)
    serial.fill(view)
    serial.accumulate(grid)
    serial.fill(grid)
    np.testing.assert_array_equal(grid, before)
    assert serial.bytes_sent == {"halo": 0, "migration": 0}


def test_serial_migrate_is_identity(serial):
    fields = {"x": np.arange(12.0).reshape(6, 2), "id": np.arange(6)}
    out = serial.migrate(fields, np.zeros(6, dtype=int))
    assert out.keys() == fields.keys()
    for key in fields:
        np.testing.assert_array_equal(out[key], fields[key])
    empty = serial.migrate({"x": np.empty((0, 2))}, np.empty(0, dtype=int))
    assert empty["x"].shape == (0, 2)


def test_serial_migrate_rejects_far_destination(serial):
    with pytest.raises(RuntimeError, match="2 rows on rank 0 go to ranks \\[1, 3\\]"):
        serial.migrate({"x": np.zeros(3)}, np.array([0, 1, 3]))


def test_serial_alltoallv_copies_rows():
    fields = {"x": np.arange(6.0).reshape(3, 2), "flag": np.array([1, 0, 1], np.int8)}
    out = alltoallv_fields(MPI.COMM_SELF, fields, np.zeros(3, dtype=int))
    for key in fields:
        np.testing.assert_array_equal(out[key], fields[key])
        assert out[key].dtype == fields[key].dtype
        assert not np.shares_memory(out[key], fields[key])


def test_serial_reductions_and_rebalance(serial):
    assert serial.allreduce_sum(3) == 3
    assert serial.allreduce_max(2.5) == 2.5
    np.testing.assert_array_equal(serial.allreduce_min(np.array([1, 2])), [1, 2])
    assert serial.exscan_sum(7) == 0
    assert serial.imbalance(0.0) == 1.0
    assert serial.imbalance(5.0) == 1.0
    ncols = serial.n_nodes[serial.axis]
    assert serial.rebalance(np.arange(ncols, dtype=float)) is False
