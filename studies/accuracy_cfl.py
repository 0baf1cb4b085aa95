"""The time step in the accuracy study: the CFL number varied (``pmpm bench accuracy``).

For the bar and the frame and every B-spline basis, at one cell size each (MUSL, 2 x 2
particles per cell), the run is repeated at CFL 0.3, 0.5, 0.7 and 0.9 and at the largest stable
CFL number, found by bisection:

* a run is **stable** when it reaches its end time without the solver's divergence checks
  stopping it and its energy balance (total energy against initial energy plus external work,
  relative to the energies in play) drifts by at most STABLE_DRIFT at the end: healthy runs of
  the solver stay within a few percent (pmpm/core/solver.py), an unstable mode grows
  exponentially and passes any such bound within a few hundred steps once it is excited;
* the bracket starts from the sweep's values (the largest stable one, the smallest unstable
  one above it; with all four stable it is widened by CFL_GROWTH until a run fails, up to
  CFL_CEILING) and is halved until it is narrower than the tolerance. The value reported is the
  bracket's lower (stable) end. A mode growing too slowly to show within the run's duration is
  not seen: the value is "stable for this run", not a proven bound.

Each row carries its error against the problem's reference (the bar's exact solution; the
frame's finest run of the main sweep) and ``dt_effect``: the relative change of its error
measure against the same setting at the smallest CFL number of the sweep (the bar: of its error;
the frame: of its first peak), which isolates what the time step changes from the spatial error.

The recommendation: for each error target, the cheapest setting of the main sweep (CFL 0.5),
then, when that setting's shape and cell size were swept here, the largest CFL number of the
sweep (at most SAFETY times the largest stable one) whose run still meets the target; its cost
scales with the number of steps, 1 / CFL.
"""
import math

__all__ = ["CFL_VALUES", "cfl_plan", "run_cfl_sweep", "attach_cfl_errors", "cfl_recommendation",
           "cfl_markdown"]

CFL_VALUES = (0.3, 0.5, 0.7, 0.9)
#: energy drift at the end of a run above which it counts as unstable (see the module docstring)
STABLE_DRIFT = 0.05
#: widening factor of the bracket when every swept value is stable, and where the search stops
CFL_GROWTH = 1.3
CFL_CEILING = 4.0
#: a recommended CFL number stays at or below this fraction of the largest stable one
SAFETY = 0.9
#: (problem, cell size, shapes, bisection tolerance) of the full and the quick sweep; the frame
#: at the main job's cell size (cases/portal_frame.toml), 0.1 m in the quick sweep
CFL_SETTINGS = {
    False: {"bar": (40, ("linear", "quadratic", "cubic")), "frame": (0.05, ("linear", "quadratic", "cubic")),
            "tol": 0.02},
    True: {"bar": (40, ("linear", "quadratic", "cubic")), "frame": (0.1, ("cubic",)), "tol": 0.05},
}


def cfl_plan(quick):
    """(problem, shape, cell) of every CFL series: cell is the bar's cell count or the frame's size."""
    st = CFL_SETTINGS[bool(quick)]
    out = []
    for problem in ("bar", "frame"):
        cell, shapes = st[problem]
        out += [(problem, shape, cell) for shape in shapes]
    return out


def _run(problem, shape, cell, cfl):
    from studies import accuracy as A
    from pmpm.errors import ParticleExitError, UnstableRunError
    try:
        if problem == "bar":
            row = A.run_bar(cell, shape, "musl", 2, cfl=cfl)
        else:
            row = A.run_frame(cell, shape, "musl", 2, cfl=cfl)
    except (UnstableRunError, ParticleExitError) as exc:
        row = {"problem": problem, "shape": shape, "ppc": 2, "scheme": "musl",
               "cell_size": A.BAR_L / cell if problem == "bar" else cell, "status": f"failed: {exc}"}
    row["cfl"] = cfl
    row["stable"] = not row["status"].startswith("failed") and row.get("energy_drift", math.inf) <= STABLE_DRIFT
    return row


def largest_stable(run, known, tol):
    """Bisection for the largest stable CFL number. ``run(cfl)`` returns a row with ``stable``;
    ``known`` are rows already run. Returns (value, the rows run here)."""
    rows = []
    stable = sorted(r["cfl"] for r in known if r["stable"])
    if not stable:
        lo = 0.0
    else:
        lo = stable[-1]
    above = sorted(r["cfl"] for r in known if not r["stable"] and r["cfl"] > lo)
    hi = above[0] if above else None
    while hi is None:
        c = round(max(lo, 0.1) * CFL_GROWTH, 4)
        if c > CFL_CEILING:
            return lo, rows
        r = run(c)
        rows.append(r)
        if r["stable"]:
            lo = c
        else:
            hi = c
    while hi - lo > tol:
        c = round(0.5 * (lo + hi), 4)
        r = run(c)
        rows.append(r)
        if r["stable"]:
            lo = c
        else:
            hi = c
    return lo, rows


def run_cfl_sweep(quick, log, progress=None):
    """Every CFL series of ``cfl_plan(quick)``; returns (rows, {problem: {shape: largest stable}})."""
    tol = CFL_SETTINGS[bool(quick)]["tol"]
    rows, best = [], {}
    for problem, shape, cell in cfl_plan(quick):
        series = []
        for c in CFL_VALUES:
            r = _run(problem, shape, cell, c)
            series.append(r)
            _log(log, r)
        value, extra = largest_stable(lambda c: _log(log, _run(problem, shape, cell, c)), series, tol)
        for r in extra:
            r["bisection"] = True
        best.setdefault(problem, {})[shape] = value
        print(f"[accuracy] CFL {problem} {shape}: largest stable {value:g} (tolerance {tol:g})", file=log, flush=True)
        rows += series + extra
    return rows, best


def _log(log, r):
    what = (f"error {r['error']:.3g}" if r.get("error") is not None else
            f"peak {r['peak_mm']:.3f} mm" if r.get("peak_mm") is not None else r["status"][:70])
    drift = f", energy drift {r['energy_drift']:.2g}" if r.get("energy_drift") is not None else ""
    print(f"[accuracy] CFL {r['cfl']:g} {r['problem']} {r['shape']} h {r['cell_size']:.4g}: {what}{drift}, "
          f"{'stable' if r['stable'] else 'UNSTABLE'}", file=log, flush=True)
    return r


def attach_cfl_errors(rows, ref_peak_mm):
    """Frame errors against the reference peak; ``dt_effect`` of every stable row against its
    series' smallest CFL number."""
    for r in rows:
        if r["problem"] == "frame" and r.get("peak_mm") is not None and ref_peak_mm:
            r["error"] = abs(r["peak_mm"] - ref_peak_mm) / ref_peak_mm
    for r in rows:
        base = [q for q in rows if (q["problem"], q["shape"], q["cell_size"]) ==
                (r["problem"], r["shape"], r["cell_size"]) and q["stable"]]
        if not r["stable"] or not base:
            continue
        b = min(base, key=lambda q: q["cfl"])
        key = "error" if r["problem"] == "bar" else "peak_mm"
        if b.get(key) is not None and r.get(key) is not None and b[key]:
            r["dt_effect"] = abs(r[key] - b[key]) / abs(b[key])
    return rows


def cfl_recommendation(rec, rows, best, target):
    """The CFL number for the recommended setting ``rec`` (a dict of the main sweep, CFL 0.5)
    at ``target``: the largest swept CFL meeting it (see the module docstring), with the steps and
    cost scaled; ``swept`` False (CFL 0.5 kept) when its shape and cell size were not swept."""
    out = dict(rec, cfl=0.5, swept=False)
    if rec["ppc"] != 2 or rec["scheme"] != "musl":
        return out
    series = [r for r in rows if r["problem"] == "frame" and r["shape"] == rec["shape"]
              and math.isclose(r["cell_size"], rec["cell_size"]) and r["stable"] and r.get("error") is not None]
    limit = SAFETY * best.get("frame", {}).get(rec["shape"], 0.0)
    ok = [r for r in series if r["error"] <= target and r["cfl"] <= limit and not r.get("bisection")]
    if not ok:
        return out
    r = max(ok, key=lambda r: r["cfl"])
    scale = 0.5 / r["cfl"]
    out.update(cfl=r["cfl"], swept=True, error=r["error"], steps=r.get("steps"),
               wall_s=rec["wall_s"] * scale, cpu_s=rec["cpu_s"] * scale)
    return out


def cfl_markdown(rows, best):
    """The CFL table and the largest stable values, as markdown lines."""
    lines = ["## The time step: CFL number (MUSL, 2 x 2 particles per cell)", "",
             "Largest stable CFL number (bisection; stable: the run ends and its energy balance drifts "
             f"at most {STABLE_DRIFT:.0%}):", ""]
    for problem, shapes in best.items():
        lines.append(f"- {problem}: " + ", ".join(f"{s} {v:g}" for s, v in shapes.items()))
    lines += ["", "| problem | shape | cell | CFL | steps | wall (s) | CPU (s) | error | change from the smallest CFL "
              "| energy drift | stable |", "|" + "|".join(["---"] * 11) + "|"]
    for r in sorted(rows, key=lambda r: (r["problem"], r["shape"], r["cfl"])):
        cell = f"{r['cell_size']:.4g}"
        err = "" if r.get("error") is None else f"{r['error']:.3g}"
        eff = "" if r.get("dt_effect") is None else f"{r['dt_effect']:.2g}"
        dr = "" if r.get("energy_drift") is None else f"{r['energy_drift']:.2g}"
        wall = "" if r.get("wall_s") is None else f"{r['wall_s']:.2f}"
        cpu = "" if r.get("cpu_s") is None else f"{r['cpu_s']:.2f}"
        stable = "yes" if r["stable"] else ("no" if r["status"] == "ok" else "no (" + r["status"][:40] + ")")
        lines.append(f"| {r['problem']} | {r['shape']} | {cell} | {r['cfl']:g}{' (bisection)' if r.get('bisection') else ''} "
                     f"| {r.get('steps', '')} | {wall} | {cpu} | {err} | {eff} | {dr} | {stable} |")
    return lines
