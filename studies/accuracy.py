"""What accuracy costs in time: ``pmpm bench accuracy``.

Two problems, each run in-process on one rank (``build_solver(scene, MPI.COMM_SELF)``):

* **bar** -- the fixed-free elastic bar of tests/verification/test_bar.py (L = 25, E = 100,
  rho = 1, one cell deep, nu = 0) started with v = v0 sin(beta x), v0 = 1e-3 (small amplitude,
  design.md section 7), run for one period. Error: the largest over the run and over all
  particles of |u - u_exact| / amplitude, u_exact = (v0 / omega) sin(omega t) sin(beta x).
  10, 20, 40, 80 and 160 cells over the length (finer, the error meets the finite-amplitude
  floor of v0 = 1e-3, see BAR_CELLS).
* **frame** -- the elastic variant of cases/portal_frame.toml, regridded over the case's domain
  (x in [-0.5, 6.6], y in [0, 4.2]) and run to FRAME_T_END (past the first peak, at about
  0.02 s). Response: the mass-weighted mean horizontal displacement of the joint panel (the
  particles the lateral load acts on), sampled every FRAME_SAMPLE s; the first peak is the
  largest sample (refined by a parabola through it and its neighbours). A panel mean, not the
  case's single tracked particle, because the particle nearest the joint moves with the cell
  size and the joint's rotation times that offset is of the order of the errors measured here
  (the tracked particle's peak is recorded too, ``peak_track_mm``). Error:
  |peak - peak_ref| / peak_ref against the finest run (cubic, MUSL, 2 x 2 particles per cell,
  the finest cell size of the sweep).

The sweep varies the shape function (linear, quadratic, cubic B-spline), particles per cell per
axis (1, 2, 3), cell size (halvings) and scheme (USF, USL, MUSL, MLS-MPM) at CFL 0.5; then the CFL
number alone (0.3 ... 0.9 and the largest stable, by bisection: studies/accuracy_cfl.py).
The bar is a full factorial (it is cheap). The frame is not (the finest runs take many minutes
each): every shape at every cell size with 2 x 2 particles and MUSL; the full factorial over
particles per cell and scheme at 0.05 m; particles per cell and scheme varied one at a time at
0.1 m and 0.025 m. The I-section strips need enough particle rows across a member's depth, so
1 particle per cell is refused at 0.1 m; runs that diverge (the solver's energy check) are
recorded as such.

Wall time is that of the stepping loop only (time.perf_counter around ``solver.step()``; set-up,
sampling and error evaluation excluded) after a warm-up that compiles every kernel the sweep
uses, so numba's compile time is excluded. CPU time (time.process_time) is recorded beside it:
on a shared machine it is the steadier of the two.

Reported: the table (``accuracy.csv``, ``accuracy.md``), a log-log plot of error against wall
time per problem with the Pareto front (no other run both faster and more accurate) marked
(``accuracy.png``), the observed convergence order of each shape function (least-squares slope
of log error against log cell size over the finest ORDER_POINTS cell sizes of the bar, MUSL,
2 x 2 particles; the frame's orders are printed too, for information), the equal-wall-time
comparison of cubic against linear B-splines (frame and bar), and the cheapest setting for 10%,
1% and 0.1% error on the frame's first peak, overall and per shape function (a setting qualifies
when its run, and every finer run of the same shape, particles per cell and scheme, of which
there must be at least one besides the reference, meet the target: a lucky cancellation at one
cell size does not count). The last line printed is one JSON object.

``--quick`` (a test's budget: one minute on this 2-vCPU machine when idle, two when shared): the
bar with MUSL and 2 x 2 particles at 10 ... 160 cells for the three shapes, and the frame at 0.1
and 0.05 m for the three shapes against a cubic 0.025 m reference. ``--clock cpu`` analyses CPU
instead of wall time; ``--from-csv FILE`` redoes the analysis of an earlier accuracy.csv without
running anything. Results and recommendations: docs/accuracy.md.
"""
import csv
import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

__all__ = ["add_arguments", "accuracy", "study", "bar_scene", "run_bar", "frame_scene", "run_frame",
           "convergence_orders", "pareto_front", "equal_time_comparison", "recommendations"]

SHAPES = ("linear", "quadratic", "cubic")
SCHEMES = ("usf", "usl", "musl", "mls")
PPCS = (1, 2, 3)

# -- the bar (tests/verification/test_bar.py) -------------------------------------------------
BAR_L, BAR_E, BAR_RHO = 25.0, 100.0, 1.0
BAR_BETA = math.pi / (2 * BAR_L)
BAR_OMEGA = BAR_BETA * math.sqrt(BAR_E / BAR_RHO)
BAR_PERIOD = 2 * math.pi / BAR_OMEGA
BAR_V0 = 1e-3
#: four halvings; at 320 cells the error (3e-5 to 8e-5) meets the finite-amplitude floor of
#: v0 = 1e-3 (the solver is updated-Lagrangian, the closed form linear: with v0 = 1e-4 the cubic
#: error keeps its second order down to 320 cells, with 1e-3 it stalls there)
BAR_CELLS = (10, 20, 40, 80, 160)
BAR_CELLS_QUICK = BAR_CELLS

# -- the frame (cases/portal_frame.toml, variant "elastic") -----------------------------------
FRAME_CASE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "cases", "portal_frame.toml")
FRAME_DOMAIN = ((-0.5, 0.0), (6.6, 4.2))
FRAME_T_END = 0.026        # s; the first peak comes at 0.019-0.023 s
FRAME_SAMPLE = 5e-5        # s between samples of the joint displacement
FRAME_CELLS = (0.1, 0.05, 0.025, 0.0125)
FRAME_CELLS_QUICK = (0.1, 0.05, 0.025)
REFERENCE = {"shape": "cubic", "ppc": 2, "scheme": "musl"}   # at the finest cell size
#: the CFL number of the main sweep (the frame's runs set it explicitly: the case's own may differ)
STUDY_CFL = 0.5

#: orders: fit over this many of the finest cell sizes (two halvings)
ORDER_POINTS = 3
#: the two clocks each run records
CLOCKS = {"wall_s": "wall time", "cpu_s": "CPU time"}
#: error targets of the recommendations (frame, first peak)
TARGETS = (0.10, 0.01, 0.001)

CSV_COLUMNS = ("problem", "shape", "ppc", "scheme", "cell_size", "particles", "steps", "wall_s",
               "cpu_s", "error", "peak_mm", "t_peak_s", "peak_track_mm", "pareto", "status")


# -- scenes and runs ---------------------------------------------------------------------------

def bar_scene(cells, shape="cubic", scheme="musl", ppc=2, v0=BAR_V0, cfl=0.5, end=BAR_PERIOD):
    """The bar on ``cells`` cells over its length (the scene of tests/verification/test_bar.py)."""
    from pmpm.scene.config import parse_scene
    h = BAR_L / cells
    return parse_scene({
        "particles_per_cell": ppc,
        "grid": {"cell_size": h, "cells": [cells + 4, 3]},
        "materials": {"bar": {"type": "linear_elastic", "E": BAR_E, "nu": 0.0, "density": BAR_RHO}},
        "bodies": [{"shape": "rectangle", "material": "bar", "lower": [0.0, 0.0], "upper": [BAR_L, h],
                    "velocity": [f"{v0} * sin({BAR_BETA} * x)", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 3 * h]}],
        "solver": {"shape_function": shape, "scheme": scheme, "end_time": end, "cfl": cfl},
    }, "bar.toml")


def _timed_steps(solver, end, sample):
    """Step ``solver`` to ``end``; call ``sample(solver)`` after every step (not timed).
    Returns (wall, cpu) of the steps alone."""
    wall = cpu = 0.0
    clock, pclock = time.perf_counter, time.process_time
    while solver.t < end * (1 - 1e-12):
        w0, c0 = clock(), pclock()
        solver.step()
        wall += clock() - w0
        cpu += pclock() - c0
        sample(solver)
    return wall, cpu


def run_bar(cells, shape, scheme, ppc, v0=BAR_V0, cfl=0.5):
    """One bar run: error (max over the run of |u - u_exact| / amplitude) and its cost."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    scene = bar_scene(cells, shape, scheme, ppc, v0)
    if cfl != 0.5:   # replace(), not the scene parser: the bisection tries CFL numbers above 1
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, cfl=float(cfl)))
    s = build_solver(scene, MPI.COMM_SELF)
    amp = v0 / BAR_OMEGA
    worst = [0.0]

    def sample(s):
        p = s.particles
        u = p["x"][:, 0] - p["x0"][:, 0]
        exact = amp * math.sin(BAR_OMEGA * s.t) * np.sin(BAR_BETA * p["x0"][:, 0])
        worst[0] = max(worst[0], float(np.abs(u - exact).max()) / amp)

    wall, cpu = _timed_steps(s, scene.solver.end_time, sample)
    return {"problem": "bar", "shape": shape, "ppc": ppc, "scheme": scheme, "cell_size": BAR_L / cells,
            "particles": int(s.n_total), "steps": int(s.step_count), "wall_s": wall, "cpu_s": cpu,
            "error": worst[0], "status": "ok", "cfl": cfl, "energy_drift": energy_drift(s)}


def energy_drift(solver):
    """|total energy - (initial energy + external work)| relative to the energies in play (the
    measure of the solver's divergence check, pmpm/core/solver.py check_energy)."""
    e = solver.energies()
    scale = abs(solver.initial_energy) + abs(e["external_work"]) + abs(e["internal_work"])
    return abs(e["total"] - solver.initial_energy - e["external_work"]) / scale if scale > 0 else 0.0


def frame_scene(cell_size, shape="cubic", scheme="musl", ppc=2, t_end=FRAME_T_END, case=FRAME_CASE, cfl=None):
    """The elastic portal frame regridded with ``cell_size`` over the case's domain (``cfl``:
    the CFL number, default the case's)."""
    from pmpm.scene.config import load_scene
    (x0, y0), (x1, y1) = FRAME_DOMAIN
    cells = (int(round((x1 - x0) / cell_size)), int(round((y1 - y0) / cell_size)))
    for lo, hi, n in zip((x0, y0), (x1, y1), cells):
        if not math.isclose(lo + n * cell_size, hi, abs_tol=1e-9):
            raise ValueError(f"cell size {cell_size} does not divide the frame's domain [{lo}, {hi}]")
    # the grid is set before the scene is read: a [frame] case expands its supports, load box
    # and cuts on the grid it runs on (their extents are counted in cells)
    scene = load_scene(case, "elastic", overrides={"grid.origin": [x0, y0], "grid.cell_size": float(cell_size),
                                                   "grid.cells": list(cells)})[0]
    solver = dataclasses.replace(scene.solver, shape_function=shape, scheme=scheme, end_time=float(t_end),
                                 cfl=float(scene.solver.cfl if cfl is None else cfl))
    bodies = tuple(dataclasses.replace(b, particles_per_cell=ppc) for b in scene.bodies)
    output = dataclasses.replace(scene.output, checkpoint_interval=None)
    return dataclasses.replace(scene, solver=solver, bodies=bodies, output=output)


def _first_peak(t, u):
    """Largest sample, refined by the parabola through it and its two neighbours."""
    i = int(np.argmax(u))
    if 0 < i < len(u) - 1:
        a, b, c = u[i - 1], u[i], u[i + 1]
        den = a - 2 * b + c
        if den < 0:
            d = 0.5 * (a - c) / den
            return float(b - 0.25 * (a - c) * d), float(t[i] + d * (t[i + 1] - t[i - 1]) / 2)
    return float(u[i]), float(t[i])


def run_frame(cell_size, shape, scheme, ppc, t_end=FRAME_T_END, cfl=STUDY_CFL):
    """One frame run: the first peak of the joint panel's mean ux and its cost."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    scene = frame_scene(cell_size, shape, scheme, ppc, t_end, cfl=cfl)
    s = build_solver(scene, MPI.COMM_SELF)
    box = scene.loads.forces[0]
    p = s.particles
    x0 = p["x0"]
    inside = np.all((x0 >= np.array(box.lower)) & (x0 <= np.array(box.upper)), axis=1)
    panel = np.zeros(int(p["id"].max()) + 1, dtype=bool)
    panel[p["id"][inside]] = True
    tracker = Tracker([tr for tr in scene.output.track if tr.name == "upper_left_joint"], s)
    t, u, ut = [0.0], [0.0], [0.0]
    nxt = [FRAME_SAMPLE]

    def sample(s):
        if s.t < nxt[0] - 1e-12:
            return
        q = s.particles
        k = panel[q["id"]]
        m = q["m"][k]
        t.append(s.t)
        u.append(float(np.sum(m * (q["x"][k, 0] - q["x0"][k, 0])) / m.sum()))
        ut.append(float(tracker.sample()[0, 0]))
        while nxt[0] <= s.t + 1e-12:
            nxt[0] += FRAME_SAMPLE

    wall, cpu = _timed_steps(s, t_end, sample)
    t, u, ut = np.array(t), np.array(u), np.array(ut)
    peak, t_peak = _first_peak(t, u)
    status = "ok" if t_peak < t_end - 1.5e-3 else "peak at the end of the run"
    return {"problem": "frame", "shape": shape, "ppc": ppc, "scheme": scheme, "cell_size": cell_size,
            "particles": int(s.n_total), "steps": int(s.step_count), "wall_s": wall, "cpu_s": cpu,
            "peak_mm": peak * 1e3, "t_peak_s": t_peak, "peak_track_mm": float(ut.max()) * 1e3,
            "status": status, "cfl": cfl, "energy_drift": energy_drift(s)}


def warm_up(combos, log):
    """Compile every kernel specialisation the sweep uses: a few steps of the coarsest scene of
    each (problem, shape, scheme)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    t0 = time.perf_counter()
    for problem, shape, scheme in sorted(combos):
        if problem == "bar":
            scene = bar_scene(10, shape, scheme, 2)
        else:
            scene = frame_scene(0.1, shape, scheme, 2)
        s = build_solver(scene, MPI.COMM_SELF)
        for _ in range(3):
            s.step()
    print(f"[accuracy] warm-up (kernel compilation) {time.perf_counter() - t0:.1f} s", file=log, flush=True)


# -- the plan --------------------------------------------------------------------------------

def plan(quick):
    """The runs, as (problem, shape, ppc, scheme, cell_size), cheapest first within a problem."""
    runs = []
    if quick:
        for n in BAR_CELLS_QUICK:
            for shape in SHAPES:
                runs.append(("bar", shape, 2, "musl", BAR_L / n))
        for h in FRAME_CELLS_QUICK[:-1]:
            for shape in SHAPES:
                runs.append(("frame", shape, 2, "musl", h))
        runs.append(("frame", REFERENCE["shape"], REFERENCE["ppc"], REFERENCE["scheme"], FRAME_CELLS_QUICK[-1]))
        return runs
    for n in BAR_CELLS:
        for shape in SHAPES:
            for ppc in PPCS:
                for scheme in SCHEMES:
                    runs.append(("bar", shape, ppc, scheme, BAR_L / n))
    frame = []
    for h in FRAME_CELLS:
        for shape in SHAPES:
            frame.append((shape, 2, "musl", h))
    for shape in SHAPES:
        for ppc in PPCS:
            for scheme in SCHEMES:
                frame.append((shape, ppc, scheme, 0.05))
        for h in (0.1, 0.025):
            for ppc in (1, 3):
                frame.append((shape, ppc, "musl", h))
            for scheme in ("usf", "usl"):
                frame.append((shape, 2, scheme, h))
    seen, ordered = set(), []
    for r in sorted(frame, key=lambda r: (-r[3], r[1], r[0], r[2])):
        if r not in seen:
            seen.add(r)
            ordered.append(("frame",) + r)
    return runs + ordered


# -- analysis --------------------------------------------------------------------------------

def _is_reference(row, finest):
    return (row["problem"] == "frame" and row["cell_size"] == finest
            and all(row[k] == v for k, v in REFERENCE.items()))


def attach_frame_errors(rows):
    """Set each frame run's error against the reference run; returns the reference row."""
    frame = [r for r in rows if r["problem"] == "frame" and r["status"] == "ok"]
    if not frame:
        return None
    finest = min(r["cell_size"] for r in frame)
    ref = [r for r in frame if _is_reference(r, finest)]
    if not ref:
        return None
    ref = ref[0]
    for r in frame:
        r["error"] = abs(r["peak_mm"] - ref["peak_mm"]) / ref["peak_mm"]
    ref["status"] = "reference"
    return ref


def _series(rows, problem, shape, ppc=2, scheme="musl"):
    """Runs of one setting over cell size (coarsest first), reference and failures left out."""
    out = [r for r in rows if r["problem"] == problem and r["shape"] == shape and r["ppc"] == ppc
           and r["scheme"] == scheme and r["status"] == "ok" and r.get("error") is not None]
    return sorted(out, key=lambda r: -r["cell_size"])


def _slope(x, y):
    x, y = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    return float(np.polyfit(x, y, 1)[0])


def convergence_orders(rows, problem="bar", points=ORDER_POINTS):
    """Least-squares slope of log(error) against log(cell size) over the finest ``points`` cell
    sizes, per shape function (MUSL, 2 x 2 particles per cell)."""
    out = {}
    for shape in SHAPES:
        s = _series(rows, problem, shape)[-points:]
        if len(s) >= 2 and all(r["error"] > 0 for r in s):
            out[shape] = {"order": _slope([r["cell_size"] for r in s], [r["error"] for r in s]),
                          "cell_sizes": [r["cell_size"] for r in s], "errors": [r["error"] for r in s]}
    return out


def pareto_front(rows, clock="wall_s"):
    """Mark ``pareto`` on each run of each problem: no other run is both at most as slow (by
    ``clock``, "wall_s" or "cpu_s") and at most as wrong (and better in one)."""
    for problem in ("bar", "frame"):
        pts = [r for r in rows if r["problem"] == problem and r["status"] == "ok" and r.get("error")]
        best = math.inf
        for r in sorted(pts, key=lambda r: (r[clock], r["error"])):
            r["pareto"] = r["error"] < best
            best = min(best, r["error"])
    return rows


def _loglog_interp(series, t, clock="wall_s"):
    """log-log interpolation of error at time ``t`` along a series."""
    lt = np.log([r[clock] for r in series])
    le = np.log([r["error"] for r in series])
    order = np.argsort(lt)
    return float(np.exp(np.interp(math.log(t), lt[order], le[order])))


def equal_time_comparison(rows, problem="frame", a="cubic", b="linear", n=9, clock="wall_s"):
    """Error of ``a`` and ``b`` (MUSL, 2 x 2 particles, refined over cell size) at common times:
    ``n`` log-spaced times over the overlap of their time ranges. ``holds``: ``a`` at least as
    accurate at all of them; ``holds_from_s``: the first of them from which on it is."""
    sa, sb = _series(rows, problem, a), _series(rows, problem, b)
    if len(sa) < 2 or len(sb) < 2:
        return None
    lo = max(min(r[clock] for r in sa), min(r[clock] for r in sb))
    hi = min(max(r[clock] for r in sa), max(r[clock] for r in sb))
    if hi <= lo:
        return {"problem": problem, "clock": clock, "overlap_s": None, "times_s": [], "ratio": [], "holds": None}
    times = np.geomspace(lo, hi, n)
    ea = [_loglog_interp(sa, t, clock) for t in times]
    eb = [_loglog_interp(sb, t, clock) for t in times]
    ok = [x <= y for x, y in zip(ea, eb)]
    since = next((t for k, t in enumerate(times) if all(ok[k:])), None)
    return {"problem": problem, "clock": clock, "shapes": [a, b], "overlap_s": [lo, hi], "times_s": times.tolist(),
            f"error_{a}": ea, f"error_{b}": eb, "ratio": [x / y for x, y in zip(ea, eb)],
            "holds": all(ok), "holds_from_s": None if since is None else float(since)}


def _qualifying(frame, target):
    """Frame runs that meet ``target`` and stay within it under refinement: the same shape, ppc
    and scheme was also run on a finer grid (the reference, exact by construction, does not
    count) and every such finer run meets it too. One run alone can meet a target by a lucky
    cancellation (linear B-splines pass the reference on their way to a 10% error)."""
    out = []
    for r in frame:
        finer = [q for q in frame if (q["shape"], q["ppc"], q["scheme"]) == (r["shape"], r["ppc"], r["scheme"])
                 and q["cell_size"] < r["cell_size"]]
        if finer and r["error"] <= target and all(q["error"] <= target for q in finer):
            out.append(r)
    return out


def recommendations(rows, targets=TARGETS, clock="wall_s", shape=None):
    """Cheapest (by ``clock``) qualifying frame setting per error target (see _qualifying),
    optionally of one ``shape``; None where no setting qualifies."""
    frame = [r for r in rows if r["problem"] == "frame" and r["status"] == "ok"]
    out = {}
    for target in targets:
        ok = [r for r in _qualifying(frame, target) if shape is None or r["shape"] == shape]
        r = min(ok, key=lambda r: r[clock]) if ok else None
        out[f"{target:g}"] = None if r is None else {
            k: r[k] for k in ("shape", "ppc", "scheme", "cell_size", "error", "wall_s", "cpu_s", "particles", "steps")}
    return out


def reference_self_error(rows, ref):
    """Richardson estimate of the reference's own error: with the cubic runs at 2h and h (the
    reference) and their observed order p from 4h, 2h, h, |p_h - p_2h| / (2^p - 1) / p_h."""
    if ref is None:
        return None
    s = [r for r in rows if r["problem"] == "frame" and all(r[k] == v for k, v in REFERENCE.items())
         and r["status"] in ("ok", "reference")]
    s = sorted(s, key=lambda r: -r["cell_size"])
    if len(s) < 3:
        return None
    p4, p2, p1 = (r["peak_mm"] for r in s[-3:])
    if (p4 - p2) * (p2 - p1) <= 0 or p2 == p1:
        order = 2.0   # not monotone: assume the nominal second order
    else:
        order = math.log2(abs(p4 - p2) / abs(p2 - p1))
    est = abs(p1 - p2) / (2 ** order - 1) / p1
    return {"order": order, "relative_error": est, "extrapolated_peak_mm": p1 + (p1 - p2) / (2 ** order - 1)}


# -- output ----------------------------------------------------------------------------------

def _fmt(v, spec):
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def write_csv(rows, path):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") if r.get(k) is not None else "" for k in CSV_COLUMNS})


def _short_status(status):
    """'refused: bodies[0].depth: 3 particle row(s) ...' -> 'refused (3 particle rows)', etc."""
    import re
    m = re.search(r"(\d+) particle row", status)
    if status.startswith("refused") and m:
        return f"refused ({m.group(1)} particle rows across a member)"
    m = re.search(r"diverged at t = ([0-9.eE+-]+) s", status)
    if m:
        return f"diverged at t = {float(m.group(1)):.3g} s"
    m = re.search(r"non-finite velocity or inverted volume at t = ([0-9.eE+-]+) s", status)
    if m:
        return f"unstable at t = {float(m.group(1)):.3g} s"
    return status[:60]


def markdown_table(rows):
    head = ("| problem | shape | ppc | scheme | cell (m) | particles | steps | wall (s) | CPU (s) "
            "| error | first peak (mm) | Pareto |")
    lines = [head, "|" + "|".join(["---"] * 12) + "|"]
    for r in rows:
        if r["status"] == "reference":
            err = "reference"
        elif r.get("error") is None:
            err = _short_status(r["status"])
        else:
            err = f"{r['error']:.3g}"
        lines.append(f"| {r['problem']} | {r['shape']} | {r['ppc']} | {r['scheme']} | {r['cell_size']:.4g} "
                     f"| {r.get('particles', '')} | {r.get('steps', '')} | {_fmt(r.get('wall_s'), '.2f')} "
                     f"| {_fmt(r.get('cpu_s'), '.2f')} | {err} | {_fmt(r.get('peak_mm'), '.3f')} "
                     f"| {'yes' if r.get('pareto') else ''} |")
    return "\n".join(lines)


def write_markdown(rows, summary, path):
    lines = ["# pmpm bench accuracy", "", f"Command: `{summary['command']}`", "",
             "Study wall time: " + (f"{summary['study_wall_s']:.0f} s" if summary["study_wall_s"] is not None
                                    else "(re-analysis of an earlier accuracy.csv)"), ""]
    lines.append("## Convergence order (bar, MUSL, 2 x 2 particles per cell)")
    lines.append("")
    for shape, o in summary["orders"].items():
        lines.append(f"- {shape}: {o['order']:.2f} (cell sizes {', '.join(f'{h:.4g}' for h in o['cell_sizes'])})")
    if summary.get("frame_orders"):
        lines += ["", "Frame (first peak against the reference, MUSL, 2 x 2 particles per cell), for information:", ""]
        for shape, o in summary["frame_orders"].items():
            lines.append(f"- {shape}: {o['order']:.2f} (cell sizes {', '.join(f'{h:.4g}' for h in o['cell_sizes'])})")
    clock = CLOCKS[summary["clock"]]
    for name in ("equal_time", "equal_time_bar"):
        cmp_ = summary.get(name)
        if cmp_ and cmp_.get("overlap_s"):
            lines += ["", f"## Cubic against linear at equal {clock} ({cmp_['problem']}, MUSL, 2 x 2 particles "
                          "per cell, log-log interpolation along the cell-size refinement)", "",
                      f"| {clock} (s) | error cubic | error linear | cubic / linear |", "|---|---|---|---|"]
            for t, a, b, q in zip(cmp_["times_s"], cmp_["error_cubic"], cmp_["error_linear"], cmp_["ratio"]):
                lines.append(f"| {t:.3g} | {a:.3g} | {b:.3g} | {q:.2f} |")
    if summary.get("recommendations"):
        lines += ["", f"## Cheapest setting per error target (frame, first peak, by {clock})", "",
                  "A setting counts when it and every finer run of the same shape, ppc and scheme (at least "
                  "one, the reference excluded) meet the target.", "",
                  "CFL: the largest number of the CFL sweep at which that setting still meets the target "
                  "(at most 0.9 of the largest stable one), with the error and the cost (scaled by the step "
                  "count) at it; 0.5 (the main sweep's) where the shape and cell size were not swept.", "",
                  "| target | shape | ppc | scheme | cell (m) | CFL | error | wall (s) | CPU (s) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        from studies.accuracy_cfl import cfl_recommendation
        cfl = summary.get("cfl")
        groups = [("any", summary["recommendations"])] + list(summary.get("recommendations_by_shape", {}).items())
        for label, recs in groups:
            for key, r in recs.items():
                head = f"{float(key):.1%}" + ("" if label == "any" else f" ({label} only)")
                if r is None:
                    lines.append(f"| {head} | none qualifies | | | | | | | |")
                    continue
                if cfl:
                    r = cfl_recommendation(r, cfl["rows"], cfl["largest_stable"], float(key))
                c = f"{r.get('cfl', 0.5):g}" + ("" if r.get("swept") or not cfl else " (not swept)")
                lines.append(f"| {head} | {r['shape']} | {r['ppc']} | {r['scheme']} | {r['cell_size']:g} "
                             f"| {c} | {r['error']:.3%} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} |")
    if summary.get("cfl"):
        from studies.accuracy_cfl import cfl_markdown
        lines += [""] + cfl_markdown(summary["cfl"]["rows"], summary["cfl"]["largest_stable"])
    if summary.get("reference"):
        ref = summary["reference"]
        lines += ["", f"Frame reference: {ref['shape']}, {ref['ppc']} x {ref['ppc']} particles per cell, "
                      f"{ref['scheme'].upper()}, {ref['cell_size']:g} m: first peak {ref['peak_mm']:.3f} mm."]
        if summary.get("reference_self_error"):
            se = summary["reference_self_error"]
            lines.append(f"Richardson estimate of its own error: {se['relative_error']:.2%} "
                         f"(observed order {se['order']:.2f}, extrapolated peak {se['extrapolated_peak_mm']:.3f} mm).")
    lines += ["", "## All runs", "", markdown_table(rows), ""]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


def write_plot(rows, path, clock="wall_s"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    problems = [p for p in ("bar", "frame") if any(r["problem"] == p and r.get("error") for r in rows)]
    if not problems:   # (--cfl-only: the main sweep's plot has nothing to show)
        return
    fig, axes = plt.subplots(1, len(problems), figsize=(6.5 * len(problems), 5.2), squeeze=False)
    colors = {"linear": "tab:blue", "quadratic": "tab:orange", "cubic": "tab:green"}
    markers = {"musl": "o", "usl": "s", "usf": "^", "mls": "D"}
    sizes = {1: 18, 2: 40, 3: 75}
    for ax, problem in zip(axes[0], problems):
        pts = [r for r in rows if r["problem"] == problem and r["status"] == "ok" and r.get("error")]
        for r in pts:
            ax.scatter(r[clock], r["error"], c=colors[r["shape"]], marker=markers[r["scheme"]],
                       s=sizes.get(r["ppc"], 40), alpha=0.75, edgecolors="none")
        for shape in SHAPES:   # the cell-size refinement of MUSL, 2 x 2
            s = sorted(_series(rows, problem, shape), key=lambda r: r[clock])
            if s:
                ax.plot([r[clock] for r in s], [r["error"] for r in s], "-", color=colors[shape], lw=1, alpha=0.6)
        front = sorted([r for r in pts if r.get("pareto")], key=lambda r: r[clock])
        if front:
            xs, ys = [front[0][clock]], [front[0]["error"]]
            for r in front[1:]:
                xs += [r[clock], r[clock]]
                ys += [ys[-1], r["error"]]
            ax.plot(xs, ys, "k--", lw=1.2, label="Pareto front")
            ax.scatter([r[clock] for r in front], [r["error"] for r in front], s=140, facecolors="none",
                       edgecolors="k", linewidths=1.2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"{CLOCKS[clock]} of the stepping (s, one rank)")
        ax.set_ylabel("max |u - u_exact| / amplitude" if problem == "bar" else "|peak - peak_ref| / peak_ref")
        if problem == "bar":
            ax.set_title("axial bar, one period, against the exact solution")
        else:
            ref = [r for r in rows if r["problem"] == "frame" and r["status"] == "reference"]
            ax.set_title("elastic portal frame, first peak, against the finest run"
                         + (f"\n(reference {ref[0]['shape']}, {ref[0]['ppc']}x{ref[0]['ppc']} ppc, "
                            f"{ref[0]['scheme'].upper()}, {ref[0]['cell_size']:g} m: not shown)" if ref else ""),
                         fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        from matplotlib.lines import Line2D
        handles = [Line2D([], [], color=c, marker="o", ls="-", label=k) for k, c in colors.items()]
        handles += [Line2D([], [], color="grey", marker=m, ls="", label=k.upper()) for k, m in markers.items()]
        handles += [Line2D([], [], color="grey", marker="o", ls="", markersize=math.sqrt(s), label=f"{p} x {p} ppc")
                    for p, s in sizes.items()]
        handles += [Line2D([], [], color="k", ls="--", marker="o", mfc="none", label="Pareto front")]
        ax.legend(handles=handles, fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- the command -----------------------------------------------------------------------------

def add_arguments(p):
    """Options of ``pmpm bench accuracy``."""
    p.add_argument("--quick", action="store_true", help="reduced sweep (one to two minutes, for the test)")
    p.add_argument("--outdir", default="accuracy_results", help="directory for accuracy.csv/.md/.png")
    p.add_argument("--from-csv", metavar="CSV", default=None,
                   help="run nothing: redo the analysis and the files from an earlier accuracy.csv")
    p.add_argument("--no-cfl", action="store_true", help="skip the CFL-number sweep (studies/accuracy_cfl.py)")
    p.add_argument("--cfl-only", action="store_true",
                   help="run only the frame's reference and the CFL-number sweep")
    p.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                   help="time axis of the analysis: wall (default) or CPU time of the stepping")
    p.add_argument("--implicit", action="store_true",
                   help="with --response: the implicit integrator's rows (time steps T1/20 ... T1/400) beside the "
                        "main job's explicit setting (issue 37)")
    p.add_argument("--response", action="store_true",
                   help="instead: the whole 0.25 s response of the elastic frame per setting (cell, shape, scheme, "
                        "CFL, transfer): numerical damping, every peak and the period against the continuum FE "
                        "model, cost (studies/accuracy_response.py; with --quick, --outdir)")


#: an accuracy.csv holds a few hundred rows; a larger file is not one
MAX_CSV_BYTES = 16 << 20


def read_csv(path):
    """Rows of an earlier accuracy.csv, typed as the sweep makes them; anything else (a missing
    file, a folder, a FIFO or device, binary bytes, a missing column, a non-number) is a
    ConfigError naming the file (one line, exit 2)."""
    from pmpm.errors import ConfigError
    import stat as _stat
    try:
        st = os.stat(path)
    except OSError as exc:
        raise ConfigError(path, f"cannot be read ({exc.strerror or type(exc).__name__})") from None
    if not _stat.S_ISREG(st.st_mode):
        raise ConfigError(path, "is not a regular file (a folder, FIFO or device): not an accuracy.csv")
    if st.st_size > MAX_CSV_BYTES:
        raise ConfigError(path, f"is larger than {MAX_CSV_BYTES >> 20} MiB: not an accuracy.csv")
    try:
        with open(path, "rb") as fh:
            text = fh.read(MAX_CSV_BYTES + 1).decode("utf-8")
        if "\0" in text:
            raise ValueError("holds NUL bytes (a binary file)")
        return _typed_rows(csv.DictReader(text.splitlines()))
    except UnicodeDecodeError:
        raise ConfigError(path, "is not UTF-8 text: not an accuracy.csv") from None
    except KeyError as exc:
        raise ConfigError(path, f"has no column {exc.args[0]!r}: not an accuracy.csv") from None
    except (ValueError, TypeError, csv.Error) as exc:
        raise ConfigError(path, f"is not an accuracy.csv ({exc})") from None


def _typed_rows(reader):
    rows = []
    for r in reader:
        row = {"problem": r["problem"], "shape": r["shape"], "ppc": int(r["ppc"]), "scheme": r["scheme"],
               "cell_size": float(r["cell_size"]), "status": r["status"]}
        for k in ("particles", "steps"):
            if r[k]:
                row[k] = int(r[k])
        for k in ("wall_s", "cpu_s", "error", "peak_mm", "t_peak_s", "peak_track_mm"):
            if r[k]:
                row[k] = float(r[k])
        if row["status"] == "reference":
            row["status"] = "ok"
        if row["problem"] == "frame":
            row.pop("error", None)
        rows.append(row)
    if not rows:
        raise ValueError("holds no rows")
    return rows


def study(quick=False, outdir="accuracy_results", log=None, out=None, command=None, from_csv=None,
          clock="wall_s", cfl=True, cfl_only=False):
    """Run the sweep (and, ``cfl``, the CFL-number sweep; ``cfl_only``: the frame's reference
    and the CFL sweep alone), write the files, print the figures; returns the summary dict (the JSON)."""
    # the streams of the call, not of the import (a caller may redirect them, as the tests do)
    log = sys.stderr if log is None else log
    out = sys.stdout if out is None else out
    from studies import accuracy_cfl
    from pmpm.errors import ConfigError
    from pmpm.io import ownership
    t_study = time.perf_counter()
    if os.path.lexists(outdir) and not os.path.isdir(outdir):
        raise ConfigError(outdir, "--outdir exists and is not a folder")
    csv_path = os.path.join(outdir, "accuracy.csv")
    cfl_rows = best = None
    rows = read_csv(from_csv) if from_csv else None  # checked before anything is written
    # every file through the gate, all claimed before the first is written: a user's file, a
    # link or a FIFO of these names stops the study before it writes; a failure (or Ctrl-C)
    # takes back the study's files and restores the previous ones (pmpm.io.ownership)
    with ownership.writing("accuracy") as w:
        if from_csv:
            ownership.protect_input(from_csv)  # redone in place: the input is read, never rewritten
        names = ["md", "png"] + ([] if from_csv and _same_file(from_csv, csv_path) else ["csv"])
        names += ["cfl.csv"] if (cfl or cfl_only) and not from_csv else []
        for name in names:
            w.claim(os.path.join(outdir, "accuracy_cfl.csv" if name == "cfl.csv" else f"accuracy.{name}"))
        return _study(rows, quick, outdir, csv_path, t_study, log, out, command, clock, cfl, cfl_only,
                      write_rows="csv" in names)


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _study(rows, quick, outdir, csv_path, t_study, log, out, command, clock, cfl, cfl_only, write_rows):
    from studies import accuracy_cfl
    from_csv = rows is not None
    cfl_rows = best = None
    if not from_csv:
        runs = plan(quick)
        if cfl_only:
            runs = [r for r in runs if r[0] == "frame" and r[1:4] == tuple(REFERENCE.values())
                    and r[4] == min(q[4] for q in runs if q[0] == "frame")]
            warm_up({(p, shape, "musl") for p, shape, _ in accuracy_cfl.cfl_plan(quick)}, log)
        rows = _sweep(runs, csv_path, log)
        if cfl or cfl_only:
            cfl_rows, best = accuracy_cfl.run_cfl_sweep(quick, log)
    return _report(rows, quick, outdir, csv_path if write_rows else None, None if from_csv else t_study, out,
                   command, clock, cfl_rows=cfl_rows, best=best)


def _sweep(runs, csv_path, log):
    from pmpm.errors import ConfigError, ParticleExitError, UnstableRunError
    warm_up({(r[0], r[1], r[3]) for r in runs}, log)
    rows = []
    for k, (problem, shape, ppc, scheme, h) in enumerate(runs):
        try:
            if problem == "bar":
                row = run_bar(int(round(BAR_L / h)), shape, scheme, ppc)
            else:
                row = run_frame(h, shape, scheme, ppc)
        except ConfigError as exc:
            row = {"problem": problem, "shape": shape, "ppc": ppc, "scheme": scheme, "cell_size": h,
                   "status": f"refused: {exc}"}
        except (UnstableRunError, ParticleExitError) as exc:
            row = {"problem": problem, "shape": shape, "ppc": ppc, "scheme": scheme, "cell_size": h,
                   "status": f"failed: {exc}"}
        rows.append(row)
        what = (f"error {row['error']:.3g}" if row.get("error") is not None else
                f"peak {row['peak_mm']:.3f} mm at {row['t_peak_s']:.4f} s" if row.get("peak_mm") is not None
                else row["status"])
        cost = f", wall {row['wall_s']:.2f} s, {row['steps']} steps" if row.get("wall_s") is not None else ""
        print(f"[accuracy] {k + 1}/{len(runs)} {problem} {shape} ppc {ppc} {scheme} h {h:.4g}: {what}{cost}",
              file=log, flush=True)
        write_csv(rows, csv_path)   # a failed run keeps the rows before it (a crash of the study takes its files back)
    return rows


def _report(rows, quick, outdir, csv_path, t_study, out, command, clock="wall_s", cfl_rows=None, best=None):
    from studies import accuracy_cfl
    ref = attach_frame_errors(rows)
    pareto_front(rows, clock)
    orders = convergence_orders(rows, "bar")
    summary = {
        "command": command or "pmpm bench accuracy" + (" --quick" if quick else "") + f" --outdir {outdir}",
        "quick": quick, "study_wall_s": None if t_study is None else time.perf_counter() - t_study,
        "runs": len(rows), "clock": clock,
        "orders": orders, "frame_orders": convergence_orders(rows, "frame") if ref else {},
        "equal_time": equal_time_comparison(rows, "frame", clock=clock) if ref else None,
        "equal_time_bar": equal_time_comparison(rows, "bar", clock=clock),
        "recommendations": recommendations(rows, clock=clock) if ref else {},
        "recommendations_by_shape": ({shape: recommendations(rows, clock=clock, shape=shape) for shape in SHAPES}
                                     if ref else {}),
        "reference": ({k: ref[k] for k in ("shape", "ppc", "scheme", "cell_size", "peak_mm", "wall_s")}
                      if ref else None),
        "reference_self_error": reference_self_error(rows, ref),
        "files": {k: os.path.join(outdir, f"accuracy.{k}") for k in ("csv", "md", "png")},
    }
    if cfl_rows is not None:
        accuracy_cfl.attach_cfl_errors(cfl_rows, ref["peak_mm"] if ref else None)
        summary["cfl"] = {"largest_stable": best, "rows": cfl_rows,
                          "recommendations": {k: (None if r is None else accuracy_cfl.cfl_recommendation(
                              r, cfl_rows, best, float(k))) for k, r in summary["recommendations"].items()}}
        cfl_csv = os.path.join(outdir, "accuracy_cfl.csv")
        with open(cfl_csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS + ("cfl", "energy_drift", "dt_effect", "stable", "bisection"),
                               extrasaction="ignore")
            w.writeheader()
            for r in cfl_rows:
                w.writerow({k: v for k, v in r.items() if v is not None})
        summary["files"]["cfl_csv"] = cfl_csv
    if csv_path is not None:  # not when the rows were read from it (--from-csv in place)
        write_csv(rows, csv_path)
    write_markdown(rows, summary, summary["files"]["md"])
    write_plot(rows, summary["files"]["png"], clock)
    print(markdown_table(rows), file=out)
    print("", file=out)
    for shape, o in orders.items():
        print(f"convergence order ({shape}, bar, MUSL, 2x2 ppc, finest {len(o['cell_sizes'])} cell sizes): "
              f"{o['order']:.2f}", file=out)
    for shape, o in summary["frame_orders"].items():
        print(f"frame order ({shape}, against the reference): {o['order']:.2f}", file=out)
    for name in ("equal_time", "equal_time_bar"):
        c = summary[name]
        if c and c.get("overlap_s"):
            lo, hi = c["overlap_s"]
            print(f"cubic vs linear at equal {CLOCKS[clock]} ({c['problem']}, {lo:.3g}-{hi:.3g} s): "
                  f"error ratio cubic/linear {min(c['ratio']):.2f}-{max(c['ratio']):.2f}, "
                  f"cubic at least as accurate: {c['holds']}"
                  + ("" if c["holds"] or c["holds_from_s"] is None else f" (from {c['holds_from_s']:.2f} s on)"),
                  file=out)
    for key, r in summary["recommendations"].items():
        if r is None:
            print(f"{float(key):.1%} on the frame's first peak: no setting qualifies", file=out)
        else:
            print(f"{float(key):.1%} on the frame's first peak: {r['shape']}, {r['ppc']}x{r['ppc']} ppc, "
                  f"{r['scheme'].upper()}, h = {r['cell_size']:g} m ({r['error']:.3%}, wall {r['wall_s']:.1f} s, "
                  f"CPU {r['cpu_s']:.1f} s)", file=out)
    if summary.get("cfl"):
        for problem, shapes in summary["cfl"]["largest_stable"].items():
            print(f"largest stable CFL number ({problem}): "
                  + ", ".join(f"{k} {v:g}" for k, v in shapes.items()), file=out)
        for key, r in summary["cfl"]["recommendations"].items():
            if r is not None:
                print(f"{float(key):.1%} on the frame's first peak with the time step: {r['shape']}, "
                      f"h = {r['cell_size']:g} m, CFL {r['cfl']:g}"
                      + (f" ({r['error']:.3%}, wall about {r['wall_s']:.1f} s)" if r["swept"] else
                         " (this shape and cell size not in the CFL sweep)"), file=out)
    took = "" if summary["study_wall_s"] is None else f"study wall time {summary['study_wall_s']:.0f} s; "
    print(f"{took}wrote {', '.join(summary['files'].values())}", file=out)
    print(json.dumps(_jsonable(summary), separators=(",", ":")), file=out)
    out.flush()
    return summary


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, float):
        return float(f"{x:.6g}") if math.isfinite(x) else None
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return _jsonable(x.item())
    return x


def accuracy(args):
    """``pmpm bench accuracy``: returns the exit code."""
    from mpi4py import MPI
    if MPI.COMM_WORLD.size > 1:
        print("pmpm bench accuracy runs on one rank (start it without mpirun -n > 1)", file=sys.stderr)
        return 2
    if args.response:
        from studies.accuracy_response import main as response
        return response((["--quick"] if args.quick else []) + (["--implicit"] if args.implicit else [])
                        + ["--outdir", args.outdir])
    command = None
    if sys.argv[1:3] == ["bench", "accuracy"]:
        command = ("pmpm bench accuracy " + " ".join(sys.argv[3:])).strip()
    from pmpm.errors import ConfigError
    try:
        study(args.quick, args.outdir, command=command, from_csv=args.from_csv, clock=args.clock + "_s",
              cfl=not args.no_cfl, cfl_only=args.cfl_only)
    except ConfigError as exc:  # a bad --from-csv, --outdir onto a file, a foreign file there
        print(f"pmpm: error: {exc}", file=sys.stderr)
        return 2
    return 0
