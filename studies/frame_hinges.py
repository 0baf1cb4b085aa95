"""The paper's portal frame at multiples of its load: when its sections reach My and Mp.

Runs the ``elastoplastic`` variant of cases/portal_frame.toml with the lateral load scaled by
each ``--factors`` entry (everything else as in the case: its six section cuts, base reactions
and hysteresis request), writes each run's results and plots into ``--out`` (one HDF5 file per
factor, ``portal_frame_x<factor>.h5``, and the structural CSV/PNG files), and prints, per
factor, the cuts in the order they reach Mp with the times of My and Mp and the peak
utilisation, as a Markdown table and as one JSON line (also written to ``--json``).
docs/structural_results.md compares them with tests/verification/frame_hinge_model.py.

``--compare DIR`` runs nothing in pmpm: it reads the results files a study wrote into DIR and
prints them beside tests/verification/frame_hinge_model.py (an independent plastic-hinge frame
model, NumPy only): when each cut reaches My and Mp, its moment carried to the member end
(M + a V, a the cut's distance from the end, the short piece's inertia neglected), the base
reactions' moments, and the model's hinge times, as docs/structural_results.md quotes them.

Run (one rank, 5 to 15 minutes per factor on this shared machine)::

    python -m studies.frame_hinges --factors 1.5 2 --out /tmp/frame_hinges \
        --json /tmp/frame_hinges.json
    python -m studies.frame_hinges --factors 1.5 2 --compare /tmp/frame_hinges
"""
import argparse
import dataclasses
import json
import math
import os
import sys

import numpy as np

from studies import verification_models

__all__ = ["scaled_scene", "run_factor", "main"]

CASE = os.path.join(os.path.dirname(__file__), "..", "cases", "portal_frame.toml")


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
    from pmpm.runner import Run
    scene = scaled_scene(factor, outdir, t_end)
    summary = Run(scene, MPI.COMM_SELF).execute()
    postprocess([scene], [summary["output"]])
    return hinge_rows(read_tables(summary["output"])["sections"]), summary["output"]


def _finite(x):
    """``x`` with NaN (a time never reached) as None, so the JSON is standard."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def _table(factor, rows):
    lines = [f"load x{factor:g}", "", "| section | My reached (ms) | Mp reached (ms) | max abs(M)/Mp | max abs(N)/Np |",
             "|---|---|---|---|---|"]
    for r in rows:
        ms = [f"{r[k] * 1e3:.1f}" if math.isfinite(r[k]) else "-" for k in ("t_My", "t_Mp")]
        lines.append(f"| {r['name']} | {ms[0]} | {ms[1]} | {r['M/Mp']:.3f} | {r['N/Np']:.3f} |")
    return "\n".join(lines)


#: distance from each cut to its member's end, towards the start (+) or the end (-) side
END_OFFSET = {"left_column_left_base": 0.2, "right_column_right_base": 0.2, "beam_upper_left_joint": 0.15,
              "beam_upper_right_joint": -0.15}
#: the hinge model's name of the hinge nearest each cut of the scene
HINGE_OF_CUT = {"left_column_left_base": "left_base", "right_column_right_base": "right_base",
                "left_column_upper_left_joint": "left_column_top", "right_column_upper_right_joint": "right_column_top",
                "beam_upper_left_joint": "beam_left_end", "beam_upper_right_joint": "beam_right_end"}


def _hinge_model():
    return verification_models.load("frame_hinge_model")


def compare(factor, outdir):
    """Rows (one per cut) of the MPM run of ``factor`` in ``outdir`` beside the hinge model."""
    from pmpm.results.hinges import first_reached
    from pmpm.results.post import read_tables
    H = _hinge_model()
    tables = read_tables(os.path.join(outdir, f"portal_frame_x{factor:g}.h5"))
    model = H.hinge_response(factor)
    rows = {}
    for k, name in enumerate(H.CUTS):
        s, a = tables["sections"][name], tables["sections"][name]["attrs"]
        end = (first_reached(s["time"], s["M"] + END_OFFSET[name] * s["V"], a["Mp"])
               if name in END_OFFSET else math.nan)
        hinge = HINGE_OF_CUT[name]
        rows[name] = {"mpm_My": first_reached(s["time"], s["M"], a["My"]),
                      "mpm_Mp": first_reached(s["time"], s["M"], a["Mp"]), "mpm_end_Mp": end,
                      "model_cut_My": first_reached(model["t"], model["cut_moments"][:, k], a["My"]),
                      "model_cut_max": float(np.abs(model["cut_moments"][:, k]).max() / a["Mp"]),
                      "model_hinge_Mp": model["first_mp"][hinge]}
    for name, r in tables["reactions"].items():
        a = tables["sections"][{"left_base": "left_column_left_base", "right_base": "right_column_right_base"}[name]]["attrs"]
        rows[f"reaction {name}"] = {"mpm_end_Mp": first_reached(r["time"], np.nan_to_num(r["M"]), a["Mp"]),
                                    "max_M/Mp": float(np.nanmax(np.abs(r["M"])) / a["Mp"])}
    rows["model"] = {"order": model["order"], "max_drift": float(model["drift"].max())}
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--factors", type=float, nargs="+", default=[1.5, 2.0])
    p.add_argument("--out", default="frame_hinges")
    p.add_argument("--t-end", type=float, default=None)
    p.add_argument("--json", default=None)
    p.add_argument("--compare", metavar="DIR", default=None)
    args = p.parse_args(argv)
    if args.compare:
        out = {f"{f:g}": compare(f, args.compare) for f in args.factors}
        print(json.dumps(_finite(out), indent=1))
        return 0
    from pmpm.log import setup_logging
    setup_logging(0)
    result = {}
    for factor in args.factors:
        rows, path = run_factor(factor, args.out, args.t_end)
        result[f"{factor:g}"] = rows
        print(_table(factor, rows), "\n", flush=True)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(_finite(result), fh, indent=1)
    print(json.dumps(_finite(result)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
