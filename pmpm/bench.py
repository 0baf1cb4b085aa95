"""Benchmarks (not tests): throughput of the step, and parallel scaling.

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

__all__ = ["add_bench_parser", "main", "block_scene", "warm_kernels"]
logger = logging.getLogger(__name__)

#: the benchmark block's materials (the plastic ones' yield stress is set by block_scene)
MATERIALS = {
    "elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "linear_elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "smooth_vonmises": {"type": "smooth_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                        "yield_stress": 250e6, "hardening": 0.05, "smoothness": 10.0},
    "bilinear_vonmises": {"type": "bilinear_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                          "yield_stress": 250e6, "hardening": 0.05},
}


#: steps of the block's shear after which a plastic block material yields (see block_scene);
#: the benchmarks run them before timing. Not fewer than ~15: the smooth model sub-steps
#: increments above 0.1 of the yield strain, and the step's shear increment is 1/30 of it here.
YIELD_AFTER_STEPS = 30


def block_scene(particles, shape="cubic", scheme="musl", material="elastic", ppc=2, aspect=1.0,
                gravity=None, force=False, extra_solver=None, extra_loads=None):
    """A square (or ``aspect`` wide) elastic block filling a grid, loaded hard enough to yield.

    The block is clamped at its base and starts with a shear velocity field (2 m/s at the
    top), so every particle moves. A plastic material's yield stress is set to the von Mises
    stress that shear reaches after ``YIELD_AFTER_STEPS`` steps: steel's 250 MPa would need
    ~100 times more steps than a benchmark runs, and a plastic model far below yield costs
    what an elastic one does, so the figures are those of the yielding regime, the model's
    most expensive one.
    """
    from .config import parse_scene
    cells_total = particles / ppc ** 2
    ny = max(4, int(round(math.sqrt(cells_total / aspect))))
    nx = max(4, int(round(cells_total / ny)))
    h = 0.01
    mat = dict(MATERIALS[material])
    if "yield_stress" in mat:
        E, nu, rho = mat["E"], mat["nu"], mat["density"]
        cfl = (extra_solver or {}).get("cfl", 0.5)
        dt = cfl * h / math.sqrt(E / (rho * (1 - nu * nu)))  # the CFL step below (plane stress)
        shear_rate = 2.0 / (ny * h)
        mat["yield_stress"] = math.sqrt(3.0) * E / (2 * (1 + nu)) * shear_rate * dt * YIELD_AFTER_STEPS
    data = {
        "title": f"throughput block {nx}x{ny} cells",
        "particles_per_cell": ppc,
        "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": [nx + 4, ny + 3]},
        "materials": {"m": mat},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [2 * h, 0.0],
                    "upper": [(nx + 2) * h, ny * h],
                    "velocity": [f"2.0 * y / {ny * h}", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [(nx + 4) * h, 0.0]}],
        "solver": {"shape_function": shape, "scheme": scheme, "end_time": 1.0, "cfl": 0.5,
                   **(extra_solver or {})},  # (the yield stress above assumes this CFL number)
    }
    if gravity or force or extra_loads:
        data["loads"] = dict(extra_loads or {})
        if gravity:
            data["loads"]["gravity"] = [0.0, -9.81]
        if force:
            data["loads"]["forces"] = [{"lower": [2 * h, (ny - 1) * h], "upper": [(nx + 2) * h, ny * h],
                                        "force": [1e3, 0.0]}]
    return parse_scene(data, "bench.toml")


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


def warm_kernels(verbose=False):
    """Compile every kernel specialisation the shipped cases and tests use (fills the cache)."""
    from mpi4py import MPI
    from .solver import Solver
    for shape in ("cubic", "quadratic", "linear"):
        for scheme in ("musl", "usl", "usf"):
            for loads in (False, True):
                s = Solver(block_scene(400, shape, scheme, gravity=loads, force=loads), MPI.COMM_SELF)
                for _ in range(2):
                    s.step()
                if verbose:
                    print(f"warm: {shape} {scheme} loads={loads}")
    # the shipped cases' extra specialisations: plasticity, and multi-field contact
    from .config import load_scene
    from .contact import ContactSolver
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for solver_class, case, variant in ((Solver, "portal_frame.toml", "elastoplastic"),
                                        (ContactSolver, "disks_contact.toml", None)):
        path = os.path.join(root, "cases", case)
        if os.path.exists(path):
            s = solver_class(load_scene(path, variant)[0], MPI.COMM_SELF)
            for _ in range(2):
                s.step()


@nb.njit(cache=True)
def _triad(a, b, c, scalar):
    for i in range(a.shape[0]):
        a[i] = b[i] + scalar * c[i]


def stream_triad_bandwidth(n=20_000_000, repeat=7):
    """Memory bandwidth of this core in bytes/s, STREAM-triad style (a = b + s c on arrays far
    larger than the caches; 24 bytes per element counted, as STREAM does), best of ``repeat``."""
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    _triad(a, b, c, 3.0)
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        _triad(a, b, c, 3.0)
        best = min(best, time.perf_counter() - t0)
    return 24 * n / best


def step_bytes_per_particle(solver):
    """Bytes the step must stream per particle: every particle array each phase reads or writes
    (counted once per phase) plus the grid window's passes, per particle."""
    p = solver.particles
    size = {k: a.itemsize * (a.size // max(len(a), 1)) for k, a in p.fields.items()}
    size.setdefault("strain", 0)  # kept only when the scene outputs it
    passes = [  # (read, written) particle fields per phase of the MUSL step
        (("x", "m", "v", "vol", "stress"), ()),                               # particles_to_grid
        (("x", "m", "v"), ("v",)),                                            # grid_to_particles
        (("x", "m", "vol", "strain"), ("x", "vol", "strain")),                # update_strain
        (("stress", "vol"), ("stress",)),                                     # update_stress
    ]
    scratch = 16 + 16 + 24 + 24 + 24  # dx written and read, de written and read twice
    particle = sum(size[f] for r, w in passes for f in r + w) + scratch
    grid_nodes = solver.window.G.shape[0] * solver.window.G.shape[1]
    grid = grid_nodes * solver.window.G.shape[2] * 8 * 6 / p.n  # reset, scatter x2, update, velocity, gather
    return particle + grid


def throughput(args):
    """Particle-steps per second of one rank on an elastic (or plastic) block."""
    from mpi4py import MPI
    from .solver import Solver
    t0 = time.perf_counter()
    warm = Solver(block_scene(1000, args.shape, args.scheme, args.material), MPI.COMM_SELF)
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
        solver = Solver(block_scene(n, args.shape, args.scheme, args.material), MPI.COMM_SELF)
        for _ in range(YIELD_AFTER_STEPS):  # first-touch of the arrays; a plastic block yields
            solver.step()
        times = [_time_steps(solver, args.steps) for _ in range(args.repeat)]
        med = statistics.median(t[0] for t in times)
        cpu = statistics.median(t[1] for t in times)
        n_real = solver.particles.n
        rate = n_real * args.steps / med
        mem = (_peak_rss_bytes() - base) / n_real
        res = {"particles": n_real, "steps": args.steps, "repeats": args.repeat, "shape": args.shape,
               "scheme": args.scheme, "material": args.material, "median_s": med,
               "particle_steps_per_s": rate, "ns_per_particle_step": 1e9 / rate,
               "cpu_particle_steps_per_s": n_real * args.steps / cpu,
               "bytes_per_particle": mem, "bytes_moved_per_particle_step": step_bytes_per_particle(solver)}
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
        "ground motion": block_scene(n, extra_loads=gm),
        "large rotations": block_scene(n, extra_solver={"large_rotations": True}),
        "plasticity (smooth_vonmises)": block_scene(n, material="smooth_vonmises"),
    }


def _print_phases(solver, steps, n):
    """The instrumented step: ns per particle-step of each kernel (pmpm/phase_profile.py)."""
    from .phase_profile import phase_times
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
    from .solver import Solver
    with tempfile.TemporaryDirectory() as tmp:
        record = os.path.join(tmp, "record.txt")
        t = np.linspace(0.0, 10.0, 2001)
        np.savetxt(record, np.column_stack([t, 0.5 * np.sin(2 * np.pi * t)]))
        solvers = {name: Solver(scene, MPI.COMM_SELF) for name, scene in _effect_scenes(args.particles, record).items()}
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


def add_bench_parser(sub):
    """Register ``pmpm bench throughput|scaling`` on an argparse sub-parser set."""
    b = sub.add_parser("bench", help="benchmarks (throughput, scaling)")
    bs = b.add_subparsers(dest="bench", required=True)
    t = bs.add_parser("throughput", help="particle-steps per second on one core")
    t.add_argument("--particles", type=int, nargs="+", default=[200_000])
    t.add_argument("--steps", type=int, default=20)
    t.add_argument("--repeat", type=int, default=5)
    t.add_argument("--shape", default="cubic", choices=["linear", "quadratic", "cubic"])
    t.add_argument("--scheme", default="musl", choices=["usf", "usl", "musl"])
    t.add_argument("--material", default="elastic", choices=sorted(MATERIALS))
    t.add_argument("--phases", action="store_true",
                   help="also time every kernel call of the step (after the timed repeats)")
    e = bs.add_parser("effects", help="cost of each optional effect alone")
    e.add_argument("--particles", type=int, default=100_000)
    e.add_argument("--steps", type=int, default=10)
    e.add_argument("--repeat", type=int, default=5)
    s = bs.add_parser("scaling", help="run under mpirun: compute/communication split per rank")
    s.add_argument("--mode", choices=["strong", "weak"], default="strong")
    s.add_argument("--particles", type=int, default=1_000_000)
    s.add_argument("--steps", type=int, default=20)
    s.add_argument("--repeat", type=int, default=3)
    s.add_argument("--ppc", type=int, default=2,
                   help="particles per cell per direction (more particles on the same grid)")
    from .accuracy import add_arguments
    add_arguments(bs.add_parser("accuracy", help="error against wall time over shape, ppc, cell size, scheme"))


def main(args):
    """Dispatch ``pmpm bench <name>``."""
    if args.bench == "throughput":
        return throughput(args)
    if args.bench == "accuracy":
        from .accuracy import accuracy
        return accuracy(args)
    if args.bench == "effects":
        return effects(args)
    from .scaling import scaling
    return scaling(args)
