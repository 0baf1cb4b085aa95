"""Shared machinery of the hard cases (issue "hard cases that stay numerically stable").

The scenes live in ``cases/hard/*.toml``; docs/hard_cases.md says what each one breaks in a naive
MPM code and what pmpm measured. ``run_case`` steps a scene on a communicator to its end time and
records, every step, the energies and the tracked points, plus per-case probes; the serial tests
(tests/hard/test_hard_cases.py) check the record, the MPI test (tests/hard/mpi/) compares a run on
COMM_WORLD with a serial run.

The energy criterion of the issue: the total energy (kinetic + internal work, the integrated
stress power) never exceeds the initial energy plus the external work by more than 2% of the
largest energy in play, taken as the largest over the run of the kinetic energy, |internal work|
and |initial energy| + |external work|.
"""
import math
import os
import time

import numpy as np
from mpi4py import MPI

from pmpm.scene.config import load_scene
from pmpm.build import build_solver
from pmpm.io.tracking import Tracker
from pmpm.stop import make_stop_check

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASES_DIR = os.path.join(ROOT, "cases", "hard")

#: the cases that must run to their end (the fixed-step divergence case is tested on its own)
CASES = ("impact", "travelling_block", "sparse_free_surface", "thin_member",
         "cantilever_large_rotation", "frame_near_collapse", "frame_collapse", "high_cfl")

#: the issue's tolerance on energy growth, relative to the largest energy in play
ENERGY_TOLERANCE = 0.02


def scene_path(name):
    return os.path.join(CASES_DIR, name + ".toml")


def load(name, variant=None):
    """The scene of a hard case (its only variant unless ``variant`` is given)."""
    return load_scene(scene_path(name), variant)[0]


def wave_speed(solver):
    return max(m.wave_speed() for m in solver.materials)


class Record:
    """What one run of a case leaves behind (identical on every rank of its communicator)."""

    def __init__(self):
        self.t = []            # time after each step
        self.dt = []           # step used
        self.energy = []       # kinetic, internal work, external work, total, strain
        self.tracks = []       # (n_tracks, 9) Tracker samples
        self.probes = []       # per-case probe values
        self.ranks_used = 0    # ranks that held particles at some step
        self.initial_energy = None
        self.solver = None
        self.wall = 0.0
        self.error = None
        self.stopped = None    # the [[stop]] record (pmpm.stop.Stopped) if one ended the run

    def finish(self):
        for k in ("t", "dt", "energy", "tracks", "probes"):
            setattr(self, k, np.array(getattr(self, k)))

    # -- the checks --------------------------------------------------------------------
    def energy_scale(self, external=None):
        """The largest energy in play over the run (``external``: the external work per sample,
        default pmpm's)."""
        e = self.energy
        kinetic, internal = e[:, 0], e[:, 1]
        external = e[:, 2] if external is None else external
        return float(max(np.abs(kinetic).max(), np.abs(internal).max(),
                         (abs(self.initial_energy) + np.abs(external)).max()))

    def energy_excess(self):
        """Per step: (total - (initial + external work)) / largest energy in play."""
        e = self.energy
        return (e[:, 3] - (self.initial_energy + e[:, 2])) / self.energy_scale()

    def energy_loss(self, work):
        """Per step: the energy lost, (initial + ``work`` - total) / largest energy in play, with
        ``work`` the external work per sample (e.g. the exact work of the loads): numerical
        dissipation plus whatever the scene dissipates physically outside the internal work
        (contact; plastic work is inside the internal work, so plasticity loses nothing here)."""
        return ((self.initial_energy + work) - self.energy[:, 3]) / self.energy_scale(external=work)

    def track(self, name):
        """(steps, 9) history of a tracked point: ux, uy, vx, vy, x, y, sxx, syy, sxy."""
        names = [t.name for t in self.scene.output.track]
        return self.tracks[:, names.index(name), :]


def run_case(scene, comm=None, probe=None, sample_every=1):
    """Step ``scene`` on ``comm`` (default COMM_SELF) to its end time or its ``[[stop]]``, recording the energies, the
    tracked points and ``probe(solver)`` (collective if it reduces) every ``sample_every`` steps.
    Instability or particle loss is kept in ``record.error``, not raised."""
    comm = comm or MPI.COMM_SELF
    rec = Record()
    s = build_solver(scene, comm)
    rec.solver, rec.scene = s, scene
    rec.initial_energy = s.initial_energy
    tracker = Tracker(scene.output.track, s)
    stop = make_stop_check(scene, s)  # the scene's [[stop]], as pmpm.run applies it
    end = scene.solver.end_time
    held = np.zeros(comm.Get_size(), dtype=bool)

    def sample(dt):
        e = s.energies()
        rec.t.append(s.t)
        rec.dt.append(dt)
        rec.energy.append([e["kinetic"], e["internal_work"], e["external_work"], e["total"], e["strain"]])
        rec.tracks.append(tracker.sample())
        if probe is not None:
            rec.probes.append(probe(s))

    t0 = time.perf_counter()
    try:
        while s.t < end - 1e-12 * end:
            held[comm.Get_rank()] |= s.particles.n > 0
            dt = s.step()
            sampled = s.step_count % sample_every == 0 or s.t >= end - 1e-12 * end
            if sampled:
                sample(dt)
            rec.stopped = stop.check() if stop is not None else None
            if rec.stopped is not None:
                if not sampled:  # the stop's step is always sampled
                    sample(dt)
                break
    except Exception as exc:  # UnstableRunError, ParticleExitError: reported by the checks
        rec.error = exc
    rec.wall = time.perf_counter() - t0
    everywhere = np.zeros_like(held, dtype=np.int64)
    comm.Allreduce(held.astype(np.int64), everywhere, op=MPI.MAX)
    rec.ranks_used = int(np.count_nonzero(everywhere))
    rec.finish()
    return rec


def refined(scene, factor=2):
    """The same scene on a grid ``factor`` times finer (same extent, same particles per cell, so
    ``factor``^2 as many particles and, at a fixed CFL number, ``factor`` times as many steps):
    the second point of a convergence study."""
    import dataclasses
    g = scene.grid
    grid = dataclasses.replace(g, cell_size=g.cell_size / factor, cells=tuple(int(c * factor) for c in g.cells))
    return dataclasses.replace(scene, grid=grid)


def gather_particles(solver, names=("id", "x", "v", "stress")):
    """Particle fields of every rank, concatenated in id order, on rank 0 (None elsewhere)."""
    fields = {k: solver.particles[k] for k in names}
    parts = solver.comm.gather(fields, root=0)
    if solver.comm.Get_rank() != 0:
        return None
    cat = {k: np.concatenate([p[k] for p in parts]) for k in names}
    order = np.argsort(cat["id"], kind="stable")
    return {k: v[order] for k, v in cat.items()}


def polite_barrier(comm, poll=0.005):
    """A barrier that sleeps instead of spinning, so ranks waiting for rank 0's serial reference
    run do not take the CPU from it (2 vCPUs, 3 ranks)."""
    req = comm.Ibarrier()
    while not req.Test():
        time.sleep(poll)


# -- per-case probes ---------------------------------------------------------------------------

def lightest_active_node(solver):
    """Smallest nodal mass above the mass cutoff in this rank's window, relative to the heaviest
    particle mass (inf if none): how light the nodes are that still take part in the step."""
    m = solver.window.G[..., 0]
    active = m[m > solver.mass_cutoff]
    mp = solver.particles["m"].max() if solver.particles.n else 1.0
    return float(active.min() / mp) if active.size else math.inf


def body_frame_energy(solver):
    """Kinetic energy relative to the centre of mass plus recoverable strain energy: the body's
    vibration energy, which cell crossing must neither pump up nor drain (serial runs only)."""
    p = solver.particles
    m, v = p["m"], p["v"]
    vcm = (m[:, None] * v).sum(axis=0) / m.sum()
    kinetic = 0.5 * float(np.sum(m * np.sum((v - vcm) ** 2, axis=1)))
    strain = 0.0
    for k, mat in enumerate(solver.materials):
        sel = p["mat"] == k
        strain += float(np.sum(p["vol"][sel] * mat.elastic_energy_density(p["stress"][sel])))
    return kinetic + strain


def exact_load_work(solver):
    """Work of the scene's loads so far, computed from the particle displacements alone: every
    hard case's loads are constant in time (gravity, and step forces from t = 0), so the work is
    sum_p f_p . (x_p - x0_p) exactly, with f_p = m_p g plus the particle's share of its force set.
    Supports that do not move do no work. Serial runs only."""
    p, loads = solver.particles, solver.effect("loads")
    f = np.zeros_like(p["x"])
    if loads is None:
        return 0.0
    if loads.gravity is not None:
        f += p["m"][:, None] * loads.gravity
    for k, force in enumerate(loads.forces):
        tf = force.time_function
        assert tf["type"] == "step" and tf.get("start", 0.0) == 0.0, "not a constant load"
        sel = p["load_id"] == k
        f[sel] += p["load_w"][sel, None] * np.asarray(force.force)
    return float(np.sum(f * (p["x"] - p["x0"])))


def body_velocities(solver):
    """Mass-weighted mean x-velocity of each body (serial runs only)."""
    p = solver.particles
    out = []
    for b in range(int(p["body"].max()) + 1):   # every body of the hard cases keeps particles
        sel = p["body"] == b
        out.append(float(np.sum(p["m"][sel] * p["v"][sel, 0]) / np.sum(p["m"][sel])))
    return out
