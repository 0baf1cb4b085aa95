"""``pmpm bench fixedcost``: the per-step fixed cost of small scenes.

A step costs a + b n for n particles: ``a`` is what a step costs whatever its size (Python
orchestration of the phases, the halo exchanges and allreduces, which are no-ops or cheap on one
rank, the checks, the grid passes over a window that does not shrink with the particles), ``b``
the particles' share. The benchmark runs the benchmark block (cubic, MUSL, elastic) at several
particle counts in one process, round robin (each size in turn, ``--repeat`` rounds, so a drift
of a shared machine hits every size alike), each sample the process CPU time of as many steps
as make about ``--work`` particle-steps, and prints the median ns per particle-step of each size,
its ratio to the largest size's, and a and b from a least-squares fit of the median step times.
The main job (cases/portal_frame.toml) has about 7,700 particles, hence the default sizes.
"""
import json
import statistics
import time

import numpy as np

from pmpm.benchmarks.block import block_scene

__all__ = ["fixed_cost", "measure", "fit_fixed_cost"]


def measure(sizes, repeat, work, material="elastic", clock=time.process_time):
    """{particles: [CPU seconds per step of each round]} of the block at each of ``sizes``."""
    from mpi4py import MPI
    from pmpm.core.solver import Solver
    solvers = [Solver(block_scene(n, material=material), MPI.COMM_SELF) for n in sizes]
    steps = [max(2, int(round(work / s.particles.n))) for s in solvers]
    for s, k in zip(solvers, steps):  # first touch of the arrays, cache warm
        for _ in range(min(k, 30)):
            s.step()
    samples = {s.particles.n: [] for s in solvers}
    for _ in range(repeat):
        for s, k in zip(solvers, steps):
            t0 = clock()
            for _ in range(k):
                s.step()
            samples[s.particles.n].append((clock() - t0) / k)
    return samples


def fit_fixed_cost(n, t):
    """Least-squares (a, b) of t = a + b n: the fixed seconds per step and seconds per particle-step."""
    b, a = np.polyfit(np.asarray(n, float), np.asarray(t, float), 1)
    return float(a), float(b)


def fixed_cost(args):
    """``pmpm bench fixedcost``: returns the exit code."""
    samples = measure(args.particles, args.repeat, args.work, args.material)
    sizes = sorted(samples)
    med = {n: statistics.median(samples[n]) for n in sizes}
    ref = sizes[-1]
    a, b = fit_fixed_cost(sizes, [med[n] for n in sizes])
    print(f"pmpm bench fixedcost: block, cubic MUSL {args.material}, {args.repeat} rounds, about "
          f"{args.work:.0f} particle-steps per sample, process CPU time, median")
    print(f"{'particles':>10s} {'us/step':>10s} {'ns/particle-step':>17s} {'vs largest':>11s}")
    rows = []
    for n in sizes:
        ns = med[n] / n * 1e9
        ratio = ns / (med[ref] / ref * 1e9)
        per_round = [(x / n) / (y / ref) for x, y in zip(samples[n], samples[ref])]
        rows.append({"particles": n, "us_per_step": med[n] * 1e6, "ns_per_particle_step": ns,
                     "ratio_to_largest": ratio, "ratio_per_round": per_round})
        print(f"{n:>10d} {med[n] * 1e6:>10.1f} {ns:>17.1f} {ratio:>11.3f}")
    print(f"fit t = a + b n: fixed cost a = {a * 1e6:.1f} us per step, b = {b * 1e9:.1f} ns per particle-step")
    print(json.dumps({"material": args.material, "repeat": args.repeat, "work": args.work,
                      "fixed_us_per_step": a * 1e6, "ns_per_particle_step_fit": b * 1e9, "sizes": rows}))
    return 0
