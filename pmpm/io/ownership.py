"""Which files in a folder pmpm wrote: the only files it overwrites or deletes.

pmpm shares its output folder with the user's own files and with other scenes. Before it
writes over or deletes a file that already exists, it asks whether the file is its own, by a
record that only pmpm writes (docs/output.md, "Which files pmpm writes and deletes"):

- an HDF5 file (results, checkpoints, last good state) carries the root attribute
  ``pmpm_owner``, the stem of the scene file that wrote it;
- an XDMF sidecar carries the comment ``<!-- pmpm sidecar of <file>.h5 -->`` on its second line;
- every other file (CSV, PNG, VTU, PVD) is listed in the folder's manifest ``pmpm-files.json``
  with its SHA-256 and owner, written when the file is.

A file that exists and lacks its record, holds another owner's, or whose content changed since
pmpm wrote it (its hash differs), is *foreign*: :func:`check_owned` raises
:class:`ForeignFileError` naming it, and nothing is written. Writers of post-processed files
work inside :func:`writing`: each file is claimed (checked) before it is written, and if
anything fails the files of that call are taken back (new files removed, replaced ones
restored), so a failed ``pmpm plot`` or ``pmpm export`` leaves the folder as it was.
"""
import contextlib
import hashlib
import json
import os
import re
import stat
import tempfile

from pmpm.errors import ConfigError

__all__ = ["OWNER_ATTR", "MANIFEST", "ForeignFileError", "check_owned", "hdf5_owner",
           "xdmf_marker", "writing", "claim", "remove_owned"]

#: root attribute of every HDF5 file pmpm writes: the stem of the scene file
OWNER_ATTR = "pmpm_owner"
#: the manifest of the files other than HDF5 and XDMF pmpm wrote into a folder
MANIFEST = "pmpm-files.json"
MANIFEST_FORMAT = "pmpm-files-1"
_MARKER = re.compile(r"<!-- pmpm sidecar of (.+?) -->")
_HDF5_SUFFIXES = (".h5",)
_XDMF_SUFFIXES = (".xdmf",)
#: a manifest is a few kilobytes; a larger "manifest" is not pmpm's
MAX_MANIFEST_BYTES = 16 << 20


class ForeignFileError(ConfigError):
    """An existing file pmpm would overwrite or delete is not its own (exit 2, one line)."""


def xdmf_marker(h5_name):
    """The comment that marks a sidecar as pmpm's: ``<!-- pmpm sidecar of <h5_name> -->``."""
    return f"<!-- pmpm sidecar of {h5_name} -->"


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _regular(path):
    """True if ``path`` is a regular file and not a symbolic link (lstat: never followed)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def hdf5_owner(path):
    """The ``pmpm_owner`` of an HDF5 file, or None (not HDF5, no record, unreadable)."""
    if not _regular(path):
        return None
    import h5py
    try:
        with h5py.File(path, "r") as f:
            value = f.attrs.get(OWNER_ATTR)
    except Exception:  # noqa: BLE001 - any file h5py cannot read is simply not ours
        return None
    value = value.decode() if isinstance(value, bytes) else value
    return value if isinstance(value, str) else None


def _xdmf_target(path):
    """The results file a pmpm sidecar names in its marker, or None."""
    if not _regular(path):
        return None
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace")
    except OSError:
        return None
    lines = head.splitlines()
    m = _MARKER.fullmatch(lines[1].strip()) if len(lines) > 1 else None
    return m.group(1) if m else None


def _load_manifest(folder):
    """``{name: {"sha256", "owner"}}`` of ``folder``'s manifest ({} when there is none);
    a manifest that is not pmpm's (a link, not JSON, another format) is a ForeignFileError."""
    path = os.path.join(folder, MANIFEST)
    if not os.path.lexists(path):
        return {}
    if not _regular(path):
        raise _foreign(path, "is not a regular file, so not pmpm's manifest")
    try:
        if os.path.getsize(path) > MAX_MANIFEST_BYTES:
            raise ValueError("too large")
        with open(path, "rb") as fh:
            data = json.loads(fh.read().decode("utf-8"))
        if not (isinstance(data, dict) and data.get("format") == MANIFEST_FORMAT
                and isinstance(data.get("files"), dict)):
            raise ValueError("another format")
        files = {k: v for k, v in data["files"].items()
                 if isinstance(k, str) and isinstance(v, dict) and isinstance(v.get("sha256"), str)}
    except (OSError, ValueError, UnicodeDecodeError):
        raise _foreign(path, "is not pmpm's manifest of the files it wrote") from None
    return files


def _save_manifest(folder, files):
    """Write ``folder``'s manifest atomically (a temporary file renamed over it)."""
    path = os.path.join(folder, MANIFEST)
    fd, tmp = tempfile.mkstemp(prefix=".pmpm-files.", suffix=".tmp", dir=folder)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # as a plain open() would make it (mkstemp makes 0600)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump({"format": MANIFEST_FORMAT, "files": dict(sorted(files.items()))}, fh, indent=1)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise


def _foreign(path, why):
    return ForeignFileError(path, f"exists and {why}: pmpm overwrites or deletes only the files "
                                  f"it wrote for this scene (move it, or choose another output folder)")


def check_owned(path, owner):
    """Raise :class:`ForeignFileError` unless ``path`` is missing or pmpm's file of ``owner``.

    Parameters
    ----------
    path : str
        A file pmpm is about to write over or delete.
    owner : str or None
        Stem of the scene file the write is for; None accepts any pmpm owner.
    """
    if not os.path.lexists(path):
        return
    if not _regular(path):
        raise _foreign(path, "is not a regular file (a link, a folder or a device)")
    name = os.path.basename(path)
    if name.endswith(_HDF5_SUFFIXES):
        found = hdf5_owner(path)
        if found is None:
            raise _foreign(path, f"carries no '{OWNER_ATTR}' record of pmpm")
        if owner is not None and found != owner:
            raise _foreign(path, f"belongs to scene {found!r}, not {owner!r}")
        return
    if name.endswith(_XDMF_SUFFIXES):
        target = _xdmf_target(path)
        if target is None:
            raise _foreign(path, "is not a sidecar pmpm wrote (no pmpm marker)")
        return
    entry = _load_manifest(os.path.dirname(path) or ".").get(name)
    if entry is None:
        raise _foreign(path, f"is not listed in {MANIFEST}")
    # the entry's owner is not compared: `pmpm plot a.h5 b.h5` writes b's energy plot for a's
    # command; names carry their run's stem, and the HDF5 records keep two scenes apart
    if entry["sha256"] != _sha256(path):
        raise _foreign(path, "changed since pmpm wrote it (its SHA-256 differs)")


def remove_owned(path, owner):
    """Delete ``path`` if it exists and is pmpm's file of ``owner``; else ForeignFileError."""
    check_owned(path, owner)
    if os.path.lexists(path):
        os.remove(path)


class Writes:
    """The files one post-processing call writes: claimed before, recorded after, taken back
    if the call fails. Use through :func:`writing` and :func:`claim`."""

    def __init__(self, owner):
        self.owner = owner
        self.paths = []      # claimed, in order
        self.backups = {}    # path -> the previous (owned) file, moved aside
        self.made = []       # folders this call created, outermost first

    def makedirs(self, folder):
        """Create ``folder`` (and missing parents), remembering them to remove on failure."""
        folder = os.path.abspath(folder)
        missing = []
        probe = folder
        while not os.path.exists(probe):
            missing.append(probe)
            probe = os.path.dirname(probe)
        if os.path.lexists(folder) and not os.path.isdir(folder):
            raise _foreign(folder, "is not a folder")
        os.makedirs(folder, exist_ok=True)
        self.made += [m for m in reversed(missing) if m not in self.made]
        return folder

    def claim(self, path):
        """Check ``path`` (ForeignFileError if it is not ours) and set any old copy aside."""
        path = os.fspath(path)
        if path in self.paths:
            return path
        folder = os.path.dirname(os.path.abspath(path))
        if os.path.isdir(folder):
            _load_manifest(folder)  # a foreign manifest is refused before anything is written
        check_owned(path, self.owner)
        self.makedirs(folder)
        if os.path.lexists(path):
            fd, backup = tempfile.mkstemp(prefix=".pmpm-old.", dir=folder)
            os.close(fd)
            os.replace(path, backup)
            self.backups[path] = backup
        self.paths.append(path)
        return path

    def commit(self):
        """Record every written file in its folder's manifest; drop the old copies."""
        by_folder = {}
        for path in self.paths:
            name = os.path.basename(path)
            if os.path.exists(path) and not name.endswith(_HDF5_SUFFIXES + _XDMF_SUFFIXES):
                by_folder.setdefault(os.path.dirname(os.path.abspath(path)), []).append(path)
        for folder, paths in by_folder.items():
            files = {n: e for n, e in _load_manifest(folder).items()
                     if os.path.exists(os.path.join(folder, n))}
            for path in paths:
                files[os.path.basename(path)] = {"sha256": _sha256(path), "owner": self.owner}
            _save_manifest(folder, files)
        for backup in self.backups.values():
            with contextlib.suppress(OSError):
                os.remove(backup)
        self.backups.clear()

    def abort(self):
        """Take the call's files back: new ones removed, replaced ones restored."""
        for path in reversed(self.paths):
            with contextlib.suppress(OSError):
                if os.path.lexists(path):
                    os.remove(path)
            backup = self.backups.pop(path, None)
            if backup is not None:
                with contextlib.suppress(OSError):
                    os.replace(backup, path)
        for folder in reversed(self.made):
            with contextlib.suppress(OSError):
                os.rmdir(folder)  # only if empty: a folder another process filled meanwhile stays


_ACTIVE = []


@contextlib.contextmanager
def writing(owner):
    """Context of one call that writes files: yields its :class:`Writes` (the enclosing one's
    when nested, so a command's plots and CSV files commit or fail together)."""
    if _ACTIVE:
        yield _ACTIVE[-1]
        return
    w = Writes(owner)
    _ACTIVE.append(w)
    try:
        yield w
    except BaseException:
        w.abort()
        raise
    else:
        w.commit()
    finally:
        _ACTIVE.pop()


def claim(path):
    """Claim ``path`` in the active :func:`writing` context (which must exist); returns it."""
    if not _ACTIVE:
        raise RuntimeError("pmpm.io.ownership.claim outside a writing() context")
    return _ACTIVE[-1].claim(path)
