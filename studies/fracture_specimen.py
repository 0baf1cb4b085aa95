"""The round-notched steel plate pulled to ductile fracture initiation: pmpm against an
independent finite-element model of the same specimen, material and locus (issue 39).

The specimen and the FE model are tests/verification/notched_specimen_fe_model.py (NumPy only,
4-node quadrilaterals, its own plane-stress return mapping and damage; nothing from pmpm). The
same specimen is built here as a pmpm scene (:func:`scene`: the plate as a polygon whose arcs
have 64 chords, the supports on the body's faces, the held face's reaction recorded). For each
size h (mm; the MPM cell and the FE element edge) the study prints

* the displacement of the pulled face at fracture initiation (the first point that fails: with
  the specimen's characteristic length, where the void growth index averaged over l* reaches 1,
  docs/fracture.md) from both models and their difference;
* pmpm's refinement (second table): the displacement at initiation and its change between
  sizes, and the fracture energy dissipated by ``--end-time`` (the crack has then run through
  the ligament: the force left is printed) over G_f times the ligament's area, which the
  Hillerborg regularisation (l_c = max(band_cells x h, band_lstar x l*): :data:`BAND_CELLS`,
  :data:`BAND_LSTAR`) should keep independent of h, and the crack band's width in cells;
* the force-displacement curves to initiation: the held face's reaction averaged over windows
  of ``--window`` seconds (the elastic waves of the sudden pull ring with a period of 2 L / c,
  about 40 us: the window averages them out the same way in both), its largest difference
  over the windows up to the earlier initiation, relative to the FE model's largest force;

then one JSON line. Run::

    python -m studies.fracture_specimen --sizes 3.3333333333 3 2 1

``--local`` runs the specimen as before the nonlocal criterion (local, l_c = h); ``--profile
T1 T2 ..`` prints instead the diagnosis of the local initiation's refinement (the largest
eps_p_eq by depth below the notch root, both models, at those times in ms).

(the 1 mm MPM run takes 5 to 15 minutes on this machine; run it under ``nice -n 10``). Nothing
is written. tests/verification/test_fracture_specimen.py runs the two coarsest sizes in CI.
"""
import argparse
import json
import math
import time

import numpy as np

from pmpm.api import run as pmpm_run
from pmpm.physics.materials import fracture as fracture_option
from studies import verification_models

__all__ = ["fe_module", "scene", "mpm", "fe", "compare", "window_means", "main"]



def fe_module():
    """tests/verification/notched_specimen_fe_model.py."""
    return verification_models.load("notched_specimen_fe_model")


#: the crack band's width in cells that the specimen's release length takes (``band_cells``):
#: the width the crack runs with in this specimen with cubic B-splines and the nonlocal
#: criterion, measured by this study (the table's "band width" column; docs/fracture.md)
BAND_CELLS = 1.3

#: the crack band's least width in units of l* (``band_lstar``): once the grids resolve l* the
#: band's width follows l*, not the cell. Measured at 2, 1.5 and 1 mm with l* = 6 mm (docs/fracture.md,
#: "The release length once l* is resolved"): the failed band 2.92, 2.77, 2.52 mm (mean 0.46 l*),
#: the fully released band within it 2.08, 2.39, 1.96 mm (mean 0.36 l*); the band that dissipates
#: lies between the two (a failed point on the flank stops releasing when the crack opens beside
#: it), so l_c = max(BAND_CELLS h, BAND_LSTAR l*) with the midpoint, 0.40 l* (+- 0.05 l*, 0.3 mm)
BAND_LSTAR = 0.40

#: pmpm's end time (s): with the specimen's l* = 6 mm initiation is near 2.0 ms and the crack has
#: crossed the ligament by 2.7 ms (the table's force at the end, a few % of the peak)
END_TIME = 2.7e-3


def fracture_table(sp):
    """The scene's ``[materials.steel.fracture]`` of the specimen ``sp``: the nonlocal criterion
    when ``sp`` has a characteristic length (None: the local one), the crack band length when it
    has a ``band_cells`` (the release length in cells; absent: :data:`BAND_CELLS`; None: the
    default of pmpm, one cell)."""
    table = {"model": "void_growth", "eta": sp["eta"], "fracture_energy": sp["fracture_energy"]}
    if sp.get("characteristic_length"):
        table["characteristic_length"] = sp["characteristic_length"]
    band = sp.get("band_cells", BAND_CELLS)
    if band:
        table["band_cells"] = band
    lstar_band = sp.get("band_lstar", BAND_LSTAR)
    if lstar_band and band and sp.get("characteristic_length"):
        table["band_lstar"] = lstar_band
    return table


def scene(h, end_time=2.0e-3, sp=None, history_interval=1.0e-5):
    """The specimen as a pmpm scene (a TOML dict) at cell size ``h`` (m)."""
    sp = sp or fe_module().SPECIMEN
    margin = 2
    return {
        "title": f"round-notched plate to fracture initiation, h = {h * 1e3:.3g} mm",
        "formulation": "plane_stress",
        "particles_per_cell": 2,
        "grid": {"origin": [-margin * h, -margin * h], "cell_size": h,
                 # the pulled face moves by pull x end_time: room for it beyond the margin
                 "cells": [int(math.ceil((sp["length"] + sp["pull"] * end_time) / h - 1e-9)) + 2 * margin,
                           int(math.ceil(sp["width"] / h - 1e-9)) + 2 * margin]},
        "materials": {"steel": {
            "type": "bilinear_vonmises", "E": sp["E"], "nu": sp["nu"], "density": sp["density"],
            "yield_stress": sp["yield_stress"], "hardening": sp["hardening"],
            "fracture": fracture_table(sp)}},
        "bodies": [{"name": "plate", "shape": "polygon", "material": "steel", "thickness": sp["thickness"],
                    "vertices": fe_module().polygon(sp)}],
        "boundary": [
            {"name": "held", "type": "fixed", "body": "plate", "face": "left", "reaction": True},
            {"name": "pulled", "type": "velocity", "velocity": [sp["pull"], 0.0], "body": "plate", "face": "right"}],
        "solver": {"end_time": end_time, "cfl": 0.5},
        "output": {"interval": end_time, "history_interval": history_interval, "fields": ["x", "damage", "crack_strain"]},
    }


def mpm(h, end_time=2.0e-3, sp=None, overrides=None):
    """pmpm's run: {time, force (mean Rx of the held face per sample), initiation, wall}."""
    t0 = time.perf_counter()
    r = pmpm_run(scene(h, end_time, sp), overrides=overrides, dataframes=False)
    wall = time.perf_counter() - t0
    reaction = r.reactions["held"]
    first = r.summary.get("first_fracture", {}).get("plate")
    return {"time": np.asarray(reaction["time"]), "force": np.asarray(reaction["Rx"]),
            "initiation": None if first is None else float(first), "wall": wall, "result": r}


def fe(h, end_time=2.0e-3, sp=None):
    """The FE model's run (same keys as :func:`mpm`)."""
    model = fe_module()
    t0 = time.perf_counter()
    r = model.run(h, sp or model.SPECIMEN, end_time=end_time)
    r["wall"] = time.perf_counter() - t0
    return r


def window_means(time_, force, window, until):
    """Mean force over consecutive windows of ``window`` s up to ``until`` (the samples are
    means over equal sampling intervals ending at ``time_``): (window ends, means)."""
    edges = np.arange(window, until + 1e-12, window)
    means = []
    for hi in edges:
        sel = (time_ > hi - window + 1e-12) & (time_ <= hi + 1e-12)
        means.append(force[sel].mean() if sel.any() else np.nan)
    return edges, np.array(means)


def _mpm_figures(a, h, sp):
    """pmpm's own figures of a run ``a`` of :func:`mpm` (those of its refinement table)."""
    r = a["result"]
    ligament = sp["width"] - 2 * sp["radius"]
    failed = r.frames["damage"][-1] >= 1.0
    crack = np.asarray(r.frames["crack_strain"][-1])
    released = failed & (crack[:, 0] >= crack[:, 1])
    work = float(r.energies["fracture_work"][-1])
    lc = fracture_option.band_length(fracture_option.read_fracture(fracture_table(sp), "fracture"), h)
    return {"h_mm": h * 1e3, "u_init_mpm_mm": sp["pull"] * a["initiation"] * 1e3 if a["initiation"] else math.nan,
            "fracture_work_J": work,
            "fracture_work_over_GfA": work / (sp["fracture_energy"] * ligament * sp["thickness"]),
            "failed_points": int(failed.sum()),
            # the crack band's mean width in cells: the failed particles' area (h^2 / 4 each at
            # 2 particles per cell) over the ligament's length
            "band_cells": float(failed.sum()) * (h * h / 4) / (ligament * h),
            # the same of the fully released particles (w = 1), and the run's release length
            "released_band_cells": float(released.sum()) * (h * h / 4) / (ligament * h),
            "band_mm": float(failed.sum()) * (h * h / 4) / ligament * 1e3, "l_c_mm": lc * 1e3,
            "wall_mpm_s": a["wall"]}


def compare(h, window=1.0e-4, end_time=END_TIME, sp=None, progress=None):
    """Both models at size ``h``: a dict of the figures the table prints. ``progress``, if
    given, is called with pmpm's own figures before the FE model runs."""
    sp = sp or fe_module().SPECIMEN
    a = mpm(h, end_time, sp)
    own = _mpm_figures(a, h, sp)
    if progress:
        progress(own)
    b = fe(h, end_time, sp)
    ua = sp["pull"] * a["initiation"] if a["initiation"] else math.nan
    ub = sp["pull"] * b["initiation"] if b["initiation"] else math.nan
    until = min(x for x in (a["initiation"], b["initiation"], end_time) if x)
    until = window * math.floor(until / window)
    ta, fa = window_means(a["time"], a["force"], window, until)
    _, fb = window_means(b["time"], b["force"], window, until)
    peak = np.nanmax(np.abs(fb))
    r = a["result"]
    failed = r.frames["damage"][-1] >= 1.0
    lstar = sp.get("characteristic_length") or 0.0
    return {**own, "lstar_over_h": lstar / h,
            "end_force_over_peak": float(abs(a["force"][-10:].mean())) / peak, "u_init_fe_mm": ub * 1e3,
            "u_init_diff": (ua - ub) / ub, "force_max_diff": float(np.nanmax(np.abs(fa - fb)) / peak),
            "force_peak_fe_kN": peak / 1e3, "force_peak_mpm_kN": float(np.nanmax(np.abs(fa))) / 1e3,
            "windows": len(ta), "wall_fe_s": b["wall"],
            "fe_where": b["where"], "failed_x0": r.frames["x"][0][failed].tolist(),
            "curve": {"u_mm": (sp["pull"] * ta * 1e3).tolist(), "mpm_kN": (fa / 1e3).tolist(),
                      "fe_kN": (fb / 1e3).tolist()}}


def _depth_bins(x, eq, sp, bins):
    """The largest eps_p_eq in each depth bin below the lower notch's arc, within 20 degrees
    of its root (x: current positions)."""
    xc = 0.5 * sp["length"]
    depth = np.hypot(x[:, 0] - xc, x[:, 1]) - sp["radius"]
    near_root = (np.abs(np.degrees(np.arctan2(x[:, 0] - xc, x[:, 1]))) < 20.0) & (x[:, 1] < 0.5 * sp["width"])
    out = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        sel = near_root & (depth >= lo) & (depth < hi)
        out.append(float(eq[sel].max()) if sel.any() else math.nan)
    return out


def surface_profile(h, times, sp=None, bins=(0.0, 0.5e-3, 1.0e-3, 2.0e-3, 4.0e-3, 8.0e-3)):
    """The diagnosis of the initiation's refinement: the largest equivalent plastic strain by
    depth below the notch arc near its root, pmpm's particles and the FE model's Gauss points,
    at the given ``times`` (s), both with the local criterion's fields (no point has failed
    before its first initiation). Returns rows (t, model, [max eps_p_eq per bin])."""
    sp = dict(sp or fe_module().SPECIMEN)
    end = max(times) + 1e-9
    sc = scene(h, end, sp)
    sc["output"]["fields"] = ["x", "eps_p_eq"]
    sc["output"]["interval"] = min(times)
    r = pmpm_run(sc, dataframes=False)
    rows = []
    ft = np.asarray(r.frame_times)
    model = fe_module()
    snaps = model.run(h, sp, end_time=end, stop_at_initiation=False, snapshots=times)["snapshots"]
    for k, t in enumerate(times):
        i = int(np.argmin(np.abs(ft - t)))
        rows.append((float(ft[i]), "pmpm", _depth_bins(np.asarray(r.frames["x"][i]),
                                                       np.asarray(r.frames["eps_p_eq"][i]), sp, bins)))
        rows.append((float(snaps["time"][k]), "FE", _depth_bins(snaps["x"][k].reshape(-1, 2),
                                                                 snaps["eps_p_eq"][k].ravel(), sp, bins)))
    return rows


def refinement_table(rows):
    """pmpm's own refinement: initiation, its change from the previous size, the fracture
    energy dissipated by the end (over G_f times the ligament's area) and the force left."""
    lines = ["| h (mm) | l* / h | u at initiation (mm) | change from previous | fracture work (J) | "
             "/ (G_f A_ligament) | band width (cells) | force at the end / FE peak | wall pmpm (s) |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    prev = None
    for r in rows:
        change = "" if prev is None else f"{100 * (r['u_init_mpm_mm'] - prev) / prev:+.1f}%"
        lines.append(f"| {r['h_mm']:.3g} | {r['lstar_over_h']:.2f} | {r['u_init_mpm_mm']:.4f} | {change} | "
                     f"{r['fracture_work_J']:.3f} | {r['fracture_work_over_GfA']:.3f} | {r['band_cells']:.2f} | "
                     f"{r['end_force_over_peak']:.3f} | {r['wall_mpm_s']:.0f} |")
        prev = r["u_init_mpm_mm"]
    if len(rows) >= 2:
        a, b = rows[-2], rows[-1]
        lines.append("")
        lines.append(f"between the two finest grids ({a['h_mm']:.3g} and {b['h_mm']:.3g} mm): "
                     f"pmpm {100 * finest_step(rows, 'u_init_mpm_mm'):+.1f}%, "
                     f"FE {100 * finest_step(rows, 'u_init_fe_mm'):+.1f}% (the issue's target: within 5%)")
    return "\n".join(lines)


def finest_step(rows, key):
    """The change of ``key`` from the second finest size to the finest, over the second finest's
    value (as the table's "change from previous")."""
    a, b = sorted(rows, key=lambda r: -r["h_mm"])[-2:]
    return (b[key] - a[key]) / a[key]


def markdown_table(rows):
    lines = ["| h (mm) | u at initiation, pmpm (mm) | FE (mm) | difference | force, largest difference / FE peak | FE peak (kN) | wall pmpm / FE (s) |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['h_mm']:.3g} | {r['u_init_mpm_mm']:.4f} | {r['u_init_fe_mm']:.4f} | "
                     f"{100 * r['u_init_diff']:+.1f}% | {100 * r['force_max_diff']:.1f}% | "
                     f"{r['force_peak_fe_kN']:.1f} | {r['wall_mpm_s']:.0f} / {r['wall_fe_s']:.0f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[10 / 3, 2.0, 1.0], help="cell / element sizes (mm)")
    ap.add_argument("--window", type=float, default=1.0e-4, help="force averaging window (s)")
    ap.add_argument("--end-time", type=float, default=END_TIME, help="pmpm's end time (s): past the separation")
    ap.add_argument("--curves", action="store_true", help="print the windowed force-displacement curves")
    ap.add_argument("--profile", type=float, nargs="+", metavar="T_MS",
                    help="instead: the largest eps_p_eq by depth below the notch root at these times (ms), "
                         "pmpm and FE, local criterion, at each of --sizes")
    ap.add_argument("--local", action="store_true",
                    help="the local criterion (no characteristic length) and l_c = h: the specimen before "
                         "the nonlocal criterion")
    ap.add_argument("--characteristic-length", type=float, metavar="MM",
                    help="the nonlocal criterion's l* (mm) instead of the specimen's (6 mm)")
    ap.add_argument("--band-lstar", type=float, metavar="C",
                    help="the release length's least width in l* (default %g; 0: l_c = band_cells x h alone, "
                         "as before)" % BAND_LSTAR)
    ap.add_argument("--pmpm-only", action="store_true",
                    help="only pmpm's figures at each size (initiation, fracture work, band): no FE model, no tables")
    args = ap.parse_args(argv)
    sp = dict(fe_module().SPECIMEN)
    if args.characteristic_length:
        sp["characteristic_length"] = args.characteristic_length * 1e-3
    if args.band_lstar is not None:
        sp["band_lstar"] = args.band_lstar
    if args.local:
        sp["characteristic_length"] = None
        sp["band_cells"] = None
    if args.profile:
        print("| h (mm) | t (ms) | model | depth 0-0.5 mm | 0.5-1 | 1-2 | 2-4 | 4-8 |")
        print("| ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |")
        for size in args.sizes:
            local = dict(sp, characteristic_length=None)
            for t, name, vals in surface_profile(size * 1e-3, [v * 1e-3 for v in args.profile], local):
                print(f"| {size:g} | {t * 1e3:.2f} | {name} | " + " | ".join(f"{v:.4f}" for v in vals) + " |")
        return
    if args.pmpm_only:
        for size in args.sizes:
            a = mpm(size * 1e-3, args.end_time, sp)
            print(json.dumps({"pmpm": _mpm_figures(a, size * 1e-3, sp)}), flush=True)
        return
    rows = []
    for size in args.sizes:
        row = compare(size * 1e-3, args.window, args.end_time, sp,
                      progress=lambda f: print(json.dumps({"pmpm": f}), flush=True))
        rows.append(row)
        # each size's figures as soon as they exist (the finest runs take long)
        print(json.dumps({"size": {k: v for k, v in row.items() if k not in ("curve", "failed_x0")}}), flush=True)
        if args.curves:
            c = row["curve"]
            print(f"h = {size:g} mm: u (mm), pmpm, FE (kN)")
            for u, x, y in zip(c["u_mm"], c["mpm_kN"], c["fe_kN"]):
                print(f"  {u:.3f}  {x:9.2f}  {y:9.2f}")
    print(markdown_table(rows))
    print()
    print(refinement_table(rows))
    print(json.dumps({"fracture_specimen": [{k: v for k, v in r.items() if k not in ("curve", "failed_x0")}
                                            for r in rows]}))


if __name__ == "__main__":
    main()
