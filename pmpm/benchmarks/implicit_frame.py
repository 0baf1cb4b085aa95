"""The three-storey frame (cases/frame_3storey.toml) for the implicit integrator's benchmarks
and studies: the case on a chosen cell size with either integrator, its explicit twin, and a
run that records the left joints' drifts (floors 2, 3 and the roof) relative to the ground.

What ``pmpm bench implicit --scenes frame3-step frame3-record`` (pmpm.benchmarks.implicit_tts)
and studies/northridge_implicit.py both need lives here: studies sit outside the package, and
the benchmark may not import them.

The explicit twin of a scene whose implicit run brings gravity to equilibrium statically first
(``initial_static``) starts from that equilibrium: the explicit integrator has no static stage,
and gravity switched on at t = 0 makes the frame oscillate about its sagged shape (undamped, for
the whole run) with a sway at the left joints that is not the record's. static_start runs the
implicit scene's static stage (the record left out) and adopt_state hands its particle state to
the explicit solver before its first step: both integrators then start from the same state.
"""
import dataclasses
import time

import numpy as np

from decomposition import alltoallv_fields
from pmpm.benchmarks.args import FRAME3_CASE
from pmpm.build import build_solver
from pmpm.io.tracking import Tracker
from pmpm.scene.config import apply_overrides, parse_scene, read_toml

__all__ = ["JOINTS", "frame3_scene", "strip_explicit_only", "undamped", "explicit_twin", "static_stage",
           "static_start",
           "adopt_state", "drift_history"]

#: the tracked left joints of floors 2, 3 and the roof (the case's frame node names)
JOINTS = ("c0_f1", "c0_f2", "c0_f3")


def frame3_scene(cell_size, variant, ppc=None, time_step=None, end_time=None, implicit=None, petsc=None,
                 case=FRAME3_CASE):
    """The case's ``variant`` on cells of ``cell_size`` over the case's own domain, with the
    implicit integrator (the ``northridge_implicit`` variant's own settings, or for a variant
    that names none, steps of ``time_step``), without the support reactions and section cuts
    (strip_explicit_only). ``ppc``: particles per cell (default the case's); ``end_time``,
    ``time_step``, ``implicit`` and ``petsc`` override the scene's."""
    data = read_toml(case)
    data = apply_overrides(data, data["variants"][variant], f"variants.{variant}")
    data.pop("variants")
    grid = data["grid"]
    extent = [grid["cell_size"] * n for n in grid["cells"]]
    cells = [int(round(e / cell_size)) for e in extent]
    if any(abs(n * cell_size - e) > 1e-9 for n, e in zip(cells, extent)):
        raise ValueError(f"cells of {cell_size} m do not tile the case's domain {extent} m")
    data["grid"] = dict(grid, cell_size=float(cell_size), cells=cells)
    if ppc is not None:
        data["particles_per_cell"] = int(ppc)
    solver = data["solver"]
    solver["integrator"] = "implicit"
    if time_step is not None:
        solver["time_step"] = float(time_step)
    if end_time is not None:
        solver["end_time"] = float(end_time)
    if implicit:
        solver["implicit"] = {**solver.get("implicit", {}), **implicit}
    if petsc:
        solver["petsc"] = {**solver.get("petsc", {}), **petsc}
    if "time_step" not in solver:
        raise ValueError(f"variant {variant}: the implicit integrator needs a time step")
    scene = parse_scene(data, case)
    return strip_explicit_only(dataclasses.replace(scene, variant=variant))


def strip_explicit_only(scene):
    """The frame without its support reactions and section cuts (the drifts do not need them,
    and they cost a pass each step)."""
    boundary = tuple(dataclasses.replace(b, reaction=False) for b in scene.boundaries)
    output = dataclasses.replace(scene.output, sections=(), hysteresis=None, checkpoint_interval=None)
    return dataclasses.replace(scene, boundaries=boundary, output=output)


def undamped(scene):
    """``scene`` without its Rayleigh damping. The explicit twin of the frame under the record
    needs it: the stiffness-proportional viscous stress bounds the explicit step (7.1e-7 s at
    0.1 m cells for the northridge_implicit variant's 2 %, 4.3 million steps for 3 s) where the
    CFL step is 1.7e-5 s."""
    return dataclasses.replace(scene, loads=dataclasses.replace(scene.loads, rayleigh=None))


def explicit_twin(scene, end_time=None, cfl=None):
    """``scene`` under the explicit integrator (MUSL at the CFL number ``cfl``, default the
    scene's), to ``end_time`` (default the scene's). The same loads: a static stage of the
    implicit run (``initial_static``) has no explicit counterpart, so its gravity is applied at
    t = 0."""
    solver = dataclasses.replace(scene.solver, integrator="explicit", scheme="musl", time_step=None,
                                 analysis="dynamic", implicit={}, petsc={},
                                 cfl=float(cfl if cfl is not None else scene.solver.cfl),
                                 end_time=float(end_time if end_time is not None else scene.solver.end_time))
    return dataclasses.replace(scene, solver=solver)


def static_stage(scene):
    """Whether ``scene``'s run brings its loads to equilibrium statically before its dynamics."""
    return scene.solver.integrator == "implicit" and bool(scene.solver.implicit.get("initial_static"))


def static_start(scene, comm):
    """The particle state (this rank's fields) of ``scene``'s implicit run after its static
    stage (``solver.implicit.initial_static``: the loads at t = 0 brought to equilibrium), or
    None when the scene has no static stage. Runs the scene without its ground motion for one
    implicit step: the static stage, then a step under the same constant loads in which nothing
    moves (a_0 = 0 after the stage, pmpm.core.implicit.scheme; the record's first step would
    move the supports). Time stays out of any figure: it is the explicit twin's start."""
    if not static_stage(scene):
        return None
    solver = dataclasses.replace(scene.solver, end_time=scene.solver.time_step)
    quiet = dataclasses.replace(scene, solver=solver, loads=dataclasses.replace(scene.loads, ground_motion=None))
    s = build_solver(quiet, comm)
    s.step()
    return dict(s.particles.fields)


def adopt_state(s, fields, comm):
    """Give the solver ``s`` (not yet stepped) the particle state ``fields`` (each rank's rows,
    from a solver of the same scene: the same particles and ids), as a restart does
    (pmpm.runner.Run._restore): the fields ``s`` carries, sent to the ranks owning their
    columns; the step and the energy balance from that state. Fields the other run carried
    and ``s`` does not (the implicit integrator's particle accelerations) are dropped."""
    wanted = s.particles.spec()
    missing = sorted(set(wanted) - set(fields))
    if missing:
        raise ValueError(f"the start state has no particle field {missing[0]!r}")
    rows = {k: np.ascontiguousarray(fields[k], dtype=wanted[k][1]) for k in wanted}
    cols = np.floor((rows["x"][:, s.axis] - s.grid.origin[s.axis]) * s.grid.inv_h).astype(np.int64)
    s.particles.fields = alltoallv_fields(comm, rows, s.decomp.owner_of_columns(cols))
    s.vmax = s.decomp.allreduce_max(s._local_speed())
    s.dt = s.stable_dt(s.vmax)
    s._vmax_healthy = s.vmax
    # the energy balance from the adopted state: its stored strain energy is the run's initial
    # energy, counted as the internal work that made it (this rank's share). Left at zero, the
    # prestress's work on the small motions that follow (negative as often as not) makes the
    # "initial energy plus external work" negative and the divergence check's kinetic-energy
    # test fires at once (it did, at t = 0.056 s of the record's twin)
    s.internal_work = float(s.local_energies()[1])
    s.initial_energy = s.energies()["total"]


def drift_history(scene, comm, joints=JOINTS, interval=0.0, progress=None, start=None):
    """Run ``scene`` to its end on ``comm``, recording the ux of the tracked points ``joints``
    minus the ground's displacement (the absolute formulation's supports move with the record,
    pmpm.physics.groundmotion) and minus their value before the first step, at the first step
    at or after each multiple of ``interval`` (0: every step).

    Returns a dict: ``t`` (n,), ``drift`` (n, len(joints)) (from the first step on when the run
    has a static stage, static_stage), ``wall_s`` (rank 0's), ``cpu_s``
    (time.process_time of the run summed over the ranks), ``cpu_s_rank0``, ``steps`` and the
    scheme's ``stats`` (the implicit integrator's Newton counts; empty for the explicit one).
    ``progress``: a callable(t, steps, wall) called on rank 0 about a hundred times. ``start``:
    particle fields to start from (static_start; adopt_state), the drifts still measured from
    the particles' positions before it (those of the implicit run's first sample)."""
    s = build_solver(scene, comm)
    names = [t.name for t in scene.output.track]
    missing = [j for j in joints if j not in names]
    if missing:
        raise ValueError(f"{scene.variant or scene.title}: no tracked point {missing[0]!r}")
    tracker = Tracker([t for t in scene.output.track if t.name in joints], s)
    kept = [t.name for t in scene.output.track if t.name in joints]
    order = [kept.index(j) for j in joints]
    ground = s.effect("ground_motion")

    def sample():
        ux = np.asarray(tracker.sample())[order, 0].copy()
        return ux - (ground.displacement(s.t) if ground is not None else 0.0)

    x0 = sample()
    if start is not None:
        adopt_state(s, start, comm)
    # an implicit run's state at t = 0 is its static stage's equilibrium, which its first step
    # computes: its history starts at that step (its first sample would be the unloaded frame)
    t, drift = ([], []) if static_stage(scene) else ([0.0], [sample() - x0])
    end = scene.solver.end_time
    next_sample, next_shown = interval, 0.0
    comm.Barrier()
    start, cpu = time.perf_counter(), time.process_time()
    while s.t < end * (1 - 1e-12):
        s.step()
        if s.t >= next_sample * (1 - 1e-9) or s.t >= end * (1 - 1e-12):
            t.append(s.t)
            drift.append(sample() - x0)
            next_sample = (np.floor(s.t / interval + 1e-9) + 1) * interval if interval > 0 else 0.0
        if progress is not None and comm.rank == 0 and s.t >= next_shown:
            progress(s.t, s.step_count, time.perf_counter() - start)
            next_shown += end / 100
    cpu = time.process_time() - cpu
    wall = time.perf_counter() - start
    return {"t": np.array(t), "drift": np.array(drift), "wall_s": comm.bcast(wall), "cpu_s": comm.allreduce(cpu),
            "cpu_s_rank0": comm.bcast(cpu), "steps": s.step_count,
            "stats": dict(getattr(s.scheme, "stats", {}) or {})}
