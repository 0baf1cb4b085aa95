"""Step cost of the main job written as a [frame] against the same scene written by hand.

The two scenes (cases/portal_frame.toml and tests/verification/portal_frame_handwritten.toml,
elastic variant, 0.05 m cells) give identical particle arrays (tests/verification/
test_frame_frontend.py), so the step is the same computation; this measures it anyway: both
solvers in one process, warmed up, then rounds of 200 steps each in turn (the order
alternating), CPU time per step,
the median of the rounds. Prints the figures and a final JSON line.

Run: ``python -m studies.frame_frontend_cost [--rounds 7]``
"""
import argparse
import json
import os
import statistics
import time

__all__ = ["main"]

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
SCENES = {"frame": os.path.join(ROOT, "cases", "portal_frame.toml"),
          "handwritten": os.path.join(ROOT, "tests", "verification", "portal_frame_handwritten.toml")}


def _solver(path):
    from mpi4py import MPI

    from pmpm.build import build_solver
    from pmpm.scene.config import load_scene
    return build_solver(load_scene(path, "elastic")[0], MPI.COMM_SELF)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--steps", type=int, default=200)
    args = p.parse_args(argv)
    solvers = {k: _solver(v) for k, v in SCENES.items()}
    for s in solvers.values():
        for _ in range(50):  # compiled and warm
            s.step()
    times = {k: [] for k in solvers}
    for r in range(args.rounds):
        order = list(solvers) if r % 2 == 0 else list(solvers)[::-1]   # neither always goes first
        for k in order:
            s = solvers[k]
            c = time.process_time()
            for _ in range(args.steps):
                s.step()
            times[k].append((time.process_time() - c) / args.steps)
    med = {k: statistics.median(v) for k, v in times.items()}
    ratio = med["frame"] / med["handwritten"]
    for k, v in med.items():
        print(f"{k}: {v * 1e3:.3f} ms per step (CPU, median of {args.rounds} rounds of {args.steps})")
    print(f"frame / handwritten: {ratio:.3f}")
    print(json.dumps({"ms_per_step": {k: v * 1e3 for k, v in med.items()}, "ratio": ratio,
                      "particles": int(solvers["frame"].n_total)}))


if __name__ == "__main__":
    main()
