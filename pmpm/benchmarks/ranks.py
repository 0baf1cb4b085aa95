"""``pmpm bench ranks``: the main job on one rank and on two, idle and under a background load.

The main job is ``mpirun -n 2 --bind-to core pmpm cases/portal_frame.toml``. This benchmark
runs its elastic variant for ``--steps`` steps as that command runs it (``pmpm.runner.Run`` with
its output: frames, histories, tracked points, section cuts, reactions, energies and the final
checkpoint, into a temporary folder), on 1 and on 2 ranks, each launched by ``mpirun``
itself, ``--repeat`` times in turn (1, 2, 1, 2, ...), and prints the median wall time of the
stepping loop, the CPU time of all ranks and the speed-up of two ranks over one. ``--case`` and
``--variant`` time another scene the same way (the three-storey frame on 1, 2 and 4 ranks, say:
``pmpm bench ranks --case cases/frame_3storey.toml --ranks 1 2 4 --load none``).

With ``--load busy`` (and ``both``, the default) the same runs are repeated under a background
load the benchmark starts itself: one ``nice -n 19`` busy loop pinned to each core, each in a
session of its own, which is what a user's background work in another terminal is to the
scheduler (Linux's autogroups share the CPU between sessions first: a nice-19 process of
another session gets a core's full share against the run, its niceness counts only inside its
session). The loops are killed at the end, also when the benchmark is interrupted.

``--phases`` times the step's phases instead (pmpm.benchmarks.phase_profile, a solver without
output, on each rank): where the time goes on one rank and on two, idle and loaded.
``--count-calls`` runs each rank count once more with a PMPI shim (jobs/mpi_calls, built with
``mpicc``) and prints the MPI calls per step: the synchronisation points.

The child processes run this module: ``python -m pmpm.benchmarks.ranks --child ...``.
"""
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from pmpm.benchmarks.args import FRAME_CASE, VARIANT, positive
from pmpm.benchmarks.args import ranks_arguments as add_arguments  # noqa: F401  (its options)
from pmpm.build import build_solver
from pmpm.scene.config import load_scene
from pmpm.benchmarks.phase_profile import phase_times
from pmpm.runner import Run
from pmpm.benchmarks.cpuinfo import cpu_model
from pmpm.errors import ConfigError

__all__ = ["ranks", "add_arguments", "BackgroundLoad"]

#: steps a child runs before it times anything (the numba cache read, first touch of the arrays)
WARM_STEPS = 5


# -- the background load ------------------------------------------------------------------------
class BackgroundLoad:
    """One ``nice -n 19`` busy loop per core, each pinned to its core and in its own session;
    a context manager that kills them (by their process ids) on the way out."""

    def __init__(self, cores=None):
        self.cores = list(range(os.cpu_count() or 1)) if cores is None else list(cores)
        self.procs = []

    def __enter__(self):
        for core in self.cores:
            self.procs.append(subprocess.Popen(
                ["taskset", "-c", str(core), "nice", "-n", "19", sys.executable, "-c", "while True: pass"],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, start_new_session=True))
        time.sleep(0.5)  # let them start spinning
        return self

    def __exit__(self, *exc):
        for p in self.procs:
            if p.poll() is None:
                p.kill()
        for p in self.procs:
            p.wait()
        self.procs = []
        return False


# -- one child run ------------------------------------------------------------------------------
def _mpirun(k, bind, args, env=None):
    """Run ``python -m pmpm.benchmarks.ranks`` on ``k`` ranks; ``args`` = (mode, steps). Returns
    the JSON record the child's rank 0 wrote."""
    with tempfile.TemporaryDirectory(prefix="pmpm_ranks_") as tmp:
        out = os.path.join(tmp, "result.json")
        if k > (os.cpu_count() or 1):
            # more ranks than cores: Open MPI refuses to bind two ranks to one core, so they float
            cmd = ["mpirun", "-n", str(k), "--bind-to", "none", "--oversubscribe"]
        else:
            cmd = ["mpirun", "-n", str(k), "--bind-to", bind]
        mode, steps, case, variant = args
        cmd += [sys.executable, "-m", "pmpm.benchmarks.ranks", "--child", mode, out, "--steps", steps,
                "--case", case, "--variant", variant]
        # an explicit environment: with env=None the child inherits the C-level one, where an
        # MPI already initialised in this process (a singleton, as under pytest) has put its own
        # PMIx variables, and the new mpirun then fails without a word
        proc = subprocess.run(cmd, env=dict(os.environ) if env is None else env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if proc.returncode != 0 or not os.path.exists(out):
            raise RuntimeError(f"{' '.join(cmd)} failed (exit {proc.returncode}):\n{proc.stdout[-3000:]}")
        with open(out) as f:
            return json.load(f)


def _child(mode, steps, out, scene_file=FRAME_CASE, variant=VARIANT):
    """Under mpirun: run the scene (``mode`` "run", "solver" or "phases") and write its figures."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    tmp = comm.bcast(tempfile.mkdtemp(prefix="pmpm_ranks_run_") if comm.rank == 0 else None)
    cwd = os.getcwd()
    os.chdir(tmp)  # the scene's output folder is relative to the working directory
    try:
        case = os.path.join(tmp, os.path.basename(scene_file))
        if comm.rank == 0:
            # the copy sits beside the scene's own data folders (a record file, say) as links;
            # never its output folder, so the run writes only into the temporary one
            shutil.copy(scene_file, case)
            here = os.path.dirname(os.path.abspath(scene_file))
            output = load_scene(scene_file, variant)[0].output.directory
            writes = os.path.normpath(output).split(os.sep)[0]
            for entry in os.listdir(here):
                if os.path.isdir(os.path.join(here, entry)) and entry != writes and not entry.endswith("_results"):
                    os.symlink(os.path.join(here, entry), os.path.join(tmp, entry))
        comm.Barrier()
        scene = load_scene(case, variant, overrides={"solver.max_steps": steps + WARM_STEPS})[0]
        warm = build_solver(scene, comm)  # the kernels read from numba's cache, outside the timing
        for _ in range(WARM_STEPS):
            warm.step()
        particles = comm.allreduce(warm.particles.n)
        del warm
        record = {"ranks": comm.size, "steps": steps, "mode": mode, "particles_total": particles}
        if mode == "phases":
            s = build_solver(scene, comm)
            for _ in range(WARM_STEPS):
                s.step()
            comm.Barrier()
            cpu0 = time.process_time()
            total, phases = phase_times(s, steps)
            cpu = time.process_time() - cpu0
            record.update(wall=comm.allreduce(total, op=MPI.MAX), cpu=comm.allreduce(cpu),
                          phases=comm.gather(phases), particles=comm.gather(s.particles.n))
        else:
            if mode == "run":
                run = Run(scene, comm)
                go = run.execute
            else:
                s = build_solver(scene, comm)

                def go():
                    for _ in range(steps + WARM_STEPS):
                        s.step()
            comm.Barrier()
            wall0, cpu0 = time.perf_counter(), time.process_time()
            go()
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            record.update(wall=comm.allreduce(wall, op=MPI.MAX), cpu=comm.allreduce(cpu),
                          cpu_per_rank=comm.gather(cpu))
        if comm.rank == 0:
            with open(out, "w") as f:
                json.dump(record, f)
    finally:
        comm.Barrier()
        os.chdir(cwd)
        if comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


# -- the PMPI call counter ----------------------------------------------------------------------
def _build_counter(tmp):
    """Build jobs/mpi_calls/count_mpi_calls.c into ``tmp``; returns the library's path or None."""
    src = os.path.join(os.path.dirname(FRAME_CASE), "..", "jobs", "mpi_calls", "count_mpi_calls.c")
    if not os.path.exists(src) or shutil.which("mpicc") is None:
        return None
    lib = os.path.join(tmp, "libcount_mpi_calls.so")
    proc = subprocess.run(["mpicc", "-shared", "-fPIC", "-O2", "-o", lib, src], capture_output=True, text=True)
    return lib if proc.returncode == 0 else None


def _count_calls(k, bind, child_args, steps, tmp, lib):
    """MPI calls per step of every rank: {name: calls per step} (mean over the ranks), from the
    difference of a run of ``steps`` and one of twice as many (the set-up's calls cancel)."""
    per_steps = {}
    for n in (steps, 2 * steps):
        path = os.path.join(tmp, f"calls_{k}_{n}.txt")
        env = dict(os.environ, LD_PRELOAD=lib, PMPM_MPI_CALLS=path)
        args = list(child_args)
        args[1] = str(n)
        _mpirun(k, bind, args, env)
        totals = {}
        with open(path) as f:
            for line in f:
                for item in line.split(":", 1)[1].split(","):
                    if item.strip():
                        name, c = item.rsplit(None, 1)
                        totals[name.strip()] = totals.get(name.strip(), 0) + int(c) / k
        per_steps[n] = totals
    names = sorted(set(per_steps[steps]) | set(per_steps[2 * steps]))
    return {nm: (per_steps[2 * steps].get(nm, 0) - per_steps[steps].get(nm, 0)) / steps for nm in names}


# -- the parent -----------------------------------------------------------------------------------
def _summary(records):
    walls = [r["wall"] for r in records]
    cpus = [r["cpu"] for r in records]
    return {"wall_s": statistics.median(walls), "wall_range": [min(walls), max(walls)],
            "cpu_s": statistics.median(cpus), "runs": len(records), "walls": walls, "cpus": cpus}


def _print_phases(load, k, records, steps):
    """Per-phase wall time per step (us), the median over the runs of the slowest rank's."""
    names = sorted({n for r in records for ph in r["phases"] for n in ph})
    print(f"  phases, load {load}, {k} rank(s) (us per step, median over runs of the slowest rank):")
    out = {}
    for n in names:
        value = statistics.median(max(ph.get(n, 0.0) for ph in r["phases"]) for r in records) / steps * 1e6
        out[n] = value
    for n, v in sorted(out.items(), key=lambda kv: -kv[1]):
        print(f"    {n:>22s} {v:9.1f}")
    return out


def ranks(args):
    """``pmpm bench ranks``: returns the exit code."""
    if getattr(args, "child", None):
        return _child(args.child[0], args.steps, args.child[1], os.path.abspath(args.case), args.variant)
    if shutil.which("mpirun") is None:
        print("pmpm: error: bench ranks: mpirun not found (Open MPI's launcher)", file=sys.stderr)
        return 2
    mode = "phases" if args.phases else ("solver" if args.no_output else "run")
    case = os.path.abspath(args.case)
    if not os.path.isfile(case):
        print(f"pmpm: error: bench ranks: --case {args.case}: no such file", file=sys.stderr)
        return 2
    try:  # the scene and its variant checked here, once: not a traceback from every child
        load_scene(case, args.variant or None)
    except ConfigError as exc:
        print(f"pmpm: error: bench ranks: {exc}", file=sys.stderr)
        return 2
    child_args = [mode, str(args.steps), case, args.variant]
    loads = {"both": ["none", "busy"], "none": ["none"], "busy": ["busy"]}[args.load]
    print(f"pmpm bench ranks: {os.path.relpath(case)} [{args.variant}], {args.steps} steps, "
          f"{'solver only' if args.no_output else 'phases' if args.phases else 'with its output'}, "
          f"ranks {args.ranks}, {args.repeat} runs each in turn, mpirun --bind-to {args.bind}; "
          f"{os.cpu_count()} CPUs ({cpu_model()}), load average {os.getloadavg()[0]:.2f} at the start",
          flush=True)
    results = {"scene": f"{os.path.basename(case)} [{args.variant}]", "steps": args.steps,
               "mode": mode, "repeat": args.repeat, "bind": args.bind, "cpu_model": cpu_model(),
               "cpus": os.cpu_count(), "mpi_env": {k: v for k, v in os.environ.items() if k.startswith("OMPI_MCA_mpi")},
               "loads": {}}
    old = signal.signal(signal.SIGTERM, lambda *a: sys.exit(143))
    try:
        for load in loads:
            records = {k: [] for k in args.ranks}
            with (BackgroundLoad() if load == "busy" else _Nothing()):
                for _ in range(args.repeat):
                    for k in args.ranks:
                        records[k].append(_mpirun(k, args.bind, child_args))
            results["loads"][load] = {str(k): _summary(rs) for k, rs in records.items()}
            results["particles"] = records[args.ranks[0]][0].get("particles_total")
            if args.phases:
                for k, rs in records.items():
                    results["loads"][load][str(k)]["phases_us_per_step"] = _print_phases(load, k, rs, args.steps)
        if args.count_calls:
            with tempfile.TemporaryDirectory(prefix="pmpm_calls_") as tmp:
                lib = _build_counter(tmp)
                if lib is None:
                    print("count-calls: no mpicc or no jobs/mpi_calls source: not counted")
                else:
                    results["mpi_calls_per_step"] = {
                        str(k): _count_calls(k, args.bind, ["run" if mode == "phases" else mode, "", case, args.variant],
                                             args.steps, tmp, lib) for k in args.ranks if k > 1}
    finally:
        signal.signal(signal.SIGTERM, old)
    _print_table(results, args)
    print(json.dumps(results))
    return 0


class _Nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _print_table(results, args):
    print(f"{'load':>6s} {'ranks':>5s} {'wall s (median)':>16s} {'range':>15s} {'us/step':>9s} "
          f"{'CPU s, all ranks':>17s} {'speed-up':>9s}")
    for load, by_k in results["loads"].items():
        base = by_k.get(str(min(args.ranks)))
        for k in args.ranks:
            r = by_k[str(k)]
            speed = base["wall_s"] / r["wall_s"] if base else float("nan")
            r["speed_up"] = speed
            lo, hi = r["wall_range"]
            print(f"{load:>6s} {k:>5d} {r['wall_s']:>16.3f} {lo:>7.2f}-{hi:<7.2f} "
                  f"{r['wall_s'] / args.steps * 1e6:>9.0f} {r['cpu_s']:>17.3f} {speed:>9.2f}")
    for k, calls in results.get("mpi_calls_per_step", {}).items():
        print(f"MPI calls per step on {k} ranks (mean per rank, set-up taken out): "
              + ", ".join(f"{n} {c:.3f}" for n, c in calls.items() if abs(c) > 5e-4))


if __name__ == "__main__":
    import argparse
    parser = argparse.ArgumentParser(prog="python -m pmpm.benchmarks.ranks")
    add_arguments(parser)
    # the child runs under mpirun (not a user's option, so not in ``pmpm bench ranks --help``)
    parser.add_argument("--child", nargs=2, metavar=("MODE", "OUT"), help="internal: run one child, write OUT")
    sys.exit(ranks(parser.parse_args()))
