"""Sudden column loss (cases/hard/column_loss.toml) at several cell sizes (issue 23, item 3).

Each cell size runs the case in-process on one rank through the Python API (the grid's cell
count scaled to the same extent; the bodies regenerate their strips at each cell size).
Reported per cell size, for the point on the beam's axis above the removed column:

- the peak vertical displacement (most negative uy) and its time;
- the permanent displacement: the time mean of uy over whole periods of the residual vibration,
  from the peak (the first trough) to the last trough of the record (``permanent_uy``). The
  light damping has not stilled the swing by 0.2 s, and its period differs a little between cell
  sizes, so a fixed window (the earlier 0.16 to 0.20 s mean, kept as ``window_uy``) cuts each
  run's oscillation at a different phase and its mean carries part of the amplitude (about
  +-36 mm here); a mean over whole periods does not. ``midpoint_uy`` is the centre of the last
  trough and the crest before it, a second estimate of the same centre;
- arrest or collapse: arrested when the point's speed falls back below 5% of its peak speed
  after the peak and the displacement stays within 1.5 times the peak over the rest of the run;
- the beams' section forces at the cut 0.3 m left of the removed column and at the left end:
  the axial force N and moment M before the removal (t = 0.079 s) and at the peak, and the
  largest tension and compression after the removal (catenary action shows as tension);
- the energy balance's largest gap (kinetic + internal work + damping works + removed energy -
  external work), relative to the external work at the end.

Then the relative difference of the two finest runs' peak and permanent displacements, a
Markdown table, and one JSON line (also written to ``--out``). ``--histories FILE.npz`` keeps
t, uy and the cuts' N, M per cell size for the plot (``--plot PNG`` draws it).

A finer grid can be run on several ranks with the command line and read back here:
``--results H=FILE.h5`` (repeatable) summarises a results file written at cell size H (the
scene's copy with ``cell_size`` and ``cells`` changed; ``end_time`` at least 0.2 s).

Run::

    python -m studies.column_loss --cells 0.1 0.05 --out /tmp/column_loss.json \
        --histories /tmp/column_loss.npz --plot docs/column_loss_history.png
    # 0.025 m on two ranks (about 30 minutes on this machine, loaded), then read back:
    mpirun -n 2 pmpm /tmp/cl025/column_loss.toml
    python -m studies.column_loss --cells 0.05 \
        --results 0.025=/tmp/cl025/column_loss_results/column_loss.h5 --plot docs/column_loss_history.png
"""
import argparse
import json
import math
import os
import time

import numpy as np

__all__ = ["run_cell", "summarise", "main"]

CASE = os.path.join(os.path.dirname(__file__), "..", "cases", "hard", "column_loss.toml")
TRACK = "above_removed"
CUTS = ("beam_mid_left", "beam_left_end")
EXTENT = (13.2, 4.2)    # the case's grid: 264 x 84 cells of 0.05 m
#: the permanent displacement is the mean over this window (s)
PERMANENT_WINDOW = (0.16, 0.20)


def run_cell(h, overrides=None, comm=None):
    """Run the case at cell size ``h``; returns the API Result and the wall time."""
    import pmpm
    ov = {"grid.cell_size": h, "grid.cells": [int(round(EXTENT[0] / h)), int(round(EXTENT[1] / h))]}
    ov.update(overrides or {})
    t0 = time.perf_counter()
    r = pmpm.run(CASE, overrides=ov, dataframes=False, comm=comm)
    return r, time.perf_counter() - t0


def troughs_after(t, uy, k):
    """Indices of the local minima of uy from index ``k`` (the peak) on."""
    i = np.arange(k + 1, len(uy) - 1)
    m = i[(uy[i] < uy[i - 1]) & (uy[i] <= uy[i + 1])]
    return np.concatenate([[k], m]).astype(int)


def whole_period_mean(t, uy, k):
    """Time mean of uy from the peak trough ``k`` to the last trough (whole periods), the centre of
    the last trough and the crest before it, and the number of periods; NaN without a second trough."""
    tr = troughs_after(t, uy, k)
    # a trough of the swing, not numerical ripple: deeper than the mean of the two neighbouring crests
    tr = [j for j in tr if j == k or uy[j] < 0.5 * (uy[k] + uy[k:j + 1].max())]
    if len(tr) < 2:
        return math.nan, math.nan, 0
    a, b = tr[0], tr[-1]
    mean = float(np.trapezoid(uy[a:b + 1], t[a:b + 1]) / (t[b] - t[a]))
    crest = a + int(np.argmax(uy[a:b + 1])) if len(tr) == 2 else tr[-2] + int(np.argmax(uy[tr[-2]:b + 1]))
    return mean, float(0.5 * (uy[crest] + uy[b])), len(tr) - 1


def summarise(r, removal_time=0.08):
    """The figures of the module doc from one Result."""
    h = r.histories[TRACK]
    t, uy, vy = (np.asarray(h[c]) for c in ("time", "uy", "vy"))
    k = int(np.argmin(uy))
    after = t > t[k]
    speed = np.abs(vy)
    peak_speed = float(speed[t > removal_time].max())
    arrested = bool(after.any() and speed[after].min() < 0.05 * peak_speed
                    and uy[after].min() > 1.5 * uy[k])
    last = (t >= PERMANENT_WINDOW[0]) & (t <= PERMANENT_WINDOW[1])
    before = int(np.argmin(np.abs(t - (removal_time - 0.001))))
    cuts = {}
    for name in CUTS:
        N, M = np.asarray(r.sections[name]["N"]), np.asarray(r.sections[name]["M"])
        post = t > removal_time
        cuts[name] = {"N_before": float(N[before]), "M_before": float(M[before]), "N_peak": float(N[k]),
                      "M_peak": float(M[k]), "N_max_tension": float(np.nanmax(N[post])),
                      "N_max_compression": float(np.nanmin(N[post]))}
    e = r.energies
    held = (np.asarray(e["kinetic"]) + e["internal_work"] + e["damping_work"] + e["viscous_damping_work"]
            + e["removed_energy"] - e["external_work"])
    permanent, midpoint, periods = whole_period_mean(t, uy, k)
    return {"peak_uy": float(uy[k]), "t_peak": float(t[k]), "permanent_uy": permanent,
            "midpoint_uy": midpoint, "periods": periods, "window_uy": float(uy[last].mean()),
            "uy_before": float(uy[before]), "arrested": arrested, "peak_speed": peak_speed, "cuts": cuts,
            "energy_gap": float(np.abs(held - held[0]).max() / abs(e["external_work"][-1])),
            "removed_energy": float(e["removed_energy"][-1]), "steps": r.summary["steps"],
            "particles": r.summary["particles"]}


#: the floor load of the case (N over the beam's clear length) and that length (m)
FLOOR_FORCE, CLEAR_SPAN = 355762.5, 11.85875
BEAM_WEIGHT = 0.0068387 * 7850.0 * 9.81     # N/m, the W16x36's self-weight
BEAM_CUTS = ("beam_left_end", "beam_mid_left", "beam_mid_right", "beam_right_end")


def catenary_overrides(factor):
    """The heavy-floor variant: the floor load times ``factor``, nothing else changed."""
    return {"loads.forces.0.force": [0.0, -FLOOR_FORCE * factor]}


def catenary_summary(r, factor, removal_time=0.08):
    """Axial force and moment at the beam's cuts against the cable estimate T = w L^2 / (8 delta)
    of the double span (w the floor load and the beam's weight, L the clear span, delta the drop
    of the point above the removed column): at the peak and at the end, and the time the mid cut's
    N turns from compression to tension (bending giving way to catenary action)."""
    h = r.histories[TRACK]
    t, uy = np.asarray(h["time"]), np.asarray(h["uy"])
    k = int(np.argmin(uy))
    w = FLOOR_FORCE * factor / CLEAR_SPAN + BEAM_WEIGHT
    out = {"factor": factor, "w": w, "peak_uy": float(uy[k]), "t_peak": float(t[k]), "end_uy": float(uy[-1]),
           "arrested": summarise(r, removal_time)["arrested"], "cuts": {}}
    for name in BEAM_CUTS:
        N, M = np.asarray(r.sections[name]["N"]), np.asarray(r.sections[name]["M"])
        post = np.nonzero(t > removal_time)[0]
        tens = post[N[post] > 0]
        out["cuts"][name] = {"N_peak": float(N[k]), "M_peak": float(M[k]), "N_end": float(N[-1]),
                             "M_end": float(M[-1]), "N_max": float(N[post].max()),
                             "t_tension": float(t[tens[0]]) if len(tens) else math.nan}
    for key, j in (("T_cable_peak", k), ("T_cable_end", len(t) - 1)):
        out[key] = float(w * CLEAR_SPAN ** 2 / (8 * max(abs(uy[j]), 1e-9)))
    return out


def plot(histories, path):
    """uy above the removed column and N, M at the mid cut against time, per cell size."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8, 8), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    for h, d in sorted(histories.items(), reverse=True):
        ax[0].plot(d["t"], d["uy"] * 1e3, lw=1, label=f"{h:g} m cells")
        ax[1].plot(d["t"], d["N_" + CUTS[0]] / 1e3, lw=1, label=f"{h:g} m cells")
        ax[2].plot(d["t"], d["M_" + CUTS[0]] / 1e3, lw=1, label=f"{h:g} m cells")
    for a in ax:
        a.axvspan(0.08, 0.085, color="0.85", label="column removed")
        a.grid(True, alpha=0.3)
    ax[0].set_ylabel("uy above the column (mm)")
    ax[1].set_ylabel(f"N at {CUTS[0]} (kN)\n(tension +)")
    ax[2].set_ylabel(f"M at {CUTS[0]} (kN m)")
    ax[2].set_xlabel("time (s)")
    ax[0].legend(loc="lower left", fontsize=8)
    ax[0].set_title("sudden loss of the middle column: two-bay portal, 30 kN/m floor load")
    fig.savefig(path, dpi=110)
    return path


def plot_catenary(d, factor, h, path):
    """uy above the removed column and N, M at the beam's cuts for the heavy-floor variant."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8, 8), layout="constrained")
    ax = fig.subplots(3, 1, sharex=True)
    ax[0].plot(d["t"], d["uy"] * 1e3, lw=1)
    for name in BEAM_CUTS:
        ax[1].plot(d["t"], d["N_" + name] / 1e3, lw=1, label=name)
        ax[2].plot(d["t"], d["M_" + name] / 1e3, lw=1, label=name)
    for a in ax:
        a.axvspan(0.08, 0.085, color="0.85")
        a.grid(True, alpha=0.3)
    ax[0].set_ylabel("uy above the column (mm)")
    ax[1].set_ylabel("N (kN, tension +)")
    ax[2].set_ylabel("M (kN m)")
    ax[2].set_xlabel("time (s)")
    ax[1].legend(fontsize=8)
    ax[0].set_title(f"column loss, floor load x{factor:g} ({30 * factor:g} kN/m), {h:g} m cells")
    fig.savefig(path, dpi=110)
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", type=float, nargs="*", default=[0.1, 0.05],
                    help="cell sizes run (m); none with --cells alone (e.g. for --catenary only)")
    ap.add_argument("--out")
    ap.add_argument("--histories")
    ap.add_argument("--plot")
    ap.add_argument("--results", action="append", default=[], metavar="H=FILE.h5",
                    help="summarise a results file of cell size H instead of running it")
    ap.add_argument("--catenary", type=float, nargs=2, metavar=("FACTOR", "H"),
                    help="also run the heavy-floor variant: the floor load times FACTOR, at cell size H")
    ap.add_argument("--catenary-plot", metavar="PNG")
    args = ap.parse_args(argv)
    results, histories = {}, {}
    import pmpm
    given = {float(a.split("=", 1)[0]): a.split("=", 1)[1] for a in args.results}
    for h in list(args.cells) + sorted(given):
        if h in given:
            r, wall = pmpm.load_results(given[h], dataframes=False), math.nan
            r.summary = {"steps": math.nan, "particles": len(r.frames["id"][0])}
        else:
            r, wall = run_cell(h)
        s = summarise(r)
        s["wall"] = wall
        results[h] = s
        d = {"t": np.asarray(r.histories[TRACK]["time"]), "uy": np.asarray(r.histories[TRACK]["uy"])}
        for name in CUTS:
            d["N_" + name] = np.asarray(r.sections[name]["N"])
            d["M_" + name] = np.asarray(r.sections[name]["M"])
        histories[h] = d
        print(f"h = {h:g} m: peak uy {s['peak_uy'] * 1e3:.2f} mm at {s['t_peak']:.4f} s, permanent "
              f"{s['permanent_uy'] * 1e3:.2f} mm, before removal {s['uy_before'] * 1e3:.3f} mm, "
              f"{'arrested' if s['arrested'] else 'NOT arrested'}; energy gap {s['energy_gap']:.2e} of the "
              f"external work; {s['particles']} particles, {s['steps']} steps, {wall:.0f} s", flush=True)
        for name, c in s["cuts"].items():
            print(f"   {name}: before N {c['N_before'] / 1e3:.1f} kN M {c['M_before'] / 1e3:.1f} kN m; at the peak "
                  f"N {c['N_peak'] / 1e3:.1f} kN M {c['M_peak'] / 1e3:.1f} kN m; after removal N from "
                  f"{c['N_max_compression'] / 1e3:.1f} to {c['N_max_tension'] / 1e3:.1f} kN", flush=True)
    out = {"cells": {str(h): s for h, s in results.items()}}
    if len(results) >= 2:
        a, b = sorted(results)[:2]
        out["peak_difference"] = abs(results[a]["peak_uy"] / results[b]["peak_uy"] - 1)
        out["permanent_difference"] = abs(results[a]["permanent_uy"] / results[b]["permanent_uy"] - 1)
        print(f"finest two ({a:g}, {b:g} m): peak differs by {100 * out['peak_difference']:.2f}%, permanent by "
              f"{100 * out['permanent_difference']:.2f}%")
    print("| cells (m) | peak uy (mm) | at (s) | permanent uy (mm) | arrested | energy gap |")
    print("|---|---|---|---|---|---|")
    for h, s in sorted(results.items(), reverse=True):
        print(f"| {h:g} | {s['peak_uy'] * 1e3:.2f} | {s['t_peak']:.4f} | {s['permanent_uy'] * 1e3:.2f} | "
              f"{'yes' if s['arrested'] else 'no'} | {s['energy_gap']:.1e} |")
    if args.catenary:
        factor, hc = args.catenary
        r, wall = run_cell(hc, catenary_overrides(factor))
        c = catenary_summary(r, factor)
        out["catenary"] = c
        print(f"catenary variant: floor load x{factor:g} (w = {c['w'] / 1e3:.1f} kN/m), {hc:g} m cells: peak uy "
              f"{c['peak_uy'] * 1e3:.1f} mm at {c['t_peak']:.4f} s, at the end {c['end_uy'] * 1e3:.1f} mm, "
              f"{'arrested' if c['arrested'] else 'NOT arrested'}; cable estimate w L^2/(8 delta) "
              f"{c['T_cable_peak'] / 1e3:.0f} kN at the peak, {c['T_cable_end'] / 1e3:.0f} kN at the end; {wall:.0f} s")
        for name, q in c["cuts"].items():
            print(f"   {name}: at the peak N {q['N_peak'] / 1e3:.0f} kN M {q['M_peak'] / 1e3:.0f} kN m; at the end "
                  f"N {q['N_end'] / 1e3:.0f} kN M {q['M_end'] / 1e3:.0f} kN m; largest N {q['N_max'] / 1e3:.0f} kN; "
                  f"tension from {q['t_tension']:.4f} s", flush=True)
        d = {"t": np.asarray(r.histories[TRACK]["time"]), "uy": np.asarray(r.histories[TRACK]["uy"])}
        for name in BEAM_CUTS:
            d["N_" + name] = np.asarray(r.sections[name]["N"])
            d["M_" + name] = np.asarray(r.sections[name]["M"])
        if args.catenary_plot:
            plot_catenary(d, factor, hc, args.catenary_plot)
    if args.histories:
        np.savez(args.histories, **{f"{h:g}/{k}": v for h, d in histories.items() for k, v in d.items()})
    if args.plot:
        plot(histories, args.plot)
    line = json.dumps(out)
    print(line)
    if args.out:
        with open(args.out, "w") as f:
            f.write(line + "\n")


if __name__ == "__main__":
    main()
