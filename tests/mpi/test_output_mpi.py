"""MPI tests of pmpm.io: results file, histories, energies, restarts, checkpoints.

Run under 1, 2 and 3 ranks, e.g.::

    mpirun -n 3 --oversubscribe python -m pytest tests/mpi/test_output_mpi.py -q
    mpirun -n 3 --oversubscribe python tests/mpi/test_output_mpi.py

With more than one rank, rank 1 holds ZERO particles in every write, so the
empty-selection collective path is exercised.  A hang in a collective write fails
the run through ``faulthandler.dump_traceback_later`` instead of blocking CI.  Every
assertion is reduced over all ranks first (``everywhere``).
"""

import faulthandler
import os
import shutil
import tempfile

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.io import OutputFile, checkpoint_paths, read_checkpoint, write_checkpoint
from pmpm.io.hdf5 import read_energies, read_history
from pmpm.io.layout import frame_fields

comm = MPI.COMM_WORLD
pytestmark = pytest.mark.mpi(min_size=1)

HANG_TIMEOUT = 120.0  # seconds; a healthy test here takes well under one
EMPTY_RANK = 1
FRAME_FIELDS = {
    "x": ((2,), "f8"),
    "v": ((2,), "f8"),
    "stress": ((4,), "f8"),
    "mat": ((), "i4"),
    "eps_p_eq": ((), "f8"),
}
TRACKS = ["tip", "base"]
HISTORY_COLUMNS = ["ux", "uy"]
ENERGY_COLUMNS = ["time", "kinetic", "strain_energy", "plastic_work", "external_work", "total"]


def everywhere(ok):
    """Return True only if ``ok`` holds on every rank (collective)."""
    return comm.allreduce(bool(ok), op=MPI.LAND)


@pytest.fixture(autouse=True)
def hang_guard():
    """Dump all tracebacks and exit if a test hangs (a skipped collective)."""
    faulthandler.dump_traceback_later(HANG_TIMEOUT, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


@pytest.fixture
def shared_dir():
    """A temporary folder that every rank sees (pytest's tmp_path differs per rank)."""
    path = comm.bcast(tempfile.mkdtemp(prefix="pmpm_io_") if comm.rank == 0 else None)
    yield path
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


# ------------------------------------------------------------------ particles
def _values(ids):
    """Field values as functions of the id, so any layout can be checked."""
    ids = np.asarray(ids)
    f = ids.astype(float)
    return {
        "id": ids.astype(np.int64),
        "x": np.stack([f, -2.0 * f], axis=1),
        "v": np.stack([0.5 * f, np.ones_like(f)], axis=1),
        "stress": f[:, None] + np.array([0.0, 0.25, 0.5, 0.75]),
        "mat": (ids % 3).astype(np.int32),
        "eps_p_eq": 1e-3 * f,
    }


def local_particles(n_total, missing=(), seed=0):
    """This rank's particles: all ids but ``missing``, none on EMPTY_RANK, shuffled."""
    ids = np.array([i for i in range(n_total) if i not in missing], dtype=np.int64)
    holders = [r for r in range(comm.size) if comm.size == 1 or r != EMPTY_RANK]
    mine = ids[np.array([holders[i % len(holders)] for i in range(len(ids))]) == comm.rank] \
        if len(ids) else ids
    np.random.default_rng(seed + comm.rank).shuffle(mine)
    return _values(mine)


def expected_frame(n_total, missing=()):
    """Every frame field in id order, NaN / -1 for missing ids."""
    full = _values(np.arange(n_total))
    for name, arr in full.items():
        if len(missing):
            arr[list(missing)] = np.nan if arr.dtype.kind == "f" else -1
    return full


def new_output(path, n_total, mode="mpio", **kwargs):
    """Create (or reopen) a results file with the test layout."""
    attrs = {"scene": {"name": "test", "dx": 0.1}, "variant": "elastic", "history_columns": HISTORY_COLUMNS}
    return OutputFile(path, comm, attrs,
                      n_total, FRAME_FIELDS, TRACKS, HISTORY_COLUMNS, ENERGY_COLUMNS,
                      mode=mode, **kwargs)


def on_root(fn):
    """Run ``fn`` on rank 0 only and return its bool result on every rank."""
    ok = True
    if comm.rank == 0:
        ok = bool(fn())
    return everywhere(ok)


# ------------------------------------------------------------------ frames
@pytest.mark.parametrize("mode", ["mpio", "gather"])
@pytest.mark.parametrize("n_total", [11, 2])
def test_frame_with_empty_rank_reads_back_in_id_order(shared_dir, mode, n_total):
    # n_total = 2 on 3 ranks also leaves rank 2's id block empty
    path = os.path.join(shared_dir, f"frames_{mode}_{n_total}.h5")
    missing = (7,) if n_total > 7 else ()
    fields = local_particles(n_total, missing)
    if comm.size > 1:
        assert everywhere(comm.rank != EMPTY_RANK or len(fields["id"]) == 0)
    with new_output(path, n_total, mode) as out:
        out.write_frame(0.0, 0, fields)
        out.write_frame(0.5, 10, fields)
        assert everywhere(out.n_frames == 2)
    expected = expected_frame(n_total, missing)

    def check():
        with h5py.File(path, "r") as f:
            assert list(f["frames/time"][()]) == [0.0, 0.5]
            assert list(f["frames/step"][()]) == [0, 10]
            assert f.attrs["variant"] == "elastic" and '"dx": 0.1' in f.attrs["scene"]
            assert list(f.attrs["history_columns"]) == HISTORY_COLUMNS
            assert list(f["frames/stress"].attrs["components"]) == ["sxx", "syy", "sxy", "szz"]
            stored = frame_fields(f)  # mat is a constant, written once (pmpm.io.layout)
            assert "mat" in f["particles"] and "id" not in f["frames"]
            for name in [*FRAME_FIELDS, "id"]:
                got = stored[name][()]
                assert got.shape == (2, n_total) + FRAME_FIELDS.get(name, ((), "i8"))[0]
                for frame in range(2):
                    np.testing.assert_array_equal(got[frame], expected[name])
            np.testing.assert_array_equal(f["topology/vertices"][()], np.arange(n_total))
        return True

    assert on_root(check)


def test_missing_id_reads_nan(shared_dir):
    path = os.path.join(shared_dir, "missing.h5")
    with new_output(path, 9) as out:
        out.write_frame(1.0, 1, local_particles(9, missing=(0, 4, 8)))

    def check():
        with h5py.File(path, "r") as f:
            x, mat = f["frames/x"][0], frame_fields(f)["mat"][0]
        assert np.isnan(x[[0, 4, 8]]).all() and np.isfinite(np.delete(x, [0, 4, 8], axis=0)).all()
        return list(mat[[0, 4, 8]]) == [-1, -1, -1]

    assert on_root(check)


def test_bad_fields_raise_on_every_rank(shared_dir):
    path = os.path.join(shared_dir, "bad.h5")
    with new_output(path, 5) as out:
        fields = local_particles(5)
        if comm.rank == 0:
            fields["x"] = np.zeros((len(fields["id"]), 3))
        with pytest.raises(ValueError, match="shape"):
            out.write_frame(0.0, 0, fields)
        # The file is still usable after the refused write
        out.write_frame(0.0, 0, local_particles(5))
        dup = local_particles(5)
        if comm.rank == 0:
            dup = {k: np.concatenate([v, v[:1]]) if len(v) else v for k, v in dup.items()}
        with pytest.raises(ValueError, match="more than once"):
            out.write_frame(0.1, 1, dup)
        assert everywhere(out.n_frames == 1)


# ------------------------------------------------------------------ histories, energies
@pytest.mark.parametrize("mode", ["mpio", "gather"])
def test_history_and_energies_append(shared_dir, mode):
    path = os.path.join(shared_dir, f"hist_{mode}.h5")
    rows1 = {"tip": np.array([[1.0, 2.0], [3.0, 4.0]]), "base": np.zeros((2, 2))}
    rows2 = {"tip": np.array([[5.0, 6.0]])}  # "base" left out: NaN
    with new_output(path, 4, mode) as out:
        out.write_history([0.1, 0.2], rows1)
        out.write_history([0.3], rows2)
        for i in range(3):
            out.write_energies({"time": 0.1 * i, "kinetic": 1.0 + i, "external_work": 2.0 * i})
        # Several rows in one call
        out.write_energies({"time": [0.3, 0.4], "kinetic": [4.0, 5.0]})
        assert everywhere((out.n_history, out.n_energies) == (3, 5))

    def check():
        times, tracks, columns = read_history(path)
        np.testing.assert_array_equal(times, [0.1, 0.2, 0.3])
        assert columns == HISTORY_COLUMNS
        np.testing.assert_array_equal(tracks["tip"], [[1, 2], [3, 4], [5, 6]])
        assert np.isnan(tracks["base"][2]).all() and (tracks["base"][:2] == 0).all()
        energies = read_energies(path)
        assert sorted(energies) == sorted(ENERGY_COLUMNS)
        np.testing.assert_allclose(energies["kinetic"], [1, 2, 3, 4, 5])
        assert np.isnan(energies["external_work"][3:]).all()
        return np.isnan(energies["strain_energy"]).all()

    assert on_root(check)


# ------------------------------------------------------------------ series groups, units
@pytest.mark.parametrize("mode", ["mpio", "gather"])
def test_added_series_group_with_units_survives_a_restart(shared_dir, mode):
    """A group like /reactions is one add_series call (collective, also on the empty rank),
    carries its units, and is truncated on a restart like the energies."""
    path = os.path.join(shared_dir, f"series_{mode}.h5")
    columns = {"time": "s", "rx": ("N", "horizontal base reaction"), "ry": ("N", "vertical")}
    with new_output(path, 4, mode) as out:
        out.add_series("reactions", columns)
        for i in range(3):
            assert everywhere(out.write_series("reactions", {"time": float(i), "rx": 10.0 * i}) == 1)
        out.write_energies({"time": 0.0, "kinetic": 1.0})
    with new_output(path, 4, mode, append=True, truncate_after=1.0) as out:
        out.add_series("reactions", columns)  # exists: checked, not created again
        out.write_series("reactions", {"time": [1.5, 2.5], "rx": [1.0, 2.0], "ry": [3.0, 4.0]})

    def check():
        with h5py.File(path, "r") as f:
            g = f["reactions"]
            assert g.attrs["kind"] == "series"
            assert list(g["time"][()]) == [0.0, 1.0, 1.5, 2.5]
            assert list(g["rx"][()]) == [0.0, 10.0, 1.0, 2.0] and np.isnan(g["ry"][:2]).all()
            assert g["rx"].attrs["units"] == "N" and g["rx"].attrs["description"] == "horizontal base reaction"
            assert g["time"].attrs["units"] == "s"
            # every dataset of the file says its units
            datasets = []
            f.visititems(lambda name, obj: datasets.append(obj) if isinstance(obj, h5py.Dataset) else None)
            assert len(datasets) > 10  # list.append returns None: visititems saw every dataset
            assert [d.name for d in datasets if "units" not in d.attrs] == []
            assert f["energies/kinetic"].attrs["units"] == "J" and f["frames/stress"].attrs["units"] == "Pa"
        return True

    assert on_root(check)


def test_add_series_refuses_bad_groups(shared_dir):
    with new_output(os.path.join(shared_dir, "series_bad.h5"), 3) as out:
        with pytest.raises(ValueError, match="needs a 'time' column"):
            out.add_series("reactions", {"rx": "N"})
        with pytest.raises(ValueError, match="invalid series group"):
            out.add_series("frames", {"time": "s"})
        with pytest.raises(ValueError, match="no series group"):
            out.write_series("sections", {"time": 0.0})


# ------------------------------------------------------------------ restart
def _times(path, group):
    """The time column of one group, read on rank 0."""
    with h5py.File(path, "r") as f:
        return list(f[f"{group}/time"][()])


@pytest.mark.parametrize("mode", ["mpio", "gather"])
def test_truncate_after_drops_later_rows(shared_dir, mode):
    path = os.path.join(shared_dir, f"restart_{mode}.h5")
    fields = local_particles(6)
    with new_output(path, 6, mode) as out:
        for i in range(4):
            out.write_frame(float(i), 10 * i, fields)
            out.write_energies({"time": float(i), "kinetic": 1.0})
        out.write_history([0.5, 1.5, 2.5], {"tip": np.ones((3, 2))})
    with new_output(path, 6, mode, append=True, truncate_after=1.5) as out:
        assert everywhere((out.n_frames, out.n_history, out.n_energies) == (2, 2, 2))
        out.write_frame(2.0, 20, fields)
        out.write_energies({"time": 2.0, "kinetic": 7.0})
        out.write_history([2.0], {"tip": np.full((1, 2), 9.0)})

    def check():
        assert _times(path, "frames") == [0.0, 1.0, 2.0]
        assert _times(path, "energies") == [0.0, 1.0, 2.0]
        assert _times(path, "history") == [0.5, 1.5, 2.0]
        with h5py.File(path, "r") as f:
            assert list(f["frames/step"][()]) == [0, 10, 20]
            assert f["frames/x"].shape[0] == 3 and list(f.attrs["restart_times"]) == [1.5]
            return list(f["energies/kinetic"][()]) == [1.0, 1.0, 7.0]

    assert on_root(check)


# ------------------------------------------------------------------ every field, both precisions
#: every particle field a run can write (pmpm/io/schema.py), with the solver's dtypes
ALL_FIELDS = {"x": ((2,), "f8"), "x0": ((2,), "f8"), "v": ((2,), "f8"), "m": ((), "f8"),
              "vol": ((), "f8"), "vol0": ((), "f8"), "stress": ((4,), "f8"), "back_stress": ((4,), "f8"),
              "strain": ((3,), "f8"), "eps_p": ((3,), "f8"), "F": ((5,), "f8"), "eps_p_eq": ((), "f8"),
              "plastic_work": ((), "f8"), "damage": ((), "f8"), "fracture_work": ((), "f8"),
              "crack_strain": ((2,), "f8"), "effective_stress": ((4,), "f8"), "mat": ((), "i4"),
              "body": ((), "i4")}
ROUND_TRIP_N, ROUND_TRIP_FRAMES, REMOVED, REMOVED_FROM = 13, 3, 4, 2
#: IEEE single precision rounds to nearest: |fl32(a) - a| <= 2**-24 |a| (unit roundoff)
UNIT_ROUNDOFF_F4 = 2.0 ** -24


def _all_values(ids, frame):
    """Every field as a function of the id and the frame, none exactly representable in float32
    (multiples of pi, offsets of 6 m as the portal frame's positions); constants of the id only."""
    f = ids.astype(float) * np.pi + 6.0
    out = {"id": ids.astype(np.int64)}
    for k, (name, (trailing, dtype)) in enumerate(sorted(ALL_FIELDS.items())):
        width = int(np.prod(trailing, dtype=int))
        lag = 0 if name in ("x0", "m", "vol0", "mat", "body") else frame + 1
        base = f[:, None] * (1.0 + 0.1 * np.arange(width)) + lag * np.e + k * 0.37
        out[name] = (base.astype(dtype) if dtype == "f8" else ids[:, None] % 5 + k).reshape((len(ids),) + trailing)
    return out


def _migrating_particles(frame):
    """This rank's particles of ``frame``: every id but REMOVED from frame REMOVED_FROM on, dealt
    to the ranks anew each frame (as migration moves them), none on EMPTY_RANK in frame 1."""
    ids = np.array([i for i in range(ROUND_TRIP_N) if not (i == REMOVED and frame >= REMOVED_FROM)])
    holders = [r for r in range(comm.size) if comm.size == 1 or frame != 1 or r != EMPTY_RANK]
    owner = np.array([holders[(i + frame) % len(holders)] for i in range(len(ids))])
    mine = ids[owner == comm.rank]
    np.random.default_rng(frame * 7 + comm.rank).shuffle(mine)
    return {k: v.copy() for k, v in _all_values(mine, frame).items()}


@pytest.mark.parametrize("precision", ["double", "single"])
@pytest.mark.parametrize("mode", ["mpio", "gather"])
def test_every_field_round_trips(shared_dir, mode, precision):
    """Every field of every frame reads back (pmpm.io.layout.frame_fields and load_results) as
    written: exactly at double precision and for the constants (written once, float64) and
    integers; within the unit roundoff of IEEE single for the changing floats at single. The
    removed particle reads NaN / -1 from its frame on. Particles change rank between frames.
    Shown to fail: with the constants' first write skipped (hdf5.OutputFile._constants) they
    read the fill value; with the rows stored as float16 instead of float32 the bound fails."""
    from pmpm.api import load_results
    path = os.path.join(shared_dir, f"all_{mode}_{precision}.h5")
    with OutputFile(path, comm, {"scene": "{}"}, ROUND_TRIP_N, ALL_FIELDS, [], [], ["time"], mode=mode,
                    precision=precision) as out:
        for frame in range(ROUND_TRIP_FRAMES):
            out.write_frame(0.1 * frame, frame, _migrating_particles(frame))

    def check():
        result = load_results(path).frames
        with h5py.File(path, "r") as f:
            assert sorted(f["particles"]) == ["body", "m", "mat", "vol0", "x0"]
            assert "id" not in f["frames"] and "x0" not in f["frames"]
            stored = frame_fields(f)
            assert sorted(stored) == sorted([*ALL_FIELDS, "id"])
            for name, field in stored.items():
                dset = f["particles"].get(name) if name in f["particles"] else f["frames"].get(name)
                if dset is not None:  # every particle dataset compressed (the id is implicit)
                    assert dset.compression == "gzip" and dset.shuffle, name
                single = precision == "single" and name in f["frames"] and field.dtype.kind == "f"
                assert field.dtype == (np.float32 if single else np.dtype(ALL_FIELDS.get(name, ((), "i8"))[1]))
                for frame in range(ROUND_TRIP_FRAMES):
                    want = _all_values(np.arange(ROUND_TRIP_N), frame)[name]
                    got = field[frame]
                    np.testing.assert_array_equal(result[name][frame], got)
                    gone = frame >= REMOVED_FROM
                    if gone:
                        assert np.all(np.isnan(got[REMOVED]) if got.dtype.kind == "f" else got[REMOVED] == -1), name
                    keep = np.arange(ROUND_TRIP_N) != REMOVED if gone else slice(None)
                    if single:
                        err = np.abs(got[keep].astype(float) - want[keep])
                        assert np.all(err <= UNIT_ROUNDOFF_F4 * np.abs(want[keep])), (name, err.max())
                        assert np.any(err > 0), name  # really stored in float32
                    else:
                        np.testing.assert_array_equal(got[keep], want[keep])
        return True

    assert on_root(check)


def test_a_changed_constant_is_refused_on_every_rank(shared_dir):
    """The writer stores x0, m, vol0, mat, body once; a frame that carries other values for a
    particle (a solver that changed one) raises on every rank instead of being lost."""
    path = os.path.join(shared_dir, "constants.h5")
    with OutputFile(path, comm, {"scene": "{}"}, ROUND_TRIP_N, ALL_FIELDS, [], [], ["time"]) as out:
        out.write_frame(0.0, 0, _migrating_particles(0))
        fields = _migrating_particles(1)
        fields["m"] = fields["m"] * (1.0 + 1e-12)
        with pytest.raises(ValueError, match=r"per-particle constants \['m'\] changed"):
            out.write_frame(0.1, 1, fields)


def test_append_drops_frame_cut_short_and_checks_layout(shared_dir):
    path = os.path.join(shared_dir, "cut.h5")
    with new_output(path, 5) as out:
        out.write_frame(0.0, 0, local_particles(5))
    if comm.rank == 0:
        # A crash between the resize and the time write leaves a NaN time
        with h5py.File(path, "r+") as f:
            for dset in f["frames"].values():
                dset.resize(2, axis=0)
    comm.Barrier()
    with new_output(path, 5, append=True) as out:
        assert everywhere(out.n_frames == 1)
    with pytest.raises(ValueError, match="n_total"):
        new_output(path, 6, append=True)


# ------------------------------------------------------------------ checkpoints
def _check_block(fields, attrs, sub, n_total, missing, step):
    """Rank ``sub.rank`` of ``sub`` holds exactly the existing ids of its block."""
    from decomposition.slab import block_range

    count, start = block_range(n_total, sub.size, sub.rank)
    ids = [i for i in range(start, start + count) if i not in missing]
    want = _values(np.array(ids, dtype=np.int64))
    ok = attrs["step"] == step and attrs["dt"] == 1e-4 and attrs["n_total"] == n_total
    for name, arr in want.items():
        ok &= fields[name].shape == arr.shape and np.array_equal(fields[name], arr)
    return ok


@pytest.mark.parametrize("mode", ["mpio", "gather"])
def test_checkpoint_reads_back_on_other_rank_counts(shared_dir, mode):
    n_total, missing = 13, (3,)
    base = os.path.join(shared_dir, f"ck_{mode}")
    fields = local_particles(n_total, missing)
    fields["back_stress"] = np.ones((len(fields["id"]), 4))
    written = write_checkpoint(base, comm, 0.25, 40, fields, {"dt": 1e-4, "external_work": 3.5},
                               mode=mode)
    assert everywhere(written == checkpoint_paths(base)[0])
    # One rank (a different count whenever the writer had more than one)
    if comm.rank == 0:
        got, attrs = read_checkpoint(base, MPI.COMM_SELF)
        ok = _check_block(got, attrs, MPI.COMM_SELF, n_total, missing, 40)
        ok &= attrs["external_work"] == 3.5 and attrs["time"] == 0.25
        ok &= got["back_stress"].shape == (n_total - 1, 4)
    else:
        ok = True
    assert everywhere(ok)
    # Sub-communicators of sizes other than the writer's: 3 ranks read as 2 + 1
    sub = comm.Split(color=int(comm.rank >= 2), key=comm.rank)
    got, attrs = read_checkpoint(base, sub)
    assert everywhere(_check_block(got, attrs, sub, n_total, missing, 40))
    sub.Free()


def test_checkpoint_alternates_and_picks_newest_complete(shared_dir):
    base = os.path.join(shared_dir, "alt")
    paths = checkpoint_paths(base)
    fields = local_particles(7)
    slots = [write_checkpoint(base, comm, 0.1 * s, s, fields, {"dt": 1e-4}) for s in (10, 20, 30)]
    # 10 -> slot 0, 20 -> slot 1, 30 replaces the older (step 10) in slot 0
    assert everywhere(slots == [paths[0], paths[1], paths[0]])
    assert everywhere(read_checkpoint(base, comm)[1]["step"] == 30)
    if comm.rank == 0:
        # Corrupt the newest file: garbage over its superblock
        with open(paths[0], "r+b") as fh:
            fh.write(b"\0garbage" * 64)
    comm.Barrier()
    assert everywhere(read_checkpoint(base, comm)[1]["step"] == 20)
    # The next checkpoint goes to the corrupted slot, keeping the intact one
    assert everywhere(write_checkpoint(base, comm, 4.0, 40, fields, {"dt": 1e-4}) == paths[0])
    if comm.rank == 0:
        # A write cut short never sets complete = True
        for path in paths:
            with h5py.File(path, "r+") as f:
                f.attrs["complete"] = False
    comm.Barrier()
    with pytest.raises(ValueError, match="no complete checkpoint"):
        read_checkpoint(base, comm)
    with pytest.raises(FileNotFoundError, match="nope.ckpt0.h5"):
        read_checkpoint(os.path.join(shared_dir, "nope"), comm)


if __name__ == "__main__":
    import sys

    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
