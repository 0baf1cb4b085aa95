"""Cost of the structural results on the portal frame (cases/portal_frame.toml, elastic variant,
one rank): CPU time per step with the case's six section cuts and two base reactions sampled every
``output.history_interval``, against the same scene without them, in alternating repeats; and the
CPU time of one sample (all cuts and reactions, one allreduce).

``--kernel`` times the grid-update kernel alone on the frame's window, with the reaction
bookkeeping (the case's two base reactions) and without it.

Run::

    python -m studies.structural_cost --steps 1000 --repeat 5
    python -m studies.structural_cost --kernel
"""
import argparse
import dataclasses
import os
import sys
import time

__all__ = ["main"]

CASE = os.path.join(os.path.dirname(__file__), "..", "cases", "portal_frame.toml")


def _scenes():
    from pmpm.scene.config import load_scene
    base = load_scene(CASE, "elastic")[0]
    plain = dataclasses.replace(
        base, boundaries=tuple(dataclasses.replace(b, reaction=False) for b in base.boundaries),
        output=dataclasses.replace(base.output, sections=()))
    return base, plain


def _cpu_per_step(scene, steps, every):
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.results.recorder import StructuralRecorder
    s = build_solver(scene, MPI.COMM_SELF)
    rec = StructuralRecorder(s) if (s.effect("sections") or s.effect("reactions") is not None) else None
    for _ in range(20):
        s.step()
    c0 = time.process_time()
    for k in range(steps):
        s.step()
        if rec is not None and k % every == 0:
            rec.sample()
    return (time.process_time() - c0) / steps


def kernel_timing(calls=2000, repeat=5):
    """Best-of-``repeat`` seconds per grid-update call on the frame's window: (without, with)."""
    from mpi4py import MPI
    from pmpm.core import kernels as K
    from pmpm.build import build_solver
    s = build_solver(_scenes()[0], MPI.COMM_SELF)
    for _ in range(5):
        s.step()
    w = s.window
    G0 = w.G.copy()

    def best(react):
        G, out = G0.copy(), float("inf")
        for _ in range(repeat):
            c0 = time.perf_counter()
            for _ in range(calls):
                K.grid_update(G, 1e-6, s.mass_cutoff, w.bc_mask, w.bc_vel, 0, w.shape[0], 0, w.shape[1],
                              None, s._owned_local, react)
            out = min(out, (time.perf_counter() - c0) / calls)
        return out
    best(None), best(s.effect("reactions").kernel_arg())  # compiled and warm
    return min(best(None), best(None)), best(s.effect("reactions").kernel_arg()), w.shape


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--kernel", action="store_true")
    args = p.parse_args(argv)
    if args.kernel:
        without, with_, shape = kernel_timing(repeat=args.repeat)
        print(f"grid_update on the frame window {shape}: without {without * 1e6:.1f} us, "
              f"with reactions {with_ * 1e6:.1f} us (best of {args.repeat} x 2000 calls)")
        return 0
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.results.recorder import StructuralRecorder
    base, plain = _scenes()
    s = build_solver(base, MPI.COMM_SELF)
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
    print(f"one sample ({len(s.effect('sections'))} cuts + {len(s.effect('reactions').names)} reactions, one allreduce): "
          f"{sample * 1e6:.1f} us CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
