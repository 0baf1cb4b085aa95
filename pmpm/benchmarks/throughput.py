"""Benchmarks (not tests): throughput of the step on one core, and the cost of each effect.

Each prints its figures and, last, one JSON line. Compile time is excluded (a short warm-up
run compiles every kernel first). Quote medians: this machine is noisy.
"""
import json
import logging
import math
import resource
import statistics
import time

import numba as nb
import numpy as np

from pmpm.benchmarks.block import MATERIALS, YIELD_AFTER_STEPS, block_scene
from pmpm.build import build_solver
from pmpm.benchmarks.phase_profile import phase_times

__all__ = ["throughput", "effects", "stream_triad_bandwidth", "step_bytes_per_particle"]
logger = logging.getLogger(__name__)

def _status_kib(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    raise KeyError(key)


def _memory_baseline():
    """Resident bytes now, with the kernel's peak-RSS mark reset to it (Linux clear_refs), so
    that a later _peak_rss_bytes() sees only what came after: not numba's compile-time peak,
    not an earlier, freed problem. Without clear_refs: the lifetime peak, so the difference
    can read low (down to 0) when an earlier peak was higher."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return _status_kib("VmRSS") * 1024
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _peak_rss_bytes():
    try:
        return _status_kib("VmHWM") * 1024
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _time_steps(solver, steps):
    """(wall s, process CPU s) of ``steps`` steps."""
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        solver.step()
    return time.perf_counter() - t0, time.process_time() - c0


@nb.njit(cache=True)
def _triad(a, b, c, scalar):
    for i in range(a.shape[0]):
        a[i] = b[i] + scalar * c[i]


def stream_triad_bandwidth(n=20_000_000, repeat=7, clock=time.process_time):
    """Memory bandwidth of this core in bytes/s, STREAM-triad style (a = b + s c on arrays far
    larger than the caches; 24 bytes per element counted, as STREAM does), best of ``repeat``.
    Timed by the process CPU clock by default: on a shared machine the wall clock also counts
    the time other processes hold the core (it read 4 GB/s for 30-40 GB/s on a loaded minute)."""
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    _triad(a, b, c, 3.0)
    best = math.inf
    for _ in range(repeat):
        t0 = clock()
        _triad(a, b, c, 3.0)
        best = min(best, clock() - t0)
    return 24 * n / best


def step_bytes_per_particle(solver):
    """Bytes the step must stream per particle: every particle array each phase reads or writes
    (counted once per phase) plus the grid window's passes, per particle."""
    p = solver.particles
    size = {k: a.itemsize * (a.size // max(len(a), 1)) for k, a in p.fields.items()}
    for optional in ("strain", "F", "vol0"):  # kept only when the scene needs them
        size.setdefault(optional, 0)
    reads_F = ("F",) if any(m.needs_deformation_gradient for m in solver.materials) else ()
    passes = [  # (read, written) particle fields per phase of the MUSL step
        (("x", "m", "v", "vol", "stress"), ()),                               # particles_to_grid
        (("x", "m", "v"), ("v",)),                                            # grid_to_particles
        (("x", "m", "vol", "strain", "F", "vol0"), ("x", "vol", "strain", "F")),  # update_strain
        (("stress", "vol") + reads_F, ("stress",) + reads_F),                 # update_stress
    ]
    grid_passes = 6   # reset, scatter x2, update, velocity, gather
    scratch = 16 + 16 + 24 + 24 + 24  # dx written and read, de written and read twice
    if solver.scheme.name == "mls":   # one P2G, one G2P that also takes the strain (pmpm.core.mls)
        size.setdefault("C", 0)
        passes = [
            (("x", "m", "v", "C", "vol", "stress"), ()),                      # particles_to_grid
            # g2p with the move (and the strays count and first work half: ``tail_fusable``)
            (("x", "v", "C", "vol", "strain", "F", "vol0", "stress"), ("x", "v", "C", "vol", "strain", "F")),
            (("stress", "vol") + reads_F, ("stress",) + reads_F),             # update_stress
        ]
        grid_passes = 4   # reset, scatter, update, gather
        scratch = 16 + 24 + 24        # dx written, de written and read once
    particle = sum(size[f] for r, w in passes for f in r + w) + scratch
    grid_nodes = solver.window.G.shape[0] * solver.window.G.shape[1]
    grid = grid_nodes * solver.window.G.shape[2] * 8 * grid_passes / p.n
    return particle + grid


def throughput(args):
    """Particle-steps per second of one rank on an elastic (or plastic) block."""
    from mpi4py import MPI
    t0 = time.perf_counter()
    interp = getattr(args, "interpolation", "point")
    extra = None if interp == "point" else {"interpolation": interp}
    track_F = getattr(args, "track_F", False)
    warm = build_solver(block_scene(1000, args.shape, args.scheme, args.material, extra_solver=extra,
                              track_F=track_F), MPI.COMM_SELF)
    for _ in range(3):
        warm.step()
    del warm
    if time.perf_counter() - t0 > 5.0:
        print("note: the kernels were compiled in this process (numba's cache was empty); the "
              "memory the compiler freed is reused by the arrays, so the peak memory below may "
              "read low: run the benchmark again for it")
    results = []
    for n in args.particles:
        base = _memory_baseline()
        solver = build_solver(block_scene(n, args.shape, args.scheme, args.material, extra_solver=extra,
                                    track_F=track_F),
                        MPI.COMM_SELF)
        for _ in range(YIELD_AFTER_STEPS):  # first-touch of the arrays; a plastic block yields
            solver.step()
        times = [_time_steps(solver, args.steps) for _ in range(args.repeat)]
        med = statistics.median(t[0] for t in times)
        cpu = statistics.median(t[1] for t in times)
        n_real = solver.particles.n
        rate = n_real * args.steps / med
        mem = (_peak_rss_bytes() - base) / n_real
        res = {"particles": n_real, "steps": args.steps, "repeats": args.repeat, "shape": args.shape,
               "scheme": args.scheme, "material": args.material, "interpolation": interp,
               "track_F": solver.keeps_F, "median_s": med,
               "particle_steps_per_s": rate, "ns_per_particle_step": 1e9 / rate,
               "cpu_particle_steps_per_s": n_real * args.steps / cpu,
               "bytes_per_particle": mem,
               # what the particle arrays hold, exactly (the RSS figure above can read low at
               # small sizes, when the allocator reuses pages an earlier problem freed)
               "array_bytes_per_particle": sum(a.nbytes for a in solver.particles.fields.values()) / n_real,
               "bytes_moved_per_particle_step": step_bytes_per_particle(solver)}
        print(f"{n_real:>9d} particles  {args.steps} steps x {args.repeat}: median {med:.3f} s  "
              f"{rate / 1e6:.2f} M particle-steps/s  {1e9 / rate:.1f} ns/particle-step "
              f"(CPU time: {res['cpu_particle_steps_per_s'] / 1e6:.2f} M/s)  peak memory {mem:.0f} B/particle")
        if args.phases:
            res["phases_ns"] = _print_phases(solver, args.steps, n_real)
        results.append(res)
        del solver
    bandwidth = stream_triad_bandwidth()
    print(f"memory bandwidth (STREAM triad, one core): {bandwidth / 1e9:.1f} GB/s")
    for res in results:
        floor_ns = res["bytes_moved_per_particle_step"] / bandwidth * 1e9
        res.update(bandwidth_bytes_per_s=bandwidth, bandwidth_floor_ns=floor_ns,
                   fraction_of_bandwidth_floor=floor_ns / res["ns_per_particle_step"])
        print(f"{res['particles']:>9d} particles stream ~{res['bytes_moved_per_particle_step']:.0f} "
              f"B/particle-step: bandwidth floor {floor_ns:.1f} ns, reached "
              f"{100 * res['fraction_of_bandwidth_floor']:.0f}% of it")
    last = dict(results[-1])
    last["all"] = results
    print(json.dumps(last))
    return 0


def _effect_scenes(n, record):
    """The same block with one effect switched on at a time (name -> scene)."""
    gm = {"ground_motion": {"file": record, "direction": "x"}}
    return {
        "none": block_scene(n),
        "gravity": block_scene(n, gravity=True),
        "force (step)": block_scene(n, force=True),
        "damping": block_scene(n, extra_loads={"damping": 0.5}),
        # the step's own cost of the stiffness part (the shorter stable step is not in it)
        "Rayleigh damping (ratio)": block_scene(n, extra_loads={"damping": {"ratio": 0.02, "periods": [1.0, 0.2]}}),
        "ground motion": block_scene(n, extra_loads=gm),
        "large rotations": block_scene(n, extra_solver={"large_rotations": True}),
        "large rotations (Green-Naghdi)": block_scene(n, extra_solver={"objective_rate": "green_naghdi"}),
        "deformation gradient kept": block_scene(n, track_F=True),
        "plasticity (smooth_vonmises)": block_scene(n, material="smooth_vonmises"),
        "plasticity (bilinear_vonmises)": block_scene(n, material="bilinear_vonmises"),
        # the damage update on every yielding point (none fails): the fracture option's own cost
        "fracture (bilinear_vonmises)": block_scene(n, material="bilinear_vonmises", fracture=True),
        "fracture (smooth_vonmises)": block_scene(n, material="smooth_vonmises", fracture=True),
        "hyperelasticity (neo_hookean)": block_scene(n, material="neo_hookean"),
    }


def _print_phases(solver, steps, n):
    """The instrumented step: ns per particle-step of each kernel (pmpm/benchmarks/phase_profile.py)."""
    total, phases = phase_times(solver, steps)
    scale = 1e9 / (steps * n)
    rows = {k: v * scale for k, v in sorted(phases.items(), key=lambda kv: -kv[1])}
    print(f"    where the time goes (instrumented, {steps} steps): total {total * scale:.1f} ns/particle-step")
    for name, ns in rows.items():
        print(f"      {name:22s} {ns:6.1f} ns  {100 * ns / (total * scale):4.0f}%")
    return rows


def effects(args):
    """Cost of each optional effect alone: CPU ns per particle-step with and without it."""
    import os
    import tempfile
    from mpi4py import MPI
    with tempfile.TemporaryDirectory() as tmp:
        record = os.path.join(tmp, "record.txt")
        t = np.linspace(0.0, 10.0, 2001)
        np.savetxt(record, np.column_stack([t, 0.5 * np.sin(2 * np.pi * t)]))
        solvers = {name: build_solver(scene, MPI.COMM_SELF) for name, scene in _effect_scenes(args.particles, record).items()}
        for s in solvers.values():  # compile, first-touch, and the plastic block yields
            for _ in range(YIELD_AFTER_STEPS):
                s.step()
        samples = {name: [] for name in solvers}
        for _ in range(args.repeat):  # round robin, so drifts of the machine hit every variant alike
            for name, s in solvers.items():
                t0 = time.process_time()
                for _ in range(args.steps):
                    s.step()
                samples[name].append((time.process_time() - t0) / (args.steps * s.particles.n) * 1e9)
    base = statistics.median(samples["none"])
    print(f"pmpm bench effects: {args.particles} particles, {args.steps} steps x {args.repeat} "
          f"(CPU time, median)")
    print(f"{'effect':32s} {'ns/particle-step':>17s} {'overhead':>9s}  {'spread':>8s}")
    rows = {}
    for name, vals in samples.items():
        med = statistics.median(vals)
        spread = (max(vals) - min(vals)) / med
        rows[name] = {"ns_per_particle_step": med, "overhead": med / base - 1, "spread": spread}
        print(f"{name:32s} {med:17.1f} {100 * (med / base - 1):8.1f}%  {100 * spread:7.1f}%")
    print(json.dumps({"particles": args.particles, "steps": args.steps, "repeat": args.repeat,
                      "effects": rows}))
    return 0
