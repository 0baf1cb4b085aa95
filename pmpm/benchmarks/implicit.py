"""Scenes of the implicit integrator (docs/implicit.md): the fixed-free bar of design.md section 7
and a steel cantilever under gravity, as TOML data, for the tests (serial and MPI) and the
kernel warm-up."""
import argparse
import dataclasses
import json
import math
import os
import time

import numpy as np
from mpi4py import MPI

from pmpm.benchmarks.args import FRAME_CASE
from pmpm.build import build_solver
from pmpm.io.tracking import Tracker
from pmpm.scene.config import apply_overrides, parse_scene, read_toml
from pmpm.scene.frame import expand_frame

__all__ = ["bar_scene", "cantilever_scene", "timoshenko_tip_deflection", "warm_implicit"]

#: the checkout whose cases/ the portal's scene is read from (this package's, not the working folder)
CHECKOUT = os.path.dirname(os.path.dirname(FRAME_CASE))
#: the bar (design.md section 7): L = 25, E = 100, rho = 1, first mode omega = pi / 5, T = 10
BAR_L, BAR_OMEGA = 25.0, math.pi / 5
#: the bar's explicit step at CFL 0.5 with 0.5 cells: 0.5 * 0.5 / 10
BAR_CFL_STEP = 0.025
#: the cantilever: steel, L = 4 m, depth 0.4 m, unit thickness, clamped at x = 0
BEAM_L, BEAM_D, BEAM_E, BEAM_RHO, BEAM_NU, BEAM_Y0 = 4.0, 0.4, 2e11, 7850.0, 0.3, 0.8


def bar_scene(time_step, end_time, v0=0.001, cells=(54, 3), petsc=None, implicit=None):
    """The bar of cases/bar.toml in its first mode, implicit (v0 small: linear in practice)."""
    data = {"title": "bar", "formulation": "plane_stress", "particles_per_cell": 2,
            "grid": {"origin": [0.0, 0.0], "cell_size": 0.5, "cells": list(cells)},
            "materials": {"bar": {"type": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0}},
            "bodies": [{"name": "bar", "shape": "rectangle", "material": "bar", "lower": [0.0, 0.0],
                        "upper": [BAR_L, 0.5], "velocity": [f"{v0} * sin(pi * x / 50)", 0.0]}],
            "boundary": [{"name": "fixed end", "type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 1.5]}],
            "solver": {"integrator": "implicit", "time_step": time_step, "end_time": end_time}}
    if petsc:
        data["solver"]["petsc"] = dict(petsc)
    if implicit:
        data["solver"]["implicit"] = dict(implicit)
    return parse_scene(data, "bar.toml")


def cantilever_scene(gravity=9.81, h=0.1, material=None, petsc=None):
    """The clamped cantilever under its own weight, one static step."""
    mat = material or {"type": "linear_elastic", "E": BEAM_E, "nu": BEAM_NU, "density": BEAM_RHO}
    data = {"title": "cantilever", "formulation": "plane_stress", "particles_per_cell": 2,
            "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": [int(round(4.6 / h)), int(round(2.0 / h))]},
            "materials": {"steel": mat},
            "bodies": [{"name": "beam", "shape": "rectangle", "material": "steel",
                        "lower": [0.0, BEAM_Y0], "upper": [BEAM_L, BEAM_Y0 + BEAM_D]}],
            "boundary": [{"name": "wall", "type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 2.0]}],
            "loads": {"gravity": [0.0, -gravity]},
            "solver": {"integrator": "implicit", "analysis": "static", "time_step": 1.0, "end_time": 1.0}}
    if petsc:
        data["solver"]["petsc"] = dict(petsc)
    return parse_scene(data, "cantilever.toml")


def timoshenko_tip_deflection(gravity):
    """Tip deflection of the clamped cantilever under its weight q = rho g d (unit thickness):
    bending q L^4 / (8 E I) plus shear q L^2 / (2 kappa G A), kappa = 5/6."""
    q = BEAM_RHO * gravity * BEAM_D
    inertia = BEAM_D ** 3 / 12
    shear = BEAM_E / (2 * (1 + BEAM_NU))
    return q * BEAM_L ** 4 / (8 * BEAM_E * inertia) + q * BEAM_L ** 2 / (2 * 5 / 6 * shear * BEAM_D)


def warm_implicit():
    """Compile the implicit kernels' specialisations (the warm-up, pmpm.warmup): the bar
    (dynamics, elastic) and the cantilever (statics) with each material that has a tangent."""
    plastic = {"E": BEAM_E, "nu": BEAM_NU, "density": BEAM_RHO, "yield_stress": 250e6, "hardening": 0.05}
    scenes = [bar_scene(1.0, 2.0), cantilever_scene(h=0.2)]
    scenes += [cantilever_scene(h=0.2, material=dict(plastic, type=kind))
               for kind in ("bilinear_vonmises", "smooth_vonmises")]
    for scene in scenes:
        s = build_solver(scene, MPI.COMM_SELF)
        s.step()


def portal_scene(cell_size=0.05, time_step=1e-3, end_time=0.25, root=CHECKOUT, petsc=None, variant="elastic",
                 implicit=None):
    """The main job's portal frame (cases/portal_frame.toml, variant elastic or elastoplastic) for the
    implicit integrator: the frame expanded, and what the implicit step does not support yet
    left out (section cuts, hysteresis, support reactions, checkpoints); the response (the
    upper-left joint's drift) is the same scene's."""
    data = read_toml(os.path.join(root, "cases", "portal_frame.toml"))
    data = apply_overrides(data, data["variants"][variant], f"variants.{variant}")
    data.pop("variants")
    # the grid before the frame is expanded: the frame's supports and load box are counted in
    # cells of the grid it runs on (a frame expanded on the case's 0.05 m grid and then run on
    # 0.1 m cells held only 5 base nodes under each column instead of 7: a base that is not
    # clamped across its flanges, 37.8 mm instead of 31.8 mm of static drift; studies.implicit_coarse)
    data["grid"]["cell_size"] = cell_size
    data["grid"]["cells"] = [int(round(7.1 / cell_size)), int(round(4.2 / cell_size))]
    data = expand_frame(data)
    for bc in data.get("boundary", []):
        bc.pop("reaction", None)
        bc.pop("moment_about", None)
    out = data["output"]
    for key in ("section", "hysteresis", "checkpoint_interval", "deformed_plot", "reactions"):
        out.pop(key, None)
    data["solver"] = {"shape_function": "cubic", "integrator": "implicit", "time_step": time_step,
                      "end_time": end_time, "petsc": dict(petsc or {})}
    if implicit:
        data["solver"]["implicit"] = dict(implicit)
    return parse_scene(data, "portal_frame.toml")


def _joint_drift(scene, integrator_scene, every):
    """(times, drift of the upper-left joint, wall seconds, steps, solver) of one run."""
    s = build_solver(integrator_scene, MPI.COMM_WORLD)
    names = [t.name for t in integrator_scene.output.track]
    tr = Tracker(integrator_scene.output.track, s)
    k = names.index("upper_left_joint")
    t, ux = [0.0], [0.0]
    start = time.perf_counter()
    while s.t < integrator_scene.solver.end_time - 1e-12:
        s.step()
        if s.step_count % every == 0:
            sample = tr.sample()
            t.append(s.t)
            ux.append(float(np.asarray(sample)[k, 0]))
    return np.array(t), np.array(ux), time.perf_counter() - start, s.step_count, s


def portal_benchmark(cell_size=0.05, time_step=1e-3, end_time=0.25, petsc=None, explicit_run=True,
                     variant="elastic", implicit_options=None):
    """The elastic portal's step load with both integrators on this rank count (the explicit
    one unless ``explicit_run`` is False): the joint's drift peaks and the wall time of each.
    Returns the result dict (printed as JSON by main)."""
    implicit = portal_scene(cell_size, time_step, end_time, petsc=petsc, variant=variant,
                            implicit=implicit_options)
    explicit = dataclasses.replace(implicit, solver=dataclasses.replace(
        implicit.solver, integrator="explicit", scheme="musl", time_step=None, cfl=0.9, petsc={}))
    ti, ui, wall_i, steps_i, si = _joint_drift(None, implicit, 1)
    if explicit_run:
        te, ue, wall_e, steps_e, _ = _joint_drift(None, explicit, max(1, int(round(time_step / (0.9 * cell_size / 5.6e3)))))
    else:
        te, ue, wall_e, steps_e = ti, ui * np.nan, float("nan"), 0
    peaks = []
    for t, u in ((ti, ui), (te, ue)):
        i = int(np.argmax(u))
        peaks.append((float(t[i]), float(u[i])))
    return {"benchmark": "implicit_portal", "cell_size": cell_size, "time_step": time_step, "end_time": end_time,
            "ranks": MPI.COMM_WORLD.Get_size(), "implicit_wall_s": wall_i, "implicit_steps": steps_i,
            "variant": variant, "newton_iterations": si.scheme.stats["newton_iterations"],
            "halvings": si.scheme.stats["halvings"], "factorisations": si.scheme.stats["factorisations"],
            "explicit_wall_s": wall_e, "explicit_steps": steps_e,
            "implicit_peak_drift_m": peaks[0][1], "implicit_peak_time_s": peaks[0][0],
            "explicit_peak_drift_m": peaks[1][1], "explicit_peak_time_s": peaks[1][0],
            "peak_drift_difference": peaks[0][1] / peaks[1][1] - 1.0}


def main(argv=None):
    """``pmpm bench implicit [--cell 0.05] [--dt 1e-3] [--t-end 0.25]`` (or ``python -m
    pmpm.benchmarks.implicit ...``): the elastic portal with both integrators; figures, then one
    JSON line."""
    ap = argparse.ArgumentParser(prog="pmpm bench implicit", description=main.__doc__,
                                 epilog="With --scenes portal frame3-step frame3-record: implicit against explicit "
                                        "time to solution instead (pmpm.benchmarks.implicit_tts; "
                                        "pmpm bench implicit --scenes portal --help lists its options).")
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--t-end", type=float, default=0.25)
    ap.add_argument("--petsc", nargs="*", default=[], metavar="NAME=VALUE",
                    help="PETSc options of the implicit run, e.g. pc_type=cholesky")
    ap.add_argument("--implicit", nargs="*", default=[], metavar="KEY=VALUE",
                    help="[solver.implicit] keys of the implicit run, e.g. newton=modified")
    ap.add_argument("--implicit-only", action="store_true", help="skip the explicit run")
    ap.add_argument("--variant", default="elastic", choices=("elastic", "elastoplastic"))
    ap.add_argument("--static", action="store_true",
                    help="instead: one static step under the load (analysis = static), the joint's drift")
    a = ap.parse_args(argv)
    if a.static:
        return _static_portal(a)
    r = portal_benchmark(a.cell, a.dt, a.t_end, dict(o.split("=", 1) for o in a.petsc), not a.implicit_only,
                         a.variant, _implicit_keys(a.implicit))
    r["petsc"] = a.petsc
    r["implicit"] = a.implicit
    r = {k: (None if isinstance(v, float) and v != v else v) for k, v in r.items()}   # NaN: not run
    if MPI.COMM_WORLD.rank == 0:
        print(f"implicit ({a.variant}): {r['implicit_steps']} steps of {a.dt:g} s, {r['newton_iterations']} "
              f"Newton iterations, {r['factorisations']} factorisations, {r['halvings']} halvings, "
              f"{r['implicit_wall_s']:.1f} s wall ({r['implicit_wall_s'] / r['implicit_steps']:.3f} s a step); peak drift {r['implicit_peak_drift_m'] * 1e3:.3f} mm at "
              f"{r['implicit_peak_time_s']:.4f} s")
        if r["explicit_wall_s"] is not None:
            print(f"explicit: {r['explicit_steps']} steps, {r['explicit_wall_s']:.1f} s wall; peak drift "
                  f"{r['explicit_peak_drift_m'] * 1e3:.3f} mm at {r['explicit_peak_time_s']:.4f} s")
        print(json.dumps(r))


def _implicit_keys(pairs):
    """``KEY=VALUE`` strings as [solver.implicit] values (numbers, true/false, else strings)."""
    out = {}
    for pair in pairs:
        key, value = pair.split("=", 1)
        if value in ("true", "false"):
            out[key] = value == "true"
            continue
        try:
            out[key] = int(value)
        except ValueError:
            try:
                out[key] = float(value)
            except ValueError:
                out[key] = value
    return out


def _static_portal(a):
    """One static step of the portal under its load: the upper-left joint's drift (JSON line)."""
    scene = portal_scene(a.cell, 1.0, 1.0, variant=a.variant)
    scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, analysis="static"))
    s = build_solver(scene, MPI.COMM_WORLD)
    tr = Tracker(scene.output.track, s)
    start = time.perf_counter()
    s.step()
    k = [t.name for t in scene.output.track].index("upper_left_joint")
    drift = float(np.asarray(tr.sample())[k, 0])
    r = {"benchmark": "implicit_portal_static", "cell_size": a.cell, "variant": a.variant,
         "static_drift_m": drift, "newton_iterations": s.scheme.stats["newton_iterations"],
         "load_on_supports_N": [float(v) for v in s.scheme.held_force], "wall_s": time.perf_counter() - start}
    if MPI.COMM_WORLD.rank == 0:
        print(f"static ({a.variant}, {a.cell:g} m cells): drift {drift * 1e3:.2f} mm, "
              f"{r['newton_iterations']} Newton iterations, supports carry {r['load_on_supports_N']} N")
        print(json.dumps(r))


if __name__ == "__main__":
    main()
