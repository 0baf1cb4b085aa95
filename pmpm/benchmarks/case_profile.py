"""``pmpm bench profile [case]``: where a scene's step goes, phase by phase, with its output, against
the benchmark block's cost per particle-step.

Each round runs the scene as ``pmpm run`` runs it (``pmpm.runner.Run``: frames, history rows,
tracked points, section cuts, reactions, energies, the last good state, checkpoints) for
``--steps`` steps into a temporary folder, by default one frame interval of the scene (so each
run writes one frame and its history rows, the output a step of the whole run pays on
average), and between its steps, in ``--block-chunks`` chunks spread over the run, the
200,000-particle benchmark block (cubic MUSL, elastic, pmpm.benchmarks.block) for
``--block-steps`` steps, timed apart: a drift of a shared machine hits both alike (the
absolute times of a shared machine mean less than the ratio). The ratio of the two costs per
particle-step is taken per round and its median printed.

The step's phases are the solver's own methods (reset_grid, particles_to_grid, exchange_halo,
update_grid, grid_to_particles, grid_velocity, update_strain, update_stress, the step-end check,
sorting, migration), each wrapped for the measurement only; the output's are the run's
(record_history, write_frame with the history flush, the last-good-state snapshot, checkpoint);
"step: other" is the rest of ``Solver.step`` (the scheme's Python, the effects' hooks) and
"loop: other" the rest of ``Run.execute`` (its schedules, the progress line, the start's health
check). Times are wall seconds of the phases (perf_counter: the process CPU clock is a system
call of 6-16 us on this machine, docs/performance.md); the ratio uses the process CPU time of
the whole block run and of the whole ``Run.execute``. ``--tiles on|off`` forces the grid's node
passes over the active tiles or the whole window (pmpm.core.grid; the same results to the bit). The run's set-up (reading the scene,
building the solver, opening the file) is not timed: it is paid once per run, not per step.

Prints a table and, last, one JSON line.
"""
import collections
import contextlib
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

from mpi4py import MPI

import pmpm.runner as runner_module
from pmpm.benchmarks.block import block_scene
from pmpm.benchmarks.cpuinfo import cpu_model
from pmpm.benchmarks.phase_profile import timed
from pmpm.build import build_solver
from pmpm.core.grid import TILE
from pmpm.errors import ConfigError
from pmpm.runner import Run
from pmpm.scene.config import load_scene

__all__ = ["profile", "STEP_PHASES", "OUTPUT_PHASES", "staged_case"]

#: the solver's phase methods timed (in the order of a MUSL step, then the step's end)
STEP_PHASES = ("sort_particles", "reset_grid", "particles_to_grid", "exchange_halo", "update_grid",
               "grid_to_particles", "grid_velocity", "update_strain", "move_particles", "update_stress",
               "_check_and_next_dt", "check_energy", "migrate", "rebalance")
#: ``--tiles``: the node passes' tile size forced (None: the solver's choice, choose_tile)
TILES = {"auto": None, "on": TILE, "off": 0}
#: the run's output phases timed
OUTPUT_PHASES = ("record_history", "write_frame", "checkpoint", "snapshot")


@contextlib.contextmanager
def staged_case(scene_file, variant):
    """A temporary folder holding a copy of ``scene_file`` beside links to the scene's data
    folders (records, meshes; never its output folder), the working directory for the
    duration: a scene's relative output folder is then inside it. Yields the copy's path."""
    tmp = tempfile.mkdtemp(prefix="pmpm_profile_")
    cwd = os.getcwd()
    try:
        case = shutil.copy(scene_file, tmp)
        here = os.path.dirname(os.path.abspath(scene_file))
        output = load_scene(scene_file, variant)[0].output.directory
        writes = os.path.normpath(output).split(os.sep)[0]
        for entry in os.listdir(here):
            if os.path.isdir(os.path.join(here, entry)) and entry != writes and not entry.endswith("_results"):
                os.symlink(os.path.join(here, entry), os.path.join(tmp, entry))
        os.chdir(tmp)
        yield case
    finally:
        os.chdir(cwd)
        shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def _timed_snapshots(totals):
    """The run's last-good-state copies (``pmpm.runner._Snapshot``) timed as "snapshot"."""
    original = runner_module._Snapshot

    def snapshot(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            totals["snapshot"] += time.perf_counter() - t0

    runner_module._Snapshot = snapshot
    try:
        yield
    finally:
        runner_module._Snapshot = original


class _Block:
    """The reference block run in chunks between the scene's steps (``chunk(k)`` runs ``k``
    steps): its process CPU and wall seconds and its phases' wall seconds add up over a round."""

    def __init__(self, solver):
        self.solver = solver
        self.cpu = self.wall = 0.0
        self.steps = 0
        self.totals = collections.defaultdict(float)

    @contextlib.contextmanager
    def timed(self):
        with contextlib.ExitStack() as stack:
            for name in STEP_PHASES:
                stack.enter_context(timed(self.solver, name, self.totals))
            stack.enter_context(timed(self.solver, "step", self.totals))
            yield self

    def chunk(self, k):
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(k):
            self.solver.step()
        self.cpu += time.process_time() - c0
        self.wall += time.perf_counter() - t0
        self.steps += k

    def phases(self):
        phases = {k: self.totals[k] for k in STEP_PHASES if self.totals[k] > 0}
        phases["step: other"] = max(self.totals["step"] - sum(phases.values()), 0.0)
        return phases


def _profiled_run(case, variant, steps, block, block_steps, chunks, tiles=None):
    """Run the scene ``steps`` steps with its output, the ``block`` (a :class:`_Block`) run
    ``block_steps`` steps in ``chunks`` chunks spread evenly between the scene's steps (not
    counted in the scene's times), so that a drift of a shared machine hits both alike.
    ``tiles``: the scene's grid node passes over tiles of that many nodes, 0 the whole window,
    None as the solver chose. Returns (CPU s, wall s of execute, {phase: wall s}, particles,
    steps run), the block's share taken out."""
    scene = load_scene(case, variant, overrides={"solver.max_steps": steps})[0]
    run = Run(scene, MPI.COMM_SELF)
    s = run.solver
    if tiles is not None:
        s.window.use_tiles(tiles)
    totals = collections.defaultdict(float)
    every = max(1, steps // chunks)
    per_chunk = [block_steps // chunks + (1 if k < block_steps % chunks else 0) for k in range(chunks)]
    with contextlib.ExitStack() as stack:
        stack.enter_context(block.timed())
        stack.enter_context(timed(s, "step", totals))
        for name in STEP_PHASES:
            stack.enter_context(timed(s, name, totals))
        for name in OUTPUT_PHASES[:3]:
            stack.enter_context(timed(run, name, totals))
        stack.enter_context(_timed_snapshots(totals))
        timed_step = s.step

        def step():   # the block's chunk before every ``every``-th step of the scene
            if s.step_count % every == every // 2 and per_chunk:
                block.chunk(per_chunk.pop())
            return timed_step()

        s.step = step
        c0, t0 = time.process_time(), time.perf_counter()
        b_cpu, b_wall = block.cpu, block.wall
        try:
            run.execute()
        finally:
            del s.step   # the timed wrapper's own exit restores the method
            s.step = timed_step
        while per_chunk:   # a run shorter than planned: the rest of the block's steps after it
            block.chunk(per_chunk.pop())
        wall = time.perf_counter() - t0 - (block.wall - b_wall)
        cpu = time.process_time() - c0 - (block.cpu - b_cpu)
    phases = {k: totals[k] for k in STEP_PHASES + OUTPUT_PHASES if totals[k] > 0}
    phases["step: other"] = max(totals["step"] - sum(totals[k] for k in STEP_PHASES), 0.0)
    phases["loop: other"] = max(wall - totals["step"] - sum(totals[k] for k in OUTPUT_PHASES), 0.0)
    return cpu, wall, phases, s.particles.n, s.step_count


def _default_steps(case, variant):
    """Steps of one frame interval of the scene (its first time step, rounded)."""
    scene = load_scene(case, variant)[0]
    s = build_solver(scene, MPI.COMM_SELF)
    return max(10, int(round(scene.output.interval / s.dt))), s


def profile(args):
    """``pmpm bench profile``: returns the exit code."""
    case_file = os.path.abspath(args.case)
    try:   # a bad scene or variant: one line, nothing run
        variant = load_scene(case_file, args.variant)[0].variant or None   # default: the first
    except ConfigError as exc:
        print(f"pmpm: error: bench profile: {exc}", file=sys.stderr)
        return 2
    block = build_solver(block_scene(args.particles), MPI.COMM_SELF)
    for _ in range(30):   # compile (numba's cache), first touch
        block.step()
    with staged_case(case_file, variant) as case:
        steps, warm = _default_steps(case, variant) if args.steps is None else (args.steps, None)
        if warm is None:
            warm = build_solver(load_scene(case, variant)[0], MPI.COMM_SELF)
        for _ in range(5):
            warm.step()
        del warm
        rounds = []
        for _ in range(args.rounds):
            b = _Block(block)
            cpu, wall, phases, n, ran = _profiled_run(case, variant, steps, b, args.block_steps,
                                                      args.block_chunks, TILES[args.tiles])
            rounds.append({"block_cpu": b.cpu, "block_phases": b.phases(), "cpu": cpu, "wall": wall,
                           "phases": phases, "particles": n, "steps": ran})
    nb = block.particles.n
    n, ran = rounds[0]["particles"], rounds[0]["steps"]
    per_block = [r["block_cpu"] / (args.block_steps * nb) * 1e9 for r in rounds]
    per_case = [r["cpu"] / (r["steps"] * r["particles"]) * 1e9 for r in rounds]
    ratios = [c / b for c, b in zip(per_case, per_block)]

    def median_ns(key, k, count, steps_of):
        return statistics.median(r[key].get(k, 0.0) / (steps_of(r) * count) * 1e9 for r in rounds)

    names = list(dict.fromkeys(k for r in rounds for k in list(r["phases"]) + list(r["block_phases"])))
    table = {k: {"case_ns": median_ns("phases", k, n, lambda r: r["steps"]),
                 "block_ns": median_ns("block_phases", k, nb, lambda r: args.block_steps)} for k in names}
    print(f"pmpm bench profile: {os.path.relpath(case_file)} [{variant or '-'}] {n} particles, {ran} "
          f"steps per run with its output, against the block of {nb} particles ({args.block_steps} "
          f"steps); {args.rounds} interleaved rounds, medians; {cpu_model()}")
    # the phases in wall time (a shared machine inflates them all, the shares less so)
    case_wall = sum(r["case_ns"] for r in table.values())
    block_wall = sum(r["block_ns"] for r in table.values())
    print(f"{'phase (wall)':24s} {'case ns/p-step':>15s} {'share':>6s} {'block ns/p-step':>16s} {'share':>6s}")
    for k, row in sorted(table.items(), key=lambda kv: -kv[1]["case_ns"]):
        row["case_share"], row["block_share"] = row["case_ns"] / case_wall, row["block_ns"] / block_wall
        print(f"{k:24s} {row['case_ns']:15.2f} {100 * row['case_share']:5.1f}% {row['block_ns']:16.2f} "
              f"{100 * row['block_share']:5.1f}%")
    med_case, med_block, med_ratio = (statistics.median(v) for v in (per_case, per_block, ratios))
    print(f"whole run (process CPU): case {med_case:.1f} ns/particle-step ({med_case * n * 1e-6:.2f} ms "
          f"per step), block {med_block:.1f}; ratio per round {', '.join(f'{r:.3f}' for r in ratios)}: "
          f"median {med_ratio:.3f}")
    print(json.dumps({"case": os.path.relpath(case_file), "variant": variant, "particles": n,
                      "steps": ran, "block_particles": nb, "block_steps": args.block_steps,
                      "rounds": args.rounds, "cpu": cpu_model(), "tiles": args.tiles,
                      "case_ns_per_particle_step": med_case, "block_ns_per_particle_step": med_block,
                      "ratio": med_ratio, "ratio_per_round": ratios, "phases_ns": table}))
    return 0
