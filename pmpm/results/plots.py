"""Plots of the structural results: section forces, reactions, utilisation, the hinge map
and the hysteresis loop of base shear against drift (matplotlib's Agg canvas, no pyplot)."""
import logging
import math

import h5py
import numpy as np

from pmpm.io.plot import _legend
from pmpm.results.hinges import first_reached

__all__ = ["plot_sections", "plot_reactions", "plot_utilisation", "plot_hinge_map", "plot_hysteresis"]
logger = logging.getLogger(__name__)


def _figure(**kwargs):
    from matplotlib.figure import Figure
    return Figure(layout="constrained", **kwargs)


def _panels(tables, columns, labels, path, title):
    fig = _figure(figsize=(8.5, 2.2 * len(columns) + 0.6))
    axes = fig.subplots(len(columns), 1, sharex=True, squeeze=False)[:, 0]
    for name, table in tables.items():
        for ax, c, scale in zip(axes, columns, labels):
            ax.plot(table["time"], table[c] / scale[1], label=name)
    for ax, (label, _) in zip(axes, labels):
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].set_title(title)
    _legend(axes[0])  # outside the axes, right of them: it covers no curve
    axes[-1].set_xlabel("time (s)")
    fig.savefig(path, dpi=110)
    return path


def plot_sections(sections, path, label):
    """N, V, M of every cut against time."""
    return _panels(sections, ("N", "V", "M"), (("N (kN)", 1e3), ("V (kN)", 1e3), ("M (kN m)", 1e3)),
                   path, f"section forces: {label}")


def plot_reactions(reactions, path, label):
    """Rx, Ry, M of every reaction against time."""
    return _panels(reactions, ("Rx", "Ry", "M"), (("Rx (kN)", 1e3), ("Ry (kN)", 1e3), ("M (kN m)", 1e3)),
                   path, f"support reactions: {label}")


def plot_utilisation(sections, path, label):
    """|M|/Mp and |N|/Np of the cuts with capacities; My/Mp marked."""
    fig = _figure(figsize=(8.5, 5))
    top, bottom = fig.subplots(2, 1, sharex=True)
    for name, s in sections.items():
        a = s["attrs"]
        if "Mp" not in a:
            continue
        top.plot(s["time"], np.abs(s["M"]) / a["Mp"], label=name)
        if "Np" in a:
            bottom.plot(s["time"], np.abs(s["N"]) / a["Np"], label=name)
    top.axhline(1.0, color="k", lw=0.8)
    top.set_ylabel("|M| / Mp")
    bottom.set_ylabel("|N| / Np")
    bottom.set_xlabel("time (s)")
    top.set_title(f"utilisation: {label}")
    _legend(top)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)
    return path


def _outline(h5_path):
    with h5py.File(h5_path, "r") as f:
        name = "x0" if "frames/x0" in f else "x"
        return f[f"frames/{name}"][0] if f[f"frames/{name}"].shape[0] else np.zeros((0, 2))


def plot_hinge_map(h5_path, sections, path, label):
    """The structure (particles at rest) with every cut marked by the time it first reaches
    My (open marker) and Mp (filled); cuts that reach neither are grey."""
    pts = _outline(h5_path)
    fig = _figure(figsize=(8, 5))
    ax = fig.subplots()
    ax.scatter(pts[:, 0], pts[:, 1], s=0.3, color="0.8", rasterized=True)
    for name, s in sections.items():
        a = s["attrs"]
        if "Mp" not in a:
            continue
        c = np.asarray(a["center"])
        t_y = first_reached(s["time"], s["M"], a["My"]) if "My" in a else math.nan
        t_p = first_reached(s["time"], s["M"], a["Mp"])
        colour = "tab:red" if math.isfinite(t_p) else ("tab:orange" if math.isfinite(t_y) else "0.5")
        ax.plot(*c, "o", ms=9, color=colour, mfc=colour if math.isfinite(t_p) else "none", mew=2)
        text = [name]
        text.append(f"My at {t_y * 1e3:.1f} ms" if math.isfinite(t_y) else "My not reached")
        text.append(f"Mp at {t_p * 1e3:.1f} ms" if math.isfinite(t_p) else "Mp not reached")
        ax.annotate("\n".join(text), c, xytext=(8, 8), textcoords="offset points", fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"sections reaching My (open) and Mp (filled): {label}")
    fig.savefig(path, dpi=110)
    return path


def plot_hysteresis(h5_path, reactions, spec, path, label):
    """Base shear (minus the sum of the listed reactions' Rx, or Ry for ``uy``: the load the
    supports resist) against the tracked displacement."""
    names = spec.get("reactions") or list(reactions)
    column = "Rx" if spec.get("component", "ux") == "ux" else "Ry"
    shear = -sum(reactions[n][column] for n in names if n in reactions)
    with h5py.File(h5_path, "r") as f:
        cols = [c.decode() if isinstance(c, bytes) else str(c) for c in f["history"].attrs["columns"]]
        drift = f["history"][spec["track"]][:, cols.index(spec.get("component", "ux"))]
    n = min(len(drift), len(shear))
    fig = _figure(figsize=(6, 5))
    ax = fig.subplots()
    ax.plot(drift[:n] * 1e3, shear[:n] / 1e3, lw=0.8)
    ax.set_xlabel(f"{spec['track']} {spec.get('component', 'ux')} (mm)")
    ax.set_ylabel("base shear (kN)")
    ax.set_title(f"hysteresis: {label}")
    ax.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)
    return path
