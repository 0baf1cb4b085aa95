"""The results layout of pmpm before issue 40 (``pmpm-results-2``), written for comparison.

:func:`write_layout2` writes a results file of the current layout again as pmpm before issue 40
wrote it: every field, ``id`` and the constants included, in every frame, in the solver's
float64 (integers as stored), uncompressed, chunked one frame at a time of at most 1 MB as
that writer chunked it, with the sidecar's per-frame views. Two users: the tests, which check
that ``pmpm plot``, ``export`` and :func:`pmpm.load_results` still read such a file (and that a
restart refuses to append to it), and studies/output_size.py, which measures the size the old
writer gave for the same run (its input written at ``output.precision = "double"``, so nothing
is lost on the way).
"""
from __future__ import annotations

import logging
import os

import h5py
import numpy as np

from pmpm.io.layout import OLD_LAYOUTS, PARTICLES, fill_of, frame_fields
from pmpm.io.xdmf import write_views

__all__ = ["write_layout2"]

logger = logging.getLogger(__name__)

#: the old writer's chunk size bound (bytes of one chunk of one frame)
_OLD_CHUNK_BYTES = 1 << 20


def _old_dataset(frames, name, field, n_frames):
    """``/frames/<name>`` as the old writer created it, holding ``field`` (a FrameField)."""
    trailing = field.shape[2:]
    dtype = np.dtype(np.float64) if field.dtype.kind == "f" else field.dtype
    row_bytes = int(np.prod(trailing, dtype=np.int64)) * dtype.itemsize
    n = field.shape[1]
    rows = max(1, min(n, _OLD_CHUNK_BYTES // max(row_bytes, 1)))
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
    dset = frames.create_dataset(name, (n_frames, n) + trailing, dtype, maxshape=(None, n) + trailing,
                                 chunks=(1, rows) + trailing, dcpl=dcpl, fillvalue=fill_of(dtype),
                                 fill_time="never")
    for key, value in field.attrs.items():
        dset.attrs[key] = value
    if name == "id":
        dset.attrs["units"] = "1"
        dset.attrs["description"] = "particle id; row i of every frame field is the particle with id i"
    for k in range(n_frames):
        dset[k] = field[k]


def write_layout2(src, dst, views=True):
    """Write the results file ``src`` (any readable layout) to ``dst`` in layout ``pmpm-results-2``.

    Parameters
    ----------
    src, dst : str or os.PathLike
        Results file to read; file to create (replaced if it exists: a caller's scratch file).
    views : bool, optional
        Add the sidecar's per-frame virtual datasets, as a run of the old pmpm did.

    Returns
    -------
    str
        ``dst``.
    """
    dst = os.fspath(dst)
    with h5py.File(src, "r") as f, h5py.File(dst, "w") as g:
        for key, value in f.attrs.items():
            g.attrs[key] = value
        g.attrs["layout"] = OLD_LAYOUTS[0]
        for name in f:
            if name not in ("frames", PARTICLES, "views"):
                f.copy(f[name], g, name=name)
        frames = g.create_group("frames")
        for name in ("time", "step"):
            f.copy(f[f"frames/{name}"], frames, name=name)
        n_frames = f["frames/time"].shape[0]
        for name, field in frame_fields(f).items():
            _old_dataset(frames, name, field, n_frames)
    if views:
        write_views(dst)
    logger.info("wrote %s in layout %s", dst, OLD_LAYOUTS[0])
    return dst
