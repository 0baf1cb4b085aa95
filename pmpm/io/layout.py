"""The layouts of a results file and one way to read their particle fields, whichever wrote them.

``pmpm-results-3`` (written since issue 40) stores what changes once per frame and what does
not once per file:

- ``/frames/<field>`` ``(F, n_total, *trailing)``: the fields that change, row ``i`` the
  particle of id ``i`` (the parallel writer lays every frame out in id order, whatever rank a
  particle has migrated to, so ids are implicit); stored in single precision by default
  (``output.precision``), gzip-compressed with the byte shuffle;
- ``/particles/<field>`` ``(n_total, *trailing)``: the per-particle constants among the
  scene's fields (:data:`CONSTANT_FIELDS`: initial position, mass, initial volume, material and
  body index), written once, at the precision the solver holds them;
- no ``/frames/id``: a particle exists in a frame when its row of the frame's fields is not the
  fill value (NaN for floats, -1 for integers), as removed particles always read. Only a scene
  whose fields are all constants keeps ``/frames/id``, the one record then of which exist.

``pmpm-results-2`` (pmpm before issue 40) stored every field, ``id`` included, in every frame,
in the solver's float64, uncompressed. :func:`frame_fields` reads both as the same mapping of
``(F, n_total, *trailing)`` fields, ``id`` among them, so readers need not know which they hold.
"""
from __future__ import annotations

import numpy as np

__all__ = ["LAYOUT", "OLD_LAYOUTS", "READ_LAYOUTS", "CONSTANT_FIELDS", "PARTICLES", "FrameField",
           "frame_fields", "layout_of", "fill_of"]

#: the layout this pmpm writes
LAYOUT = "pmpm-results-3"
#: older layouts it still reads (pmpm plot, export, load_results), never appends to
OLD_LAYOUTS = ("pmpm-results-2",)
READ_LAYOUTS = (LAYOUT,) + OLD_LAYOUTS
#: per-particle fields no phase of the step changes (checked by the writer at every frame)
CONSTANT_FIELDS = ("x0", "m", "vol0", "mat", "body")
#: the group of the per-particle constants
PARTICLES = "particles"


def layout_of(f):
    """The ``layout`` attribute of an open results file, as text (None when absent)."""
    value = f.attrs.get("layout")
    return value.decode() if isinstance(value, bytes) else value


def fill_of(dtype):
    """The value of a missing particle's row: NaN for floats, -1 for integers."""
    dtype = np.dtype(dtype)
    return dtype.type(np.nan) if dtype.kind in "fc" else dtype.type(-1 if dtype.kind == "i" else 0)


def _exists(rows):
    """Which rows of one frame of one field hold a particle (not the fill value)."""
    flat = rows.reshape(len(rows), int(np.prod(rows.shape[1:], dtype=np.int64)))
    if rows.dtype.kind in "fc":
        return np.all(np.isfinite(flat), axis=1)
    return np.all(flat != fill_of(rows.dtype), axis=1)


class FrameField:
    """One particle field of a results file seen as ``(F, n_total, *trailing)``.

    ``field[k]`` is frame ``k`` (rows in id order, fill values where the particle does not exist),
    ``field[()]`` every frame; ``shape``, ``dtype``, ``ndim``, ``attrs`` as an h5py dataset's.
    A constant (``/particles/<name>``) or the implicit ``id`` is expanded per frame from the
    existence of the particles in that frame (``witness``, a per-frame field).
    """

    def __init__(self, name, count, dset=None, constant=None, witness=None):
        self.name, self._dset, self._constant, self._witness = name, dset, constant, witness
        self._values = None  # the constant's rows, read once
        if dset is not None:
            self.shape, self.dtype, self.attrs = dset.shape, dset.dtype, dset.attrs
        elif constant is not None:
            self.shape, self.dtype, self.attrs = (count,) + constant.shape, constant.dtype, constant.attrs
        else:  # the implicit id
            n = witness.shape[1]
            self.shape, self.dtype, self.attrs = (count, n), np.dtype(np.int64), {}
        self.ndim = len(self.shape)
        self.constant = dset is None

    def _alive(self, index):
        if self._witness is None:
            return np.ones(self.shape[1], dtype=bool)
        return _exists(self._witness[index])

    def __getitem__(self, index):
        if isinstance(index, tuple) and index == ():
            return self.read()
        if self._dset is not None:
            return self._dset[index]
        index = int(index)
        if index < 0:
            index += self.shape[0]
        if not 0 <= index < self.shape[0]:
            raise IndexError(f"frame {index} of {self.shape[0]}")
        alive = self._alive(index)
        if self._values is None:
            self._values = (self._constant[()] if self._constant is not None
                            else np.arange(self.shape[1], dtype=np.int64))
        values = self._values
        out = np.full(values.shape, fill_of(values.dtype), dtype=values.dtype)
        out[alive] = values[alive]
        return out

    def read(self, frames=None):
        """Every frame (or those of the index array ``frames``) as one array."""
        if self._dset is not None:
            data = self._dset[()]
            return data if frames is None else data[frames]
        chosen = range(self.shape[0]) if frames is None else np.arange(self.shape[0])[frames]
        rows = [self[k] for k in chosen]
        return np.stack(rows) if rows else np.empty((0,) + self.shape[1:], dtype=self.dtype)


def frame_fields(f):
    """The particle fields of an open results file of any readable layout, ``id`` among them.

    Parameters
    ----------
    f : h5py.File
        A results file (layouts :data:`READ_LAYOUTS`).

    Returns
    -------
    dict of str to FrameField
        Name -> field of shape ``(F, n_total, *trailing)``, per-frame fields first.
    """
    frames = f["frames"]
    per_frame = {n: d for n, d in frames.items() if n not in ("time", "step") and d.ndim >= 2}
    count = frames["time"].shape[0] if "time" in frames else \
        next(iter(per_frame.values())).shape[0] if per_frame else 0
    # the field whose rows say which particles exist: positions when written, else any
    witness = per_frame["x"] if "x" in per_frame else next(
        (d for n, d in per_frame.items() if n != "id"), None)
    out = {n: FrameField(n, count, dset=d) for n, d in per_frame.items()}
    particles = f.get(PARTICLES)
    if particles is not None:
        for n, d in particles.items():
            out.setdefault(n, FrameField(n, count, constant=d, witness=witness))
    if "id" not in out and witness is not None:
        out["id"] = FrameField("id", count, witness=witness)
    return out
