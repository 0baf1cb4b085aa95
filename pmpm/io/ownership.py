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
import atexit
import contextlib
import hashlib
import json
import os
import re
import socket
import stat
import tempfile

from pmpm.errors import ConfigError
from pmpm.io.validate import safe_to_open_hdf5

__all__ = ["OWNER_ATTR", "MANIFEST", "ForeignFileError", "check_owned", "hdf5_owner",
           "xdmf_marker", "writing", "claim", "remove_owned", "protect_input", "check_target",
           "exclusive_temp", "replace_into", "check_manifest", "claim_run", "release_claims",
           "remove_stale_temporaries"]

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
    if not safe_to_open_hdf5(path):  # a FIFO, a link, or a file that crashes libhdf5
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
    except (OSError, ValueError, UnicodeDecodeError, RecursionError):
        # RecursionError: JSON nested thousands deep (json.loads recurses per level)
        raise _foreign(path, "is not pmpm's manifest of the files it wrote") from None
    return files


def check_manifest(folder):
    """Validate ``folder``'s manifest (if any) as pmpm's schema, before a run writes anything
    into the folder: ForeignFileError (one line) for garbage, deep nesting, a folder, a link,
    a FIFO, a huge file or another format."""
    if os.path.isdir(folder):
        _load_manifest(folder)


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

# -- the gate: the checks every path pmpm writes passes, whoever wrote the file before ---------

#: (st_dev, st_ino) -> path of this process's input files (the scene): never written, under
#: any name. The path is kept to tell a live input from a deleted one whose inode the file
#: system has since given to a new file (a long process runs many scenes).
_PROTECTED = {}


def protect_input(path):
    """Remember ``path`` (an input: the scene file) so that no write of this process lands on
    it under any other name: a symbolic or hard link, a path through a linked folder (same
    device and inode)."""
    try:
        st = os.stat(path)
    except (OSError, ValueError, TypeError):  # no file (a Scene built in Python): nothing to guard
        return
    _PROTECTED[(st.st_dev, st.st_ino)] = os.path.abspath(path)


def _is_protected(path):
    try:
        st = os.stat(path)  # followed: a link to the scene is the scene
    except (OSError, ValueError):
        return False
    source = _PROTECTED.get((st.st_dev, st.st_ino))
    if source is None:
        return False
    try:  # still the input's inode (not one reused after the input was deleted)
        return os.path.samefile(source, path)
    except OSError:
        return False


def check_target(path, root=None):
    """The gate: raise :class:`ForeignFileError` naming ``path`` unless pmpm may create or
    replace it as far as the file system goes (ownership aside, see :func:`check_owned`).

    Refused: a symbolic link at ``path`` or at any folder between ``root`` (the output folder,
    taken as given: the user chose it) and ``path``; a special file (FIFO, device, socket) or
    a folder at ``path``; an input of this run (the scene) under any name.

    Parameters
    ----------
    path : str
        The file about to be written.
    root : str, optional
        The output folder ``path`` lies in (default: its own folder, so only ``path`` itself
        is checked for a link).
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    root = os.path.abspath(root) if root is not None else folder
    # every component below root, outermost first, the file last
    between = []
    probe = folder
    while probe != root and probe.startswith(root + os.sep):
        between.append(probe)
        probe = os.path.dirname(probe)
    for step in reversed(between):
        if os.path.islink(step):
            raise ForeignFileError(step, "is a symbolic link on the way to an output file: pmpm "
                                         "writes only inside the output folder, never through a link")
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise ForeignFileError(path, f"cannot be checked ({exc.strerror or type(exc).__name__})") from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise ForeignFileError(path, "is a symbolic link: pmpm never writes through a link "
                                         "(move it, or choose another output folder)")
        if not stat.S_ISREG(st.st_mode):
            kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a special file (FIFO, device or socket)"
            raise ForeignFileError(path, f"is {kind}, not a file pmpm wrote")
    if _is_protected(path):
        raise ForeignFileError(path, "is an input of this run (the scene file under another name): "
                                     "pmpm never writes over its input")


def exclusive_temp(path, binary=True):
    """Create a new temporary file beside ``path`` and return ``(file object, temp path)``.

    The name is fresh and created exclusively (``O_CREAT | O_EXCL | O_NOFOLLOW``, by
    :func:`tempfile.mkstemp`), so no existing file, link or FIFO is ever opened, whatever sits
    at ``<path>.tmp``. Its mode is what a plain ``open()`` would give (mkstemp makes 0600)."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".pmpm-tmp", dir=folder)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    return os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8"})), tmp


def replace_into(path, write, binary=False, root=None):
    """Write a whole file through the gate: ``path`` checked (:func:`check_target`), the
    content written by ``write(fh)`` into an exclusive temporary beside it, flushed to disk,
    then renamed over ``path``. A failure (a full disk) removes the temporary and leaves the
    old file intact."""
    check_target(path, root)
    fh, tmp = exclusive_temp(path, binary)
    try:
        with fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        check_target(path, root)  # again: nothing was put there meanwhile
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
    return path


# -- one run at a time per set of names in a folder ----------------------------------------------

#: claims this process holds (released when it exits)
_CLAIMS = set()
_ATEXIT = []


def _claim_text():
    return json.dumps({"format": "pmpm-claim-1", "pid": os.getpid(), "host": socket.gethostname()})


def _holder(path):
    """(pid, host) of an existing claim file, or None if it is not one (read as any input:
    regular and small, never a link or FIFO)."""
    try:
        if not _regular(path) or os.path.getsize(path) > 4096:
            return None
        with open(path, "rb") as fh:
            data = json.loads(fh.read().decode("utf-8"))
        if isinstance(data, dict) and data.get("format") == "pmpm-claim-1" and isinstance(data.get("pid"), int):
            return data["pid"], str(data.get("host"))
    except (OSError, ValueError, UnicodeDecodeError, RecursionError):
        pass
    return None


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, another user's
        return True
    try:  # a killed rank not yet reaped by its parent (a zombie, state Z) writes nothing more
        with open(f"/proc/{int(pid)}/stat", "rb") as fh:
            return fh.read().rsplit(b")", 1)[-1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


def claim_run(folder, run):
    """Claim the names of run ``run`` (``<stem>[_<variant>]``) in ``folder`` before the run
    writes any of them: ``.<run>.pmpm-claim`` is created exclusively (``O_EXCL | O_NOFOLLOW``)
    holding this process's id and host. A second run that would write the same names (the
    same scene started twice, or variant ``x`` of ``beam.toml`` beside ``beam_x.toml``) finds
    the claim of a live process and is refused in one line; a claim whose process is gone (a
    killed run) is taken over. The claim is removed when this process exits."""
    path = os.path.join(folder, f".{run}.pmpm-claim")
    if path in _CLAIMS:
        return path
    for _attempt in range(2):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except FileExistsError:
            holder = _holder(path)
            if holder is None:
                raise _foreign(path, "is not a claim pmpm wrote") from None
            pid, host = holder
            if pid == os.getpid() and host == socket.gethostname():
                _CLAIMS.add(path)
                return path
            if host != socket.gethostname() or _alive(pid):
                raise ForeignFileError(path, f"another pmpm run (process {pid} on {host}) is writing "
                                             f"these files: wait for it, or choose another output folder "
                                             f"(delete this file if that run is gone)")
            with contextlib.suppress(FileNotFoundError):
                os.remove(path)  # a killed run's claim
            continue
        with os.fdopen(fd, "w") as fh:
            fh.write(_claim_text())
        if not _ATEXIT:
            atexit.register(release_claims)
            _ATEXIT.append(True)
        _CLAIMS.add(path)
        return path
    raise ForeignFileError(path, "another pmpm run took this claim at the same moment")


#: the temporaries pmpm creates beside a file: checkpoint.py's ``.<name>.<12 hex>.pmpm-tmp`` and
#: replace_into's ``.<name>.<mkstemp's 8 characters>.pmpm-tmp``
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.(?:[0-9a-f]{12}|[a-z0-9_]{8})\.pmpm-tmp")


def remove_stale_temporaries(folder, run):
    """Remove the temporaries of run ``run`` that a killed process left in ``folder`` (a
    checkpoint killed between its write and its rename leaves a whole hidden file the size of
    the particle state). Only while this process holds the run's claim (no other live run of
    these names can be writing them), only names of this run's own files (``<run>.*``), only
    regular files of this user (never through a link). Returns the names removed."""
    removed = []
    if _holder(os.path.join(folder, f".{run}.pmpm-claim")) != (os.getpid(), socket.gethostname()):
        return removed  # not this process's claim: another run's temporaries may be live
    for entry in os.scandir(folder):
        m = _TEMPORARY.fullmatch(entry.name)
        if not m or not m.group("name").startswith(run + "."):
            continue
        st = entry.stat(follow_symlinks=False)
        if stat.S_ISREG(st.st_mode) and st.st_uid == os.getuid():
            with contextlib.suppress(FileNotFoundError):
                os.remove(entry.path)
                removed.append(entry.name)
    return removed


def release_claims():
    """Remove this process's claims (a run's end; at exit for any left)."""
    for path in list(_CLAIMS):
        if _holder(path) == (os.getpid(), socket.gethostname()):
            with contextlib.suppress(OSError):
                os.remove(path)
        _CLAIMS.discard(path)


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
    check_target(path)  # a link, a special file or the scene: refused whatever it holds
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

    def claim(self, path, root=None):
        """Check ``path`` (ForeignFileError if it is not ours; :func:`check_target` below
        ``root``) and set any old copy aside."""
        path = os.fspath(path)
        if path in self.paths:
            return path
        folder = os.path.dirname(os.path.abspath(path))
        check_target(path, root)
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


def claim(path, root=None):
    """Claim ``path`` in the active :func:`writing` context (which must exist); returns it.
    ``root``: the output folder, below which no folder on the way may be a link."""
    if not _ACTIVE:
        raise RuntimeError("pmpm.io.ownership.claim outside a writing() context")
    return _ACTIVE[-1].claim(path, root)
