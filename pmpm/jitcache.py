"""Keep numba's on-disk kernel cache consistent with the source it was compiled from.

numba checks a cached kernel only against the file that defines it. A kernel that inlines a
function from another file (every transfer kernel inlines the B-splines of pmpm/core/shape.py, the
material kernels share linear_elastic.py) would keep running the old machine code after that
other file changed. So pmpm keeps its kernels in a cache directory named by a hash of the
sources of all its numba modules: changed sources mean a new, empty directory, and the next run
compiles afresh (about a minute, or ``python -m pmpm.warmup``). A process that started before
the change keeps writing to its own directory, so it can never leave old code where new
processes look. Directories of other hashes are removed once a day old.

The directory goes to ``NUMBA_CACHE_DIR`` as well, so MPI ranks and subprocesses started by
this process use it too. A ``NUMBA_CACHE_DIR`` set by the user is kept as the parent.
"""
import hashlib
import os
import pathlib
import shutil
import sys
import time

__all__ = ["use_versioned_cache"]

_PACKAGE = pathlib.Path(__file__).resolve().parent
_PREFIX = "numba-"
#: directories of other source versions older than this are removed (seconds)
_KEEP_OLD = 24 * 3600.0


def _sources_hash():
    """Hash of every pmpm module that imports numba (the others cannot change a kernel)."""
    digest = hashlib.sha256()
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"import numba" in text or b"from numba" in text:
            digest.update(str(path.relative_to(_PACKAGE)).encode())
            digest.update(text)
    return digest.hexdigest()[:16]


def _prune(parent, keep):
    """Remove other versions' directories a day old (a process using one writes to it)."""
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return
    now = time.time()
    for entry in entries:
        if entry.name.startswith(_PREFIX) and entry.name != keep and entry.is_dir():
            try:
                if now - entry.stat().st_mtime > _KEEP_OLD:
                    shutil.rmtree(entry.path, ignore_errors=True)
            except OSError:
                pass


def use_versioned_cache():
    """Point numba's cache at the directory of the current sources; returns its path. Must run
    before any kernel module is imported (numba fixes a kernel's cache path when it is
    defined): pmpm/__init__.py calls it."""
    name = _PREFIX + _sources_hash()
    given = os.environ.get("NUMBA_CACHE_DIR")
    if given and os.path.basename(os.path.normpath(given)).startswith(_PREFIX):
        parent = os.path.dirname(os.path.normpath(given))  # set by a parent pmpm process
    else:
        parent = given or str(_PACKAGE / "__pycache__")
    target = os.path.join(parent, name)
    os.environ["NUMBA_CACHE_DIR"] = target
    numba = sys.modules.get("numba")
    if numba is not None:  # already imported: it read the variable at import
        numba.config.CACHE_DIR = target
    _prune(parent, name)
    return target
