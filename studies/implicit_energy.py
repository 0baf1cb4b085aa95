"""Where the implicit portal's energy goes (issue 37, docs/implicit.md): the elastic portal's step
response with the implicit integrator, its numerical energy loss against the cell size, the
points per cell and the time step.

``python -m studies.implicit_energy --runs 0.1:2:1e-3 0.1:3:1e-3 [--t-end 0.2]`` (each run
``cell:points-per-cell:time-step``; ``--shift DX`` moves the grid along x,
``--edge-mass-ratio R`` sets the implicit option of pmpm.core.implicit.edges) prints per run the energy the run lost (the solver's
``numerical_loss``) as a fraction of F u_mean (F the load, u_mean the joint's mean drift over the
run: the energy in play, as studies.accuracy_response measures it), the first peak and the
largest drift of the run's second half, and the wall time; the last line is one JSON object.
"""
import argparse
import dataclasses
import json
import time

import numpy as np

__all__ = ["run", "main"]


def run(cell, ppc, dt, t_end, shift=0.0, edge_mass_ratio=0.0):
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    from studies.accuracy_response import BASE, frame_scene, implicit_scene
    scene = implicit_scene(frame_scene(dataclasses.replace(BASE, cell=cell, ppc=ppc), t_end), dt)
    if shift:   # the grid moved along x: the members' edges sit elsewhere in their cells
        g = scene.grid
        scene = dataclasses.replace(scene, grid=dataclasses.replace(g, origin=(g.origin[0] + shift, g.origin[1])))
    if edge_mass_ratio:   # [solver.implicit] edge_mass_ratio (pmpm.core.implicit.edges)
        implicit = dict(scene.solver.implicit, edge_mass_ratio=edge_mass_ratio)
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, implicit=implicit))
    s = build_solver(scene, MPI.COMM_SELF)
    tracker = Tracker([t for t in scene.output.track if t.name == "upper_left_joint"], s)
    u, start = [], time.perf_counter()
    while s.t < t_end * (1 - 1e-12):
        s.step()
        u.append(float(tracker.sample()[0, 0]))
    e = s.energies()
    load = scene.loads.forces[0].force[0]
    return {"cell": cell, "ppc": ppc, "time_step": dt, "t_end": t_end, "grid_shift": shift,
            "edge_mass_ratio": edge_mass_ratio, "slaved_nodes": s.scheme.stats.get("slaved_nodes", 0),
            "loss_of_energy_in_play": float(e["numerical_loss"] / (load * np.mean(u))),
            "first_peak_mm": 1e3 * max(u[:len(u) // 2]), "late_peak_mm": 1e3 * max(u[len(u) // 2:]),
            "wall_s": time.perf_counter() - start}


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.implicit_energy", description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="+", default=["0.1:2:1e-3", "0.1:3:1e-3"], metavar="CELL:PPC:DT")
    ap.add_argument("--t-end", type=float, default=0.2)
    ap.add_argument("--shift", type=float, default=0.0, help="move the grid by this much along x (m)")
    ap.add_argument("--edge-mass-ratio", type=float, default=0.0, help="[solver.implicit] edge_mass_ratio (0: off)")
    a = ap.parse_args(argv)
    rows = []
    for spec in a.runs:
        cell, ppc, dt = spec.split(":")
        r = run(float(cell), int(ppc), float(dt), a.t_end, a.shift, a.edge_mass_ratio)
        rows.append(r)
        print(f"{r['cell']:g} m, {r['ppc']}x{r['ppc']} points, dt {r['time_step']:g} s, grid shifted {a.shift:g} m, "
              f"edge_mass_ratio {a.edge_mass_ratio:g} ({r['slaved_nodes']} slaved): lost "
              f"{100 * r['loss_of_energy_in_play']:.1f} % of F u_mean over {a.t_end:g} s; first peak "
              f"{r['first_peak_mm']:.2f} mm, largest of the second half {r['late_peak_mm']:.2f} mm "
              f"({r['wall_s']:.0f} s wall)", flush=True)
    print(json.dumps({"study": "implicit_energy", "rows": rows}))


if __name__ == "__main__":
    main()
