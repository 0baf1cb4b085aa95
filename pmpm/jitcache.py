"""Keep numba's on-disk kernel cache consistent with the source it was compiled from.

numba checks a cached kernel only against the file that defines it. A kernel that inlines a
function from another file (every transfer kernel inlines the B-splines of pmpm/shape.py, the
material kernels share linear_elastic.py) keeps running the old machine code after that other
file changes. So the cache is stamped with a hash of the sources of pmpm's numba modules, and
any change to them empties it: the next run compiles afresh (about a minute, or
``python -m pmpm.warmup``).
"""
import hashlib
import os
import pathlib

__all__ = ["check_cache"]

_PACKAGE = pathlib.Path(__file__).resolve().parent
_STAMP = _PACKAGE / "__pycache__" / "numba-sources.sha256"


def _sources_hash():
    """Hash of every pmpm module that uses numba (the others cannot change a kernel)."""
    digest = hashlib.sha256()
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            digest.update(str(path.relative_to(_PACKAGE)).encode())
            digest.update(text)
    return digest.hexdigest()


def check_cache():
    """Empty pmpm's numba cache if any source changed since it was filled. Returns True when
    it did. Silent where the package is read-only (numba then caches elsewhere itself)."""
    current = _sources_hash()
    try:
        if _STAMP.read_text() == current:
            return False
    except OSError:
        pass
    try:
        for pattern in ("*.nbi", "*.nbc"):
            for entry in _PACKAGE.rglob(pattern):
                entry.unlink(missing_ok=True)
        _STAMP.parent.mkdir(exist_ok=True)
        tmp = _STAMP.with_suffix(f".{os.getpid()}")
        tmp.write_text(current)
        os.replace(tmp, _STAMP)  # atomic: ranks starting together never read half a stamp
    except OSError:
        return False
    return True
