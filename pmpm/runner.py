"""A run of a scene: the solver plus output, histories, progress, checkpoints and failure.

``Run(scene).execute()`` steps the solver to the end time and writes one HDF5 file (frames of
particle fields, time histories of the tracked points, energies), an XDMF sidecar for ParaView,
CSV histories and plots. A run that goes unstable, or whose particles leave the grid, stops on
every rank with a message, writes a checkpoint of its last good state and exits non-zero.

The Python API, ``pmpm.run(scene, overrides=..., write=False)`` (:func:`pmpm.api.run`,
docs/api.md), runs scenes through this class.
"""
import gc
import json
import logging
import math
import os
import sys
import time

import h5py
import numpy as np

from decomposition import alltoallv_fields
from decomposition.slab import block_range
from pmpm import __version__
from pmpm.build import build_solver
from pmpm.core.effects import energy_terms
from pmpm.errors import ConfigError, OutputWriteError, ParticleExitError, UnstableRunError
from pmpm.io import OutputFile, read_checkpoint, write_checkpoint
from pmpm.io.checkpoint import _next_slot, _write_reason, checkpoint_paths, lastgood_path
from pmpm.io.ownership import (ForeignFileError, check_manifest, check_owned, claim_run, protect_input,
                               release_claims, remove_owned, remove_stale_temporaries)
from pmpm.io.tracking import HISTORY_COLUMNS, Tracker
from pmpm.io.validate import safe_to_open_hdf5
from pmpm.results.recorder import UNITS, StructuralRecorder
from pmpm.scene.config import check_written_scene
from pmpm.scene.fingerprint import first_difference, fingerprint, scene_record
from pmpm.scene.names import output_base, run_files, run_name
from pmpm.stop import make_stop_check

__all__ = ["Run", "output_path", "energy_summary"]
logger = logging.getLogger(__name__)

#: the energy columns of the results file: the solver's own energies around the registered
#: energy terms (pmpm.core.effects: a material's dissipation, an effect's work), which every run
#: writes (zero where the scene has no such effect)
ENERGY_COLUMNS = ("time", "kinetic", "strain_energy",
                  *[t.name for t in energy_terms() if not t.outside], "internal_work",
                  *[t.name for t in energy_terms() if t.outside], "external_work", "total", "numerical_loss")
#: the solver's name of an energy where the file's differs (the file keeps "strain" for the field)
_SOLVER_ENERGY = {"strain_energy": "strain"}
#: the energies a checkpoint keeps (rank-local accumulators, saved as their sum over the ranks)
ACCUMULATED = ("external_work", "internal_work", *[t.name for t in energy_terms() if t.outside])


def energy_summary(e):
    """The run summary's energy line: the external work and the numerical loss (J), the loss
    also as a fraction of the energy put in (initial energy plus external work)."""
    # initial energy + external work: by the definition of the loss (pmpm.core.solver), every
    # term it subtracts (each registered energy term: plastic work, damping works, removed
    # energy, ...) plus the loss
    held = [e[t.name] for t in energy_terms()]
    supplied = e["kinetic"] + e["strain"] + sum(held) + e["numerical_loss"]
    share = f" ({100 * e['numerical_loss'] / supplied:.3g}% of the energy put in)" if supplied > 0 else ""
    return (f"external work {e['external_work']:.6g} J, kinetic {e['kinetic']:.6g} J, strain "
            f"{e['strain']:.6g} J, plastic {e['plastic_work']:.6g} J, damping {e['damping_work']:.6g} J, "
            f"numerical loss {e['numerical_loss']:.6g} J{share}")


def output_path(scene):
    """``<output.directory>/<stem>[_<variant>].h5`` (names checked by pmpm.scene.names)."""
    return output_base(scene) + ".h5"


#: the output file and checkpoints of one run, by suffix after ``<stem>[_<variant>]``
RUN_SUFFIXES = (".h5", ".ckpt0.h5", ".ckpt1.h5", ".lastgood.h5")


def _owner(path):
    """(scene file, variant) that wrote a pmpm HDF5 file, or None if unknown / not ours."""
    import h5py
    if not safe_to_open_hdf5(path):  # never opened: a FIFO (would hang), a crashing file
        return None                  # (check_owned then refuses it in one line)
    try:
        with h5py.File(path, "r") as f:
            if "scene_file" in f.attrs:  # results file
                return str(f.attrs["scene_file"]), str(f.attrs.get("variant", ""))
            if "attrs" in f.attrs:        # checkpoint
                a = json.loads(f.attrs["attrs"])
                if "scene_file" in a:
                    return str(a["scene_file"]), str(a.get("variant", ""))
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return None


#: bytes left free beyond a write's estimate (HDF5 metadata, the history rows, the XDMF file)
DISK_MARGIN = 64 * 1024


def _extendable_chunk_bytes(h5file, rows):
    """Bytes of the chunks that the next frame may allocate in an open results file: one row
    more in each dataset of ``frames/``, ``rows`` more in every other growing table (HDF5
    allocates a chunk when a dataset is extended into it). Reads metadata only; called on every
    rank of a file open with the mpio driver (rank 0 alone hung opening its datasets)."""
    total = 0

    def add(name, obj):
        nonlocal total
        if isinstance(obj, h5py.Dataset) and obj.chunks and obj.maxshape and obj.maxshape[0] is None:
            n, c = obj.shape[0], obj.chunks[0]
            grow = 1 if name.startswith("frames/") else rows
            new_chunks = -(-(n + grow) // c) - (-(-n // c))
            total += new_chunks * int(np.prod(obj.chunks, dtype=np.int64)) * obj.dtype.itemsize

    h5file.visititems(add)
    return total


def describe_effects(scene, s):
    """The optional physics ``scene`` switches on in its solver ``s`` (nothing else is compiled
    in): the run header's ``effect on:`` lines, and ``pmpm --check``'s."""
    out = [f"plasticity ({m.name})" for m in s.materials if "plastic_work" in m.state_fields]
    if scene.solver.large_rotations:
        rate = {"jaumann": "Jaumann", "green_naghdi": "Green-Naghdi"}[scene.solver.objective_rate]
        out.append(f"large rotations ({rate} stress rate)" if s.rotates_stress else
                   "large rotations: no stress rotation (every material computes its stress from F)")
    if s.keeps_F:
        out.append("deformation gradient F per particle")
    out += s.effects.describe()       # the effects the scene names (pmpm.core.effects)
    out += s.scheme.describe()
    out += s.transfer.describe()
    out += s.grid_fields.describe()   # contact
    return list(dict.fromkeys(out))   # once each (several materials share a model)


def _over_file_size_limit(path, nbytes, replaces=None):
    """The reason a write of about ``nbytes`` to ``path`` would pass the process's file size
    limit (``ulimit -f``, RLIMIT_FSIZE), or None. Python ignores SIGXFSZ, so such a write fails
    with EFBIG inside HDF5, which then cannot close its file (libhdf5 crashed closing it here):
    the write is refused before it starts, as for a full disk. A file that ``replaces`` names
    is written afresh; any other grows by ``nbytes``."""
    import resource
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if limit == resource.RLIM_INFINITY:
        return None
    size = nbytes + DISK_MARGIN
    if not replaces and os.path.exists(path):
        size += os.path.getsize(path)
    if size > limit:
        return (f"File too large: about {size} bytes, over the file size limit of {limit} bytes "
                f"(ulimit -f)")
    return None


class _quiet_h5py_deallocs:
    """h5py reports an error of releasing an HDF5 id (after a failed write, e.g. on a full
    disk) through ``sys.excepthook`` from a deallocator; under MPI that hook aborts every rank.
    Within this context such reports are only logged: the failed write itself is reported."""

    def __enter__(self):
        self.previous = sys.excepthook
        sys.excepthook = lambda *exc: logger.debug("while releasing HDF5 objects: %s", exc[1])
        return self

    def __exit__(self, *exc):
        sys.excepthook = self.previous
        return False


def _scene_location(scene_path, output):
    """The scene file as seen from the output file's folder: what identifies the run that owns
    an output (a folder copied with its scene keeps it; another scene file never has it)."""
    return os.path.relpath(os.path.abspath(scene_path), os.path.dirname(os.path.abspath(output)))


def _healthy_fields(fields):
    """True if the state a checkpoint would hold is finite (position, velocity, stress, ...)."""
    return all(np.all(np.isfinite(a)) for k, a in fields.items() if a.dtype.kind == "f")


def _accumulated(solver):
    """This rank's shares of the energies a checkpoint keeps (``ACCUMULATED``)."""
    return {k: getattr(solver, k) if k in ("external_work", "internal_work") else solver.effects.energy(k)
            for k in ACCUMULATED}


def _set_accumulated(solver, name, value):
    if name in ("external_work", "internal_work"):
        setattr(solver, name, value)
    else:
        solver.effects.set_energy(name, value)


class _Snapshot:
    """A copy of the particle state a few steps back: what a failed run saves. ``reuse``: the
    snapshot this one replaces, whose arrays it overwrites where the shapes still match (the
    run takes one every energy check: fresh arrays each time cost their page faults too)."""

    def __init__(self, solver, reuse=None):
        old = reuse.fields if reuse is not None else {}
        self.fields = {}
        for k, a in solver.particles.fields.items():
            b = old.get(k)
            if b is not None and b.shape == a.shape and b.dtype == a.dtype:
                np.copyto(b, a)
            else:
                b = a.copy()
            self.fields[k] = b
        self.t, self.step, self.dt = solver.t, solver.step_count, solver.dt
        self.energies = _accumulated(solver)


class Run:
    """One scene run on the ranks of ``comm``.

    Parameters
    ----------
    scene : Scene
    comm : communicator, optional
    write : bool
        False runs without any file output (benchmarks, some tests).
    restart : str, optional
        Output file of an earlier run whose newest checkpoint to continue from.
    """

    def __init__(self, scene, comm=None, write=True, restart=None):
        self.scene = scene
        if write:
            # whoever built the scene (CLI, API, a script): no output name leaves the folder
            check_written_scene(scene)
        self.solver = build_solver(scene, comm)
        self.comm = self.solver.comm
        self.rank = self.comm.Get_rank()
        self.write = write
        self.path = output_path(scene)
        self.restarted_from = None
        self.record = scene_record(scene)
        self.fingerprint = fingerprint(self.record)
        if write:  # first: a restart reads the folder's checkpoints only after the gate's checks
            self._check_own_files()
        if restart:
            try:
                self._restore(restart)
            except BaseException:
                if write:  # refused: this run writes nothing, its claim included
                    release_claims()
                raise
        self.tracker = Tracker(scene.output.track, self.solver)
        self.stop_check = make_stop_check(scene, self.solver)  # None without [[stop]]
        self.stopped = None
        s = self.solver
        self.structural = (StructuralRecorder(s) if (s.effect("sections") or s.effect("reactions") is not None)
                           else None)
        self.output = None
        if write:
            self._make_directory()
        if write and not restart:
            self._remove_stale_checkpoints()
        if write:
            # a disk already full: refused before HDF5 leaves a results file it cannot finish
            self._ensure_space(self.path, 0)
        self.output = self._guard(self.path, self._open_output) if write else None
        self.history_t, self.history_rows, self.energy_rows = [], [], []
        self.initial_energy = None

    # -- files ------------------------------------------------------------------------------
    def _frame_fields(self):
        p = self.solver.particles
        names = ["id"] + [f for f in self.scene.output.fields if f in p and f != "id"]
        return {f: (p[f].shape[1:], p[f].dtype) for f in names}

    def _guard(self, path, fn, *args):
        """Run a write on every rank; if it fails anywhere (full disk, I/O error), close the
        output and raise OutputWriteError naming ``path`` on every rank together."""
        error, result = None, None
        with _quiet_h5py_deallocs():
            try:
                result = fn(*args)
            except (UnstableRunError, ParticleExitError):
                raise  # collective verdicts, raised on every rank together: not a write failure
            except OutputWriteError as exc:
                error = (exc.path, exc.reason)
            except (OSError, RuntimeError, ValueError) as exc:  # h5py and the OS on a failed write
                error = (path, _write_reason(exc))
            if error is not None:
                # release the failed write's HDF5 objects while their errors are quiet (only
                # then: a full collection of the interpreter's heap took 0.25-1 s here, twice
                # per frame, more than the 300 steps between two frames of the main job)
                gc.collect()
        failed = [e for e in self.comm.allgather(error) if e is not None]
        if failed:
            self._drop_output()
            raise OutputWriteError(*failed[0])
        return result

    def _ensure_space(self, path, nbytes, replaces=None, frame=False):
        """Refuse (every rank, OutputWriteError) a write of about ``nbytes`` that the file
        system of ``path`` cannot hold, before HDF5 starts it: HDF5 does not recover from a
        write cut short by a full disk (its files cannot even be closed cleanly), while a
        refused write leaves every file as it was. ``replaces``: a file the write truncates;
        ``frame``: the write is a frame and its history rows (their tables' new chunks count).
        The file size limit (``ulimit -f``) is checked alike."""
        short = None
        if frame and self.output is not None and self.output.file is not None:
            # a frame of the results file (called on every rank alike): the tables that grow with the frame (histories, energies, sections) take a new
            # chunk when they cross one (241 kB at once for the bar's first rows); every rank
            # walks the file (opening its objects is collective under the mpio driver)
            nbytes += _extendable_chunk_bytes(self.output.file, len(self.history_t) + 1)
        if self.rank == 0:
            import shutil
            try:
                free = shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free
                if replaces and os.path.exists(replaces):
                    free += os.path.getsize(replaces)
                if free < nbytes + DISK_MARGIN:
                    short = f"No space left on device: about {nbytes + DISK_MARGIN} bytes needed, {free} free"
                else:
                    short = _over_file_size_limit(path, nbytes, replaces)
            except OSError as exc:
                short = exc.strerror or type(exc).__name__
        short = self.comm.bcast(short)
        if short:
            self._drop_output()  # closed while the 64 KB margin still holds its metadata
            raise OutputWriteError(path, short)

    def _row_bytes(self, names):
        p = self.solver.particles.fields
        return sum(int(np.prod(p[k].shape[1:], dtype=np.int64)) * p[k].dtype.itemsize for k in names if k in p)

    def _drop_output(self):
        """Close the results file after a failed write, ignoring what closing it reports."""
        output, self.output = self.output, None
        with _quiet_h5py_deallocs():
            if output is not None and output.file is not None:
                try:
                    output.file.close()
                except Exception:  # a full disk fails the final flush too; nothing to save
                    pass
                output.file = None
            del output
            gc.collect()

    def _base(self):
        return _checkpoint_base(self.path)

    def _check_own_files(self):
        """Refuse to write over the output or checkpoints of another run: a file at this run's
        names written by another scene file or variant (same stem in the same directory)."""
        bad = None
        if self.rank == 0:
            me = (_scene_location(self.scene.path, self.path), self.scene.variant)
            for suffix in RUN_SUFFIXES:
                path = self._base() + suffix
                if os.path.exists(path):
                    owner = _owner(path)
                    if owner is not None and owner != me:
                        bad = path
                        break
        foreign = None
        if self.rank == 0 and bad is None:
            # every file the run and its post-processing may write over: pmpm's own or refused
            protect_input(self.scene.path)  # the gate never writes the scene, under any name
            try:
                if os.path.isdir(self.scene.output.directory):  # first: another run's files are its own
                    claim_run(self.scene.output.directory, run_name(self.scene))
                check_manifest(self.scene.output.directory)  # its schema, before anything is written
                for _key, name in run_files(self.scene):
                    check_owned(os.path.join(self.scene.output.directory, name), self.scene.stem)
            except ForeignFileError as exc:
                foreign = (exc.key, exc.reason)
                release_claims()  # refused: this run writes nothing, its claim included
        bad, foreign = self.comm.bcast((bad, foreign))
        if bad:
            raise ConfigError("output.directory", f"{bad} belongs to a run of another scene file "
                                                  f"or variant; choose another output.directory")
        if foreign:
            raise ForeignFileError(*foreign)

    def _make_directory(self):
        """Create output.directory (rank 0); a folder that cannot be made is bad input, said
        on every rank together."""
        problem = None
        if self.rank == 0:
            try:
                os.makedirs(os.path.dirname(self.path) or ".", exist_ok=True)
                # this run's names claimed before any is written: a second run of them is refused
                claim_run(os.path.dirname(self.path) or ".", run_name(self.scene))
                for name in remove_stale_temporaries(os.path.dirname(self.path) or ".", run_name(self.scene)):
                    logger.info("removed %s, a temporary of a killed run", name)
            except ForeignFileError as exc:
                problem = (exc.key, exc.reason)
            except OSError as exc:
                problem = exc.strerror or type(exc).__name__
        problem = self.comm.bcast(problem)
        if isinstance(problem, tuple):
            raise ForeignFileError(*problem)
        if problem:
            raise ConfigError("output.directory", f"{self.scene.output.directory!r} cannot be "
                                                  f"created ({problem})")

    def _remove_stale_checkpoints(self):
        """A fresh run replaces this run's results file, so the checkpoints and last good state
        of an earlier run of the same scene no longer belong to it (a later --restart would
        continue the old run)."""
        foreign = None
        if self.rank == 0:
            try:  # only pmpm's own files of this scene (checked again: never a user's file)
                for path in checkpoint_paths(self._base()) + [lastgood_path(self._base())]:
                    remove_owned(path, self.scene.stem)
            except ForeignFileError as exc:
                foreign = (exc.key, exc.reason)
        foreign = self.comm.bcast(foreign)
        if foreign:
            raise ForeignFileError(*foreign)

    def _open_output(self):
        if self.rank == 0:
            os.makedirs(os.path.dirname(self.path) or ".", exist_ok=True)
        self.comm.Barrier()
        attrs = {"scene": json.dumps(self.scene.to_dict(), default=str), "pmpm_version": __version__,
                 "variant": self.scene.variant, "title": self.scene.title,
                 "scene_file": _scene_location(self.scene.path, self.path),
                 "pmpm_owner": self.scene.stem,  # the record pmpm.io.ownership reads
                 "scene_fingerprint": self.fingerprint, "history_columns": list(HISTORY_COLUMNS),
                 # J: the start of the numerical loss (/energies/numerical_loss)
                 "initial_energy": float(self.solver.initial_energy)}
        return OutputFile(self.path, self.comm, attrs, self.solver.n_total, self._frame_fields(),
                          tracks=self.tracker.names, history_columns=list(HISTORY_COLUMNS),
                          energy_columns=list(ENERGY_COLUMNS), mode=self.scene.parallel.io,
                          append=self.restarted_from is not None, truncate_after=self.restarted_from,
                          track_attrs=self.tracker.attrs(), precision=self.scene.output.precision,
                          # the sidecar follows every frame, so a killed run leaves a current one
                          xdmf=self.path[:-3] + ".xdmf" if "x" in self.scene.output.fields else None)

    def _restore(self, path):
        """Continue from ``path``: a results file (its newest checkpoint) or a checkpoint file
        itself (``<stem>.lastgood.h5``, ``<stem>.ckpt0.h5``). Refuses a checkpoint of another
        scene (naming the first key that differs) and an inconsistent one."""
        s = self.solver
        wanted = s.particles.spec()  # what this scene's run carries (name -> shape, dtype)
        explicit = path if path.endswith(".lastgood.h5") or ".ckpt" in os.path.basename(path) else None
        try:
            fields, attrs = read_checkpoint(_checkpoint_base(path), self.comm, path=explicit)
        except (KeyError, TypeError, json.JSONDecodeError) as exc:
            raise ConfigError(path, f"not a usable pmpm checkpoint ({type(exc).__name__})") from None
        theirs = attrs.get("scene_record") if isinstance(attrs, dict) else None
        if not isinstance(theirs, dict):
            raise ConfigError(path, "the checkpoint records no scene (written by another program "
                                    "or an older pmpm): cannot tell that it belongs to this scene")
        key = first_difference(self.record, theirs)
        if key is not None:
            raise ConfigError(key, f"differs from the scene of the checkpoint {path} (only the "
                                   f"keys listed in docs/scenes.md may change on restart)")
        self._check_consistent(fields, attrs, path)
        self._complete_fields(fields, wanted, path)  # before anything is changed
        cols = np.floor((fields["x"][:, s.axis] - s.grid.origin[s.axis]) * s.grid.inv_h).astype(np.int64)
        s.particles.fields = alltoallv_fields(self.comm, fields, s.decomp.owner_of_columns(cols))
        s.t, s.step_count, s.dt = float(attrs["time"]), int(attrs["step"]), float(attrs["dt"])
        if attrs.get("step_setting") != self._step_setting():
            # the scene changed cfl or time_step (allowed on restart): the new rule from now on
            s.vmax = s.decomp.allreduce_max(s._local_speed())
            s.dt = s.stable_dt(s.vmax)
        for name in ACCUMULATED:   # the sums over the ranks: rank 0 holds them from now on
            _set_accumulated(s, name, float(attrs.get(name, 0.0)) if self.rank == 0 else 0.0)
        s.initial_energy = float(attrs["initial_energy"])
        s.removed = int(attrs.get("removed", 0))
        for effect in s.effects:
            effect.restore(s, attrs)
        self.restarted_from = s.t
        logger.info("restarted from %s at t = %.6g s (step %d)", path, s.t, s.step_count)

    def _step_setting(self):
        cfg = self.scene.solver
        return [cfg.cfl, cfg.time_step]

    def _check_consistent(self, fields, attrs, path):
        """Refuse (on every rank) a checkpoint whose state this scene cannot continue."""
        s = self.solver
        reason = None
        try:
            t, step, dt = float(attrs["time"]), int(attrs["step"]), float(attrs["dt"])
            energies = [float(attrs[k]) for k in ("external_work", "internal_work", "initial_energy")]
            n_total = int(attrs["n_total"])
        except (KeyError, TypeError, ValueError):
            t = step = dt = n_total = None
            energies = []
            reason = "lacks its time, step, time step, energies or particle count"
        if reason is None:
            if not (math.isfinite(t) and t >= 0):
                reason = f"its time {t!r} is not a finite time >= 0"
            elif t > self.scene.solver.end_time * (1 + 1e-12):
                reason = f"its time {t:g} s is beyond solver.end_time = {self.scene.solver.end_time:g} s"
            elif step < 0 or not (math.isfinite(dt) and dt > 0):
                reason = "its step or time step is not valid"
            elif not all(math.isfinite(e) for e in energies):
                reason = "its energies are not finite"
            elif n_total != s.n_total:
                reason = f"it holds {n_total} particle ids, this scene {s.n_total}"
        if reason is None:
            ids = fields.get("id")
            count, start = block_range(n_total, self.comm.Get_size(), self.rank)
            if ids is None or "x" not in fields:
                reason = "it has no particle ids or positions"
            elif np.any((ids < start) | (ids >= start + count)) or len(np.unique(ids)) != len(ids):
                reason = "its particle ids are duplicated or do not match their rows"
            elif not _healthy_fields(fields):
                reason = "it holds non-finite particle values (NaN or inf)"
        reasons = [r for r in self.comm.allgather(reason) if r is not None]
        if reasons:
            raise ConfigError(path, f"cannot restart: {reasons[0]}")

    def _complete_fields(self, fields, wanted, path):
        """Refuse a checkpoint that lacks a field this scene's run carries (it is another
        scene's: e.g. an elastic run's, without the back stress a plastic model reads)."""
        missing = [k for k in wanted if k not in fields]
        if missing:
            raise ValueError(f"the checkpoint has no field {missing[0]!r}, which this scene needs")
        for k, (trailing, dtype) in wanted.items():  # e.g. positions of 3 columns: refused
            a = fields[k]
            if a.shape[1:] != tuple(trailing) or a.dtype != dtype:
                raise ValueError(f"the checkpoint's field {k!r} has rows of shape {a.shape[1:]} and "
                                 f"dtype {a.dtype}, this scene's {tuple(trailing)} and {dtype}")

    def checkpoint(self, snap=None, path=None):
        """Write the current (or a snapshot's) state as the newest checkpoint, or to ``path``
        (the last good state). The current state is health-checked first (finite, energy
        bounded): a diverging state never becomes a regular checkpoint."""
        if not self.write:
            return None
        self.flush_history()  # so a restart from this checkpoint misses no history row
        s = self.solver
        if snap is None:
            s.check_health()
            snap = _Snapshot(s)
        target = path or (_next_slot(self._base()) if self.rank == 0 else None)
        self._ensure_space(target or self.path, s.n_total * self._row_bytes(snap.fields), replaces=target)
        sums = self.comm.allreduce(np.array([snap.energies[k] for k in ACCUMULATED]))
        return write_checkpoint(
            _checkpoint_base(self.path), self.comm, snap.t, snap.step, snap.fields,
            {"time": snap.t, "step": snap.step, "dt": snap.dt,
             **{k: float(v) for k, v in zip(ACCUMULATED, sums)},
             "initial_energy": s.initial_energy, "removed": s.removed, "n_total": s.n_total,
             "scene_file": _scene_location(self.scene.path, self.path), "variant": self.scene.variant,
             "pmpm_owner": self.scene.stem,
             "scene_fingerprint": self.fingerprint, "scene_record": self.record,
             "step_setting": self._step_setting()},
            path=path)

    # -- recording --------------------------------------------------------------------------
    def record_history(self):
        """One history row: the energies, the tracked points and the structural results, all
        summed over the ranks in one reduction."""
        s = self.solver
        energies = s.local_energies()
        tracks = self.tracker.local_rows()
        parts = [energies, tracks.ravel()]
        if self.structural is not None:
            parts.append(self.structural.local_rows())
        total = s.decomp.allreduce_sum(np.concatenate(parts))
        e = s.energies(total[:len(energies)])
        rows = total[len(energies):len(energies) + tracks.size].reshape(tracks.shape)
        self.history_t.append(s.t)
        self.history_rows.append(rows)
        self.energy_rows.append([s.t] + [e[_SOLVER_ENERGY.get(k, k)] for k in ENERGY_COLUMNS[1:]])
        if self.structural is not None:
            self.structural.sample(summed=total[len(energies) + tracks.size:])
        if self.initial_energy is None:
            self.initial_energy = e["total"]
        return e

    def flush_history(self):
        if not self.output or not self.history_t:
            return
        rows = np.array(self.history_rows)  # (S, tracks, cols)
        self.output.write_history(np.array(self.history_t),
                                  {name: rows[:, k, :] for k, name in enumerate(self.tracker.names)})
        self.output.write_energies(dict(zip(ENERGY_COLUMNS, np.array(self.energy_rows).T)))
        if self.structural is not None:
            attrs = self.structural.attributes()
            for group, columns in self.structural.drain().items():
                self.output.append_table(group, columns, UNITS, attrs[group])
        self.history_t, self.history_rows, self.energy_rows = [], [], []

    def write_frame(self):
        if self.output:
            p = self.solver.particles
            self._ensure_space(self.path, self.solver.n_total * self._row_bytes(self._frame_fields()), frame=True)
            self._guard(self.path, self.output.write_frame, self.solver.t, self.solver.step_count,
                        {f: p[f] for f in self._frame_fields()})
            self._guard(self.path, self.flush_history)

    # -- the loop ---------------------------------------------------------------------------
    def _log_start(self):
        s = self.solver
        cfg = self.scene.solver
        logger.info("pmpm %s: %s%s", __version__, self.scene.title,
                    f" [{self.scene.variant}]" if self.scene.variant else "")
        logger.info("  %d particles on %d rank(s), grid %d x %d cells of %g, slabs along %s",
                    s.n_total, s.decomp.size, *s.grid.cells, s.grid.h, "xy"[s.axis])
        logger.info("  %s B-splines, %s, PIC blend %g, CFL %g, dt %.3g s, end %g s",
                    cfg.shape_function, cfg.scheme.upper(), cfg.pic_blend, cfg.cfl, s.dt, cfg.end_time)
        for m in s.materials:
            logger.info("  material %s", m.describe())
        for line in self.effects():
            logger.info("  effect on: %s", line)
        # the same on every rank: said once, by rank 0 (other ranks log only their own troubles)
        if cfg.time_step is not None and cfg.time_step > s.critical_dt() and self.rank == 0 \
                and cfg.integrator == "explicit":   # (the implicit integrator is unconditionally stable)
            logger.warning("time_step %.3g s is above the stable limit %.3g s (CFL = 1): expect divergence",
                           cfg.time_step, s.critical_dt())

    def effects(self):
        """The optional physics this scene switches on (nothing else is compiled in)."""
        return describe_effects(self.scene, self.solver)

    def execute(self):
        """Step to the end time; returns a summary dict. Raises on failure after saving."""
        s, cfg, out = self.solver, self.scene.solver, self.scene.output
        self._log_start()
        end = cfg.end_time
        eps = 1e-12 * end
        # output schedules are multiples of their intervals from t = 0, so a restarted run
        # continues them exactly where the interrupted run would have gone on
        next_history = _next_multiple(s.t, out.history_interval, eps, self.restarted_from is None)
        next_frame = _next_multiple(s.t, out.interval, eps, self.restarted_from is None)
        next_ckpt = (_next_multiple(s.t, out.checkpoint_interval, eps, False)
                     if out.checkpoint_interval else np.inf)
        last_frame = self.restarted_from if self.restarted_from is not None else -np.inf
        try:
            s.check_health()  # the state we start from is the first last good state
        except UnstableRunError as exc:
            self.fail(exc, None)
            raise
        snap = _Snapshot(s)
        wall0 = time.perf_counter()
        last_progress = wall0
        t_start = s.t
        last_history = -np.inf
        while True:
            # the end: end_time reached or a [[stop]] condition met (the final frame and history
            # row are written at that time, off their schedules)
            done = s.t >= end - eps or self.stopped is not None
            if s.t >= next_history - eps or (self.stopped is not None and s.t > last_history + eps):
                self.record_history()
                last_history = s.t
                next_history = _next_multiple(s.t, out.history_interval, eps, False)
            if s.t >= next_frame - eps or (done and s.t > last_frame + eps):
                self.write_frame()
                last_frame = s.t
                next_frame = _next_multiple(s.t, out.interval, eps, False)
            if done or (cfg.max_steps and s.step_count >= cfg.max_steps):
                break
            try:
                if s.t >= next_ckpt - eps:
                    self._guard(self.path, self.checkpoint)
                    next_ckpt = _next_multiple(s.t, out.checkpoint_interval, eps, False)
                if s.healthy_step == s.step_count and snap.step != s.step_count:
                    snap = _Snapshot(s, reuse=snap)  # the newest state that passed the health checks
                s.step()
            except (UnstableRunError, ParticleExitError) as exc:
                self.fail(exc, snap)
                raise
            if self.stop_check is not None:
                self.stopped = self.stop_check.check()  # collective: the same on every rank
            now = time.perf_counter()
            if out.progress_interval and now - last_progress >= out.progress_interval:
                last_progress = now
                self.progress(now - wall0, t_start)
        if self.output is not None:
            self._ensure_space(self.path, 0, frame=True)  # the last rows' chunks
        self._guard(self.path, self.flush_history)
        wall = time.perf_counter() - wall0
        self.progress(wall, t_start)
        end_reason = "stop" if self.stopped else ("end_time" if s.t >= end - eps else "max_steps")
        if self.stopped and self.rank == 0:
            logger.info("stopped: %s", self.stopped.reason)
        if self.output is not None:
            self._guard(self.path, self.output.set_attrs, _end_attrs(end_reason, self.stopped),
                        [f"stop_{k}" for k in STOP_KEYS])
        if out.checkpoint_interval:
            try:
                self._guard(self.path, self.checkpoint)
            except UnstableRunError as exc:
                self.fail(exc, snap)
                raise
        self.close()
        e = s.energies()   # collective: every rank executes
        summary = {"steps": s.step_count, "time": s.t, "wall": wall, "particles": s.n_total,
                   "removed": s.removed, "output": self.path if self.write else None,
                   "end_reason": end_reason, "stopped": self.stopped,
                   "external_work": e["external_work"], "numerical_loss": e["numerical_loss"]}
        for effect in s.effects:   # the effects' own entries (first fracture, ...): collective
            summary.update(effect.summary(s))
        scheme_summary = getattr(s.scheme, "summary", None)   # the scheme's (a static run's load factors)
        if scheme_summary is not None:
            summary.update(scheme_summary(s))
        if self.rank == 0:
            logger.info("energy: %s", energy_summary(e))
        if s.removed and self.rank == 0:  # a global count
            logger.warning("%d particle(s) left the grid and were removed", s.removed)
        return summary

    def progress(self, wall, t_start):
        s = self.solver
        if self.rank != 0:
            return
        end = self.scene.solver.end_time
        frac = (s.t - t_start) / max(end - t_start, 1e-300)
        left = wall * (1 - frac) / frac if frac > 0 else float("nan")
        logger.info("t = %.5g s (%5.1f%%)  step %d  dt %.3g s  wall %.1f s  left ~%.0f s",
                    s.t, 100 * s.t / end, s.step_count, s.dt, wall, left)

    def fail(self, exc, snap):
        """Every rank arrives here together (the trouble flags are allreduced each step), with
        the same message, which the command line prints once as its error line. The newest
        state that passed the health checks goes to ``<stem>.lastgood.h5``; the regular
        checkpoints are left as they are."""
        try:
            self._guard(self.path, self.flush_history)
            if not self.write:
                return
            if snap is None:
                if self.rank == 0:
                    logger.error("no state passed the health checks: no last good state saved")
                return
            path = lastgood_path(self._base())
            self._guard(path, self.checkpoint, snap, path)
            if self.rank == 0:
                logger.error("last good state (t = %.6g s, step %d) saved to %s (continue with "
                             "--restart %s)", snap.t, snap.step, path, path)
        except OutputWriteError as write_error:
            if self.rank == 0:
                logger.error("%s", write_error)
        finally:
            self.close()

    def close(self):
        if self.output is not None:
            output, self.output = self.output, None
            self._guard(self.path, output.close)
            release_claims()  # the run's files are whole: another run may take the names
            # with positions among the fields the writer rewrote the sidecar after each frame
            if not output.xdmf and self.rank == 0:
                logger.warning("no XDMF sidecar: output.fields has no 'x' (the particle positions)")


#: the fields of a stop record (pmpm.stop.Stopped), each a root attribute ``stop_<key>``
STOP_KEYS = ("reason", "time", "step", "track", "quantity", "value", "threshold", "side")


def _end_attrs(end_reason, stopped):
    """Root attributes of how the run ended: ``end_reason`` (``end_time``, ``max_steps`` or
    ``stop``) and, after a stop, ``stop_<key>`` of its record."""
    attrs = {"end_reason": end_reason}
    if stopped:
        attrs.update({f"stop_{k}": stopped[k] for k in STOP_KEYS})
    return attrs


def _next_multiple(t, interval, eps, include_now):
    """The first multiple of ``interval`` at or after ``t`` (``include_now``) or after it."""
    k = np.floor((t + eps) / interval)
    if include_now and abs(t - k * interval) <= eps:
        return k * interval
    return (k + 1) * interval


def _checkpoint_base(path):
    return path[:-3] if path.endswith(".h5") else path
