"""Plots of a run: histories of the tracked points, energies, deformed shapes.

Figures are drawn with matplotlib's Agg canvas directly (``matplotlib.figure.Figure``,
no pyplot), so plotting works without a display and never switches the backend of
a program that imported pmpm.

Energy balance error
--------------------
The balance is ``B = kinetic + internal_work + damping_work + viscous_damping_work +
removed_energy - external_work`` when an ``internal_work`` column (the integrated stress
power: stored strain energy plus dissipation) is present, else ``B = kinetic + strain_energy +
plastic_work + damping_work + viscous_damping_work + removed_energy - external_work`` (absent
terms count as zero), else the ``total`` column.  The
plotted error is ``(B - B[0]) / scale`` with ``scale`` the largest magnitude of the
energy held by the body (kinetic + internal) or of the external work, so 0.01 means
1 % of the energy in play.

Every axis is labelled with its quantity and SI unit (read from the file's ``units``
attributes, see :mod:`pmpm.io.schema`), and legends sit outside the axes, to the right,
so they never cover a curve.

Numerical loss
--------------
A file with a ``numerical_loss`` column (J: initial energy + external work - kinetic -
strain energy - plastic work - damping work, :func:`pmpm.core.solver.numerical_loss`) gets
it drawn dashed black among the energies, and below, beside the balance error, as a
fraction of the energy put in (:func:`numerical_loss_fraction`).
"""

from __future__ import annotations

import logging
import os

import h5py
import numpy as np

import pmpm.physics  # noqa: F401  (registers the energy terms)
from pmpm.core.effects import energy_terms
from pmpm.io import schema
from pmpm.io import ownership
from pmpm.io.hdf5 import read_attrs, read_energies, read_history
from pmpm.io.layout import frame_fields
from pmpm.scene.names import energies_png, history_png

__all__ = ["plot_results", "plot_deformed", "energy_balance_error", "energy_figure",
           "numerical_loss_fraction", "scene_stem"]

logger = logging.getLogger(__name__)

#: energy the body holds or dissipated inside the internal work (the registered terms done
#: inside it: plastic work, fracture work, ...), and the damping work
STORED = ("kinetic", "strain_energy", *[t.name for t in energy_terms() if not t.outside], "damping_work")
#: energy that left the body: dissipated by damping or carried out by removed particles (the
#: registered energy terms done outside the internal work, pmpm.core.effects)
LEFT = tuple(t.name for t in energy_terms() if t.outside)
DISPLACEMENTS = ("ux", "uy", "uz")


def _new_figure(**kwargs):
    """Return a new ``matplotlib.figure.Figure`` (imported here: only plotting pays for it)."""
    from matplotlib.figure import Figure as _Figure

    return _Figure(**kwargs)


def _label(path, attrs):
    """Return the legend label of a results file: its ``variant`` or its stem."""
    variant = attrs.get("variant")
    return str(variant) if variant else os.path.splitext(os.path.basename(path))[0]


def _file_stem(path):
    return os.path.splitext(os.path.basename(path))[0]


def scene_stem(h5_path):
    """The stem of the scene file that wrote a results file (its ``scene_file`` attribute),
    else the file's own stem: the prefix of the history plots, shared by a scene's variants."""
    scene_file = read_attrs(h5_path).get("scene_file")
    if isinstance(scene_file, str) and scene_file:
        return _file_stem(scene_file)
    return _file_stem(h5_path)


def _axis(name, units):
    """Return an axis label ``name (units)``; dimensionless quantities show ``(-)``."""
    if not units or units == schema.UNKNOWN:
        return name
    return f"{name} ({'-' if units == '1' else units})"


def _legend(ax):
    """Put the legend outside the axes, right of them, so it covers no curve."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small")


def _safe(name):
    """Return ``name`` usable in a file name."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in str(name))


def energy_balance_error(energies):
    """Return the relative energy balance error of each energy row.

    Parameters
    ----------
    energies : dict of str to numpy.ndarray
        Energy columns (as from :func:`pmpm.io.read_energies`).

    Returns
    -------
    numpy.ndarray or None
        ``(B - B[0]) / scale`` (see the module docs), or None when neither
        ``kinetic`` nor ``total`` is present or there are no rows.
    """
    n = len(energies.get("time", ()))
    if n == 0:
        return None
    columns = {k: np.asarray(v, dtype=float) for k, v in energies.items()}
    work = columns.get("external_work", np.zeros(n))
    if "kinetic" in columns:
        # internal_work, when given, already holds strain energy plus dissipation
        # and the energy taken out of the body (damping, removed particles) counts as held
        held_terms = (("internal_work",) if "internal_work" in columns else STORED[1:]) + LEFT
        held_terms = tuple(dict.fromkeys(held_terms))
        held = columns["kinetic"] + sum(columns[c] for c in held_terms if c in columns)
        balance = held - work
        scale = max(np.nanmax(np.abs(held)), np.nanmax(np.abs(work)))
    elif "total" in columns:
        balance = columns["total"]
        scale = np.nanmax(np.abs(balance))
    else:
        return None
    scale = scale if np.isfinite(scale) and scale > 0 else 1.0
    return (balance - balance[0]) / scale


def _plot_track(track, runs, outdir, stem):
    """Draw the displacement columns of one track, one panel each, all runs overlaid."""
    columns = next(cols for _, _, tracks, cols in runs if track in tracks)
    # Displacements are what a history is read for; other columns only without them
    columns = [c for c in columns if c in DISPLACEMENTS] or columns
    fig = _new_figure(figsize=(8, 2.2 * len(columns) + 0.6), layout="constrained")
    axes = fig.subplots(len(columns), 1, sharex=True, squeeze=False)[:, 0]
    for label, times, tracks, cols in runs:
        if track not in tracks:
            continue
        for ax, column in zip(axes, columns):
            if column in cols:
                ax.plot(times, tracks[track][:, cols.index(column)], label=label)
    for ax, column in zip(axes, columns):
        ax.set_ylabel(_axis(column, schema.meta(schema.HISTORY, column)[0]))
        ax.grid(True, alpha=0.3)
    axes[0].set_title(f"history of {track}")
    _legend(axes[0])
    axes[-1].set_xlabel(_axis("time", "s"))
    path = ownership.claim(os.path.join(outdir, history_png(stem, _safe(track))))
    fig.savefig(path, dpi=110)
    return path


def energy_figure(label, energies):
    """The energies figure of one run: every energy column against time (the numerical loss
    dashed black, ``numerical loss (J)``), and below the relative balance error and the
    numerical loss as a fraction of the energy put in (initial energy plus external work).

    Parameters
    ----------
    label : str
        The run's name in the title.
    energies : dict of str to numpy.ndarray
        Energy columns (as from :func:`pmpm.io.read_energies`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    time = energies["time"]
    fig = _new_figure(figsize=(8, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for name, values in energies.items():
        if name == "numerical_loss":
            top.plot(time, values, "k--", label=_axis("numerical loss", "J"))
        elif name != "time":
            top.plot(time, values, label=name)
    top.set_ylabel(_axis("energy", "J"))
    top.set_title(f"energies: {label}")
    _legend(top)
    top.grid(True, alpha=0.3)
    error = energy_balance_error(energies)
    if error is not None:
        bottom.plot(time, error, color="k", label="balance error")
    share = numerical_loss_fraction(energies)
    if share is not None:
        bottom.plot(time, share, "r--", label="numerical loss / energy put in")
    bottom.set_ylabel(_axis("relative to the energy in play", "1"))
    bottom.set_xlabel(_axis("time", "s"))
    bottom.grid(True, alpha=0.3)
    _legend(bottom)
    return fig


def numerical_loss_fraction(energies):
    """The ``numerical_loss`` column over the energy put in so far (initial energy plus external
    work, which by the loss's definition is the sum of the held, dissipated and lost terms);
    NaN where nothing was put in yet, None without the column.

    Parameters
    ----------
    energies : dict of str to numpy.ndarray
    """
    if "numerical_loss" not in energies:
        return None
    c = {k: np.asarray(v, dtype=float) for k, v in energies.items()}
    zero = np.zeros(len(c["numerical_loss"]))
    supplied = sum(c.get(k, zero) for k in dict.fromkeys(STORED + LEFT)) + c["numerical_loss"]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(supplied > 0, c["numerical_loss"] / supplied, np.nan)


def _plot_energies(label, energies, outdir, run):
    """Draw :func:`energy_figure` of one run into ``<run>_energies.png``."""
    fig = energy_figure(label, energies)
    path = ownership.claim(os.path.join(outdir, energies_png(_safe(run))))
    fig.savefig(path, dpi=110)
    return path


def plot_results(h5_paths, outdir):
    """Plot the track histories and the energies of one or more results files.

    Parameters
    ----------
    h5_paths : list of str or os.PathLike
        Results files; several files (e.g. elastic and elastoplastic variants of
        one scene) are overlaid in the history plots, labelled by their ``variant``
        attribute (else the file stem).  A track's plot shows its displacement
        columns (``ux``, ``uy``) against time, or every column if it has none.
    outdir : str or os.PathLike
        Folder for the PNG files (created if needed).

    Returns
    -------
    list of str
        ``<stem>_history_<track>.png`` for every track (``<stem>``: the scene file's stem
        of the first file, see :func:`scene_stem`), then ``<file stem>_energies.png`` for
        every file with energy rows.
    """
    outdir = os.fspath(outdir)
    runs, energy_runs = [], []
    paths = list(map(os.fspath, h5_paths))
    for path in paths:
        attrs = read_attrs(path)
        label = _label(path, attrs)
        times, tracks, columns = read_history(path)
        runs.append((label, times, tracks, columns))
        energy_runs.append((label, read_energies(path), _file_stem(path)))
    stem = _safe(scene_stem(paths[0]))
    track_names = list(dict.fromkeys(t for _, _, tracks, _ in runs for t in tracks))
    # every file is claimed before it is drawn: a foreign file of the same name stops the call
    # and takes back what it wrote (pmpm.io.ownership)
    with ownership.writing(stem):
        pngs = [_plot_track(track, runs, outdir, stem) for track in track_names]
        pngs += [_plot_energies(label, e, outdir, run) for label, e, run in energy_runs
                 if len(e.get("time", ()))]
    logger.info("wrote %d plots to %s", len(pngs), outdir)
    return pngs


def _color_values(frames, index, name):
    """Return (values, label) for ``name``: a field, or a component like ``sxx``."""
    if name in frames:
        values = frames[name][index].astype(float)
        if values.ndim > 1:
            # A multi-component field is coloured by its magnitude
            return np.sqrt(np.sum(values.reshape(len(values), -1) ** 2, axis=1)), f"|{name}|"
        return values, name
    for field, dset in frames.items():
        comps = [c.decode() if isinstance(c, bytes) else str(c) for c in dset.attrs.get("components", [])]
        if name in comps:
            return dset[index][:, comps.index(name)].astype(float), name
    raise KeyError(f"no frame field or component named {name!r}; fields: {sorted(frames)}")


def _units_of(frames, name):
    """Return the units of a frame field or of the field a component belongs to."""
    for field, dset in frames.items():
        comps = [c.decode() if isinstance(c, bytes) else str(c) for c in dset.attrs.get("components", [])]
        if field == name or name in comps:
            units = dset.attrs.get("units", schema.meta(schema.FIELDS, field)[0])
            return units.decode() if isinstance(units, bytes) else str(units)
    return ""


def plot_deformed(h5_path, frame_index, color_field, scale, out_png):
    """Draw the particles of one frame with magnified displacements.

    Parameters
    ----------
    h5_path : str or os.PathLike
        Results file.
    frame_index : int
        Frame to draw (negative counts from the end).
    color_field : str
        Frame field (multi-component fields by magnitude) or component name
        (``sxx``) giving the colour.
    scale : float
        Displacement magnification: particles are drawn at ``x0 + scale (x - x0)``
        with ``x0`` the ``x0`` field if present, else the frame-0 positions.
    out_png : str or os.PathLike
        Image to write.

    Returns
    -------
    str
        ``out_png``.
    """
    with h5py.File(h5_path, "r") as f:
        frames = frame_fields(f)  # either layout (pmpm.io.layout)
        time = float(f["frames/time"][frame_index])
        x = frames["x"][frame_index]
        x0 = frames["x0"][frame_index] if "x0" in frames else frames["x"][0]
        values, label = _color_values(frames, frame_index, color_field)
        units = _units_of(frames, color_field)
    pos = x0 + scale * (x - x0)
    alive = np.all(np.isfinite(pos), axis=1)
    fig = _new_figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    size = float(np.clip(2.0e4 / max(alive.sum(), 1), 0.5, 20.0))
    points = ax.scatter(pos[alive, 0], pos[alive, 1], c=values[alive], s=size, cmap="viridis",
                        linewidths=0)
    ax.set_aspect("equal")
    ax.set_xlabel(_axis("x", "m"))
    ax.set_ylabel(_axis("y", "m"))
    ax.set_title(f"t = {time:.6g} s, displacements x {scale:g}")
    fig.colorbar(points, ax=ax, label=_axis(label, units))
    with ownership.writing(scene_stem(h5_path)):
        fig.savefig(ownership.claim(os.fspath(out_png)), dpi=130)
    return os.fspath(out_png)
