"""The run's results file: one HDF5 file per run, written by every rank at once.

Layout
------
Root attributes
    ``scene`` (the resolved scene as a JSON string), ``pmpm_version``, ``n_total``,
    ``io_mode``, ``layout`` (``"pmpm-results-3"``, :mod:`pmpm.io.layout`), ``units`` (``"SI"``),
    ``restart_times`` (after restarts) and every other attribute handed to
    :class:`OutputFile` (dicts and lists of non-numbers as JSON strings).
Every dataset
    carries ``units`` (an SI string, ``"1"`` for dimensionless; for a table of
    columns one string per column) and ``description`` attributes, from
    :mod:`pmpm.io.schema`.
``/frames/time`` (F,) float64, ``/frames/step`` (F,) int64
    Time and step of each frame.  A frame whose ``time`` is NaN was cut short by a
    crash (its fields are undefined); reopening with ``append=True`` drops it.
``/frames/<field>`` (F, n_total, \\*shape)
    One dataset per frame field that changes, chunked ``(1, rows, *shape)``, compressed
    (:data:`COMPRESSION`) and resizable along F; floating-point fields in the writer's
    ``precision`` (``"single"``: float32).  Row ``i`` is the particle with id ``i`` (no
    ``/frames/id``: the ids are the rows); particles that no longer exist (removed from the
    grid) read NaN (floats) or -1 (integers).  Fields with one trailing axis carry a
    ``components`` attribute (e.g. ``sxx syy sxy szz`` for ``stress``).
``/particles/<field>`` (n_total, \\*shape)
    The per-particle constants among the frame fields (:data:`pmpm.io.layout.CONSTANT_FIELDS`:
    ``x0``, ``m``, ``vol0``, ``mat``, ``body``), written once with the first frame, in the
    dtype handed over; every later frame is checked to carry the same values.
    :func:`pmpm.io.layout.frame_fields` reads them (and the implicit ``id``) back per frame.
``/topology/vertices`` (n_total,) int64
    ``0 .. n_total-1``: the explicit Polyvertex connectivity for the XDMF sidecar.
``/history/time`` (S,), ``/history/<track>`` (S, ncols) float64
    Time histories of tracked points; each track's ``columns`` attribute names
    its columns (also stored on ``/history``), ``units`` gives one unit per
    column, and the caller's track attributes (pmpm's runs: ``particle_id``, the
    id of the particle the track follows, and ``point``, the requested point).
``/energies/<column>`` (E,) float64
    Energy balance rows; ``time`` is always one of the columns.  As for frames, the
    time of history and energy rows is written last, so NaN marks a cut-short row.
    ``strain_energy`` is the stored elastic energy (J), unrelated to the strain
    field ``/frames/strain``.
Series groups
    ``/energies`` is one *series group*: a group (attribute ``kind = "series"``)
    of equal-length 1-D datasets, one of them ``time``.  :meth:`OutputFile.add_series`
    adds another (e.g. ``/reactions``) with its units in one call, and
    :meth:`OutputFile.write_series` appends rows to it; restarts truncate them all.
``/views/frame_NNNNN/<name>``
    Added after the run by :func:`pmpm.io.xdmf.write_views`: virtual datasets
    (no data of their own) of one frame of one field or component, for the XDMF
    sidecar (see :mod:`pmpm.io.xdmf`).

Parallel writing
----------------
``mode="mpio"`` opens the file with h5py's ``"mpio"`` driver on ``comm``.  A frame is
written by first moving each particle row, with ONE
:func:`decomposition.alltoallv_fields`, to the rank that owns its id block
(``block_range(n_total, size, r)``), so each rank then writes one contiguous
hyperslab per field in a collective write.  Every rank makes every collective call
(resize, write, flush), including ranks that hold no rows: they select nothing and
still write (h5py issue 965).  Histories and energies are identical on all ranks:
every rank resizes (a collective metadata operation) and rank 0 writes the rows.
``mode="gather"`` is the fallback behind the same interface: rows are gathered to
rank 0, which alone opens the file with plain h5py.  With one rank, ``"mpio"`` uses
the default driver (same layout, no MPI-IO).  The file is flushed after every write
call, so a killed run leaves a readable file up to its last completed write.
"""

from __future__ import annotations

import importlib.metadata
import logging
import os

import h5py
import numpy as np

from pmpm.io import schema
from pmpm.io.layout import CONSTANT_FIELDS, LAYOUT, PARTICLES, READ_LAYOUTS, frame_fields, layout_of
from pmpm.io._parallel import (
    check_all,
    fill_value,
    json_dumps,
    mpio_available,
    owner_bounds,
    to_id_blocks,
    validate_rows,
    write_rows,
)
from pmpm.io.xdmf import add_frame_views, view_specs
from pmpm.io.xdmf import write_document
from pmpm.io.validate import check_hdf5_readable
from pmpm.io.validate import check_results_schema

__all__ = [
    "OutputFile",
    "LayoutError",
    "COMPONENT_NAMES",
    "read_attrs",
    "read_frame",
    "read_history",
    "read_energies",
    "read_series",
    "component_names",
    "check_results_file",
]

logger = logging.getLogger(__name__)

MODES = ("mpio", "gather")
#: ``output.precision``: the element type of the floating-point fields of a frame
PRECISIONS = {"single": np.dtype(np.float32), "double": np.dtype(np.float64)}
#: the filters of every particle dataset (frames and constants): the byte shuffle puts the
#: bytes of equal significance together (sign and exponent bytes of neighbouring particles are
#: alike), then deflate. Parallel HDF5 (>= 1.10.2) writes filtered chunks in collective writes,
#: which is how every frame is written. Level 4: in a one-off trial on the portal frame's frames,
#: higher levels saved almost nothing more (docs/output.md, "What a frame costs").
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}

# Names of the components of known fields, stored as the ``components`` attribute
COMPONENT_NAMES = {
    "x": ("x", "y"),
    "x0": ("x0", "y0"),
    "v": ("vx", "vy"),
    "stress": ("sxx", "syy", "sxy", "szz"),
    "back_stress": ("back_xx", "back_yy", "back_xy", "back_zz"),
    "strain": ("exx", "eyy", "gxy"),
    "F": ("Fxx", "Fxy", "Fyx", "Fyy", "Fzz"),
    "eps_p": ("epxx", "epyy", "gpxy"),
}

_TARGET_CHUNK_BYTES = 1 << 20


def component_names(name, trailing):
    """Return names for the components of a field with one trailing axis.

    Parameters
    ----------
    name : str
        Field name.
    trailing : tuple of int
        Shape of one row.

    Returns
    -------
    tuple of str
        Known names from :data:`COMPONENT_NAMES` when their count matches, else
        ``name_0, name_1, ...``; empty for scalars or higher-rank rows.
    """
    if len(trailing) != 1:
        return ()
    known = COMPONENT_NAMES.get(name, ())
    if len(known) == trailing[0]:
        return tuple(known)
    return tuple(f"{name}_{i}" for i in range(trailing[0]))


def _pmpm_version():
    """Return the installed pmpm version, or ``"unknown"``."""
    try:
        return importlib.metadata.version("pmpm")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def _attr_value(value):
    """Turn ``value`` into something h5py stores as an attribute."""
    if isinstance(value, (str, bytes, bool, int, float, np.generic)):
        return value
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value)
        if arr.dtype.kind in "biuf" and arr.size:
            return arr
        if arr.dtype.kind in "U" and arr.ndim == 1:
            # Lists of names (e.g. column names) stay lists, not one JSON string
            return np.array(list(value), dtype=h5py.string_dtype())
    return json_dumps(value)


def _strings(names):
    """Names as an HDF5 array of variable-length strings."""
    return np.array(list(names), dtype=h5py.string_dtype())


def _describe(dset, units, description):
    """Store ``units`` (a string, or one per column) and ``description`` on ``dset``."""
    dset.attrs["units"] = units if isinstance(units, str) else _strings(units)
    if description:
        dset.attrs["description"] = description


def _early():
    """A dataset creation property list that allocates chunks when the dataset is extended
    (``H5D_ALLOC_TIME_EARLY``), as parallel HDF5 always does. A file written on one rank with
    serial HDF5's default (incremental allocation) cannot be extended by the mpio driver later:
    the collective write of the restarted run fails in Open MPI's ``pwritev`` with EINVAL and
    the ranks hang over a file no longer readable (issue 35, a restart from 1 rank onto 2). So
    a 1-rank run lays its file out the way an N-rank run does."""
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    return dcpl


def _all_early(path):
    """True if every extendible dataset of the HDF5 file ``path`` allocates early (so the mpio
    driver may extend it); False for a file of an older pmpm written on one rank."""
    late = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None:
            if obj.id.get_create_plist().get_alloc_time() != h5py.h5d.ALLOC_TIME_EARLY:
                late.append(name)
    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return not late


class LayoutError(ValueError):
    """A results file a restart cannot append to, or a frame that breaks the layout (a constant
    that changed); its text is the reason the user reads in pmpm's one line."""

    user_reason = True


def _same_where_present(old, new):
    """True if ``new`` equals ``old`` in every row where both hold a particle (not the fill)."""
    if old.size == 0 or new.size == 0:
        return True  # nothing to compare: no rows here (a rank outside the file in gather mode)
    fill = fill_value(new.dtype)
    width = int(np.prod(new.shape[1:], dtype=np.int64))
    flat_old, flat_new = old.reshape(len(old), width), new.reshape(len(new), width)
    if new.dtype.kind == "f":
        present = np.all(np.isfinite(flat_old), axis=1) & np.all(np.isfinite(flat_new), axis=1)
    else:
        present = np.all(flat_old != fill, axis=1) & np.all(flat_new != fill, axis=1)
    return bool(np.array_equal(flat_old[present], flat_new[present]))


def _leading_count(times, t):
    """Return how many leading entries of ``times`` are finite and ``<= t``."""
    ok = np.isfinite(times)
    if t is not None:
        ok &= times <= t
    return len(ok) if ok.all() else int(np.argmin(ok))


class OutputFile:
    """The run's HDF5 results file (frames, histories, energies), written collectively.

    Every method is collective over ``comm``: every rank calls it in the same order,
    with its own particle rows (possibly none) and identical history and energy rows.

    Parameters
    ----------
    path : str or os.PathLike
        File to create (or reopen with ``append=True``).
    comm : mpi4py.MPI.Comm
        Communicator of the ranks that write.
    attrs : dict
        Root attributes; ``"scene"`` (the resolved scene, a dict or a JSON string)
        is stored as a JSON string; rank 0's values are used.
    n_total : int
        Number of particle ids (``0 .. n_total-1``), at least 1.
    frame_fields : dict of str to (tuple, dtype)
        Trailing shape and dtype of each field written in every frame, e.g.
        ``{"x": ((2,), "f8"), "mat": ((), "i4")}``.
    tracks : list of str
        Names of the tracked points.
    history_columns : list of str
        Columns of one history row of a track.
    energy_columns : list of str
        Energy columns; must include ``"time"``.
    mode : {"mpio", "gather"}, optional
        Parallel HDF5 (default) or gather to rank 0.  ``"mpio"`` falls back to
        ``"gather"`` with a warning when h5py lacks parallel HDF5.
    append : bool, optional
        Reopen an existing file (restart) instead of creating it.
    truncate_after : float, optional
        With ``append``, drop frame, history and energy rows with time greater than
        this (rows cut short by a crash are always dropped).
    track_attrs : dict of str to dict, optional
        Extra attributes of each track's dataset, e.g. ``{"tip": {"particle_id": 12}}``.
    xdmf : str or os.PathLike, optional
        Keep this XDMF sidecar current: after each frame, add the frame's views
        (:func:`pmpm.io.xdmf.add_frame_views`, metadata only) and rewrite the sidecar
        (rank 0), so a run that is killed leaves a sidecar of the frames written so far.
        Needs ``x`` among the frame fields.
    precision : {"double", "single"}, optional
        Element type of the floating-point fields that change per frame (``"single"``:
        float32, half the bytes; the constants, histories and energies stay as handed over,
        float64 for pmpm's runs).

    Raises
    ------
    ValueError
        On an unknown mode, bad names, or an existing file whose layout differs.
    """

    def __init__(self, path, comm, attrs, n_total, frame_fields, tracks,
                 history_columns, energy_columns, mode="mpio", append=False,
                 truncate_after=None, track_attrs=None, xdmf=None, precision="double"):
        self.path = os.fspath(path)
        self.xdmf = os.fspath(xdmf) if xdmf is not None and "x" in frame_fields else None
        self._view_specs, self._view_frames = None, []   # the sidecar's frames: (index, time)
        self._sidecar_cache = {}                           # frame -> its XML (xdmf.write_document)
        self.comm = comm
        self.rank, self.size = comm.Get_rank(), comm.Get_size()
        self.mode = self._resolve_mode(mode)
        self.n_total = int(n_total)
        if precision not in PRECISIONS:
            raise ValueError(f"unknown precision {precision!r}; valid: {', '.join(PRECISIONS)}")
        # what the ranks hand over (validated, moved into id order) ...
        self.field_specs = {name: (tuple(shape), np.dtype(dtype))
                            for name, (shape, dtype) in sorted(frame_fields.items())}
        # ... split into the constants, written once, and what each frame stores
        self.const_specs = {n: spec for n, spec in self.field_specs.items() if n in CONSTANT_FIELDS}
        varying = {n: spec for n, spec in self.field_specs.items() if n not in self.const_specs}
        if set(varying) - {"id"}:
            varying.pop("id", None)  # the rows are the ids; existence reads off the fill values
        self.frame_specs = {n: (trailing, PRECISIONS[precision] if dtype.kind == "f" else dtype)
                            for n, (trailing, dtype) in varying.items()}
        self.precision = precision
        self._const_blocks = None  # this rank's id block of each constant, once written or read
        self.tracks = list(tracks)
        self.history_columns = list(history_columns)
        self.energy_columns = list(energy_columns)
        self.track_attrs = {k: dict(v) for k, v in (track_attrs or {}).items()}
        self._check_names()
        # In gather mode only rank 0 touches the file; in mpio mode every rank does
        self._meta = self.mode == "mpio" or self.rank == 0
        self._driver = "mpio" if self.mode == "mpio" and self.size > 1 else None
        self._bounds = owner_bounds(self.n_total, self.size, gather=self.mode == "gather")
        self.file = None
        self.n_frames = self.n_history = self.n_energies = 0
        self.series_columns = {"energies": self.energy_columns}
        attrs = comm.bcast(dict(attrs) if self.rank == 0 else None)
        exists = comm.bcast(os.path.exists(self.path) if self.rank == 0 else None)
        if append and not exists:
            logger.warning("append=True but %s does not exist: creating it", self.path)
        if append and exists and self._driver == "mpio":
            # a file laid out by an older pmpm on one rank cannot be extended in parallel: this
            # run writes it through rank 0 instead (the same rows; see _early)
            serial_only = comm.bcast(self._serial_only() if self.rank == 0 else None)
            if serial_only:
                logger.info("%s was written with serial chunk allocation: appending through rank 0",
                            self.path)
                self.mode, self._meta, self._driver = "gather", self.rank == 0, None
                self._bounds = owner_bounds(self.n_total, self.size, gather=True)
        if append and exists:
            self._guarded(lambda: self._reopen(attrs, truncate_after))
        else:
            self._guarded(lambda: self._create(attrs))
        counts = (self.n_frames, self.n_history, self.n_energies)
        self.n_frames, self.n_history, self.n_energies = comm.bcast(counts)

    # ------------------------------------------------------------------ setup
    def _serial_only(self):
        try:
            return not _all_early(self.path)
        except Exception:  # noqa: BLE001 - unreadable: _reopen says why, on every rank
            return False

    def _resolve_mode(self, mode):
        """Validate ``mode`` and fall back to gather without parallel h5py."""
        if mode not in MODES:
            raise ValueError(f"unknown output mode {mode!r}; valid modes: {', '.join(MODES)}")
        if mode == "mpio" and self.size > 1 and not mpio_available():
            logger.warning("h5py has no parallel HDF5 (driver 'mpio'): using mode 'gather'")
            return "gather"
        return mode

    def _check_names(self):
        """Refuse names that would clash with the layout or HDF5 paths."""
        if self.n_total < 1:
            raise ValueError(f"n_total must be at least 1, got {self.n_total}")
        # Names become HDF5 paths, and time/step are datasets of the same groups
        bad = [n for n in [*self.field_specs, *self.tracks, *self.energy_columns] if not n or "/" in n]
        bad += [n for n in self.field_specs if n in ("time", "step")]
        bad += [n for n in self.tracks if n == "time"]
        if bad:
            raise ValueError(f"invalid field, track or column names: {bad}")
        if "time" not in self.energy_columns:
            raise ValueError(f"energy_columns must include 'time', got {self.energy_columns}")
        if self.tracks and not self.history_columns:
            raise ValueError("history_columns is empty but tracks were given")

    def _guarded(self, fn):
        """Run ``fn`` on the ranks that touch the file; raise everywhere if it fails."""
        error = None
        if self._meta:
            try:
                fn()
            except Exception as exc:  # re-raised below, on every rank
                error = exc
        reasons = self.comm.allgather(None if error is None else (type(error), str(error)))
        failed = [(r, e) for r, e in enumerate(reasons) if e is not None]
        if not failed:
            return
        if self.file is not None:
            self.file.close()
            self.file = None
        if error is not None:
            raise error
        # The other ranks raise the failing rank's exception type, so callers can catch it
        exc_type, text = failed[0][1]
        try:
            exc = exc_type(f"rank {failed[0][0]}: {text}")
        except Exception:
            exc = RuntimeError(f"rank {failed[0][0]}: {exc_type.__name__}: {text}")
        raise exc

    def _open(self, h5mode):
        """Open the file on the ranks that touch it."""
        kwargs = {"driver": "mpio", "comm": self.comm} if self._driver == "mpio" else {}
        self.file = h5py.File(self.path, h5mode, **kwargs)

    def _create(self, attrs):
        """Create the file with empty, resizable datasets (collective metadata)."""
        self._open("w")
        self._write_root_attrs(attrs)
        f = self.file
        frames = f.create_group("frames")
        _describe(frames.create_dataset("time", (0,), "f8", maxshape=(None,), chunks=(1024,), dcpl=_early(),
                                        fillvalue=np.nan), *schema.meta(schema.FIELDS, "time"))
        _describe(frames.create_dataset("step", (0,), "i8", maxshape=(None,), chunks=(1024,), dcpl=_early(),
                                        fillvalue=-1), *schema.meta(schema.FIELDS, "step"))
        for name, (trailing, dtype) in self.frame_specs.items():
            self._create_frame_dataset(frames, name, trailing, dtype)
        if self.const_specs:
            particles = f.create_group(PARTICLES)
            particles.attrs["description"] = ("per-particle constants, row i the particle of id i, "
                                              "written once (the same in every frame)")
            for name, (trailing, dtype) in self.const_specs.items():
                self._create_constant_dataset(particles, name, trailing, dtype)
        self._write_vertices(f)
        hist = f.create_group("history")
        hist.attrs["columns"] = _strings(self.history_columns)
        _describe(hist.create_dataset("time", (0,), "f8", maxshape=(None,), chunks=(1024,), dcpl=_early(),
                                      fillvalue=np.nan), *schema.meta(schema.HISTORY, "time"))
        ncols = len(self.history_columns)
        units = [schema.meta(schema.HISTORY, c)[0] for c in self.history_columns]
        for track in self.tracks:
            dset = hist.create_dataset(track, (0, ncols), "f8", maxshape=(None, ncols),
                                       chunks=(256, ncols), dcpl=_early(), fillvalue=np.nan)
            dset.attrs["columns"] = _strings(self.history_columns)
            _describe(dset, units, f"time history of the tracked point {track!r}, one row per "
                      "/history/time, columns named by 'columns': " + "; ".join(
                          f"{c} ({schema.meta(schema.HISTORY, c)[1] or '?'})" for c in self.history_columns))
            for key, value in self.track_attrs.get(track, {}).items():
                dset.attrs[key] = _attr_value(value)
        self._create_series("energies", {c: schema.meta(schema.ENERGIES, c) for c in self.energy_columns})
        f.flush()
        logger.info("created %s (%s mode, %d particles)", self.path, self.mode, self.n_total)

    def _chunk_rows(self, dtype):
        """Rows of one chunk: up to 1 MB of one component (chunks are one component wide)."""
        return max(1, min(self.n_total, _TARGET_CHUNK_BYTES // dtype.itemsize))

    def _create_frame_dataset(self, frames, name, trailing, dtype):
        """Create ``/frames/<name>`` of shape (0, n_total, *trailing)."""
        rows = self._chunk_rows(dtype)
        # Every row of a frame is written, so writing fill values first is wasted IO. One
        # component per chunk: neighbouring particles' values of one component are alike (and
        # szz of plane stress all zero), so they compress better apart (docs/output.md)
        dset = frames.create_dataset(
            name, (0, self.n_total) + trailing, dtype,
            maxshape=(None, self.n_total) + trailing, chunks=(1, rows) + (1,) * len(trailing), dcpl=_early(),
            fillvalue=fill_value(dtype), fill_time="never", **COMPRESSION)
        self._label(dset, name, trailing)

    def _create_constant_dataset(self, particles, name, trailing, dtype):
        """Create ``/particles/<name>`` of shape (n_total, *trailing), filled with the first frame."""
        rows = self._chunk_rows(dtype)
        dset = particles.create_dataset(
            name, (self.n_total,) + trailing, dtype, chunks=(rows,) + (1,) * len(trailing), dcpl=_early(),
            fillvalue=fill_value(dtype), **COMPRESSION)
        self._label(dset, name, trailing)

    def _label(self, dset, name, trailing):
        """The ``components``, ``units`` and ``description`` attributes of a particle field."""
        comps = component_names(name, trailing)
        if comps:
            dset.attrs["components"] = _strings(comps)
        _describe(dset, *schema.meta(schema.FIELDS, name))

    def _create_series(self, group, columns):
        """Create the series group ``group``: one resizable 1-D dataset per column."""
        grp = self.file.create_group(group)
        grp.attrs["kind"] = "series"
        grp.attrs["columns"] = _strings(columns)  # HDF5 lists members by name; this keeps the order
        for column, (units, description) in columns.items():
            dset = grp.create_dataset(column, (0,), "f8", maxshape=(None,), chunks=(1024,), dcpl=_early(),
                                      fillvalue=np.nan)
            _describe(dset, units, description)

    def add_series(self, group, columns):
        """Add a series group (rows of named columns against time), e.g. ``/reactions``.

        Collective.  On a reopened file (restart) the group must already exist with
        these columns; then nothing is created.

        Parameters
        ----------
        group : str
            Group name (a new top-level group; not ``frames``, ``history``, ...).
        columns : dict of str to str or (str, str)
            Each column's SI units, or ``(units, description)``; must include
            ``"time"`` (units ``"s"``).

        Raises
        ------
        ValueError
            For a bad name, no ``time`` column, or a reopened file whose group differs.
        """
        columns = {c: (v, "") if isinstance(v, str) else tuple(v) for c, v in columns.items()}
        reserved = ("frames", "history", "topology", "views", "energies")
        bad = [c for c in columns if not c or "/" in c]
        if not group or "/" in group or group in reserved or bad:
            raise ValueError(f"invalid series group {group!r} or column names {bad}")
        if "time" not in columns:
            raise ValueError(f"series group {group!r} needs a 'time' column")

        def create():
            if group in self.file:
                missing = sorted(set(columns) - set(self.file[group]))
                if missing:
                    raise ValueError(f"{self.path}: /{group} has no columns {missing}")
                return
            self._create_series(group, columns)
            self.file.flush()

        self._guarded(create)
        self.series_columns[group] = list(columns)

    def write_series(self, group, row):
        """Append one row (or several) to a series group; like :meth:`write_energies`.

        Collective; the data must be identical on all ranks.

        Parameters
        ----------
        group : str
            A group made by :meth:`add_series` (or ``"energies"``).
        row : dict of str to float or array_like
            Value of each column (``"time"`` included); columns left out are NaN.

        Returns
        -------
        int
            Number of rows appended.
        """
        known = self.series_columns.get(group)
        if known is None:
            raise ValueError(f"no series group {group!r}; known: {sorted(self.series_columns)}")
        unknown = sorted(set(row) - set(known))
        if unknown:
            raise ValueError(f"unknown {group} columns {unknown}; known: {known}")
        given = {c: np.atleast_1d(np.asarray(v, dtype="f8")) for c, v in row.items()}
        lengths = {len(v) for v in given.values()}
        if len(lengths) > 1:
            raise ValueError(f"{group} columns have different lengths: {sorted(lengths)}")
        k = lengths.pop() if lengths else 1
        return self._append_rows(group, {c: given.get(c, np.full(k, np.nan)) for c in known})

    def _write_vertices(self, f):
        """Write ``/topology/vertices`` (0..n_total-1), each rank its own block."""
        dset = f.create_dataset("topology/vertices", (self.n_total,), "i8")
        _describe(dset, "1", "particle ids 0..n_total-1: the Polyvertex connectivity of the XDMF sidecar")
        start, stop = int(self._bounds[self.rank]), int(self._bounds[self.rank + 1])
        write_rows(dset, (), start, np.arange(start, stop, dtype=np.int64), self._driver == "mpio")

    def _write_root_attrs(self, attrs):
        """Store the scene, the version and the caller's attributes on the root."""
        merged = {"pmpm_version": _pmpm_version()}
        merged.update(attrs)
        merged.update(layout=LAYOUT, n_total=self.n_total, io_mode=self.mode, units="SI")
        if "scene" in merged and not isinstance(merged["scene"], str):
            merged["scene"] = json_dumps(merged["scene"])
        for key, value in merged.items():
            self.file.attrs[key] = _attr_value(value)

    def _reopen(self, attrs, truncate_after):
        """Reopen for a restart: check the layout, drop rows after ``truncate_after``."""
        self._open("r+")
        self._check_layout()
        f = self.file
        self.n_frames = _leading_count(f["frames/time"][:], truncate_after)
        self.n_history = _leading_count(f["history/time"][:], truncate_after)
        self.n_energies = _leading_count(f["energies/time"][:], truncate_after)
        counts = [("frames", self.n_frames), ("history", self.n_history)]
        # every series group (energies and any added later) is truncated by its own times
        counts += [(name, _leading_count(grp["time"][:], truncate_after)) for name, grp in f.items()
                   if isinstance(grp, h5py.Group) and grp.attrs.get("kind") == "series"]
        for group, n in counts:
            for dset in f[group].values():
                if dset.shape[0] != n:
                    dset.resize(n, axis=0)
        if "views" in f:
            del f["views"]  # they describe the old frames (rebuilt below, or by write_xdmf)
        if self.xdmf:
            times = f["frames/time"][:self.n_frames]
            for frame in np.flatnonzero(np.isfinite(times)):
                self._add_views(int(frame), float(times[frame]))
        self._write_root_attrs(attrs)
        restarts = list(f.attrs.get("restart_times", []))
        restarts.append(np.nan if truncate_after is None else float(truncate_after))
        f.attrs["restart_times"] = np.array(restarts, dtype="f8")
        f.flush()
        logger.info("reopened %s after t=%s: %d frames, %d history rows, %d energy rows",
                    self.path, truncate_after, self.n_frames, self.n_history, self.n_energies)

    def _check_layout(self):
        """Raise ValueError if the existing file does not match this writer's layout."""
        f, problems = self.file, []
        layout = layout_of(f)
        if layout != LAYOUT:
            # an older layout is read (pmpm.io.layout) but never extended: one file, one layout
            raise LayoutError(f"written by an older pmpm (layout {layout!r}); a restart "
                             f"appends only to {LAYOUT!r} files: run the scene afresh")
        if int(f.attrs.get("n_total", -1)) != self.n_total:
            problems.append(f"n_total {f.attrs.get('n_total')} != {self.n_total}")
        for name, (trailing, dtype) in self.frame_specs.items():
            dset = f.get(f"frames/{name}")
            if dset is None or dset.shape[1:] != (self.n_total,) + trailing or dset.dtype != dtype:
                problems.append(f"frame field {name!r} missing or of another shape/dtype")
        for name, (trailing, dtype) in self.const_specs.items():
            dset = f.get(f"{PARTICLES}/{name}")
            if dset is None or dset.shape != (self.n_total,) + trailing or dset.dtype != dtype:
                problems.append(f"constant {name!r} missing or of another shape/dtype")
        for track in self.tracks:
            dset = f.get(f"history/{track}")
            if dset is None or dset.shape[1] != len(self.history_columns):
                problems.append(f"history track {track!r} missing or of another width")
        problems += [f"energy column {c!r} missing" for c in self.energy_columns
                     if f"energies/{c}" not in f]
        # Datasets this writer would not extend would fall out of step with the time axis
        for group, names in (("frames", ["time", "step", *self.frame_specs]),
                             ("history", ["time", *self.tracks]), ("energies", self.energy_columns)):
            extra = sorted(set(f[group]) - set(names))
            if extra:
                problems.append(f"/{group} has datasets this run does not write: {extra}")
        if problems:
            raise ValueError(f"{self.path} does not match the run's output layout: " + "; ".join(problems))

    # ------------------------------------------------------------------ writing
    def write_frame(self, time, step, fields):
        """Append one frame: every frame field of every particle, in id order.

        Collective: every rank calls it with its own rows, also with none.

        Parameters
        ----------
        time : float
            Simulation time (rank 0's value is stored).
        step : int
            Step number (rank 0's value is stored).
        fields : dict of str to numpy.ndarray
            This rank's particles: ``"id"`` and every frame field, rows in any order;
            extra keys are ignored.

        Raises
        ------
        ValueError
            On every rank, if any rank's fields are missing, misshapen, carry ids
            outside ``[0, n_total)`` or repeat an id.
        """
        message = validate_rows(fields, self.field_specs, self.n_total)
        check_all(self.comm, message is None, message)
        blocks, duplicates = to_id_blocks(self.comm, fields, self.field_specs, self._bounds)
        check_all(self.comm, duplicates == 0, f"{duplicates} particle ids appear more than once")
        index, start = self.n_frames, int(self._bounds[self.rank])
        if self.const_specs:
            self._constants(blocks, start)
        if self._meta:
            frames = self.file["frames"]
            for name in ("time", "step", *self.frame_specs):
                frames[name].resize(index + 1, axis=0)
            for name in self.frame_specs:
                write_rows(frames[name], (index,), start, blocks[name], self._driver == "mpio")
            # time last: a frame with a NaN time was cut short (see the module docs)
            if self.rank == 0:
                frames["step"][index] = int(step)
                frames["time"][index] = float(time)
            if self.xdmf:
                self._add_views(index, self.comm.bcast(float(time)) if self._driver else float(time))
            self.file.flush()
        self.n_frames = index + 1
        if self.xdmf:
            self._guarded(self._refresh_sidecar)

    def _constants(self, blocks, start):
        """Write the constants with the first frame (or read this rank's block of them after a
        restart); later frames must carry the same values for every particle that exists
        (collective; a particle the solver changed is a bug, refused on every rank)."""
        if self._const_blocks is None:
            if self.n_frames == 0:
                if self._meta:
                    for name in self.const_specs:
                        write_rows(self.file[f"{PARTICLES}/{name}"], (), start, blocks[name],
                                   self._driver == "mpio")
                self._const_blocks = {n: blocks[n] for n in self.const_specs}
                return
            stop = int(self._bounds[self.rank + 1])
            self._const_blocks = {n: self.file[f"{PARTICLES}/{n}"][start:stop] if self._meta
                                  else blocks[n][:0] for n in self.const_specs}
        changed = [n for n, old in self._const_blocks.items() if not _same_where_present(old, blocks[n])]
        check_all(self.comm, not changed, f"the per-particle constants {changed} changed between frames",
                  exc=LayoutError)

    def _add_views(self, frame, time):
        """The XDMF views of one frame (every rank that touches the file, same arguments)."""
        if self._view_specs is None:
            self._view_specs = view_specs(self.file)
        add_frame_views(self.file, frame, time, self._view_specs)
        self._view_frames.append((frame, time))

    def _refresh_sidecar(self):
        """Rewrite the XDMF sidecar for the frames that have views (rank 0)."""
        if self.rank == 0:
            write_document(self.path, self.xdmf, self.n_total, self._view_specs, self._view_frames,
                           self._sidecar_cache)

    def _append_rows(self, group, arrays):
        """Grow every dataset of ``group`` by the rows in ``arrays``; rank 0 writes them."""
        k = len(next(iter(arrays.values())))
        check_all(self.comm, self.comm.bcast(k) == k, f"{k} rows here, another count on rank 0")
        if not self._meta:
            return k
        grp = self.file[group]
        old = grp["time"].shape[0]
        for name in arrays:
            grp[name].resize(old + k, axis=0)
        if self.rank == 0:
            # time last, as for frames: rows with a NaN time were cut short
            for name in sorted(arrays, key=lambda n: n == "time"):
                grp[name][old:old + k] = arrays[name]
        self.file.flush()
        return k

    def write_history(self, times, rows):
        """Append history rows of the tracked points.

        Collective; the data must be identical on all ranks.

        Parameters
        ----------
        times : array_like, shape (k,)
            Time of each row.
        rows : dict of str to array_like, shape (k, len(history_columns))
            Rows of each track; tracks left out get NaN rows.

        Raises
        ------
        ValueError
            For an unknown track or a row block of the wrong shape.
        """
        times = np.atleast_1d(np.asarray(times, dtype="f8"))
        unknown = sorted(set(rows) - set(self.tracks))
        if unknown:
            raise ValueError(f"unknown history tracks {unknown}; known: {self.tracks}")
        shape = (len(times), len(self.history_columns))
        arrays = {"time": times}
        for track in self.tracks:
            values = np.asarray(rows.get(track, np.full(shape, np.nan)), dtype="f8")
            if values.size != np.prod(shape):
                raise ValueError(f"history rows of {track!r} have shape {values.shape}, expected {shape}")
            arrays[track] = values.reshape(shape)
        self.n_history += self._append_rows("history", arrays)

    def append_table(self, group, columns, units, attrs=None):
        """Append rows to the table ``group`` (e.g. ``"sections/left_base"``): one 1-D dataset
        per column, created on first use with a ``units`` attribute (SI); ``attrs`` go on
        the group when it is created.

        Collective; the data must be identical on all ranks and include ``"time"``.
        """
        seen = self.__dict__.setdefault("_tables", set())
        if self._meta and group not in self.file:
            grp = self.file.require_group(group)
            for key, value in (attrs or {}).items():
                grp.attrs[key] = value
            for name in columns:
                dset = grp.create_dataset(name, (0,), "f8", maxshape=(None,), chunks=(1024,), dcpl=_early(),
                                          fillvalue=np.nan)
                dset.attrs["units"] = units.get(name, "")
        elif self._meta and group not in seen:  # a restart: drop the rows it recomputes
            grp = self.file[group]
            keep = int(np.sum(grp["time"][()] < np.min(columns["time"])))
            for dset in grp.values():
                dset.resize(keep, axis=0)
        seen.add(group)
        self._append_rows(group, {c: np.asarray(v, dtype="f8") for c, v in columns.items()})

    def write_energies(self, row):
        """Append one energy row, or several at once.

        Collective; the data must be identical on all ranks.

        Parameters
        ----------
        row : dict of str to float or array_like
            Value of each energy column (``"time"`` included), scalars for one row
            or equal-length 1-D arrays for several; columns left out are NaN.

        Raises
        ------
        ValueError
            For an unknown column or columns of different lengths.
        """
        self.n_energies += self.write_series("energies", row)

    def set_attrs(self, attrs, remove=()):
        """Set root attributes (rank 0's values) after deleting those named in ``remove``
        that the file has (a restart's stale ones). Collective."""
        attrs = self.comm.bcast(dict(attrs) if self.rank == 0 else None)

        def write():
            for key in remove:
                if key in self.file.attrs and key not in attrs:
                    del self.file.attrs[key]
            for key, value in attrs.items():
                self.file.attrs[key] = _attr_value(value)
            self.file.flush()

        self._guarded(write)

    def flush(self):
        """Flush the file to disk (collective)."""
        if self._meta and self.file is not None:
            self.file.flush()

    def close(self):
        """Flush and close the file (collective); further writes are errors."""
        if self._meta and self.file is not None:
            self.file.close()
        self.file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return (f"OutputFile({self.path!r}, mode={self.mode!r}, n_total={self.n_total}, "
                f"frames={self.n_frames}, history={self.n_history}, energies={self.n_energies})")


# ---------------------------------------------------------------------- reading
def _opened(h5):
    """Return (file, must_close) for a path or an open h5py.File."""
    if isinstance(h5, h5py.File):
        return h5, False
    return h5py.File(h5, "r"), True


def read_attrs(h5):
    """Return the root attributes of a results file.

    Parameters
    ----------
    h5 : str, os.PathLike or h5py.File
        Results file.

    Returns
    -------
    dict
        Attribute values; strings decoded.
    """
    f, close = _opened(h5)
    try:
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    finally:
        if close:
            f.close()


def read_frame(h5, index, fields=None):
    """Read one frame (rows in id order; removed particles are NaN or -1).

    Parameters
    ----------
    h5 : str, os.PathLike or h5py.File
        Results file.
    index : int
        Frame index (negative counts from the end).
    fields : list of str, optional
        Fields to read; all when omitted.

    Returns
    -------
    time : float
    fields : dict of str to numpy.ndarray
        Shape ``(n_total,) + trailing`` each.
    """
    f, close = _opened(h5)
    try:
        stored = frame_fields(f)  # either layout (pmpm.io.layout), constants and ids expanded
        names = fields or list(stored)
        return float(f["frames/time"][index]), {n: stored[n][index] for n in names}
    finally:
        if close:
            f.close()


def read_history(h5):
    """Read the time histories of the tracked points.

    Parameters
    ----------
    h5 : str, os.PathLike or h5py.File
        Results file.

    Returns
    -------
    times : numpy.ndarray, shape (S,)
    tracks : dict of str to numpy.ndarray, shape (S, ncols)
    columns : list of str
    """
    f, close = _opened(h5)
    try:
        hist = f["history"]
        columns = [c.decode() if isinstance(c, bytes) else str(c) for c in hist.attrs["columns"]]
        tracks = {n: hist[n][()] for n in hist if n != "time"}
        return hist["time"][()], tracks, columns
    finally:
        if close:
            f.close()


def read_series(h5, group):
    """Read the columns of a series group (``"energies"``, or one added by :meth:`OutputFile.add_series`).

    Parameters
    ----------
    h5 : str, os.PathLike or h5py.File
        Results file.
    group : str
        Group name.

    Returns
    -------
    dict of str to numpy.ndarray, shape (E,)
        Columns in the order they were declared (``time`` among them).
    """
    f, close = _opened(h5)
    try:
        grp = f[group]
        order = [c.decode() if isinstance(c, bytes) else str(c) for c in grp.attrs.get("columns", [])]
        names = [c for c in order if c in grp] + [c for c in grp if c not in order]
        return {n: grp[n][()] for n in names}
    finally:
        if close:
            f.close()


def read_energies(h5):
    """Read the energy columns (``time``, ``kinetic``, ``strain_energy``, ...).

    Parameters
    ----------
    h5 : str, os.PathLike or h5py.File
        Results file.

    Returns
    -------
    dict of str to numpy.ndarray, shape (E,)
    """
    return read_series(h5, "energies")


def check_results_file(path):
    """Raise ValueError with a one-line reason unless ``path`` is a pmpm results file.

    Parameters
    ----------
    path : str or os.PathLike

    Raises
    ------
    ValueError
        If the file cannot be opened as HDF5, or lacks pmpm's ``layout`` attribute
        or the ``/frames``, ``/history`` and ``/energies`` groups.
    """
    path = os.fspath(path)
    try:  # a FIFO would block HDF5's open; damaged metadata can crash libhdf5 itself
        check_hdf5_readable(path, _check_results_path)
    except OSError:
        raise ValueError("no such file") from None
    except ValueError as exc:
        if "crashed" in str(exc):
            raise ValueError(f"not a usable pmpm results file: {exc}") from None
        raise
    try:
        f = h5py.File(path, "r")
    except OSError:
        raise ValueError("not an HDF5 file (pmpm results files are HDF5)") from None
    with f:
        try:
            _check_results_open(f)
        except (OSError, RuntimeError, KeyError, TypeError) as exc:  # HDF5 cannot read a part
            raise ValueError(f"not a usable pmpm results file: an object cannot be read "
                             f"({type(exc).__name__})") from None


def _check_results_path(path):
    """The checks, then every attribute of every object: all the metadata pmpm's readers touch
    (run in a forked child first: damaged metadata may crash libhdf5)."""
    with h5py.File(path, "r") as f:
        _check_results_open(f)  # refuses links first, so the walk below follows none
        dict(f.attrs.items())
        f.visititems(lambda name, obj: dict(obj.attrs.items()))


def _check_results_open(f):
    """The checks of :func:`check_results_file` on the open file (ValueError)."""
    layout = layout_of(f)
    if not isinstance(layout, str) or not layout.startswith("pmpm-results-"):
        raise ValueError("not a pmpm results file (no 'layout' attribute of pmpm)")
    if layout not in READ_LAYOUTS:
        raise ValueError(f"results layout {layout!r}, this pmpm reads {', '.join(map(repr, READ_LAYOUTS))} "
                         f"(re-run the scene)")
    missing = [g for g in ("frames", "history", "energies") if g not in f]
    if missing:
        raise ValueError(f"not a complete pmpm results file (no /{missing[0]})")
    try:  # every group, dataset, shape, dtype and attribute the readers use
        check_results_schema(f)
    except ValueError as exc:
        raise ValueError(f"not a usable pmpm results file: {exc}") from None
