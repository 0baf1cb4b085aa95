"""Reading an input file safely (the lowest layer: scene files and ground-motion records are
read with it before anything else exists; pmpm.io.validate re-exports it with the HDF5 checks).

:func:`read_regular`: the bytes of a text input, opened without blocking (a FIFO given as a
file never hangs the run), refused (ValueError, a reason that never quotes the content) unless
it is a regular file of at most ``max_bytes``.
"""
import os
import stat

__all__ = ["read_regular"]


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
