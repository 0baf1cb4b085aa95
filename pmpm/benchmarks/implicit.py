"""Scenes of the implicit integrator (docs/implicit.md): the fixed-free bar of design.md section 7
and a steel cantilever under gravity, as TOML data, for the tests (serial and MPI) and the
kernel warm-up."""
import math

from mpi4py import MPI

from pmpm.scene.config import parse_scene

__all__ = ["bar_scene", "cantilever_scene", "timoshenko_tip_deflection", "warm_implicit"]

#: the bar (design.md section 7): L = 25, E = 100, rho = 1, first mode omega = pi / 5, T = 10
BAR_L, BAR_OMEGA = 25.0, math.pi / 5
#: the bar's explicit step at CFL 0.5 with 0.5 cells: 0.5 * 0.5 / 10
BAR_CFL_STEP = 0.025
#: the cantilever: steel, L = 4 m, depth 0.4 m, unit thickness, clamped at x = 0
BEAM_L, BEAM_D, BEAM_E, BEAM_RHO, BEAM_NU, BEAM_Y0 = 4.0, 0.4, 2e11, 7850.0, 0.3, 0.8


def bar_scene(time_step, end_time, v0=0.001, cells=(54, 3), petsc=None):
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
    from pmpm.core.solver import Solver
    plastic = {"E": BEAM_E, "nu": BEAM_NU, "density": BEAM_RHO, "yield_stress": 250e6, "hardening": 0.05}
    scenes = [bar_scene(1.0, 2.0), cantilever_scene(h=0.2)]
    scenes += [cantilever_scene(h=0.2, material=dict(plastic, type=kind))
               for kind in ("bilinear_vonmises", "smooth_vonmises")]
    for scene in scenes:
        s = Solver(scene, MPI.COMM_SELF)
        s.step()
