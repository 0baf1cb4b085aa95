"""Sudden column loss up to fracture (issue 39, "Structural"): cases/hard/column_loss.toml with
ductile fracture (docs/fracture.md) and the floor load raised step by step until the beam next
to the removed column fractures and the frame no longer arrests.

For each load factor (the case's floor load times ``--factors``, nothing else changed but the
fracture option on the steel) at cell size ``--cell``, one run on one rank through the Python API
(studies/column_loss.py's ``run_cell``). Reported per factor:

- the peak vertical displacement of the point above the removed column and whether the frame
  arrests: the speed criterion of studies.column_loss.summarise (the point's speed falls back
  below 5% of its peak and the drop stays within 1.5 times the peak) AND the beam stops clear
  of the ground. A beam that falls onto the grid's lower edge (the ground: the columns' bases)
  also comes to rest, which the speed criterion alone reads as an arrest; here that is a
  collapse (``grounded``: the beam's bottom flange within two cells of the ground at the peak);
- the first fracture per member (body) and its time (the run summary's ``first_fracture``),
  the number of failed points at the end, their distance from the removed column's axis and
  the box (x, y at the start) they lie in;
- the fracture energy dissipated (J), the particles that left the grid (fragments; removed, the
  run goes on) and the wall time;

then the smallest factor at which the frame no longer arrests (the sequence stops there unless
``--all``), a Markdown table and one JSON line (also written to ``--out``). ``--histories
FILE.npz`` keeps each factor's drop history and failed-point counts per member, ``--plot PNG``
draws the sequence (the drop against time per factor, each member's first fracture marked);
``--replot FILE.npz`` redraws it from a kept file without running.

The fracture parameters (``--eta``, ``--fracture-energy``) are ILLUSTRATIVE: no calibrated
void growth parameters for this steel are shipped (docs/fracture.md, "Parameters"); the case's
5% linear hardening reaches stresses at which a failed point's stored energy can exceed
G_f / l_c, and such a point releases at once (docs/fracture.md, "Failure and regularisation").

Run (coarse; each factor some minutes on one core of this machine, loaded)::

    nice -n 10 python -m studies.column_loss_fracture --cell 0.1 --factors 1 2 3 4 --out /tmp/clf.json
    # the sequence around the threshold, every factor, with its plot
    nice -n 10 python -m studies.column_loss_fracture --cell 0.1 --eta 0.3 --factors 3 3.5 4 --all \
        --histories /tmp/clf.npz --plot docs/column_loss_fracture.png
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
#: the height of the beam's bottom flange above the ground (the grid's lower edge, the columns'
#: bases), m: the beam's axis at 3.658 m less half the W16x36's depth 0.40284 m
BEAM_CLEARANCE = 3.658 - 0.40284 / 2


def fracture_overrides(eta, fracture_energy):
    """The void growth option on the case's steel (illustrative parameters, module doc)."""
    return {"materials.steel.fracture.model": "void_growth",
            "materials.steel.fracture.eta": eta,
            "materials.steel.fracture.fracture_energy": fracture_energy}


def grounded(peak_uy, h):
    """Whether a drop ``peak_uy`` (m, negative down) brings the beam's bottom flange within two
    cells of the ground: the beam lands on the grid's lower edge and rests there (module doc)."""
    return bool(-peak_uy >= BEAM_CLEARANCE - 2.0 * h)


def run_factor(h, factor, eta, fracture_energy, end_time=None, keep=None):
    """One run: the figures of the module doc. ``keep``: a dict that receives the run's drop
    history and failed-point counts (for the plot)."""
    # fragments a fracture throws off may leave the grid: removed (and counted), the run goes on
    ov = {**catenary_overrides(factor), **fracture_overrides(eta, fracture_energy),
          "output.fields": ["x", "damage"], "solver.on_particle_exit": "remove"}
    if end_time is not None:
        ov["solver.end_time"] = end_time
    t0 = time.perf_counter()
    r, _ = run_cell(h, ov)
    wall = time.perf_counter() - t0
    s = summarise(r)
    landed = grounded(s["peak_uy"], h)
    hist = r.histories["above_removed"]
    uy = np.asarray(hist["uy"])
    if keep is not None:
        keep["t"], keep["uy"] = np.asarray(hist["time"]), uy
        for body, tab in getattr(r, "fractures", {}).items():   # failed points per member in time
            keep["failed_t/" + body] = np.asarray(tab["time"])
            keep["failed/" + body] = np.asarray(tab["failed"])
    failed = r.frames["damage"][-1] >= 1.0
    x0 = r.frames["x"][0][failed]
    dist = np.abs(x0[:, 0] - REMOVED_X)

    def extent(a):   # (least, largest); NaN without a failed point
        return (float(a.min()), float(a.max())) if len(a) else (math.nan, math.nan)
    return {"factor": factor, "peak_uy": s["peak_uy"], "t_peak": s["t_peak"], "end_uy": float(uy[-1]),
            "speed_arrest": s["arrested"], "grounded": landed, "arrested": s["arrested"] and not landed,
            "first_fracture": {k: float(v) for k, v in r.summary.get("first_fracture", {}).items()},
            "failed_points": int(failed.sum()), "failed_nearest_m": extent(dist)[0],
            "failed_farthest_m": extent(dist)[1],
            "failed_x_m": list(extent(x0[:, 0])), "failed_y_m": list(extent(x0[:, 1])),
            "fracture_work_J": float(r.energies["fracture_work"][-1]),
            "removed_particles": int(r.summary.get("removed", 0)), "wall_s": wall}


def table(rows):
    lines = ["| factor | peak uy (m) | at (s) | speed arrest | on the ground | arrested | first fracture (member: t, s) | failed points | distance from the removed column (m) | fracture work (J) | wall (s) |",
             "| ---: | ---: | ---: | --- | --- | --- | --- | ---: | --- | ---: | ---: |"]
    for r in rows:
        first = ", ".join(f"{k}: {v:.4f}" for k, v in r["first_fracture"].items()) or "none"
        dist = (f"{r['failed_nearest_m']:.2f} - {r['failed_farthest_m']:.2f}" if r["failed_points"] else "")
        yes = {True: "yes", False: "no"}
        lines.append(f"| {r['factor']:g} | {r['peak_uy']:.4f} | {r['t_peak']:.4f} | {yes[r['speed_arrest']]} | "
                     f"{yes[r['grounded']]} | {yes[r['arrested']]} | {first} | "
                     f"{r['failed_points']} | {dist} | {r['fracture_work_J']:.1f} | {r['wall_s']:.0f} |")
    return "\n".join(lines)


def plot(panels, path):
    """The sequence, one panel per cell size and eta: the drop of the point above the removed
    column against time, one line per load factor, each member's first fracture marked on it and
    the ground's level drawn. ``panels``: (cell size, eta, {factor: :func:`run_factor`'s
    ``keep``}, rows)."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8, 4.6 * len(panels)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True))
    for ax, (h, eta, histories, rows) in zip(axes, panels):
        _draw(ax, histories, rows, h, eta)
    axes[-1].set_xlabel("time (s)")
    fig.savefig(path, dpi=110)
    return path


def _draw(ax, histories, rows, h, eta):
    markers = {"beam": "o", "left column": "<", "right column": ">", "middle column": "s"}
    by_factor = {r["factor"]: r for r in rows}
    for factor in sorted(histories):
        d = histories[factor]
        row = by_factor.get(factor, {})
        state = "arrests" if row.get("arrested") else "does not arrest"
        (line,) = ax.plot(d["t"], d["uy"], lw=1.2, label=f"x{factor:g} ({30 * factor:g} kN/m): {state}")
        # each member's first fracture: the run summary's time (the step's resolution)
        for body, tf in row.get("first_fracture", {}).items():
            ax.plot([tf], [np.interp(tf, d["t"], d["uy"])], markers.get(body, "x"), color=line.get_color(),
                    ms=7, mfc="none")
    fractured = {body for r in rows for body in r.get("first_fracture", {})}
    for body in sorted(fractured):
        ax.plot([], [], markers.get(body, "x"), color="k", mfc="none", label=f"first fracture: {body}")
    ax.axhline(-BEAM_CLEARANCE, color="0.4", lw=0.8, ls="--", label="beam's bottom flange on the ground")
    ax.axvspan(0.08, 0.085, color="0.85")
    ax.set_ylabel("uy above the removed column (m)")
    what = "no failure (locus out of reach)" if eta is not None and eta >= 100 else f"void growth eta = {eta:g}"
    ax.set_title(f"column loss, floor load raised: {h:g} m cells, {what}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")


def save_histories(histories, rows, h, eta, path):
    """Keep the histories (and the rows, as JSON) in an .npz for :func:`plot` later."""
    flat = {f"{f:g}|{k}": v for f, d in histories.items() for k, v in d.items()}
    np.savez(path, rows=json.dumps(rows), cell=h, eta=eta, **flat)


def load_histories(path):
    """The histories, rows, cell size and eta :func:`save_histories` kept."""
    z = np.load(path)
    histories = {}
    for key in z.files:
        if "|" in key:
            f, k = key.split("|", 1)
            histories.setdefault(float(f), {})[k] = z[key]
    return histories, json.loads(str(z["rows"])), float(z["cell"]), float(z["eta"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.1, help="cell size (m)")
    ap.add_argument("--factors", type=float, nargs="+", default=[1, 2, 3, 4, 5, 6],
                    help="floor load factors (increasing; any order with --all)")
    ap.add_argument("--eta", type=float, default=1.0, help="VGM fracture strain at T = 0 (illustrative)")
    ap.add_argument("--fracture-energy", type=float, default=1.0e5, help="G_f, J/m^2 (illustrative)")
    ap.add_argument("--end-time", type=float, default=None, help="override the case's end time (s)")
    ap.add_argument("--all", action="store_true", help="run every factor, not only up to the first collapse")
    ap.add_argument("--out", default=None, help="JSON file of the results")
    ap.add_argument("--histories", default=None, help="keep the drop histories in this .npz")
    ap.add_argument("--plot", default=None, help="draw the sequence to this PNG")
    ap.add_argument("--replot", default=None, metavar="NPZ",
                    help="draw --plot from --histories files (comma-separated; merged per cell size and "
                         "eta, one panel each) and exit")
    args = ap.parse_args(argv)
    if args.replot:
        cells = {}   # the files merged per (cell size, eta), one panel each, coarsest first
        for path in args.replot.split(","):
            hs, rs, h, eta = load_histories(path)
            histories, rows = cells.setdefault((h, eta), ({}, []))
            histories.update(hs)
            rows += rs
        order = sorted(cells, key=lambda k: (-k[0], k[1]))
        for h, eta in order:
            cells[h, eta][1].sort(key=lambda r: r["factor"])
            print(f"{h:g} m cells, eta = {eta:g}:")
            print(table(cells[h, eta][1]))
        plot([(h, eta, *cells[h, eta]) for h, eta in order], args.plot)
        return
    rows, collapse, histories = [], None, {}
    for f in args.factors:
        keep = {}
        row = run_factor(args.cell, f, args.eta, args.fracture_energy, args.end_time, keep=keep)
        rows.append(row)
        histories[f] = keep
        print(json.dumps(row), flush=True)
        if args.histories:   # after every factor: a cut session keeps what it ran
            save_histories(histories, rows, args.cell, args.eta, args.histories)
        if not row["arrested"] and not args.all:
            break
    rows.sort(key=lambda r: r["factor"])   # --all may run the factors in any order (bisection)
    collapse = min((r["factor"] for r in rows if not r["arrested"]), default=None)
    held = max((r["factor"] for r in rows if r["arrested"] and (collapse is None or r["factor"] < collapse)),
               default=None)
    print(table(rows))
    print(f"smallest factor at which the frame no longer arrests: {collapse if collapse is not None else 'none run'}"
          f" (largest below it that arrests: {held if held is not None else 'none run'})")
    out = {"column_loss_fracture": {"cell": args.cell, "eta": args.eta, "fracture_energy": args.fracture_energy,
                                    "collapse_factor": collapse,
                                    "arrest_factor": held, "rows": rows}}
    print(json.dumps(out))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)
    if args.plot:
        plot([(args.cell, args.eta, histories, rows)], args.plot)


if __name__ == "__main__":
    main()
