"""``pmpm bench fixedcost``: the per-step fixed cost of small scenes.

A step costs a + b n for n particles: ``a`` is what a step costs whatever its size (Python
orchestration of the phases, the halo exchanges and allreduces, which are no-ops or cheap on one
rank, the checks), ``b`` the particles' share. The benchmark runs the benchmark block (cubic,
MUSL, elastic) at several particle counts and the main job's own scene (the elastic variant of
cases/portal_frame.toml: 31,438 particles on 0.025 m cells since issue 25, 7,700 on 0.05 m before,
which docs/performance.md's figures are of) in one process, round robin
(each case in turn, ``--repeat`` rounds, so a drift of a shared machine hits every case alike),
each sample the process CPU time of as many steps as make about ``--work`` particle-steps, and
prints the median ns per particle-step of each case, its ratio to the largest block's (and the ratio of the fastest rounds), and a and
b from a least-squares fit of the blocks' median step times. The frame differs from a block of
its size by its grid: a hollow frame in a 143 x 85 node window. By default each case runs as the
solver chooses (tiles "auto": pmpm.core.grid.choose_tile); ``--whole-window`` times every case
twice instead, interleaved, with tiles ("on": node passes over the active tiles only) and
without ("off": each pass over the whole window, as before the tiles).
"""
import json
import statistics
import time

import numpy as np

from pmpm.benchmarks.block import block_scene
from pmpm.benchmarks.ranks import FRAME_CASE
from pmpm.core.grid import TILE
from pmpm.scene.config import load_scene
from pmpm.build import build_solver
from pmpm.runner import Run

__all__ = ["fixed_cost", "measure", "fit_fixed_cost", "frame_scene"]

#: the label of the main job's scene in the tables
FRAME = "frame"


def frame_scene(variant="elastic"):
    """A variant of the main job (cases/portal_frame.toml) as the benchmark runs it."""
    return load_scene(FRAME_CASE, variant)[0]


def _cases(sizes, material, frames, whole_window):
    """(scene label, tiles on, solver) of every case, the blocks first."""
    from mpi4py import MPI
    scenes = [("block", block_scene(n, material=material)) for n in sizes]
    scenes += [(f"{FRAME} {v}", frame_scene(v)) for v in frames]
    cases = []
    for tiles in ((True, False) if whole_window else (None,)):
        for label, scene in scenes:
            s = build_solver(scene, MPI.COMM_SELF)
            s.default_tile = s.window.tile   # what the solver chose (pmpm.core.grid.choose_tile)
            if whole_window:                 # both ways, whatever the default
                s.window.use_tiles(TILE if tiles else 0)
            cases.append((label, tiles, s))
    return cases


def measure(sizes, repeat, work, material="elastic", clock=time.process_time, frames=(),
            whole_window=False, output_frames=(), output_steps=1500):
    """{(scene, particles, tiles on): [CPU seconds per step of each round]} of the block at each
    of ``sizes`` and the portal frame's ``frames`` variants (every case also with the tiles off
    with ``whole_window``), and of the frame's ``output_frames`` variants run with their output
    (:class:`FrameRun`, runs of ``output_steps`` and twice as many steps)."""
    cases = _cases(sizes, material, frames, whole_window)
    steps = [max(2, int(round(work / s.particles.n))) for _, _, s in cases]
    for (_, _, s), k in zip(cases, steps):  # first touch of the arrays, cache warm
        for _ in range(min(k, 30)):
            s.step()
    samples = {(label, s.particles.n, tiles): [] for label, tiles, s in cases}
    measure.defaults = {(label, s.particles.n): (s.default_tile, s.window.G.shape[0] * s.window.G.shape[1])
                        for label, _, s in cases}
    runs = [FrameRun(v) for v in output_frames]
    try:
        for _ in range(repeat):
            for (label, tiles, s), k in zip(cases, steps):
                t0 = clock()
                for _ in range(k):
                    s.step()
                samples[label, s.particles.n, tiles].append((clock() - t0) / k)
            for run in runs:
                t = run.cpu_per_step(output_steps, clock)
                samples.setdefault((f"{FRAME} {run.variant} + output", run.n, None), []).append(t)
    finally:
        for run in runs:
            run.close()
    return samples


class FrameRun:
    """The main job's elastic frame as ``pmpm run`` steps it, with its output (frames,
    histories, tracked points, section cuts, reactions, energies, checkpoints) written into a
    temporary folder. ``cpu_per_step(steps)`` is the process CPU time of a run of ``2 steps``
    steps minus one of ``steps``, over ``steps``: the set-up, the final checkpoint and the
    closing of the files cancel, what remains is what each step costs with its share of the
    output's per-step work."""

    def __init__(self, variant="elastic"):
        import tempfile
        self.tmp = tempfile.mkdtemp(prefix="pmpm_fixedcost_")
        self.variant = variant
        import shutil
        self.case = shutil.copy(FRAME_CASE, self.tmp)
        self.n = None  # known after the first run

    def _run(self, steps, clock):
        import os
        from mpi4py import MPI
        cwd = os.getcwd()
        os.chdir(self.tmp)  # the scene's output folder is relative to the working directory
        try:
            scene = load_scene(self.case, self.variant, overrides={"solver.max_steps": steps})[0]
            run = Run(scene, MPI.COMM_SELF)
            self.n = run.solver.particles.n
            t0 = clock()
            run.execute()
            return clock() - t0
        finally:
            os.chdir(cwd)

    def cpu_per_step(self, steps, clock=time.process_time):
        return (self._run(2 * steps, clock) - self._run(steps, clock)) / steps

    def close(self):
        import shutil
        shutil.rmtree(self.tmp, ignore_errors=True)


def fit_fixed_cost(n, t):
    """Least-squares (a, b) of t = a + b n: the fixed seconds per step and seconds per particle-step."""
    b, a = np.polyfit(np.asarray(n, float), np.asarray(t, float), 1)
    return float(a), float(b)


def _rows(samples, tiles):
    """Table rows of the cases with ``tiles`` on or off, each against the largest block's."""
    keys = [k for k in samples if k[2] == tiles]
    blocks = sorted(k for k in keys if k[0] == "block")
    ref = blocks[-1]
    med = {k: statistics.median(samples[k]) for k in keys}
    ref_ns = med[ref] / ref[1]
    rows = []
    for k in blocks + [k for k in keys if k[0] != "block"]:
        label, n, _ = k
        per_round = [(x / n) / (y / ref[1]) for x, y in zip(samples[k], samples[ref])]
        # the fastest rounds' ratio beside the medians': a busy machine only ever adds time
        fastest = (min(samples[k]) / n) / (min(samples[ref]) / ref[1])
        rows.append({"scene": label, "particles": n, "tiles": tiles, "us_per_step": med[k] * 1e6,
                     "ns_per_particle_step": med[k] / n * 1e9, "ratio_to_largest": (med[k] / n) / ref_ns,
                     "ratio_of_fastest": fastest, "ratio_per_round": per_round})
    a, b = fit_fixed_cost([k[1] for k in blocks], [med[k] for k in blocks])
    return rows, a, b


def fixed_cost(args):
    """``pmpm bench fixedcost``: returns the exit code."""
    frames = getattr(args, "frame", ["elastic"])
    whole = getattr(args, "whole_window", False)
    output = frames if getattr(args, "output", False) else ()
    samples = measure(args.particles, args.repeat, args.work, args.material, frames=frames,
                      whole_window=whole, output_frames=output,
                      output_steps=getattr(args, "output_steps", 1500))
    print(f"pmpm bench fixedcost: block (cubic MUSL {args.material})"
          f"{' and the portal frame (' + ', '.join(frames) + ', 0.05 m)' if frames else ''}, "
          f"{args.repeat} rounds, about "
          f"{args.work:.0f} particle-steps per sample, process CPU time, median")
    print(f"{'scene':>24s} {'tiles':>6s} {'particles':>10s} {'us/step':>10s} {'ns/particle-step':>17s} "
          f"{'vs largest block':>17s} {'fastest rounds':>15s}")
    summary = {"material": args.material, "repeat": args.repeat, "work": args.work}
    name = {None: "auto", True: "on", False: "off"}
    for tiles in ((True, False) if whole else (None,)):
        rows, a, b = _rows(samples, tiles)
        for r in rows:
            print(f"{r['scene']:>24s} {name[tiles]:>6s} {r['particles']:>10d} "
                  f"{r['us_per_step']:>10.1f} {r['ns_per_particle_step']:>17.1f} {r['ratio_to_largest']:>17.3f} {r['ratio_of_fastest']:>15.3f}")
        print(f"fit over the blocks (tiles {name[tiles]}) t = a + b n: fixed cost "
              f"a = {a * 1e6:.1f} us per step, b = {b * 1e9:.1f} ns per particle-step")
        key = "" if tiles is not False else "_whole_window"
        summary.update({"fixed_us_per_step" + key: a * 1e6, "ns_per_particle_step_fit" + key: b * 1e9,
                        "sizes" + key: [r for r in rows if r["scene"] == "block"]})
        for r in rows:
            if r["scene"] != "block":
                summary[r["scene"].replace(" ", "_") + key] = r
    if output:
        print(f"'+ output': the variant run as `pmpm run` runs it, with its frames, histories, tracks, "
              f"sections, reactions, energies and checkpoints (runs of {args.output_steps} and "
              f"{2 * args.output_steps} steps, their difference per step)")
    for (label, n), (tile, nodes) in measure.defaults.items():
        print(f"{label} ({n} particles, {nodes} window nodes, {nodes / n:.2f} per particle): the solver's "
              f"default is {'tiles of ' + str(tile) + ' nodes' if tile else 'the whole window'}")
    summary["default_tile"] = {f"{label} {n}": tile for (label, n), (tile, _) in measure.defaults.items()}
    print(json.dumps(summary))
    return 0
