"""Export a results file to other formats: VTU series (meshio) or the XDMF sidecar.

``fmt="vtu"`` writes, into ``<stem>_vtu/`` beside the file (or ``outdir``), one
``<stem>_NNNNN.vtu`` per complete frame, each holding the particles that exist in that
frame (finite position) as ``vertex`` cells with every frame field as point data (plus
``id``, the particle id, when it is not a frame field), and a ``<stem>.pvd`` collection
that ParaView opens as a time series.  Point data are named as in the XDMF sidecar:
scalars and 2-vectors (``x``, ``v``) by the field, other fields one array per named
component (``sxx syy sxy szz``, ``exx eyy gxy``), since VTU files written by meshio
cannot name the components of one array.

``fmt="xdmf"`` writes ``<stem>.xdmf`` into the file's folder (or ``outdir``), see
:mod:`pmpm.io.xdmf`.
"""

from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET

import h5py
import numpy as np

from pmpm.io import ownership
from pmpm.io.layout import frame_fields
from pmpm.io.xdmf import view_items, write_xdmf
from pmpm.io.plot import scene_stem

__all__ = ["export", "FORMATS"]

logger = logging.getLogger(__name__)

FORMATS = ("vtu", "xdmf")


def _frame_mesh(frames, index):
    """Return the meshio.Mesh of frame ``index`` (existing particles only)."""
    import meshio  # here, not at module level: only post-processing pays its import

    x = frames["x"][index]
    alive = np.flatnonzero(np.all(np.isfinite(x), axis=1))
    # VTU points are 3-D; pad here rather than let meshio warn on every file
    points = np.zeros((len(alive), 3))
    points[:, :2] = x[alive]
    data = {"id": alive.astype(np.int64)}
    for name, dset in frames.items():
        if dset.ndim >= 2:
            rows = dset[index][alive]
            for label, _, component in view_items(name, dset):
                data[label] = rows if component is None else rows[(slice(None),) + component]
    cells = [("vertex", np.arange(len(alive), dtype=np.int64)[:, None])]
    return meshio.Mesh(points, cells, point_data=data)


def _write_pvd(path, entries):
    """Write a ParaView collection of ``(time, file name)`` entries."""
    root = ET.Element("VTKFile", type="Collection", version="0.1")
    coll = ET.SubElement(root, "Collection")
    for time, name in entries:
        ET.SubElement(coll, "DataSet", timestep=repr(float(time)), group="", part="0", file=name)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def _check_vtu_folder(outdir, root):
    """The export folder through the gate, before anything is written: not a link (nor any
    folder on the way from ``root``), and, for the default folder (``root`` given), if it exists,
    a folder pmpm made: empty or holding pmpm's manifest (a user's folder of that name is not
    written into)."""
    ownership.check_target(os.path.join(outdir, ownership.MANIFEST), root)
    if os.path.islink(outdir):
        raise ownership.ForeignFileError(outdir, "is a symbolic link: pmpm never writes through a link")
    if os.path.lexists(outdir):
        if not os.path.isdir(outdir):
            raise ownership.ForeignFileError(outdir, "exists and is not a folder")
        # the default <stem>_vtu is pmpm's own folder; a folder the user names with -o is theirs
        # to share (each file in it is still claimed)
        made_by_pmpm = os.path.lexists(os.path.join(outdir, ownership.MANIFEST))
        if root is not None and os.listdir(outdir) and not made_by_pmpm:
            raise ownership.ForeignFileError(outdir, "exists and is not a folder pmpm made (it holds files "
                                                     f"but no {ownership.MANIFEST}): move it or give --outdir")
        ownership.check_manifest(outdir)


def _export_vtu(h5_path, outdir, root=None):
    """Write one VTU per complete frame and the PVD series; return their paths. ``root``: the
    folder ``outdir`` was made in (the results file's), below which no link is followed."""
    stem = os.path.splitext(os.path.basename(h5_path))[0]
    paths, entries = [], []
    _check_vtu_folder(outdir, root)
    with h5py.File(h5_path, "r") as f:
        frames = frame_fields(f)  # either layout, constants and ids per frame (pmpm.io.layout)
        if "x" not in frames:  # checked before anything is written
            raise ValueError(f"{h5_path}: has no /frames/x to use as particle positions")
        for index, time in enumerate(f["frames/time"][()]):
            if not np.isfinite(time):
                continue  # cut short by a crash
            name = f"{stem}_{index:05d}.vtu"
            path = ownership.claim(os.path.join(outdir, name), root)  # before it is written
            _frame_mesh(frames, index).write(path, file_format="vtu")
            paths.append(path)
            entries.append((time, name))
    pvd = ownership.claim(os.path.join(outdir, f"{stem}.pvd"), root)
    _write_pvd(pvd, entries)
    return paths + [pvd]


def export(h5_path, fmt="vtu", outdir=None):
    """Export a results file (serial; call on one rank).

    Parameters
    ----------
    h5_path : str or os.PathLike
        Results file written by :class:`pmpm.io.OutputFile`.
    fmt : {"vtu", "xdmf"}, optional
        ``"vtu"``: one VTU per frame plus a PVD series (default); ``"xdmf"``: the
        XDMF sidecar (:func:`pmpm.io.write_xdmf`).
    outdir : str or os.PathLike, optional
        Output folder; default ``<stem>_vtu`` beside the file for VTU, the file's
        own folder for XDMF.

    Returns
    -------
    list of str
        Files written; for VTU the frames in order, then the ``.pvd``.

    Raises
    ------
    ValueError
        For an unknown format.
    """
    h5_path = os.fspath(h5_path)
    stem, folder = os.path.splitext(h5_path)[0], os.path.dirname(h5_path)
    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r}; valid formats: {', '.join(FORMATS)}")
    # every file is claimed before it is written; a failure takes back the call's files and
    # the folders it made, so a failed export leaves nothing behind (pmpm.io.ownership)
    with ownership.writing(scene_stem(h5_path)):
        if fmt == "vtu":
            # the default folder lies in the results file's folder: no link on the way out of it
            paths = (_export_vtu(h5_path, os.fspath(outdir)) if outdir else
                     _export_vtu(h5_path, f"{stem}_vtu", root=folder or "."))
        else:
            target_dir = os.fspath(outdir) if outdir else folder
            with h5py.File(h5_path, "r") as f:
                if "frames/x" not in f:  # checked before the folder is made
                    raise ValueError(f"{h5_path}: has no /frames/x of shape (F, n, 2) to use as geometry")
            target = ownership.claim(os.path.join(target_dir or ".", os.path.basename(stem) + ".xdmf"))
            paths = [write_xdmf(h5_path, target)]
    logger.info("exported %s to %d %s files", h5_path, len(paths), fmt)
    return paths
