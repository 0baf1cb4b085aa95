"""XDMF 3 sidecar that lets ParaView (Xdmf3 reader) open a results file directly.

The sidecar is a Temporal collection of Uniform grids, one per complete frame (finite
``/frames/time``).  Each grid has

- a Polyvertex topology over all ``n_total`` particles (one vertex cell each) whose
  connectivity is ``/topology/vertices``;
- an ``XY`` geometry: a HyperSlab of ``/frames/x`` (ParaView's Xdmf3 reader pads
  XY points with z = 0, so no 3-component copy of the positions is needed);
- one Attribute per frame field, each a HyperSlab DataItem into the HDF5 dataset:
  scalars as ``Scalar``; 2-vectors as ``Vector`` with Dimensions ``n 2`` (the Xdmf3
  reader takes the component count from the data, nvals / npoints, so it reads a
  2-component array); fields with other component counts (``stress`` with 4,
  ``strain`` with 3) as one ``Scalar`` per component, named from the dataset's
  ``components`` attribute (``sxx syy sxy szz``), each a strided HyperSlab.

Removed particles have NaN positions and are simply not drawn.  The HDF5 file name is
written relative to the sidecar, so the pair can be moved together.
"""

from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET

import h5py
import numpy as np

__all__ = ["write_xdmf", "xdmf_number_type"]

logger = logging.getLogger(__name__)


def xdmf_number_type(dtype):
    """Return the XDMF ``(NumberType, Precision)`` of a numpy dtype.

    Parameters
    ----------
    dtype : numpy.dtype
        Element type of an HDF5 dataset.

    Returns
    -------
    tuple of str

    Raises
    ------
    ValueError
        For types XDMF cannot describe (complex, strings, ...).
    """
    dtype = np.dtype(dtype)
    kinds = {"f": "Float", "i": "Int", "u": "UInt"}
    if dtype.kind not in kinds:
        raise ValueError(f"no XDMF number type for dtype {dtype}")
    name = kinds[dtype.kind]
    if dtype.itemsize == 1:
        name = "Char" if dtype.kind == "i" else "UChar"
    return name, str(dtype.itemsize)


def _dims(shape):
    """Return an XDMF Dimensions string."""
    return " ".join(str(int(s)) for s in shape)


def _heavy(parent, h5_name, dset):
    """Append the DataItem that names a whole HDF5 dataset."""
    number, precision = xdmf_number_type(dset.dtype)
    item = ET.SubElement(parent, "DataItem", Dimensions=_dims(dset.shape), NumberType=number,
                         Precision=precision, Format="HDF")
    item.text = f"{h5_name}:{dset.name}"
    return item


def _hyperslab(parent, h5_name, dset, start, count, result_shape):
    """Append a HyperSlab DataItem selecting ``count`` entries of ``dset`` from ``start``."""
    number, precision = xdmf_number_type(dset.dtype)
    slab = ET.SubElement(parent, "DataItem", ItemType="HyperSlab", Dimensions=_dims(result_shape),
                         NumberType=number, Precision=precision, Type="HyperSlab")
    select = ET.SubElement(slab, "DataItem", Dimensions=f"3 {len(start)}", NumberType="Int",
                           Format="XML")
    select.text = " ".join(_dims(row) for row in (start, (1,) * len(start), count))
    _heavy(slab, h5_name, dset)
    return slab


def _frame_slab(parent, h5_name, dset, frame, index=None):
    """Append the HyperSlab of frame ``frame`` (optionally one component ``index``)."""
    n, trailing = dset.shape[1], dset.shape[2:]
    if index is None:
        start, count = (frame, 0) + (0,) * len(trailing), (1, n) + trailing
        result = (n,) + trailing
    else:
        start, count = (frame, 0) + index, (1, n) + (1,) * len(trailing)
        result = (n,)
    return _hyperslab(parent, h5_name, dset, start, count, result)


def _component_labels(name, dset):
    """Return ``[(label, index)]`` for the components of a field written per component."""
    stored = [c.decode() if isinstance(c, bytes) else str(c) for c in dset.attrs.get("components", [])]
    indices = list(np.ndindex(*dset.shape[2:]))
    if len(stored) != len(indices):
        stored = [f"{name}_" + "_".join(map(str, idx)) for idx in indices]
    return list(zip(stored, indices))


def _attributes(grid, h5_name, frames, frame):
    """Append one Attribute (or one per component) for every frame field."""
    for name, dset in frames.items():
        if name in ("time", "step") or dset.ndim < 2:
            continue
        trailing = dset.shape[2:]
        if trailing in ((), (2,)):
            kind = "Scalar" if trailing == () else "Vector"
            attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=kind, Center="Node")
            _frame_slab(attr, h5_name, dset, frame)
            continue
        for label, index in _component_labels(name, dset):
            attr = ET.SubElement(grid, "Attribute", Name=label, AttributeType="Scalar", Center="Node")
            _frame_slab(attr, h5_name, dset, frame, index)


def _uniform_grid(collection, h5_name, f, frame, time):
    """Append the Uniform grid of one frame."""
    frames, n = f["frames"], f["frames/x"].shape[1]
    grid = ET.SubElement(collection, "Grid", Name=f"frame_{frame:05d}", GridType="Uniform")
    ET.SubElement(grid, "Time", Value=repr(float(time)))
    topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n),
                         NodesPerElement="1")
    _heavy(topo, h5_name, f["topology/vertices"])
    geom = ET.SubElement(grid, "Geometry", GeometryType="XY")
    _frame_slab(geom, h5_name, frames["x"], frame)
    _attributes(grid, h5_name, frames, frame)


def write_xdmf(h5_path, xdmf_path=None):
    """Write the XDMF 3 sidecar of a results file (serial; call on one rank).

    Parameters
    ----------
    h5_path : str or os.PathLike
        Results file written by :class:`pmpm.io.OutputFile`.
    xdmf_path : str or os.PathLike, optional
        Sidecar to write; default ``h5_path`` with the suffix ``.xdmf``.

    Returns
    -------
    str
        The sidecar's path.

    Raises
    ------
    ValueError
        If the file has no ``/frames/x`` (2-D positions) to use as geometry.
    """
    h5_path = os.fspath(h5_path)
    xdmf_path = os.fspath(xdmf_path) if xdmf_path else os.path.splitext(h5_path)[0] + ".xdmf"
    h5_name = os.path.relpath(os.path.abspath(h5_path), os.path.dirname(os.path.abspath(xdmf_path)))
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    collection = ET.SubElement(domain, "Grid", Name="particles", GridType="Collection",
                               CollectionType="Temporal")
    with h5py.File(h5_path, "r") as f:
        x = f.get("frames/x")
        if x is None or x.shape[2:] != (2,):
            raise ValueError(f"{h5_path} has no /frames/x of shape (F, n, 2) to use as geometry")
        times = f["frames/time"][()]
        for frame, time in enumerate(times):
            # A NaN time marks a frame cut short by a crash: leave it out
            if np.isfinite(time):
                _uniform_grid(collection, h5_name, f, frame, time)
    ET.indent(root)
    ET.ElementTree(root).write(xdmf_path, encoding="utf-8", xml_declaration=True)
    logger.info("wrote %s (%d frames)", xdmf_path, int(np.isfinite(times).sum()))
    return xdmf_path
