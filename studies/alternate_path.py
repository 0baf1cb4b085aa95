"""The alternate-path nonlinear static procedure (GSA 2016, UFC 4-023-03) on the frame of
cases/hard/column_loss.toml, beside the dynamic column loss (docs/implicit.md, "The
alternate-path procedure"; docs/structural_results.md, "Sudden column loss").

    python -m studies.alternate_path [--cell 0.05] [--drop 0.3] [--steps 30] [--omega 2.0]
                                     [--dead-share 1.0] [--dynamic-peak 0.12369]

The middle column is removed from the start (no event), and the gravity loads of the case (the
steel's weight and the 30 kN/m floor load on the beam), the load pattern at load factor 1, are
scaled by a load factor lambda, solved for under displacement control of the point above the
removed column (``[solver.static] control = "displacement"``, ``gravity = "pattern"``,
pmpm/core/implicit/arclength.py): the pushdown curve lambda(u). Printed:

- the pushdown curve and its largest load factor over the drop (the capacity within it);
- the procedure's demand: GSA's load combination for the bays above the removed column,
  Omega_N (1.2 D + 0.5 L), as a multiple of the case's loads D + L (``--dead-share`` of them
  dead; the case's floor load is not split into D and L), against that capacity;
- Izzuddin et al.'s (2008) pseudo-static response: for gravity applied suddenly at lambda_0,
  the dynamic peak is where the gravity's work equals the strain energy, lambda_0 u_d =
  int_0^u_d lambda(u) du in the pattern's work-conjugate drop u (the load-weighted mean drop of
  the particles, sum_p w_p (y0 - y)_p, w_p the particle's share of the pattern), i.e. where the
  pseudo-static curve lambda_ps(u) = (1/u) int_0^u lambda du reaches lambda_0; read as the point's
  drop on the static curve at that u (the response's shape taken as the static one's, damping
  and the kinetic energy left in other modes left out). lambda_ps's peak is the largest suddenly applied load the
  frame arrests. Beside it the explicit run's peak (``--dynamic-peak``, m, down; the default is
  docs/structural_results.md's 0.05 m figure, -123.69 mm: the dynamic case ramps the loads onto
  the intact frame, with its 2 % mass-proportional damping, and removes the column in 5 ms).

Implicit statics carries neither the case's large_rotations (the implicit step is objective by
construction), nor its mass-proportional damping (no dynamics), nor its event; its smooth von
Mises steel's tangent is the rate form's (docs/implicit.md). Prints the figures and a final
JSON line.
"""
import argparse
import json
import os
import time

import numpy as np

from mpi4py import MPI

from pmpm.errors import UnstableRunError
from pmpm.runner import Run
from pmpm.scene.config import parse_scene, read_toml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASE = os.path.join(ROOT, "cases", "hard", "column_loss.toml")
#: the point above the removed column (the case's track ``above_removed``)
POINT = (6.096, 3.658)


def pushdown_data(cell=0.05, drop=0.3, steps=30, material=None, implicit=None):
    """The case's frame without its middle column, under its gravity loads scaled by the load
    factor, the point above the removed column pushed down ``drop`` (m) in ``steps`` static
    steps (TOML data)."""
    data = read_toml(CASE)
    data["grid"]["cell_size"] = cell
    data["grid"]["cells"] = [int(round(13.2 / cell)), int(round(4.2 / cell))]
    data["bodies"] = [b for b in data["bodies"] if b["name"] != "middle column"]
    data["boundary"] = [b for b in data["boundary"] if b["name"] != "middle_base"]
    data.pop("events", None)
    data["loads"].pop("damping", None)
    if material is not None:
        data["materials"]["steel"] = dict(material)
    out = data["output"]
    out.pop("checkpoint_interval", None)
    out["section"] = [sec for sec in out["section"] if sec["name"] != "middle_column_base"]
    out.update(interval=1.0, history_interval=1.0 / steps, fields=["x", "x0", "stress", "eps_p_eq"])
    data["solver"] = {"shape_function": "cubic", "integrator": "implicit", "analysis": "static",
                      "time_step": 1.0 / steps, "end_time": 1.0,
                      "static": {"control": "displacement", "point": list(POINT), "component": "y",
                                 "displacement": -drop, "gravity": "pattern"}}
    if implicit:
        data["solver"]["implicit"] = dict(implicit)
    return data


def pattern_weights(solver):
    """Each particle's share of the load pattern's vertical force at load factor 1 (its weight and
    its share of the floor load), over the pattern's total: the weights of the generalised drop."""
    p = solver.particles
    g = float(-solver.gravity[1])
    f = p["m"] * g
    loads = solver.effect("loads")
    if loads is not None and loads.forces:
        vec = np.array([-fc.force[1] for fc in loads.forces])
        mine = p["load_id"] >= 0
        f = f + np.where(mine, p["load_w"] * vec[np.maximum(p["load_id"], 0)], 0.0)
    return f / solver.decomp.allreduce_sum(float(f.sum()))


def generalised_drop(solver, weights):
    """The pattern's work-conjugate drop sum_p w_p (y0_p - y_p) (Izzuddin et al.: the gravity's
    work is lambda times the pattern's total times it)."""
    p = solver.particles
    return float(solver.decomp.allreduce_sum(float(np.dot(weights, p["x0"][:, 1] - p["x"][:, 1]))))


def pseudo_static(u, lam):
    """Izzuddin et al.'s pseudo-static curve lambda_ps(u) = (1/u) int_0^u lambda du (trapezoids
    from the origin) at the points ``u`` (> 0, rising)."""
    u0, l0 = np.concatenate([[0.0], u]), np.concatenate([[0.0], lam])
    work = np.concatenate([[0.0], np.cumsum(0.5 * (l0[1:] + l0[:-1]) * np.diff(u0))])[1:]
    return work / u


def crossing(u, y, level):
    """The first u where y rises through ``level`` (linear between samples), or None."""
    for k in range(1, len(u)):
        if y[k - 1] < level <= y[k]:
            return float(u[k - 1] + (level - y[k - 1]) * (u[k] - u[k - 1]) / (y[k] - y[k - 1]))
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--drop", type=float, default=0.3, help="the point's prescribed drop (m)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--omega", type=float, default=2.0, help="GSA's dynamic increase factor Omega_N")
    ap.add_argument("--dead-share", type=float, default=1.0, help="share of the case's loads taken as dead")
    ap.add_argument("--dynamic-peak", type=float, default=0.12369, help="the explicit run's peak drop (m)")
    ap.add_argument("--material", choices=("case", "bilinear"), default="case",
                    help="the case's smooth von Mises steel, or bilinear J2 with its yield stress and hardening")
    ap.add_argument("--line-search", action="store_true", help="Newton with a line search, 40 iterations")
    args = ap.parse_args(argv)
    material = None
    if args.material == "bilinear":   # the case's steel with the bilinear J2 model (consistent tangent)
        material = {k: v for k, v in read_toml(CASE)["materials"]["steel"].items() if k != "smoothness"}
        material["type"] = "bilinear_vonmises"
    implicit = {"line_search": True, "max_iterations": 40} if args.line_search else None
    scene = parse_scene(pushdown_data(args.cell, args.drop, args.steps, material, implicit), "alternate_path.toml")
    run = Run(scene, MPI.COMM_WORLD, write=False)
    start = time.perf_counter()
    stopped = None
    weights = pattern_weights(run.solver)
    rows = []   # (load factor, the point's drop, the pattern's generalised drop, iterations) a scene step
    try:   # a step that fails at the smallest length ends the curve there (the path so far is kept)
        while run.solver.t < scene.solver.end_time * (1 - 1e-12):
            done = len(run.solver.scheme.control.path)
            run.solver.step()
            control = run.solver.scheme.control
            rows.append((control.load_factor, -control.point_displacement, generalised_drop(run.solver, weights),
                         sum(row[2] for row in control.path[done:])))
    except UnstableRunError as exc:
        stopped = str(exc)
    wall = time.perf_counter() - start
    path = np.array(rows)
    lam, u, ug = path[:, 0], path[:, 1], path[:, 2]
    ps = pseudo_static(ug, lam)
    print(f"alternate path, pushdown of the point above the removed column ({args.cell:g} m cells, "
          f"{args.steps} steps, {args.material} steel, {wall:.0f} s wall)")
    if stopped:
        print(f"stopped: {stopped}")
    print(f"{'drop (mm)':>10} {'pattern drop (mm)':>18} {'lambda':>9} {'lambda_ps':>10} {'iterations':>10}")
    for k in range(len(u)):
        print(f"{1e3 * u[k]:10.2f} {1e3 * ug[k]:18.3f} {lam[k]:9.4f} {ps[k]:10.4f} {int(path[k, 3]):10d}")
    demand = args.omega * (1.2 * args.dead_share + 0.5 * (1.0 - args.dead_share))
    capacity = float(lam.max())
    # the dynamic peak: where lambda_ps reaches 1 in the pattern's drop, read as the point's drop
    # on the static curve (the shape of the static response at that drop)
    ug_dyn = crossing(ug, ps, 1.0)
    u_dyn = None if ug_dyn is None else float(np.interp(ug_dyn, ug, u))
    print(f"capacity within the drop: lambda_max = {capacity:.4f} at {1e3 * u[int(np.argmax(lam))]:.1f} mm")
    print(f"GSA demand Omega_N (1.2 D + 0.5 L) / (D + L) = {demand:.3f} (Omega_N = {args.omega:g}, "
          f"dead share {args.dead_share:g}): {'met' if capacity >= demand else 'NOT met'} within {1e3 * args.drop:.0f} mm")
    print(f"static drop at lambda = 1: {1e3 * crossing(u, lam, 1.0):.2f} mm" if crossing(u, lam, 1.0) else
          "lambda = 1 not reached")
    print(f"pseudo-static (energy) prediction of the sudden loss's peak at lambda = 1: "
          + (f"{1e3 * u_dyn:.2f} mm" if u_dyn else "beyond the drop (not arrested within it)")
          + f"; explicit dynamic run: {1e3 * args.dynamic_peak:.2f} mm"
          + (f" (ratio {u_dyn / args.dynamic_peak:.3f})" if u_dyn else ""))
    print(f"largest suddenly applied load factor arrested within the drop (max lambda_ps): {ps.max():.4f}")
    print(json.dumps({"cell": args.cell, "steps": args.steps, "material": args.material, "wall_s": round(wall, 1),
                      "stopped": stopped, "reached_drop_mm": 1e3 * float(u[-1]),
                      "capacity_load_factor": capacity, "omega": args.omega, "demand": demand,
                      "static_drop_at_1_mm": None if crossing(u, lam, 1.0) is None else 1e3 * crossing(u, lam, 1.0),
                      "pseudo_static_peak_mm": None if u_dyn is None else 1e3 * u_dyn,
                      "dynamic_peak_mm": 1e3 * args.dynamic_peak, "max_pseudo_static": float(ps.max()),
                      "newton_iterations": int(path[:, 3].sum())}))


if __name__ == "__main__":
    main()
