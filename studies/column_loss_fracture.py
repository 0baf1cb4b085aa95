"""Sudden column loss up to fracture (issue 39, "Structural"): cases/hard/column_loss.toml with
ductile fracture (docs/fracture.md) and the floor load raised step by step until the beam next
to the removed column fractures and the frame no longer arrests.

For each load factor (the case's floor load times ``--factors``, nothing else changed but the
fracture option on the steel) at cell size ``--cell``, one run on one rank through the Python API
(studies/column_loss.py's ``run_cell``). Reported per factor:

- the peak vertical displacement of the point above the removed column and whether the frame
  arrests (studies.column_loss.summarise: the point's speed falls back below 5% of its peak
  and the drop stays within 1.5 times the peak);
- the first fracture per member (body) and its time (the run summary's ``first_fracture``),
  the number of failed points at the end, their distance from the removed column's axis and
  the box (x, y at the start) they lie in;
- the fracture energy dissipated (J), the particles that left the grid (fragments; removed, the
  run goes on) and the wall time;

then the smallest factor at which the frame no longer arrests (the sequence stops there unless
``--all``), a Markdown table and one JSON line (also written to ``--out``).

The fracture parameters (``--eta``, ``--fracture-energy``) are ILLUSTRATIVE: no calibrated
void growth parameters for this steel are shipped (docs/fracture.md, "Parameters"); the case's
5% linear hardening reaches stresses at which a failed point's stored energy can exceed
G_f / l_c, and such a point releases at once (docs/fracture.md, "Failure and regularisation").

Run (coarse; each factor some minutes on one core of this machine, loaded)::

    nice -n 10 python -m studies.column_loss_fracture --cell 0.1 --factors 1 2 3 4 --out /tmp/clf.json
"""
import argparse
import json
import math
import time

import numpy as np

from studies.column_loss import catenary_overrides, run_cell, summarise

__all__ = ["fracture_overrides", "run_factor", "main"]

#: the removed (middle) column's axis, m (cases/hard/column_loss.toml)
REMOVED_X = 6.096


def fracture_overrides(eta, fracture_energy):
    """The void growth option on the case's steel (illustrative parameters, module doc)."""
    return {"materials.steel.fracture.model": "void_growth",
            "materials.steel.fracture.eta": eta,
            "materials.steel.fracture.fracture_energy": fracture_energy}


def run_factor(h, factor, eta, fracture_energy, end_time=None):
    """One run: the figures of the module doc."""
    # fragments a fracture throws off may leave the grid: removed (and counted), the run goes on
    ov = {**catenary_overrides(factor), **fracture_overrides(eta, fracture_energy),
          "output.fields": ["x", "damage"], "solver.on_particle_exit": "remove"}
    if end_time is not None:
        ov["solver.end_time"] = end_time
    t0 = time.perf_counter()
    r, _ = run_cell(h, ov)
    wall = time.perf_counter() - t0
    s = summarise(r)
    failed = r.frames["damage"][-1] >= 1.0
    x0 = r.frames["x"][0][failed]
    dist = np.abs(x0[:, 0] - REMOVED_X) if failed.any() else np.array([math.nan])
    where = x0 if failed.any() else np.full((1, 2), math.nan)
    return {"factor": factor, "peak_uy": s["peak_uy"], "arrested": s["arrested"],
            "first_fracture": {k: float(v) for k, v in r.summary.get("first_fracture", {}).items()},
            "failed_points": int(failed.sum()), "failed_nearest_m": float(np.nanmin(dist)),
            "failed_farthest_m": float(np.nanmax(dist)),
            "failed_x_m": [float(np.nanmin(where[:, 0])), float(np.nanmax(where[:, 0]))],
            "failed_y_m": [float(np.nanmin(where[:, 1])), float(np.nanmax(where[:, 1]))],
            "fracture_work_J": float(r.energies["fracture_work"][-1]),
            "removed_particles": int(r.summary.get("removed", 0)), "wall_s": wall}


def table(rows):
    lines = ["| factor | peak uy (m) | arrested | first fracture (member: t, s) | failed points | distance from the removed column (m) | fracture work (J) | wall (s) |",
             "| ---: | ---: | --- | --- | ---: | --- | ---: | ---: |"]
    for r in rows:
        first = ", ".join(f"{k}: {v:.4f}" for k, v in r["first_fracture"].items()) or "none"
        dist = (f"{r['failed_nearest_m']:.2f} - {r['failed_farthest_m']:.2f}" if r["failed_points"] else "")
        lines.append(f"| {r['factor']:g} | {r['peak_uy']:.4f} | {'yes' if r['arrested'] else 'no'} | {first} | "
                     f"{r['failed_points']} | {dist} | {r['fracture_work_J']:.1f} | {r['wall_s']:.0f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.1, help="cell size (m)")
    ap.add_argument("--factors", type=float, nargs="+", default=[1, 2, 3, 4, 5, 6],
                    help="floor load factors, in increasing order")
    ap.add_argument("--eta", type=float, default=1.0, help="VGM fracture strain at T = 0 (illustrative)")
    ap.add_argument("--fracture-energy", type=float, default=1.0e5, help="G_f, J/m^2 (illustrative)")
    ap.add_argument("--end-time", type=float, default=None, help="override the case's end time (s)")
    ap.add_argument("--all", action="store_true", help="run every factor, not only up to the first collapse")
    ap.add_argument("--out", default=None, help="JSON file of the results")
    args = ap.parse_args(argv)
    rows, collapse = [], None
    for f in args.factors:
        row = run_factor(args.cell, f, args.eta, args.fracture_energy, args.end_time)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if not row["arrested"] and collapse is None:
            collapse = f
            if not args.all:
                break
    print(table(rows))
    print(f"smallest factor at which the frame no longer arrests: {collapse if collapse is not None else 'none run'}")
    out = {"column_loss_fracture": {"cell": args.cell, "eta": args.eta, "fracture_energy": args.fracture_energy,
                                    "collapse_factor": collapse, "rows": rows}}
    print(json.dumps(out))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
