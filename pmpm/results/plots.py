"""Plots of the structural results: section forces, reactions, utilisation, the hinge map
and the hysteresis loop of base shear against drift (matplotlib's Agg canvas, no pyplot)."""
import logging
import math

import h5py
import numpy as np

from pmpm.io.layout import frame_fields
from pmpm.io.plot import _legend
from pmpm.results.hinges import hinge_rows

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
        frames = frame_fields(f)  # either layout: x0 per frame, or once (pmpm.io.layout)
        field = frames["x0"] if "x0" in frames else frames["x"]
        return field[0] if field.shape[0] else np.zeros((0, 2))


#: up to this many cuts, each is labelled on the map with its name and times; beyond it (a
#: multi-storey frame has tens of cuts) the labels would cover the structure, so the cuts that
#: yield are numbered in the order they yield and listed beside the map
FULL_LABELS = 8


def plot_hinge_map(h5_path, sections, path, label):
    """The structure (particles at rest) with every cut marked by the time it first reaches
    My (open marker) and Mp (filled); cuts that reach neither are grey. With more than
    FULL_LABELS cuts, the yielding cuts are numbered in the order they yield (hinge_rows) and
    listed beside the map with their times and largest |M| / Mp."""
    pts = _outline(h5_path)
    rows = hinge_rows(sections)
    many = len(rows) > FULL_LABELS
    fig = _figure(figsize=(11, 5.5) if many else (8, 5))
    if many:
        fig.set_layout_engine(None)          # the map and its list are placed by hand
    ax = fig.add_axes([0.06, 0.1, 0.56, 0.8]) if many else fig.subplots()
    ax.scatter(pts[:, 0], pts[:, 1], s=0.3, color="0.8", rasterized=True)
    order = [r["name"] for r in rows if math.isfinite(r["t_My"]) or math.isfinite(r["t_Mp"])]
    width = max((len(n) for n in order), default=4)
    listing = [f"{'':>2} {'cut':<{width}} {'My ms':>6} {'Mp ms':>6}  |M|/Mp"]
    for r in rows:
        s = sections[r["name"]]
        c = np.asarray(s["attrs"]["center"])
        t_y, t_p = r["t_My"], r["t_Mp"]
        colour = "tab:red" if math.isfinite(t_p) else ("tab:orange" if math.isfinite(t_y) else "0.5")
        ax.plot(*c, "o", ms=7 if many else 9, color=colour, mfc=colour if math.isfinite(t_p) else "none", mew=2)
        times = [f"My at {t_y * 1e3:.1f} ms" if math.isfinite(t_y) else "My not reached",
                 f"Mp at {t_p * 1e3:.1f} ms" if math.isfinite(t_p) else "Mp not reached"]
        if not many:
            ax.annotate("\n".join([r["name"]] + times), c, xytext=(8, 8), textcoords="offset points", fontsize=7)
        elif r["name"] in order:
            k = order.index(r["name"]) + 1
            ax.annotate(str(k), c, xytext=(5, 5), textcoords="offset points", fontsize=8, weight="bold")
            when = [f"{x * 1e3:6.1f}" if math.isfinite(x) else "     -" for x in (t_y, t_p)]
            listing.append(f"{k:>2} {r['name']:<{width}} {when[0]} {when[1]}  {r['M/Mp']:.2f}")
    if many:
        quiet = len(rows) - len(order)
        listing.append(f"{quiet} of {len(rows)} cuts below My (grey)" if quiet else f"all {len(rows)} cuts reach My")
        fig.text(0.64, 0.9, "\n".join(listing), va="top", ha="left", fontsize=7, family="monospace")
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
