"""The capacity curve of a pushover (pmpm.physics.pushover): base shear against drift.

From a results file alone: the base shear is minus the sum of the base reactions' component
along the push (``Rx`` for a push along x: the load the supports resist), the drift the
control track's displacement along the push, both sampled with the histories (a reaction row
is the mean over the interval ending at its time: docs/structural_results.md). Marked on the
curve, from the section cuts (pmpm.results.hinges):

- first yield: the first sample at which a cut's moment, carried to its member's nearer end,
  reaches My;
- mechanism: the sample at which the ``hinges``-th cut's moment carried to the member end
  reaches ``hinge_fraction`` Mp (``[pushover] hinges``, without it the last cut that does;
  ``hinge_fraction`` default 1). With the paper's 5% hardening the portal's four hinges reach Mp
  at 81 mm of drift, past the curve's knee (docs/structural_results.md). Without hardening a
  smooth yield surface (N = 10) approaches Mp only asymptotically and the beams' axial force
  (0.17 Np in the portal's pushover) lowers their plastic moment by a few per cent: there the
  carried moments end between 0.90 and 1.04 Mp while the base shear stays within 1% of the
  collapse load, and a fraction below 1 (0.9) marks the mechanism.

The moment at the member end is abs(M) + a abs(V), a the cut's distance from the nearer end of
its body (the short piece's inertia neglected; docs/structural_results.md uses the same): the
cuts sit a few cells from the supports and joints, whose disturbance they avoid
(cases/portal_frame.toml), while the hinges of a sway mechanism form at the member ends, where
the moment is largest. A cut given by a segment has a = 0.

Reported with them: the initial stiffness, the least-squares slope through the origin of base
shear against drift over the samples after the first velocity ramp (at constant push velocity
nothing accelerates; the ramp rings the members) and below 60% of the first-yield base shear,
the peak base shear, and the quasi-static check, the largest ratio kinetic / (strain energy +
plastic work) after the first ramp.

Files (``<stem>`` the results file's): ``<stem>_capacity.csv`` with columns
``t, drift, base_shear, kinetic_ratio`` (s, m, N, -) and ``<stem>_capacity.png``.
"""
import json
import logging
import math
import os

import h5py
import numpy as np

from pmpm.io import ownership
from pmpm.results.hinges import hinge_rows
from pmpm.io.hdf5 import read_energies, read_history
from pmpm.results.recorder import read_tables

__all__ = ["capacity_curve", "write_capacity", "pushover_spec"]
logger = logging.getLogger(__name__)

#: the initial stiffness is fitted below this fraction of the base shear at first yield
ELASTIC_FRACTION = 0.6


def pushover_spec(h5_path):
    """The ``[pushover]`` table of the scene that wrote ``h5_path`` (None if it had none)."""
    with h5py.File(h5_path, "r") as f:
        scene = json.loads(f.attrs["scene"]) if "scene" in f.attrs else {}
    return scene.get("pushover")


def capacity_curve(h5_path, spec=None):
    """Capacity curve and its marks from a results file.

    Returns
    -------
    dict
        ``t``, ``drift`` (m), ``base_shear`` (N), ``kinetic_ratio`` arrays; ``first_yield`` and
        ``mechanism`` (dicts of t, drift, base_shear, cut; None if never reached),
        ``initial_stiffness`` (N/m, NaN without quasi-static elastic samples),
        ``peak_base_shear`` (N), ``max_kinetic_ratio`` (after the first ramp).
    """
    spec = spec or pushover_spec(h5_path)
    with h5py.File(h5_path, "r") as f:
        scene = json.loads(f.attrs["scene"])
    bc = next(b for b in scene["boundaries"] if b["name"] == spec["boundary"])
    axis = 0 if bc["type"] == "roller_y" else 1
    times, tracks, columns = read_history(h5_path)
    drift = tracks[spec["control"]][:, columns.index("ux" if axis == 0 else "uy")]
    tables = read_tables(h5_path)
    comp = "Rx" if axis == 0 else "Ry"
    n = min(len(drift), *(len(tables["reactions"][b][comp]) for b in spec["base"]))
    shear = -sum(np.asarray(tables["reactions"][b][comp][:n]) for b in spec["base"])
    t, drift = times[:n], drift[:n]
    e = read_energies(h5_path)
    held = np.asarray(e["strain_energy"][:n]) + np.asarray(e["plastic_work"][:n])
    ratio = np.where(held > 0, np.asarray(e["kinetic"][:n]) / np.where(held > 0, held, 1.0), np.inf)
    rows = hinge_rows(_carried_to_ends(tables["sections"], scene))
    out = {"t": t, "drift": drift, "base_shear": shear, "kinetic_ratio": ratio,
           "first_yield": None, "mechanism": None, "hinge_fraction": spec.get("hinge_fraction", 1.0)}

    def mark(time, cut):
        k = int(np.argmin(np.abs(t - time)))
        return {"t": float(t[k]), "drift": float(drift[k]), "base_shear": float(shear[k]), "cut": cut}
    yielded = sorted((r["t_My"], r["name"]) for r in rows if math.isfinite(r["t_My"]))
    if yielded:
        out["first_yield"] = mark(*yielded[0])
    fraction = spec.get("hinge_fraction", 1.0)
    hinge_at = {r["name"]: r for r in hinge_rows(_carried_to_ends(tables["sections"], scene, 1.0 / fraction))}
    hinged = sorted((r["t_Mp"], r["name"]) for r in hinge_at.values() if math.isfinite(r["t_Mp"]))
    want = spec.get("hinges")
    if hinged and (want is None or len(hinged) >= want):
        out["mechanism"] = mark(*hinged[(want or len(hinged)) - 1])
        out["mechanism"]["hinges"] = [name for _, name in hinged[:want or len(hinged)]]
    after_ramp = (t >= spec["ramp"]) & np.isfinite(shear)
    elastic = after_ramp.copy()
    if out["first_yield"] is not None:
        elastic &= np.abs(shear) <= ELASTIC_FRACTION * abs(out["first_yield"]["base_shear"])
    d, v = drift[elastic], shear[elastic]
    out["initial_stiffness"] = float(np.dot(d, v) / np.dot(d, d)) if len(d) and np.dot(d, d) > 0 else math.nan
    out["elastic_samples"] = int(elastic.sum())
    out["peak_base_shear"] = float(np.nanmax(np.abs(shear))) if n else math.nan
    out["max_kinetic_ratio"] = float(np.max(ratio[after_ramp])) if after_ramp.any() else math.nan
    return out


def _carried_to_ends(sections, scene, scale=1.0):
    """The section tables with M replaced by abs(M) + a abs(V) (module doc), times ``scale``."""
    bodies = {b["name"]: b for b in scene["bodies"]}
    cuts = {c["name"]: c for c in scene["output"].get("sections") or ()}
    out = {}
    for name, table in sections.items():
        cfg = cuts.get(name, {})
        a = 0.0
        body = bodies.get(cfg.get("body"))
        if body is not None and cfg.get("position") is not None:
            length = float(np.hypot(*np.subtract(body["geometry"]["end"], body["geometry"]["start"])))
            a = min(cfg["position"], length - cfg["position"])
        out[name] = dict(table, M=scale * (np.abs(table["M"]) + a * np.abs(table["V"])))
    return out


def write_capacity(h5_path, outdir, label=None):
    """``<stem>_capacity.csv`` and ``<stem>_capacity.png``; returns their paths. Call it inside
    ``pmpm.io.ownership.writing`` (as ``pmpm.results.post.structural_outputs`` does)."""
    spec = pushover_spec(h5_path)
    if spec is None:
        return []
    c = capacity_curve(h5_path, spec)
    stem = os.path.splitext(os.path.basename(h5_path))[0]
    # claimed before written (pmpm.io.ownership: inside the caller's ``ownership.writing``)
    csv = ownership.claim(os.path.join(outdir, f"{stem}_capacity.csv"))
    np.savetxt(csv, np.column_stack([c["t"], c["drift"], c["base_shear"], c["kinetic_ratio"]]), delimiter=",",
               header="t,drift,base_shear,kinetic_ratio", comments="", fmt="%.9g")
    png = ownership.claim(os.path.join(outdir, f"{stem}_capacity.png"))
    plot_capacity(c, png, label or stem)
    logger.info("capacity curve: initial stiffness %.4g N/m, peak base shear %.4g N, kinetic / (strain + "
                "plastic) <= %.3g after the first ramp%s%s", c["initial_stiffness"], c["peak_base_shear"],
                c["max_kinetic_ratio"],
                f"; first yield ({c['first_yield']['cut']}) at {c['first_yield']['base_shear']:.4g} N" if c["first_yield"] else "",
                f"; mechanism at {c['mechanism']['base_shear']:.4g} N" if c["mechanism"] else "")
    return [csv, png]


def plot_capacity(c, path, label, extra=None):
    """Draw a capacity curve (from ``capacity_curve``) with its marks; ``extra``: (label,
    base shear in N) horizontal reference lines."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(7, 5), layout="constrained")
    ax = fig.subplots()
    ax.plot(c["drift"] * 1e3, c["base_shear"] / 1e3, lw=1.0, color="C0", label="base shear")
    if math.isfinite(c["initial_stiffness"]):
        d = np.array([0.0, np.nanmax(c["drift"]) * 0.35])
        ax.plot(d * 1e3, c["initial_stiffness"] * d / 1e3, ls=":", color="0.4",
                label=f"initial stiffness {c['initial_stiffness'] / 1e6:.3g} MN/m")
    for key, style, text in (("first_yield", dict(marker="o", mfc="white"), "first yield"),
                             ("mechanism", dict(marker="s"), "mechanism")):
        m = c[key]
        if m is not None:
            ax.plot(m["drift"] * 1e3, m["base_shear"] / 1e3, ls="none", ms=8, color="C3", **style,
                    label=f"{text}: {m['base_shear'] / 1e3:.0f} kN at {m['drift'] * 1e3:.0f} mm ("
                          + (f"{m['cut']} at My)" if key == "first_yield" else
                             f"{len(m['hinges'])} cuts at {c['hinge_fraction']:g} Mp)"))
    for text, value in extra or ():
        ax.axhline(value / 1e3, ls="--", color="C2", lw=0.8, label=text)
    ax.set_xlabel("drift of the control point (mm)")
    ax.set_ylabel("base shear (kN)")
    ax.set_title(f"capacity curve: {label}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.savefig(path, dpi=110)
    return path
