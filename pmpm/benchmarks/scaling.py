"""``mpirun -n K pmpm bench scaling``: where the time of a distributed step goes.

Per rank it measures the CPU time spent computing (process CPU time minus the CPU time inside
halo exchanges and migration), the communication CPU time and the bytes sent per step, and it
reports the *work inflation*: the sum over ranks of the compute CPU time divided by the CPU time
one rank needs for the same work (measured here first, on rank 0 alone, while the other ranks
sleep). On this 2-vCPU machine wall-clock speed-up says little (ranks share ~1.2 cores), so the
inflation and the bytes are the figures that carry over to a cluster. Waiting inside MPI calls
burns CPU in Open MPI's polling loop; that time is reported separately (``comm_s``) and also
folded into ``work_inflation_with_comm``.

Modes: ``strong`` keeps ``--particles`` in total; ``weak`` gives every rank ``--particles``
(the block grows along x with the rank count, so each slab stays the same shape).
"""
import json
import statistics
import time

import numpy as np
from pmpm.build import build_solver
from pmpm.benchmarks.block import block_scene

__all__ = ["scaling"]


def _sleep_until(req):
    while not req.Test():
        time.sleep(0.005)


def _measure(solver, steps):
    """(process CPU s, wall s, CPU s inside communication, halo bytes, migration bytes) over
    ``steps`` steps."""
    d = solver.decomp
    d.measure_cpu = True
    d.reset_counters()
    d.comm.Barrier()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for _ in range(steps):
        solver.step()
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return cpu, wall, d.comm_cpu, d.bytes_sent["halo"], d.bytes_sent["migration"]


def _reference_cpu(scene_fn, total, steps, comm):
    """CPU time of the same work on one rank (rank 0 alone; the others sleep, not spin)."""
    from mpi4py import MPI
    cpu = None
    if comm.rank == 0:
        s = build_solver(scene_fn(total), MPI.COMM_SELF)
        for _ in range(2):
            s.step()
        cpu = min(_measure(s, steps)[0] for _ in range(2))
        del s
    _sleep_until(comm.Ibarrier())
    return comm.bcast(cpu, root=0)


def scaling(args):
    """Run the benchmark under the current MPI world; prints a table and a JSON line."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    size, rank = comm.size, comm.rank
    total = args.particles * (size if args.mode == "weak" else 1)
    aspect = size if args.mode == "weak" else 1.0

    def scene_fn(n):
        return block_scene(n, ppc=args.ppc, aspect=aspect, extra_solver={"sort_interval": 20})

    ref_cpu = _reference_cpu(scene_fn, total, args.steps, comm) if size > 1 else None
    solver = build_solver(scene_fn(total), comm)
    for _ in range(2):
        solver.step()
    runs = [_measure(solver, args.steps) for _ in range(args.repeat)]
    cpu, wall, comm_s, halo, mig = (statistics.median(r[k] for r in runs) for k in range(5))
    compute = max(cpu - comm_s, 0.0)
    rows = comm.gather((rank, solver.particles.n, compute, comm_s, halo / args.steps, mig / args.steps, cpu), 0)
    n_total = comm.allreduce(solver.particles.n)
    wall = comm.allreduce(wall, op=MPI.MAX)
    if rank != 0:
        return 0
    if ref_cpu is None:
        ref_cpu = rows[0][6]
    print(f"pmpm bench scaling: {args.mode}, {size} rank(s), {n_total} particles, {args.steps} steps "
          f"(median of {args.repeat})")
    print(f"{'rank':>4} {'particles':>10} {'compute s':>10} {'comm s':>8} {'halo B/step':>12} {'migr B/step':>12}")
    for r, n, c, m, hb, mb, _ in rows:
        print(f"{r:>4} {n:>10d} {c:>10.3f} {m:>8.3f} {hb:>12.0f} {mb:>12.0f}")
    inflation = sum(r[2] for r in rows) / ref_cpu
    with_comm = sum(r[6] for r in rows) / ref_cpu
    result = {"ranks": size, "mode": args.mode, "particles": n_total, "steps": args.steps, "ppc": args.ppc,
              "grid_cells": list(solver.grid.cells),
              "work_inflation": inflation, "work_inflation_with_comm": with_comm,
              "one_rank_cpu_s": ref_cpu,
              "halo_bytes_per_step": float(np.mean([r[4] for r in rows])),
              "migration_bytes_per_step": float(np.mean([r[5] for r in rows])),
              "comm_s_per_step": float(np.mean([r[3] for r in rows])) / args.steps,
              "particle_steps_per_s": n_total * args.steps / wall}
    print(f"work inflation {inflation:.3f} (with time in MPI calls {with_comm:.3f}); "
          f"{result['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s wall")
    print(json.dumps(result))
    return 0
