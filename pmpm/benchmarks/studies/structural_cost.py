"""Cost of the structural results on the portal frame (cases/portal_frame.toml, elastic variant,
one rank): CPU time per step with the case's six section cuts and two base reactions sampled every
``output.history_interval``, against the same scene without them, in alternating repeats; and the
CPU time of one sample (all cuts and reactions, one allreduce).

Run::

    python -m pmpm.benchmarks.studies.structural_cost --steps 1000 --repeat 5
"""
import argparse
import dataclasses
import os
import sys
import time

__all__ = ["main"]

CASE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "cases", "portal_frame.toml")


def _scenes():
    from pmpm.scene.config import load_scene
    base = load_scene(CASE, "elastic")[0]
    plain = dataclasses.replace(
        base, boundaries=tuple(dataclasses.replace(b, reaction=False) for b in base.boundaries),
        output=dataclasses.replace(base.output, sections=()))
    return base, plain


def _cpu_per_step(scene, steps, every):
    from mpi4py import MPI
    from pmpm.core.solver import Solver
    from pmpm.results.recorder import StructuralRecorder
    s = Solver(scene, MPI.COMM_SELF)
    rec = StructuralRecorder(s) if (s.sections or s.reactions is not None) else None
    for _ in range(20):
        s.step()
    c0 = time.process_time()
    for k in range(steps):
        s.step()
        if rec is not None and k % every == 0:
            rec.sample()
    return (time.process_time() - c0) / steps


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)
    from mpi4py import MPI
    from pmpm.core.solver import Solver
    from pmpm.results.recorder import StructuralRecorder
    base, plain = _scenes()
    s = Solver(base, MPI.COMM_SELF)
    every = max(1, int(round(base.output.history_interval / s.dt)))
    times = {"without": [], "with": []}
    for _ in range(args.repeat):
        times["without"].append(_cpu_per_step(plain, args.steps, every))
        times["with"].append(_cpu_per_step(base, args.steps, every))
    rec = StructuralRecorder(s)
    c0 = time.process_time()
    for _ in range(200):
        rec.sample()
    sample = (time.process_time() - c0) / 200
    lo = {k: min(v) * 1e3 for k, v in times.items()}
    print(f"sampled every {every} steps; CPU per step, best of {args.repeat}: without {lo['without']:.3f} ms, "
          f"with {lo['with']:.3f} ms (ratio {lo['with'] / lo['without']:.4f}); ranges: without "
          f"{min(times['without']) * 1e3:.3f}-{max(times['without']) * 1e3:.3f} ms, with "
          f"{min(times['with']) * 1e3:.3f}-{max(times['with']) * 1e3:.3f} ms")
    print(f"one sample ({len(s.sections)} cuts + {len(s.reactions.names)} reactions, one allreduce): "
          f"{sample * 1e6:.1f} us CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
