"""Utilisation and plastic hinges of section cuts.

A cut's capacities come from the material it cuts, integrated by the cut's own band rule
(pmpm.results.sections), so they are those of the section the MPM model carries:

    Np = sigma_y A_cut,   My = sigma_y I_cut / c,   Mp = sigma_y Z_cut

with A_cut = sum phi V / b, I_cut = sum phi V eta^2 / b, Z_cut = sum phi V |eta| / b over the
cut's particles at set-up (eta measured from the cut's centre, c the half depth of an
i_section, else the largest |eta| plus half a particle spacing). For an i_section strip A_cut
and I_cut equal the W shape's (the strip's thicknesses are fitted to them) and Z_cut is within
about 1% of the tabulated plastic modulus. ``plastic_moment`` / ``yield_moment`` in the scene
replace the computed values. Without a yield stress (elastic materials) and without those
keys a cut has no capacities and no utilisation.

A section "reaches" My or Mp at the first output time at which |M| >= My or |M| >= Mp. With
hardening (the paper's 5%) and a smooth yield surface |M| passes Mp only when the section is
almost fully plastic; the time it does is what the hinge plot and table report.
"""
import logging
import math

import numpy as np

__all__ = ["cut_properties", "first_reached", "hinge_rows"]
logger = logging.getLogger(__name__)


def _yield_stress(scene, body_index):
    material = scene.materials[scene.bodies[body_index].material]
    value = material.get("yield_stress")
    return float(value) if value is not None else None


def cut_properties(cut, cfg, scene, points):
    """Dict of A, I, Z (m^2, m^4, m^3) and, when a yield stress or the scene's values give
    them, Np (N), My and Mp (N m) of ``cut`` from the scene's particles ``points``."""
    phi = cut.weights(points["x"], points["body"])
    sel = phi > 0
    w = phi[sel] * points["vol"][sel] / cut.width
    eta = (points["x"][sel] - cut.center) @ cut.tangent
    props = {"A": float(w.sum()), "I": float(np.sum(w * eta ** 2)), "Z": float(np.sum(w * np.abs(eta)))}
    bodies = np.unique(points["body"][sel])
    body = int(bodies[0])
    if scene.bodies[body].shape == "i_section":
        c = scene.bodies[body].geometry["depth"] / 2
    else:
        c = float(np.abs(eta).max()) + cut.spacing / 2
    sigma_y = _yield_stress(scene, body)
    if sigma_y is not None:
        props.update(sigma_y=sigma_y, Np=sigma_y * props["A"], My=sigma_y * props["I"] / c,
                     Mp=sigma_y * props["Z"])
    if cfg.plastic_moment is not None:
        props["Mp"] = cfg.plastic_moment
    if cfg.yield_moment is not None:
        props["My"] = cfg.yield_moment
    return props


def first_reached(t, values, limit):
    """First time at which |values| >= limit (NaN if never)."""
    hit = np.flatnonzero(np.abs(values) >= limit)
    return float(t[hit[0]]) if len(hit) else math.nan


def hinge_rows(sections):
    """Per cut: name, time of My and of Mp, max |M|/Mp, max |N|/Np, sorted by the Mp time
    (then the My time). ``sections`` maps name -> {"time", "N", "M", "attrs"}."""
    rows = []
    for name, s in sections.items():
        a = s["attrs"]
        if "Mp" not in a:
            continue
        rows.append({"name": name,
                     "t_My": first_reached(s["time"], s["M"], a["My"]) if "My" in a else math.nan,
                     "t_Mp": first_reached(s["time"], s["M"], a["Mp"]),
                     "M/Mp": float(np.nanmax(np.abs(s["M"])) / a["Mp"]),
                     "N/Np": float(np.nanmax(np.abs(s["N"])) / a["Np"]) if "Np" in a else math.nan})
    return sorted(rows, key=lambda r: (np.nan_to_num(r["t_Mp"], nan=np.inf),
                                       np.nan_to_num(r["t_My"], nan=np.inf)))
