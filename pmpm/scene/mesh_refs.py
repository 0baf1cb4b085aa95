"""The files a mesh file pulls in, checked before meshio opens any of them (issue 35).

meshio follows an Abaqus ``*INCLUDE, INPUT=<file>`` and an XDMF ``DataItem`` of format
``Binary`` (``numpy.fromfile``) or ``HDF`` (``h5py.File``) without looking at what the file is:
a FIFO there blocks the run for ever, a device streams without end, a crafted HDF5 file crashes
libhdf5. :func:`check_mesh_references` resolves each reference the way meshio does and refuses,
in one line naming the referenced file, anything that is not a regular file of a bounded size,
and an HDF5 file that crashes libhdf5 in a forked child (:func:`pmpm.files.check_hdf5_readable`).
Abaqus includes are followed recursively (a loop of includes is refused, not recursed into).
"""
import os
import stat

from pmpm.files import _not_regular, check_hdf5_readable, read_regular

__all__ = ["check_mesh_references", "MeshReferenceError"]

#: deepest chain of Abaqus includes followed (meshio would recurse until Python's limit)
MAX_INCLUDE_DEPTH = 16


class MeshReferenceError(ValueError):
    """A file a mesh pulls in cannot be used: ``path`` (the referenced file) and ``reason``."""

    def __init__(self, path, reason):
        super().__init__(f"{path}: {reason}")
        self.path, self.reason = path, reason


def _regular(path, max_bytes, what):
    """Refuse ``path`` unless it is a regular file (stat: never opened) of at most ``max_bytes``."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise MeshReferenceError(path, f"{what} cannot be read ({exc.strerror or type(exc).__name__})") from None
    if not stat.S_ISREG(st.st_mode):
        raise MeshReferenceError(path, f"{what} {_not_regular(st.st_mode)}")
    if st.st_size > max_bytes:
        raise MeshReferenceError(path, f"{what} is larger than {max_bytes >> 20} MB")


def _abaqus_includes(path, max_bytes):
    """The files named by ``*INCLUDE`` lines of the Abaqus file ``path``, resolved as meshio
    resolves them (as given if it exists, else beside the including file)."""
    text = read_regular(path, max_bytes).decode("utf-8", "replace")
    out = []
    for line in text.splitlines():
        line = line.strip()
        if not line.startswith("*") or line.startswith("**"):
            continue
        if line.partition(",")[0].strip().replace("*", "").upper() != "INCLUDE":
            continue
        name = line.split("=")[-1].strip()
        if not os.path.exists(name):
            name = os.path.join(os.path.dirname(path), name)
        out.append(name)
    return out


def _read_hdf5_item(path, h5path):
    """What meshio reads of the file (the item), and the root attributes: a file whose
    metadata crashes libhdf5 anywhere pmpm looks is refused as damaged."""
    import h5py
    with h5py.File(path, "r") as f:
        dict(f.attrs)
        obj = f
        for key in h5path.strip("/").split("/"):
            obj = obj[key]
        obj[()]


def _xdmf_items(path, max_bytes):
    """(format, file, HDF5 path or None) of each DataItem of the XDMF file ``path`` that reads
    another file, resolved as meshio resolves them (Binary: as written; HDF: beside the file)."""
    import xml.etree.ElementTree as ET
    try:
        root = ET.fromstring(read_regular(path, max_bytes))
    except ET.ParseError:
        return []  # meshio refuses it itself
    out = []
    for item in root.iter("DataItem"):
        fmt, text = item.get("Format"), (item.text or "").strip()
        if fmt == "Binary":
            out.append(("Binary", text, None))
        elif fmt == "HDF" and ":" in text:
            name, h5path = text.split(":", 1)
            out.append(("HDF", os.path.join(os.path.dirname(os.path.realpath(path)), name), h5path))
    return out


def check_mesh_references(path, max_bytes):
    """Raise :class:`MeshReferenceError` naming the first file the mesh ``path`` pulls in that
    meshio must not open; ``max_bytes`` bounds each file (meshio reads them whole)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".inp":
        todo = [(path, (os.path.realpath(path),))]  # each file with the chain that includes it
        while todo:
            current, chain = todo.pop()
            for name in _abaqus_includes(current, max_bytes):
                _regular(name, max_bytes, f"included by {os.path.basename(current)}:")
                real = os.path.realpath(name)
                if real in chain:
                    raise MeshReferenceError(name, "includes itself (a loop of *INCLUDE files)")
                if len(chain) >= MAX_INCLUDE_DEPTH:
                    raise MeshReferenceError(name, f"*INCLUDE nested deeper than {MAX_INCLUDE_DEPTH}")
                if os.path.splitext(name)[1].lower() == ".inp":
                    todo.append((name, chain + (real,)))
    elif ext in (".xdmf", ".xmf"):
        for fmt, name, h5path in _xdmf_items(path, max_bytes):
            what = f"a {fmt} data item of {os.path.basename(path)}:"
            _regular(name, max_bytes, what)
            if fmt == "HDF":
                try:
                    check_hdf5_readable(name, lambda p: _read_hdf5_item(p, h5path))
                except (OSError, ValueError) as exc:
                    raise MeshReferenceError(name, f"{what} {exc}") from None
