"""Reading an input file safely (the lowest layer: scene files and ground-motion records are
read with it before anything else exists; pmpm.io.validate re-exports it with the HDF5 checks).

:func:`check_hdf5_readable`: the one check before any HDF5 file is opened (a regular file that
does not crash libhdf5 in a forked child); here, not in pmpm.io, because a scene's mesh may pull
in HDF5 data (pmpm.scene.mesh_refs).

:func:`read_regular`: the bytes of a text input, opened without blocking (a FIFO given as a
file never hangs the run), refused (ValueError, a reason that never quotes the content) unless
it is a regular file of at most ``max_bytes``.
"""
import faulthandler
import os
import signal
import stat

__all__ = ["read_regular", "check_hdf5_readable", "crashes_reading"]


def _kind(mode):
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _not_regular(mode):
    kind = _kind(mode)
    return "is not a regular file" + (f" ({kind})" if kind != "not a regular file" else "")


def read_regular(path, max_bytes):
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    Opened with ``O_NONBLOCK``, so opening a FIFO returns at once instead of waiting for a
    writer; refused (ValueError) unless the open file is regular and small enough.
    Raises OSError when the file cannot be opened.
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(_not_regular(st.st_mode))
        if st.st_size > max_bytes:
            raise ValueError(f"larger than {_size(max_bytes)}")
        chunks, left = [], max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
        raw = b"".join(chunks)
    finally:
        os.close(fd)
    if len(raw) > max_bytes:
        raise ValueError(f"larger than {_size(max_bytes)}")
    return raw


def _size(n):
    return f"{n >> 20} MB" if n >= 1 << 20 else f"{n >> 10} KB"


#: the signals a crash of libhdf5 raises in the child
_CRASH_SIGNALS = ("SIGSEGV", "SIGBUS", "SIGFPE", "SIGILL", "SIGABRT")


def _silence_child():
    """Let a crash in the forked child die quietly: the default action for the crash signals
    (Open MPI, once MPI is initialised, installs its own handler that prints a 30-line stack
    trace to standard error; Python's faulthandler prints another) and its standard output and
    error sent to /dev/null (libhdf5 prints its error stack there). The parent says the one line."""
    try:
        faulthandler.disable()
    except RuntimeError:
        pass
    for name in _CRASH_SIGNALS:
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.dup2(null, 2)
    os.close(null)


def crashes_reading(fn, *args):
    """True if ``fn(*args)`` kills the process (a signal: libhdf5 dereferences the damaged
    metadata of a corrupted file and segfaults, which no exception can catch). It runs in a
    forked child that only reads and exits without flushing anything; its exceptions are the
    caller's to meet again in the parent. Without ``os.fork`` (Windows) nothing is checked."""
    if not hasattr(os, "fork"):
        return False
    pid = os.fork()
    if pid == 0:  # the child: read, then leave at once (no atexit, no buffers flushed)
        code = 0
        try:
            _silence_child()
            fn(*args)
        except BaseException:  # noqa: BLE001 - the parent reports exceptions itself
            code = 1
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.WIFSIGNALED(status)


def _open_attrs(path):
    import h5py
    with h5py.File(path, "r") as f:
        dict(f.attrs)


def check_hdf5_readable(path, reader=None, follow_links=True):
    """The one check before pmpm opens an HDF5 file it did not just write (a results file given
    to ``plot``, ``export``, :func:`pmpm.load_results` or ``--restart``, a checkpoint, a file
    at an output name). Raises ValueError with a one-line reason unless ``path`` is a regular
    file (``os.stat``; ``os.lstat`` with ``follow_links=False``: a link is refused) that
    ``reader(path)`` (default: open it and read the root attributes) does not crash libhdf5 on,
    tried first in a forked child. A FIFO would block HDF5's open for ever and is never opened;
    a crafted file would kill the process by a segmentation fault (issue 35). FileNotFoundError
    when it does not exist."""
    st = os.stat(path) if follow_links else os.lstat(path)
    if stat.S_ISLNK(st.st_mode):
        raise ValueError("is a symbolic link")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(_not_regular(st.st_mode))
    if crashes_reading(reader or _open_attrs, path):
        raise ValueError("HDF5 crashed reading it (the file is damaged)")
