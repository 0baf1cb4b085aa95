"""The portal's static pushover (implicit integrator, ``solver.analysis = "static"``) against
the dynamic one and the sway mechanism (docs/implicit.md, "Static analyses").

    python -m studies.static_pushover [--cell 0.05] [--ppc 2] [--shift 0] [--edge-mass-ratio 0]
                                      [--skip-dynamic] [--skip-mechanism]

1. Initial stiffness: the elastic portal (cases/portal_pushover.toml's frame) pushed 20 mm in 4
   static steps, base shear over the joint's drift (least squares through the origin), beside
   the dynamic (explicit) push of tests/verification/test_pushover.py at the same cells (20 mm
   over 0.03 s, quarter-sine ramps, then a 10 ms hold: the base shear averaged over the hold
   over the mean drift) and the plane-stress FE model's P / static drift
   (tests/verification/frame_fe_model.py, levels 0-2 and their Richardson extrapolation).
2. Mechanism: the elastoplastic portal without hardening (the collapse load is then a
   rigid-perfectly-plastic theorem) pushed 0.1 m in ``--mechanism-steps`` static steps: the
   base shear at the end against P_c = (2 Mp,col + 2 Mp,beam (1 + 2 e / L_b)) / h with the cuts'
   own Mp (docs/structural_results.md), and the Newton iterations and halvings it took.

Prints the figures and a final JSON line.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

import pmpm
from pmpm.benchmarks.implicit_static import portal_pushover_data
from pmpm.scene.config import read_toml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ELASTIC = {"type": "linear_elastic", "E": 207e9, "nu": 0.3, "density": 7850.0}


def base_shear(r):
    R = r.reactions
    return -(np.asarray(R["left_base"]["Rx"]) + np.asarray(R["right_base"]["Rx"]))


def static_stiffness(cell, push=0.02, steps=4, ppc=None, shift=0.0, edge_mass_ratio=0.0):
    """(stiffness N/m, wall s, base shear, drift) of the static elastic push (``ppc``: points
    per cell, default the case's 2; ``shift``: the grid moved by this much along x, which moves
    the members' edges against the grid lines: docs/implicit.md, "The points as the quadrature
    of the strips"); ``edge_mass_ratio``: the implicit option, pmpm.core.implicit.edges)."""
    data = portal_pushover_data(cell, push, steps, ELASTIC, root=ROOT)
    if ppc is not None:
        data["particles_per_cell"] = ppc
    data["grid"]["origin"] = [data["grid"]["origin"][0] + shift, data["grid"]["origin"][1]]
    if edge_mass_ratio:
        data["solver"]["implicit"] = {"edge_mass_ratio": edge_mass_ratio}
    start = time.perf_counter()
    r = pmpm.run(data, dataframes=False)
    wall = time.perf_counter() - start
    V, u = base_shear(r)[1:], np.asarray(r.histories["upper_left_joint"]["ux"])[1:]
    return float(np.dot(u, V) / np.dot(u, u)), wall, V, u


def dynamic_stiffness(cell, push=0.02, hold_from=0.03, end=0.04, ppc=None):
    """(stiffness N/m, wall s) of the explicit push of tests/verification/test_pushover.py."""
    data = read_toml(os.path.join(ROOT, "cases", "portal_pushover.toml"))
    if ppc is not None:
        data["particles_per_cell"] = ppc
    data["grid"]["cell_size"] = cell
    data["grid"]["cells"] = [int(round(7.1 / cell)), int(round(4.2 / cell))]
    data["materials"]["steel"] = dict(ELASTIC)
    data["output"].update(fields=["x", "x0", "v", "stress"], section=[], history_interval=5e-4)
    for key in ("checkpoint_interval", "deformed_plot"):
        data["output"].pop(key, None)
    data["pushover"].update(displacement=push, duration=hold_from, ramp=hold_from / 2)
    data["solver"]["end_time"] = end
    start = time.perf_counter()
    r = pmpm.run(data, dataframes=False)
    wall = time.perf_counter() - start
    t = np.asarray(r.histories["upper_left_joint"]["time"])
    u = np.asarray(r.histories["upper_left_joint"]["ux"])
    hold = t > hold_from + 1e-9
    return float(base_shear(r)[hold].mean() / u[hold].mean()), wall


def fe_stiffness():
    sys.path.insert(0, os.path.join(ROOT, "tests", "verification"))
    import frame_fe_model as fem
    drifts = [fem.frame_fe(0.2, level).static()[1] for level in (0, 1, 2)]
    return float(fem.read_scene().load[0] / fem.richardson(drifts)[0])


def collapse_load(sections, data):
    """P_c of the sway mechanism from the cuts' Mp (tests/verification/test_pushover.py)."""
    bodies = {b["name"]: b for b in data["bodies"]}
    col, beam = bodies["left column"], bodies["beam"]
    e = col["depth"] / 2
    span = beam["end"][0] - beam["start"][0]
    height = beam["start"][1]
    mp_col = 0.5 * (sections["left_column_base"]["attrs"]["Mp"] + sections["right_column_base"]["attrs"]["Mp"])
    mp_beam = 0.5 * (sections["beam_left_end"]["attrs"]["Mp"] + sections["beam_right_end"]["attrs"]["Mp"])
    return float((2 * mp_col + 2 * mp_beam * (1 + 2 * e / span)) / height)


def mechanism(cell, steps, material):
    """(base shear curve, drift curve, P_c, wall s, Newton iterations, halvings)."""
    from pmpm.results.recorder import read_tables
    from pmpm.runner import Run
    from pmpm.scene.config import parse_scene
    data = portal_pushover_data(cell, 0.1, steps, material, root=ROOT)
    scene = parse_scene(data, os.path.join(ROOT, "cases", "portal_pushover.toml"))
    start = time.perf_counter()
    run = Run(scene, write=False)
    run.execute()
    wall = time.perf_counter() - start
    rows = run.structural.rows
    names = run.structural.reaction_names
    V = -np.array([r[2][names.index("left_base"), 0] + r[2][names.index("right_base"), 0] for r in rows])
    cuts = {c.name: {"attrs": c.properties} for c in run.structural.cuts}
    st = run.solver.scheme.stats
    return V, None, collapse_load(cuts, data), wall, st["newton_iterations"], st["halvings"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--mechanism-steps", type=int, default=20)
    ap.add_argument("--material", choices=("smooth_vonmises", "bilinear_vonmises"), default="smooth_vonmises",
                    help="the mechanism run's steel (the case's smooth model, or J2 with its consistent tangent)")
    ap.add_argument("--ppc", type=int, default=None, help="points per cell of the elastic pushes (the case's 2)")
    ap.add_argument("--shift", type=float, default=0.0, help="move the static push's grid by this much along x (m)")
    ap.add_argument("--edge-mass-ratio", type=float, default=0.0,
                    help="[solver.implicit] edge_mass_ratio of the static push (0: off)")
    ap.add_argument("--skip-dynamic", action="store_true")
    ap.add_argument("--skip-mechanism", action="store_true")
    args = ap.parse_args(argv)
    out = {"cell": args.cell, "ppc": args.ppc or 2, "grid_shift": args.shift, "edge_mass_ratio": args.edge_mass_ratio}
    k_static, wall, V, u = static_stiffness(args.cell, ppc=args.ppc, shift=args.shift,
                                            edge_mass_ratio=args.edge_mass_ratio)
    k_fe = fe_stiffness()
    out.update(static_stiffness=k_static, static_wall=wall, fe_stiffness=k_fe, static_over_fe=k_static / k_fe,
               static_step_secant=[float(x) for x in V / u])
    print(f"static elastic push, {args.cell:g} m cells: k = {k_static / 1e6:.4g} MN/m ({wall:.1f} s); "
          f"FE model {k_fe / 1e6:.4g} MN/m (ratio {k_static / k_fe:.4f}); per step "
          + ", ".join(f"{x / 1e6:.4g}" for x in V / u))
    if not args.skip_dynamic:
        k_dyn, wall = dynamic_stiffness(args.cell, ppc=args.ppc)
        out.update(dynamic_stiffness=k_dyn, dynamic_wall=wall, static_over_dynamic=k_static / k_dyn)
        print(f"dynamic (explicit) push: k = {k_dyn / 1e6:.4g} MN/m ({wall:.1f} s); static / dynamic = "
              f"{k_static / k_dyn:.4f}")
    if not args.skip_mechanism:
        steel = {"type": args.material, "E": 207e9, "nu": 0.3, "density": 7850.0, "yield_stress": 470e6,
                 "hardening": 0.0}
        if args.material == "smooth_vonmises":
            steel["smoothness"] = 10.0
        V, _, P_c, wall, its, halvings = mechanism(args.cell, args.mechanism_steps, steel)
        out.update(mechanism_base_shear=[float(x) for x in V], collapse_load=P_c, mechanism_wall=wall,
                   newton_iterations=its, halvings=halvings, end_over_collapse=float(V[-1] / P_c))
        print(f"mechanism ({args.material}, no hardening, 0.1 m in {args.mechanism_steps} steps, {wall:.1f} s, "
              f"{its} Newton iterations, {halvings} halvings): base shear "
              + ", ".join(f"{x / 1e3:.0f}" for x in V[1:]) + f" kN; P_c = {P_c / 1e3:.0f} kN; end / P_c = "
              f"{V[-1] / P_c:.4f}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
