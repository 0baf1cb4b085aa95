"""Scenes of the implicit integrator's static analyses (docs/implicit.md, "Static analyses"): a
cantilever column pushed at its top by displacement control (``[pushover]`` under
``solver.analysis = "static"``), with its closed forms, for the tests (serial and MPI) and
studies/static_pushover.py.

The column: a steel strip of width ``COLUMN_B`` (unit thickness, plane stress), height
``COLUMN_L``, clamped on the grid's lower edge (fixed nodes at y = 0), its top node row held
along x at the pushed displacement (a ``roller_y`` boundary: y free, so the top rotates as a
cantilever's tip does). Elastic-perfectly-plastic J2 steel (``bilinear_vonmises`` with no
hardening: its consistent tangent makes Newton quadratic in the elastic range and fast where
it yields).
"""
import math
import os

from pmpm.scene.config import parse_scene, read_toml

__all__ = ["column_pushover_scene", "column_tip_stiffness", "column_collapse_load", "COLUMN_B", "COLUMN_L",
           "COLUMN_E", "COLUMN_NU", "COLUMN_SY", "portal_gravity_data", "portal_pushover_data",
           "column_load_factor_scene", "beam_column_drift", "column_plastic_moment", "COLUMN_LATERAL_ARM",
           "COLUMN_AXIAL_ARM"]

#: the column: width (m), pushed height (m), steel's E (Pa), nu, yield stress (Pa)
COLUMN_B, COLUMN_L, COLUMN_E, COLUMN_NU, COLUMN_SY = 0.4, 4.0, 200e9, 0.3, 250e6


def column_pushover_scene(displacement=0.2, steps=10, h=0.1, material="bilinear_vonmises", sections=True,
                          petsc=None, implicit=None, checkpoint_interval=None, folder=None, max_steps=None,
                          axis="auto"):
    """The column pushed by ``displacement`` (m) at its top in ``steps`` static steps of equal
    displacement (pseudo-time 1 s; no velocity ramp: the profile is linear), with its base
    reaction, the push's reaction, a section cut at 0.5 m and the top's track. ``folder``: the
    scene's place (its results in ``folder/results``); ``max_steps``: stop after so many;
    ``axis``: the slabs' axis (``"x"`` cuts the base and the pushed row across slabs)."""
    mat = {"type": material, "E": COLUMN_E, "nu": COLUMN_NU, "density": 7850.0}
    if material != "linear_elastic":
        mat.update(yield_stress=COLUMN_SY, hardening=0.0)
    x_left = -0.6 - COLUMN_B / 2
    data = {"title": "pushed column", "formulation": "plane_stress", "particles_per_cell": 2,
            "grid": {"origin": [x_left, 0.0], "cell_size": h,
                     "cells": [int(round(1.6 / h)), int(round((COLUMN_L + 0.6) / h))]},
            "materials": {"steel": mat},
            "bodies": [{"name": "column", "shape": "rectangle", "material": "steel",
                        "lower": [-COLUMN_B / 2, 0.0], "upper": [COLUMN_B / 2, COLUMN_L + h]}],
            "boundary": [{"name": "base", "type": "fixed", "lower": [x_left, 0.0], "upper": [1.0, 0.0],
                          "reaction": True, "moment_about": [0.0, 0.0]},
                         {"name": "push", "type": "roller_y", "lower": [-COLUMN_B / 2, COLUMN_L],
                          "upper": [COLUMN_B / 2, COLUMN_L], "reaction": True}],
            "pushover": {"boundary": "push", "displacement": displacement, "duration": 1.0, "ramp": 0.0,
                         "control": "top", "base": ["base"]},
            "solver": {"integrator": "implicit", "analysis": "static", "time_step": 1.0 / steps, "end_time": 1.0},
            "output": {"interval": 1.0, "history_interval": 1.0 / steps, "fields": ["x", "x0", "stress"],
                       "track": [{"name": "top", "point": [0.0, COLUMN_L]}]}}
    if sections:
        data["output"]["section"] = [{"name": "base_cut", "segment": [[-0.3, 0.5], [0.3, 0.5]]}]
    if checkpoint_interval is not None:
        data["output"]["checkpoint_interval"] = checkpoint_interval
    data["parallel"] = {"axis": axis}
    if max_steps is not None:
        data["solver"]["max_steps"] = max_steps
    if petsc:
        data["solver"]["petsc"] = dict(petsc)
    if implicit:
        data["solver"]["implicit"] = dict(implicit)
    if folder is not None:
        data["output"]["directory"] = os.path.join(folder, "results")
    return parse_scene(data, os.path.join(folder or ".", "column.toml"))


def column_tip_stiffness():
    """Force per tip displacement of the clamped column (Timoshenko: bending L^3 / (3 E I) plus
    shear L / (kappa G A), kappa = 5/6, unit thickness)."""
    inertia = COLUMN_B ** 3 / 12
    shear = COLUMN_E / (2 * (1 + COLUMN_NU))
    return 1.0 / (COLUMN_L ** 3 / (3 * COLUMN_E * inertia) + COLUMN_L / (5 / 6 * shear * COLUMN_B))


def column_collapse_load(arm=COLUMN_L):
    """The plastic collapse load Mp / arm of the cantilever (one hinge at the base):
    Mp = sigma_y b^2 / 4 of the rectangle (unit thickness)."""
    return COLUMN_SY * COLUMN_B ** 2 / 4 / arm


def _portal_data(cell_size, root="."):
    """cases/portal_pushover.toml's data (the portal frame with its base reactions and cuts) on
    ``cell_size`` cells, a static implicit run, without checkpoints and plots."""
    data = read_toml(os.path.join(root, "cases", "portal_pushover.toml"))
    data["grid"]["cell_size"] = cell_size
    data["grid"]["cells"] = [int(round(7.1 / cell_size)), int(round(4.2 / cell_size))]
    for key in ("checkpoint_interval", "deformed_plot"):
        data["output"].pop(key, None)
    # the pushed node row on the grid line nearest the beam's axis (3.658 m)
    y = round(3.658 / cell_size) * cell_size
    push = next(b for b in data["boundary"] if b["name"] == "push")
    push["lower"], push["upper"] = [push["lower"][0], y], [push["upper"][0], y]
    return data


def portal_gravity_data(cell_size=0.1, root="."):
    """The elastic portal under its own weight in one static step (TOML data)."""
    data = _portal_data(cell_size, root)
    data.pop("pushover")
    data["boundary"] = [b for b in data["boundary"] if b["name"] != "push"]
    data["output"].pop("hysteresis", None)
    data["materials"]["steel"] = {"type": "linear_elastic", "E": 207e9, "nu": 0.3, "density": 7850.0}
    data["output"].update(fields=["x", "x0", "stress"], history_interval=1.0)
    data["loads"] = {"gravity": [0.0, -9.81]}
    data["solver"] = {"shape_function": "cubic", "integrator": "implicit", "analysis": "static",
                      "time_step": 1.0, "end_time": 1.0}
    return data


def portal_pushover_data(cell_size=0.05, displacement=0.02, steps=4, material=None, root="."):
    """cases/portal_pushover.toml pushed ``displacement`` statically in ``steps`` equal steps
    (pseudo-time 1 s, no ramps), ``material`` (a [materials.steel] table) or the case's."""
    data = _portal_data(cell_size, root)
    if material is not None:
        data["materials"]["steel"] = dict(material)
        if material["type"] == "linear_elastic":
            data["output"]["fields"] = ["x", "x0", "stress"]
    data["pushover"].update(displacement=displacement, duration=1.0, ramp=0.0)
    data["output"].update(history_interval=1.0 / steps, interval=1.0)
    data["solver"] = {"shape_function": "cubic", "integrator": "implicit", "analysis": "static",
                      "time_step": 1.0 / steps, "end_time": 1.0}
    return data


#: heights of the load bands' centroids in :func:`column_load_factor_scene` at 0.1 m cells (2 x 2
#: points a cell: rows at h/4 and 3h/4 of the band): the lateral pattern, the axial load
COLUMN_LATERAL_ARM, COLUMN_AXIAL_ARM = COLUMN_L + 0.05, COLUMN_L - 0.05


def beam_column_drift(H, N, z=None, a=None, b=None):
    """The lateral displacement at height ``z`` (default: ``a``) of the clamped elastic column
    under a lateral load ``H`` at height ``a`` and a compression ``N`` at height ``b`` <= a
    (defaults: the load bands' of :func:`column_load_factor_scene`), unit thickness.

    Second-order Euler-Bernoulli on 0..b with k = sqrt(N / EI): a tip shear H gives the
    displacement H A and the slope H B, a tip moment M0 the displacement M0 B and the slope
    M0 C, A = (tan kb - kb) / (N k), B = (1 / cos kb - 1) / N, C = tan kb / (k EI); above b
    the column carries H alone (the tip moment at b is M0 = H (a - b)): a cantilever of length
    a - b on the slope there. Plus the shear flexibility H a / (kappa G A), kappa = 5/6. Above
    ``a`` the column is straight. N = 0: Timoshenko's cantilever."""
    a = COLUMN_LATERAL_ARM if a is None else a
    b = COLUMN_AXIAL_ARM if b is None else b
    z = a if z is None else z
    EI = COLUMN_E * COLUMN_B ** 3 / 12
    shear = H * a / (5 / 6 * COLUMN_E / (2 * (1 + COLUMN_NU)) * COLUMN_B)
    c = a - b
    M0 = H * c
    if N == 0.0:
        ub, tb = H * b ** 3 / (3 * EI) + M0 * b ** 2 / (2 * EI), H * b ** 2 / (2 * EI) + M0 * b / EI
    else:
        k = (N / EI) ** 0.5
        kb = k * b
        A = (math.tan(kb) - kb) / (N * k)
        B = (1 / math.cos(kb) - 1) / N
        C = math.tan(kb) / (k * EI)
        ub, tb = H * A + M0 * B, H * B + M0 * C
    tip = ub + tb * c + H * c ** 3 / (3 * EI)
    slope = tb + H * c ** 2 / (2 * EI)
    return tip + shear + (z - a) * slope


def column_plastic_moment(N=0.0):
    """Plastic moment of the column's rectangle (unit thickness) under the axial force N:
    Mp (1 - (N / Np)^2), Mp = sigma_y b^2 / 4, Np = sigma_y b."""
    return COLUMN_SY * COLUMN_B ** 2 / 4 * (1 - (N / (COLUMN_SY * COLUMN_B)) ** 2)


def column_load_factor_scene(control="arc_length", steps=20, h=0.1, axial=0.0, lateral=1e6, material="bilinear_vonmises",
                             displacement=0.3, increment=0.1, max_load_factor=None, target_iterations=4,
                             axis="auto", implicit=None, stop_drift=None, hardening=0.0):
    """The clamped column of :func:`column_pushover_scene` (base on the grid's lower edge, top
    free) under a lateral load pattern (``lateral`` N along +x, a force set on the particles of
    the band y in [L, L + h]) scaled by the load factor, and an axial load ``axial`` N (down, a
    force set on the band y in [L - h, L], held at its value: outside the pattern), under
    ``control`` = ``"arc_length"`` (first step's load factor ``increment``) or
    ``"displacement"`` (the x displacement of the particle nearest (h/4, L + h/4) reaches
    ``displacement`` at the end). Tracks (particles): ``lateral`` (h/4, L + h/4), ``axial``
    (h/4, L - h/4), ``low`` (h/4, 2 h + h/4). ``stop_drift``: end the run when ``lateral``'s
    drift passes it."""
    mat = {"type": material, "E": COLUMN_E, "nu": COLUMN_NU, "density": 7850.0}
    if material != "linear_elastic":
        mat.update(yield_stress=COLUMN_SY, hardening=hardening)
    x_left = -0.6 - COLUMN_B / 2
    half = COLUMN_B / 2
    # the axial load on the row of cells below the top one, the lateral on the top row: an
    # axial load of 75 MPa on the free top row's corner particles (a corner of two free edges,
    # whose nodes carry the cubic splines' tails) crushed them once the top had rotated
    forces = [{"name": "lateral", "body": "column", "lower": [-half, COLUMN_L + 1e-9 * h],
               "upper": [half, COLUMN_L + h], "force": [lateral, 0.0]}]
    if axial:
        forces.append({"name": "axial", "body": "column", "lower": [-half, COLUMN_L - h],
                       "upper": [half, COLUMN_L], "force": [0.0, -axial]})
    static = {"control": control, "pattern": ["lateral"]}
    if control == "arc_length":
        static.update(load_factor_increment=increment, target_iterations=target_iterations)
    else:
        static.update(point=[h / 4, COLUMN_L + h / 4], component="x", displacement=displacement)
    if max_load_factor is not None:
        static["max_load_factor"] = max_load_factor
    data = {"title": "column under a lateral load pattern", "formulation": "plane_stress", "particles_per_cell": 2,
            "grid": {"origin": [x_left, 0.0], "cell_size": h,
                     "cells": [int(round(1.6 / h)), int(round((COLUMN_L + 0.6) / h))]},
            "materials": {"steel": mat},
            "bodies": [{"name": "column", "shape": "rectangle", "material": "steel",
                        "lower": [-half, 0.0], "upper": [half, COLUMN_L + h]}],
            "boundary": [{"name": "base", "type": "fixed", "lower": [x_left, 0.0], "upper": [1.0, 0.0],
                          "reaction": True, "moment_about": [0.0, 0.0]}],
            "loads": {"forces": forces},
            "solver": {"integrator": "implicit", "analysis": "static", "time_step": 1.0 / steps, "end_time": 1.0,
                       "static": static},
            "output": {"interval": 1.0, "history_interval": 1.0 / steps, "fields": ["x", "x0", "stress"],
                       # particles (2 x 2 a cell): the rows nearest the two load bands' centroids
                       # and the row 2 h above the base, at x = h / 4
                       "track": [{"name": "lateral", "point": [h / 4, COLUMN_L + h / 4]},
                                 {"name": "axial", "point": [h / 4, COLUMN_L - h / 4]},
                                 {"name": "low", "point": [h / 4, 2 * h + h / 4]}]},
            "parallel": {"axis": axis}}
    if implicit:
        data["solver"]["implicit"] = dict(implicit)
    if stop_drift is not None:   # [[stop]]: the run ends when the lateral band's drift passes it
        data["stop"] = [{"track": "lateral", "quantity": "ux", "above": stop_drift}]
    return data
