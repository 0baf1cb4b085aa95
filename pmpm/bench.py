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

import numpy as np

__all__ = ["add_bench_parser", "main", "block_scene", "warm_kernels"]
logger = logging.getLogger(__name__)

MATERIALS = {
    "elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "linear_elastic": {"type": "linear_elastic", "E": 200e9, "nu": 0.3, "density": 7850.0},
    "smooth_vonmises": {"type": "smooth_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                        "yield_stress": 250e6, "hardening": 0.05, "smoothness": 10.0},
    "bilinear_vonmises": {"type": "bilinear_vonmises", "E": 200e9, "nu": 0.3, "density": 7850.0,
                          "yield_stress": 250e6, "hardening": 0.05},
}


def block_scene(particles, shape="cubic", scheme="musl", material="elastic", ppc=2, aspect=1.0,
                gravity=None, force=False, extra_solver=None, extra_loads=None):
    """A square (or ``aspect`` wide) elastic block filling a grid, loaded hard enough to yield.

    The block is clamped at its base and starts with a shear velocity field (2 m/s at the
    top), so every particle moves and the plastic models really yield.
    """
    from .config import parse_scene
    cells_total = particles / ppc ** 2
    ny = max(4, int(round(math.sqrt(cells_total / aspect))))
    nx = max(4, int(round(cells_total / ny)))
    h = 0.01
    data = {
        "title": f"throughput block {nx}x{ny} cells",
        "particles_per_cell": ppc,
        "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": [nx + 4, ny + 3]},
        "materials": {"m": dict(MATERIALS[material])},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [2 * h, 0.0],
                    "upper": [(nx + 2) * h, ny * h],
                    "velocity": [f"2.0 * y / {ny * h}", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [(nx + 4) * h, 0.0]}],
        "solver": {"shape_function": shape, "scheme": scheme, "end_time": 1.0, "cfl": 0.5,
                   **(extra_solver or {})},
    }
    if gravity or force or extra_loads:
        data["loads"] = dict(extra_loads or {})
        if gravity:
            data["loads"]["gravity"] = [0.0, -9.81]
        if force:
            data["loads"]["forces"] = [{"lower": [2 * h, (ny - 1) * h], "upper": [(nx + 2) * h, ny * h],
                                        "force": [1e3, 0.0]}]
    return parse_scene(data, "bench.toml")


def _rss_bytes():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _time_steps(solver, steps):
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step()
    return time.perf_counter() - t0


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


def throughput(args):
    """Particle-steps per second of one rank on an elastic (or plastic) block."""
    from mpi4py import MPI
    from .solver import Solver
    warm = Solver(block_scene(1000, args.shape, args.scheme, args.material), MPI.COMM_SELF)
    for _ in range(3):
        warm.step()
    del warm
    base = _rss_bytes()
    results = []
    for n in args.particles:
        solver = Solver(block_scene(n, args.shape, args.scheme, args.material), MPI.COMM_SELF)
        solver.step()  # first-touch of the grid window and scratch arrays
        times = [_time_steps(solver, args.steps) for _ in range(args.repeat)]
        med = statistics.median(times)
        n_real = solver.particles.n
        rate = n_real * args.steps / med
        mem = (_rss_bytes() - base) / n_real
        res = {"particles": n_real, "steps": args.steps, "repeats": args.repeat, "shape": args.shape,
               "scheme": args.scheme, "material": args.material, "median_s": med,
               "particle_steps_per_s": rate, "ns_per_particle_step": 1e9 / rate,
               "bytes_per_particle": mem}
        print(f"{n_real:>9d} particles  {args.steps} steps x {args.repeat}: median {med:.3f} s  "
              f"{rate / 1e6:.2f} M particle-steps/s  {1e9 / rate:.1f} ns/particle-step  "
              f"peak memory {mem:.0f} B/particle")
        results.append(res)
        del solver
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
        for s in solvers.values():  # compile and first-touch
            for _ in range(3):
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
    e = bs.add_parser("effects", help="cost of each optional effect alone")
    e.add_argument("--particles", type=int, default=100_000)
    e.add_argument("--steps", type=int, default=10)
    e.add_argument("--repeat", type=int, default=5)
    s = bs.add_parser("scaling", help="run under mpirun: compute/communication split per rank")
    s.add_argument("--mode", choices=["strong", "weak"], default="strong")
    s.add_argument("--particles", type=int, default=1_000_000)
    s.add_argument("--steps", type=int, default=20)
    s.add_argument("--repeat", type=int, default=3)
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
