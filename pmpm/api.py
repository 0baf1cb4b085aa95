"""Python API: run a scene and get its results as arrays, from a script or a notebook.

    import pmpm
    res = pmpm.run("cases/bar.toml", overrides={"solver.end_time": 2.5})
    res.histories["free_end"]["ux"]      # numpy array (pandas column when pandas is installed)

``overrides`` use the syntax of a scene's ``[variants.<name>]`` tables (dotted keys, applied
by :func:`pmpm.scene.config.apply_overrides`, the same code), after the chosen variant's own
overrides.  See docs/api.md.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

__all__ = ["run", "Result", "load_results"]


def _scenes(scene, overrides, variant):
    """The scenes to run: a path or TOML dict with overrides applied, or a ready Scene; every
    one through the checks of names and paths the CLI makes (pmpm.scene.config.resolve_scenes)."""
    from pmpm.scene.config import Scene, check_run_names, read_toml, resolve_scenes

    if isinstance(scene, Scene):
        if overrides:
            raise TypeError("overrides need the scene as a path or a dict of TOML data, not a Scene "
                            "(a Scene is already resolved)")
        check_run_names([scene])
        # a Scene built or changed in Python never passed the parser's bounds: checked here
        from pmpm.scene.limits import check_work_bounds
        check_work_bounds(scene)
        return [scene]
    if isinstance(scene, (str, os.PathLike)):
        path = os.fspath(scene)
        data = read_toml(path)
    elif isinstance(scene, dict):
        path, data = "<scene>", scene
    else:
        raise TypeError(f"scene must be a path, a dict of TOML data or a Scene, not {type(scene).__name__}")
    if overrides is not None and not isinstance(overrides, dict):
        raise TypeError(f"overrides must be a dict of dotted keys, not {type(overrides).__name__}")
    return resolve_scenes(data, path, variant, overrides)


def _check_arguments(write, progress, comm, dataframes):
    """Refuse arguments of the wrong kind in one ConfigError naming the argument (before
    anything is read or written), as the command line refuses a bad option."""
    from pmpm.errors import ConfigError

    if not isinstance(write, bool):
        raise ConfigError("write", f"must be True or False, not {type(write).__name__}")
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise ConfigError("progress", f"must be True, False or a callable, not {type(progress).__name__}")
    if not (dataframes is None or isinstance(dataframes, bool)):
        raise ConfigError("dataframes", f"must be None, True or False, not {type(dataframes).__name__}")
    if comm is not None:
        from mpi4py import MPI
        if not isinstance(comm, MPI.Comm) or comm == MPI.COMM_NULL:
            raise ConfigError("comm", f"must be an mpi4py communicator (e.g. MPI.COMM_WORLD), "
                                      f"not {type(comm).__name__}")


def _progress_callback(progress):
    """Return ``callback(t, end_time)`` or None for the ``progress`` argument of :func:`run`."""
    if progress is None or progress is False:
        return None
    if callable(progress):
        return progress
    try:
        from tqdm.auto import tqdm  # a notebook widget in Jupyter, a text bar elsewhere
    except ImportError:
        tqdm = None
    state = {}

    def show(t, end):
        done = t >= end * (1 - 1e-9)  # the run stops within a rounding error of its end time
        if tqdm is not None:
            bar = state.get("bar") or state.setdefault("bar", tqdm(total=end, unit="s", unit_scale=True))
            bar.update(t - bar.n)
            if done:
                bar.close()
                state.pop("bar")  # the next run (variant) gets its own bar
            return
        end_char = "\n" if done else "\r"
        sys.stderr.write(f"pmpm: t = {t:.4g} s of {end:.4g} s ({100 * t / end:5.1f}%){end_char}")
        sys.stderr.flush()

    return show


def _collecting_run(scene, comm, write, callback):
    """A :class:`pmpm.runner.Run` that also keeps frames in memory (without output) and reports
    progress to ``callback``."""
    from pmpm.io._parallel import fill_value
    from pmpm.runner import Run

    class CollectingRun(Run):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.frames = []
            self._last_report = -np.inf

        def write_frame(self):
            if self.output is not None:
                return super().write_frame()
            p = self.solver.particles
            mine = {f: p[f].copy() for f in self._frame_fields()}
            gathered = self.comm.gather(mine, root=0)
            if self.rank == 0:
                n = self.solver.n_total
                frame = {}
                for name, a in mine.items():
                    rows = np.full((n,) + a.shape[1:], fill_value(a.dtype), a.dtype)
                    for part in gathered:
                        rows[part["id"]] = part[name]
                    frame[name] = rows
                self.frames.append((self.solver.t, self.solver.step_count, frame))

        def record_history(self):
            e = super().record_history()
            now = time.perf_counter()
            if callback is not None and self.rank == 0 and now - self._last_report >= 0.2:
                self._last_report = now
                callback(self.solver.t, self.scene.solver.end_time)
            return e

    return CollectingRun(scene, comm, write=write)


def run(scene, overrides=None, write=False, variant=None, progress=None, comm=None, dataframes=None):
    """Run a scene and return its results.

    Parameters
    ----------
    scene : str, os.PathLike, dict or pmpm.scene.config.Scene
        Scene file (TOML), its parsed TOML data, or a scene from :func:`pmpm.load_scene`.
    overrides : dict, optional
        Dotted-key overrides, as in ``[variants.<name>]``: ``{"solver.cfl": 0.3,
        "materials.steel.E": 200e9}``; applied after the variant's.  Not with a Scene.
    write : bool, optional
        Write the results file and XDMF sidecar into the scene's output directory
        (False, the default, keeps everything in memory and writes nothing).
    variant : str, optional
        Run only this variant; by default every variant of a scene that has some.
    progress : bool or callable, optional
        True shows a progress bar (tqdm's, notebook-aware, when tqdm is installed;
        else a line on stderr); a callable is called as ``progress(t, end_time)``
        (simulation times, s) a few times a second (a run that a ``[[stop]]``
        ends reports last with ``end_time = t``).
    comm : mpi4py.MPI.Comm, optional
        Ranks that run it (default: every rank); results are complete on rank 0.
    dataframes : bool, optional
        Return tables as pandas DataFrames; default: when pandas is installed.

    Returns
    -------
    Result or dict of str to Result
        One :class:`Result`, or, when the scene has variants and none is chosen,
        one per variant name.

    Raises
    ------
    pmpm.errors.ConfigError
        For a bad scene or override (the message names the key, e.g.
        ``overrides.solver.cfl``).
    pmpm.errors.UnstableRunError, pmpm.errors.ParticleExitError
        When the run fails (its last good state is saved when writing).
    """
    _check_arguments(write, progress, comm, dataframes)
    scenes = _scenes(scene, overrides, variant)
    callback = _progress_callback(progress)
    results = {}
    for sc in scenes:
        r = _collecting_run(sc, comm, write, callback)
        summary = r.execute()
        if callback is not None and r.rank == 0:
            # a run ended by [[stop]] ends before its end time: its last report says t = end
            callback(r.solver.t, r.solver.t if summary["stopped"] else sc.solver.end_time)
        if write:
            res = load_results(r.path, dataframes=dataframes) if r.rank == 0 else None
        else:
            res = _from_memory(r, dataframes) if r.rank == 0 else None
        if res is not None:
            res.scene, res.summary, res.stopped = sc, summary, summary["stopped"]
        results[sc.variant] = res
    if len(scenes) == 1 and (variant is not None or not scenes[0].variant):
        return results[scenes[0].variant]
    return results


# ---------------------------------------------------------------------------------- results
def _use_pandas(dataframes):
    if dataframes is False:
        return None
    try:
        import pandas
    except ImportError:
        if dataframes:
            raise
        return None
    return pandas


def _table(columns, pandas):
    """A DataFrame, or a numpy structured array, of equal-length 1-D columns."""
    if pandas is not None:
        return pandas.DataFrame(columns)
    names = list(columns)
    table = np.empty(len(next(iter(columns.values()))) if columns else 0,
                     dtype=[(n, np.asarray(columns[n]).dtype) for n in names])
    for n in names:
        table[n] = columns[n]
    return table


class Result:
    """The results of one run: histories, energies, frames (row i = particle id i).

    Attributes
    ----------
    scene : Scene or None
        The scene that ran (None for :func:`load_results`).
    path : str or None
        The results file (None when nothing was written).
    summary : dict or None
        Steps, end time, wall time, particles, removed particles, ``end_reason``
        (``"end_time"``, ``"max_steps"`` or ``"stop"``) and ``stopped`` (below).
    stopped : dict or None
        When a ``[[stop]]`` condition ended the run: ``reason`` (the log line's text),
        ``time`` (s), ``step``, ``track``, ``quantity``, ``value``, ``threshold`` and
        ``side`` (``"above"`` or ``"below"``); None when it ran to its end.
    histories : dict of str to table
        Per track: columns ``time``, ``ux``, ``uy``, ``vx``, ``vy``, ``x``, ``y``,
        ``sxx``, ``syy``, ``sxy`` (SI units, see docs/output.md).
    track_ids : dict of str to int
        Id of the particle each track follows.
    energies : table
        ``time``, ``kinetic``, ``strain_energy``, ``plastic_work``, ... (J).
    frame_times : numpy.ndarray, shape (F,)
    frames : dict of str to numpy.ndarray, shape (F, n_total, ...)
        Frame fields, row ``i`` the particle with id ``i`` (NaN or -1 where removed).
    sections, reactions : dict of str to table
        The structural tables of the run's ``[[output.section]]`` cuts (``time``,
        ``N``, ``V``, ``M``) and reactions (``time``, ``Rx``, ``Ry``, ``M``), by name;
        empty when the scene asks for none (docs/structural_results.md).
    fractures : dict of str to table
        With ductile fracture and structural tables: each body's (member's) count of failed
        points over time (``time``, ``failed``), by body name;
        :func:`pmpm.results.recorder.first_fracture` gives each member's first fracture.
    series : dict of str to table
        Every series group (:meth:`pmpm.io.OutputFile.add_series`) other than energies.

    A *table* is a pandas DataFrame when pandas is installed (and ``dataframes`` was
    not False), else a numpy structured array; both index by column name.
    """

    def __init__(self, histories, track_ids, energies, frame_times, frames, series=None,
                 path=None, scene=None, summary=None, pandas=None, structural=None, stopped=None):
        self.histories, self.track_ids, self.energies = histories, track_ids, energies
        self.frame_times = frame_times
        self._frames = frames
        self.series = series or {}
        structural = structural or {}
        self.sections = {n: _table(t, pandas) for n, t in structural.get("sections", {}).items()}
        self.reactions = {n: _table(t, pandas) for n, t in structural.get("reactions", {}).items()}
        self.fractures = {n: _table(t, pandas) for n, t in structural.get("fracture", {}).items()}
        self.path, self.scene, self.summary = path, scene, summary
        self.stopped = stopped
        self._pandas = pandas

    @property
    def frames(self):
        if callable(self._frames):  # file-backed: read on first use
            self._frames = self._frames()
        return self._frames

    def frame(self, index):
        """One frame as a table: a column per scalar and per named component.

        Parameters
        ----------
        index : int
            Frame index (negative counts from the end).

        Returns
        -------
        table
            Rows in particle-id order; columns e.g. ``id``, ``x``, ``y``, ``vx``,
            ``vy``, ``sxx``, ``syy``, ``sxy``, ``szz``, ``exx``, ``eyy``, ``gxy``.
        """
        from pmpm.io.hdf5 import component_names

        columns = {}
        for name, values in self.frames.items():
            row = values[index]
            names = component_names(name, row.shape[1:])
            if row.ndim == 1:
                columns[name] = row
            for k, label in enumerate(names):
                columns[label if label not in columns else f"{name}.{label}"] = row[:, k]
        return _table(columns, self._pandas)

    def __repr__(self):
        n = len(self.frame_times)
        e = self.energies
        columns = list(e.columns) if hasattr(e, "columns") else list(e.dtype.names)
        return (f"Result({self.path or 'in memory'}, {n} frames, tracks {sorted(self.histories)}, "
                f"energies {columns})")


def _history_tables(times, tracks, columns, pandas):
    return {name: _table({"time": times, **{c: rows[:, k] for k, c in enumerate(columns)}}, pandas)
            for name, rows in tracks.items()}


def _from_memory(r, dataframes):
    """The Result of a run without output, from what the run kept in memory."""
    from pmpm.io.tracking import HISTORY_COLUMNS
    from pmpm.runner import ENERGY_COLUMNS

    pandas = _use_pandas(dataframes)
    times = np.array(r.history_t, dtype=float)
    shape = (len(times), len(r.tracker.names), len(HISTORY_COLUMNS))
    rows = np.array(r.history_rows, dtype=float).reshape(shape)
    tracks = {name: rows[:, k, :] for k, name in enumerate(r.tracker.names)}
    energy = np.array(r.energy_rows, dtype=float).reshape(len(times), len(ENERGY_COLUMNS))
    energies = _table({c: energy[:, k] for k, c in enumerate(ENERGY_COLUMNS)}, pandas)
    frame_times = np.array([t for t, _, _ in r.frames])
    names = list(r.frames[0][2]) if r.frames else []
    frames = {n: np.stack([f[n] for _, _, f in r.frames]) for n in names}
    ids = {name: int(i) for name, i in zip(r.tracker.names, r.tracker.ids)}
    structural = {"sections": {}, "reactions": {}}
    if getattr(r, "structural", None) is not None:  # rows kept in memory without output
        for group, columns in r.structural.drain().items():
            kind, name = group.split("/", 1)
            structural.setdefault(kind, {})[name] = columns
    return Result(_history_tables(times, tracks, list(HISTORY_COLUMNS), pandas), ids, energies,
                  frame_times, frames, pandas=pandas, structural=structural)


def load_results(path, dataframes=None):
    """Open a results file written by a run as a :class:`Result` (frames read on first use).

    Parameters
    ----------
    path : str or os.PathLike
        ``<output.directory>/<stem>[_<variant>].h5``.
    dataframes : bool, optional
        As for :func:`run`.

    Returns
    -------
    Result

    Raises
    ------
    ValueError
        If ``path`` is not a pmpm results file.
    """
    import h5py

    from pmpm.io.hdf5 import check_results_file, read_history, read_series
    from pmpm.io.layout import frame_fields

    path = os.fspath(path)
    try:  # the whole layout the reads below use (pmpm.io.validate)
        check_results_file(path)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    pandas = _use_pandas(dataframes)
    times, tracks, columns = read_history(path)
    with h5py.File(path, "r") as f:
        ids = {n: int(d.attrs["particle_id"]) for n, d in f["history"].items()
               if n != "time" and "particle_id" in d.attrs}
        frame_times = f["frames/time"][()]
        complete = np.isfinite(frame_times)
        groups = [n for n, g in f.items() if isinstance(g, h5py.Group) and g.attrs.get("kind") == "series"]
        stopped = _stop_record(f.attrs)

    def frames():
        with h5py.File(path, "r") as f:  # either layout, constants and ids per frame
            return {n: d.read(complete) for n, d in frame_fields(f).items()}

    series = {g: _table(read_series(path, g), pandas) for g in groups}
    energies = series.pop("energies")
    from pmpm.results.post import read_tables
    from pmpm.results.recorder import FRACTURE_COLUMNS, REACTION_COLUMNS, SECTION_COLUMNS
    order = {"sections": SECTION_COLUMNS, "reactions": REACTION_COLUMNS,  # HDF5 lists by name
             "fracture": FRACTURE_COLUMNS}
    structural = {kind: {n: {c: t[c] for c in order[kind] if c in t} for n, t in tables.items()}
                  for kind, tables in read_tables(path).items()}
    return Result(_history_tables(times, tracks, columns, pandas), ids, energies, frame_times[complete],
                  frames, series=series, path=path, pandas=pandas, structural=structural,
                  stopped=stopped)


def _stop_record(attrs):
    """The stop record of a results file's root attributes (``stop_<key>``), or None."""
    from pmpm.runner import STOP_KEYS

    if attrs.get("end_reason") != "stop":
        return None
    plain = {k: attrs[f"stop_{k}"] for k in STOP_KEYS}
    plain = {k: v.item() if isinstance(v, np.generic) else v for k, v in plain.items()}
    return {k: v.decode() if isinstance(v, bytes) else v for k, v in plain.items()}
