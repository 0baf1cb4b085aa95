"""The paper's portal frame at multiples of its load: when its sections reach My and Mp.

Runs the ``elastoplastic`` variant of cases/portal_frame.toml with the lateral load scaled by
each ``--factors`` entry (everything else as in the case: its six section cuts, base reactions
and hysteresis request), writes each run's results and plots into ``--out`` (one HDF5 file per
factor, ``portal_frame_x<factor>.h5``, and the structural CSV/PNG files), and prints, per
factor, the cuts in the order they reach Mp with the times of My and Mp and the peak
utilisation, as a Markdown table and as one JSON line (also written to ``--json``).
docs/structural_results.md compares them with tests/verification/frame_hinge_model.py.

Run (one rank, about 3 minutes per factor here)::

    python -m pmpm.benchmarks.studies.frame_hinges --factors 1.5 2 --out /tmp/frame_hinges \
        --json docs/structural_results_frame.json
"""
import argparse
import dataclasses
import json
import math
import os
import sys

import numpy as np

__all__ = ["scaled_scene", "run_factor", "main"]

CASE = os.path.join(os.path.dirname(__file__), "..", "..", "..", "cases", "portal_frame.toml")


def scaled_scene(factor, outdir, t_end=None, case=CASE):
    """The elastoplastic portal frame with its load times ``factor``, writing into ``outdir``."""
    from pmpm.scene.config import load_scene
    scene = load_scene(case, "elastoplastic")[0]
    forces = tuple(dataclasses.replace(f, force=tuple(factor * c for c in f.force)) for f in scene.loads.forces)
    solver = scene.solver if t_end is None else dataclasses.replace(scene.solver, end_time=t_end)
    output = dataclasses.replace(scene.output, directory=outdir, checkpoint_interval=None,
                                 progress_interval=30.0)
    return dataclasses.replace(scene, loads=dataclasses.replace(scene.loads, forces=forces),
                               solver=solver, output=output, variant=f"x{factor:g}")


def run_factor(factor, outdir, t_end=None):
    """Run one factor; returns (hinge rows, path of the results file)."""
    from mpi4py import MPI
    from pmpm.io.post import postprocess
    from pmpm.results.hinges import hinge_rows
    from pmpm.results.post import read_tables
    from pmpm.run import Run
    scene = scaled_scene(factor, outdir, t_end)
    summary = Run(scene, MPI.COMM_SELF).execute()
    postprocess([scene], [summary["output"]])
    return hinge_rows(read_tables(summary["output"])["sections"]), summary["output"]


def _table(factor, rows):
    lines = [f"load x{factor:g}", "", "| section | My reached (ms) | Mp reached (ms) | max abs(M)/Mp | max abs(N)/Np |",
             "|---|---|---|---|---|"]
    for r in rows:
        ms = [f"{r[k] * 1e3:.1f}" if math.isfinite(r[k]) else "-" for k in ("t_My", "t_Mp")]
        lines.append(f"| {r['name']} | {ms[0]} | {ms[1]} | {r['M/Mp']:.3f} | {r['N/Np']:.3f} |")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--factors", type=float, nargs="+", default=[1.5, 2.0])
    p.add_argument("--out", default="frame_hinges")
    p.add_argument("--t-end", type=float, default=None)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    from pmpm.log import setup_logging
    setup_logging(0)
    result = {}
    for factor in args.factors:
        rows, path = run_factor(factor, args.out, args.t_end)
        result[f"{factor:g}"] = rows
        print(_table(factor, rows), "\n", flush=True)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(result, fh, indent=1, default=lambda v: None if not math.isfinite(v) else v)
    print(json.dumps(result, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
