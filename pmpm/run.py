"""A run of a scene: the solver plus output, histories, progress, checkpoints and failure.

``Run(scene).execute()`` steps the solver to the end time and writes one HDF5 file (frames of
particle fields, time histories of the tracked points, energies), an XDMF sidecar for ParaView,
CSV histories and plots. A run that goes unstable, or whose particles leave the grid, stops on
every rank with a message, writes a checkpoint of its last good state and exits non-zero.

Calling this module, ``pmpm.run(scene, overrides=..., write=False)``, is the Python API:
:func:`pmpm.api.run` (docs/api.md).
"""
import json
import logging
import os
import sys
import time
import types

import numpy as np

from pmpm import __version__
from pmpm.errors import ParticleExitError, UnstableRunError
from pmpm.core.solver import Solver
from pmpm.io.tracking import HISTORY_COLUMNS, Tracker
from pmpm.results.recorder import UNITS, StructuralRecorder

__all__ = ["Run", "output_path"]
logger = logging.getLogger(__name__)

ENERGY_COLUMNS = ("time", "kinetic", "strain_energy", "plastic_work", "internal_work", "damping_work",
                  "external_work", "total")
#: the solver's name of an energy where the file's differs (the file keeps "strain" for the field)
_SOLVER_ENERGY = {"strain_energy": "strain"}


def output_path(scene):
    """``<output.directory>/<stem>[_<variant>].h5``."""
    name = scene.stem + (f"_{scene.variant}" if scene.variant else "")
    return os.path.join(scene.output.directory, name + ".h5")


class _Snapshot:
    """A copy of the particle state a few steps back: what a failed run saves."""

    def __init__(self, solver):
        self.fields = {k: a.copy() for k, a in solver.particles.fields.items()}
        self.t, self.step, self.dt = solver.t, solver.step_count, solver.dt
        self.external_work = solver.external_work
        self.internal_work = solver.internal_work
        self.damping_work = solver.damping_work


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

    def __init__(self, scene, comm=None, write=True, restart=None, snapshot_every=50):
        self.scene = scene
        from pmpm.physics.contact import ContactSolver  # scene [contact]: one velocity field per body
        self.solver = (Solver if scene.contact is None else ContactSolver)(scene, comm)
        self.comm = self.solver.comm
        self.rank = self.comm.Get_rank()
        self.write = write
        self.path = output_path(scene)
        self.snapshot_every = snapshot_every
        self.restarted_from = None
        if restart:
            self._restore(restart)
        self.tracker = Tracker(scene.output.track, self.solver)
        s = self.solver
        self.structural = StructuralRecorder(s) if (s.sections or s.reactions is not None) else None
        self.output = self._open_output() if write else None
        self.history_t, self.history_rows, self.energy_rows = [], [], []
        self.initial_energy = None

    # -- files ------------------------------------------------------------------------------
    def _frame_fields(self):
        p = self.solver.particles
        names = ["id"] + [f for f in self.scene.output.fields if f in p and f != "id"]
        return {f: (p[f].shape[1:], p[f].dtype) for f in names}

    def _open_output(self):
        from pmpm.io import OutputFile
        if self.rank == 0:
            os.makedirs(os.path.dirname(self.path) or ".", exist_ok=True)
        self.comm.Barrier()
        attrs = {"scene": json.dumps(self.scene.to_dict(), default=str), "pmpm_version": __version__,
                 "variant": self.scene.variant, "title": self.scene.title,
                 "history_columns": list(HISTORY_COLUMNS)}
        return OutputFile(self.path, self.comm, attrs, self.solver.n_total, self._frame_fields(),
                          tracks=self.tracker.names, history_columns=list(HISTORY_COLUMNS),
                          energy_columns=list(ENERGY_COLUMNS), mode=self.scene.parallel.io,
                          append=self.restarted_from is not None, truncate_after=self.restarted_from,
                          track_attrs=self.tracker.attrs())

    def _restore(self, path):
        from pmpm.io import read_checkpoint
        s = self.solver
        wanted = s.particles.spec()  # what this scene's run carries (name -> shape, dtype)
        fields, attrs = read_checkpoint(_checkpoint_base(path), self.comm)
        self._complete_fields(fields, wanted, path)  # before anything is changed
        cols = np.floor((fields["x"][:, s.axis] - s.grid.origin[s.axis]) * s.grid.inv_h).astype(np.int64)
        from decomposition import alltoallv_fields
        s.particles.fields = alltoallv_fields(self.comm, fields, s.decomp.owner_of_columns(cols))
        s.t, s.step_count, s.dt = float(attrs["time"]), int(attrs["step"]), float(attrs["dt"])
        s.external_work = float(attrs["external_work"]) if self.rank == 0 else 0.0
        s.internal_work = float(attrs["internal_work"]) if self.rank == 0 else 0.0
        s.initial_energy = float(attrs["initial_energy"])
        s.damping_work = float(attrs.get("damping_work", 0.0)) if self.rank == 0 else 0.0
        s.removed = int(attrs.get("removed", 0))
        self.restarted_from = s.t
        logger.info("restarted from %s at t = %.6g s (step %d)", path, s.t, s.step_count)

    def _complete_fields(self, fields, wanted, path):
        """Refuse a checkpoint that lacks a field this scene's run carries (it is another
        scene's: e.g. an elastic run's, without the back stress a plastic model reads)."""
        missing = [k for k in wanted if k not in fields]
        if missing:
            raise ValueError(f"the checkpoint has no field {missing[0]!r}, which this scene needs")

    def checkpoint(self, snap=None):
        """Write the current (or a snapshot's) state as the newest checkpoint."""
        if not self.write:
            return
        from pmpm.io import write_checkpoint
        self.flush_history()  # so a restart from this checkpoint misses no history row
        s = self.solver
        snap = snap or _Snapshot(s)
        ext, internal, damped = self.comm.allreduce(
            np.array([snap.external_work, snap.internal_work, snap.damping_work]))
        write_checkpoint(_checkpoint_base(self.path), self.comm, snap.t, snap.step, snap.fields,
                         {"time": snap.t, "step": snap.step, "dt": snap.dt, "external_work": float(ext),
                          "internal_work": float(internal), "damping_work": float(damped),
                          "initial_energy": s.initial_energy,
                          "removed": s.removed, "n_total": s.n_total})

    # -- recording --------------------------------------------------------------------------
    def record_history(self):
        e = self.solver.energies()
        self.history_t.append(self.solver.t)
        self.history_rows.append(self.tracker.sample())
        self.energy_rows.append([self.solver.t] + [e[_SOLVER_ENERGY.get(k, k)] for k in ENERGY_COLUMNS[1:]])
        if self.structural is not None:
            self.structural.sample()
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
            self.output.write_frame(self.solver.t, self.solver.step_count,
                                    {f: p[f] for f in self._frame_fields()})
            self.flush_history()

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
        if cfg.time_step is not None and cfg.time_step > s.critical_dt() and self.rank == 0:
            logger.warning("time_step %.3g s is above the stable limit %.3g s (CFL = 1): expect divergence",
                           cfg.time_step, s.critical_dt())

    def effects(self):
        """The optional physics this scene switches on (nothing else is compiled in)."""
        s = self.solver
        out = self.solver.loads.describe()
        out += [f"plasticity ({m.name})" for m in s.materials if "plastic_work" in m.state_fields]
        if self.scene.solver.large_rotations:
            rate = {"jaumann": "Jaumann", "green_naghdi": "Green-Naghdi"}[self.scene.solver.objective_rate]
            out.append(f"large rotations ({rate} stress rate)")
        if s.keeps_F:
            out.append("deformation gradient F per particle")
        if s.damping is not None:
            out.append(f"mass-proportional damping ({s.damping:g} 1/s)")
        if s.ground is not None:
            out.append(s.ground.describe())
        if hasattr(s, "describe"):  # solvers that add physics of their own (contact)
            out.append(s.describe())
        return out

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
        snap = _Snapshot(s)
        wall0 = time.perf_counter()
        last_progress = wall0
        t_start = s.t
        while True:
            if s.t >= next_history - eps:
                self.record_history()
                next_history = _next_multiple(s.t, out.history_interval, eps, False)
            if s.t >= next_frame - eps or (s.t >= end - eps and s.t > last_frame + eps):
                self.write_frame()
                last_frame = s.t
                next_frame = _next_multiple(s.t, out.interval, eps, False)
            if s.t >= end - eps or (cfg.max_steps and s.step_count >= cfg.max_steps):
                break
            if s.t >= next_ckpt - eps:
                self.checkpoint()
                next_ckpt = _next_multiple(s.t, out.checkpoint_interval, eps, False)
            if s.step_count % self.snapshot_every == 0:
                snap = _Snapshot(s)
            try:
                s.step()
            except (UnstableRunError, ParticleExitError) as exc:
                self.fail(exc, snap)
                raise
            now = time.perf_counter()
            if out.progress_interval and now - last_progress >= out.progress_interval:
                last_progress = now
                self.progress(now - wall0, t_start)
        self.flush_history()
        wall = time.perf_counter() - wall0
        self.progress(wall, t_start)
        if out.checkpoint_interval:
            self.checkpoint()
        self.close()
        summary = {"steps": s.step_count, "time": s.t, "wall": wall, "particles": s.n_total,
                   "removed": s.removed, "output": self.path if self.write else None}
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
        the same message, which the command line prints once as its error line."""
        try:
            self.flush_history()
            self.checkpoint(snap)
            if self.rank == 0:
                logger.error("last good state (t = %.6g s, step %d) saved to %s", snap.t, snap.step,
                             _checkpoint_base(self.path) + ".ckpt*.h5" if self.write else "(no output)")
        finally:
            self.close()

    def close(self):
        if self.output is not None:
            self.output.close()
            self.output = None
            if self.rank == 0 and "x" in self.scene.output.fields:
                from pmpm.io import write_xdmf
                write_xdmf(self.path)
            elif self.rank == 0:
                logger.warning("no XDMF sidecar: output.fields has no 'x' (the particle positions)")


def _next_multiple(t, interval, eps, include_now):
    """The first multiple of ``interval`` at or after ``t`` (``include_now``) or after it."""
    k = np.floor((t + eps) / interval)
    if include_now and abs(t - k * interval) <= eps:
        return k * interval
    return (k + 1) * interval


def _checkpoint_base(path):
    return path[:-3] if path.endswith(".h5") else path


class _CallableModule(types.ModuleType):
    """``pmpm.run(scene, overrides=...)`` is the Python API (:func:`pmpm.api.run`), and
    ``pmpm.run`` is also this module: importing a submodule binds its name on the package, so
    the name cannot be a plain function. The module is made callable instead."""

    def __call__(self, *args, **kwargs):
        """Run a scene and return its results: :func:`pmpm.api.run` (docs/api.md)."""
        from pmpm.api import run
        return run(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
