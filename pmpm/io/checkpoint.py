"""Restart checkpoints: the full particle state in id order, two files alternating.

Files
-----
``<path_base>.ckpt0.h5`` and ``<path_base>.ckpt1.h5``.  Each write replaces the
older (or an incomplete) one, so a crash while writing leaves the other intact.
``<path_base>.lastgood.h5`` (:func:`lastgood_path`, written with ``path=``) holds the
last good state of a failed run and is never one of the two.

Layout of one checkpoint
------------------------
``/particles/<field>`` (n_total, \\*shape)
    Every particle field handed to :func:`write_checkpoint`, row ``i`` = id ``i``;
    ids that no longer exist hold NaN / -1 (``/particles/id`` is -1 there).
Root attributes
    ``time``, ``step``, ``n_total``, ``layout`` (``"pmpm-checkpoint-1"``), ``attrs``
    (JSON of the caller's dict plus time, step and n_total; pmpm's run adds the scene
    record and fingerprint that ``--restart`` compares, see pmpm.scene.fingerprint) and
    ``complete``, set to True last, after a flush, so a file without it was cut short.
    A write that fails (full disk) raises :class:`pmpm.errors.OutputWriteError` on every
    rank and leaves the other file as it was.

Rows are put into id order with the same one-Alltoallv redistribution as the results
file, and each rank writes its id block; reading gives rank ``r`` the id block
``block_range(n_total, size, r)``, so a run may restart on a different rank count.
"""

from __future__ import annotations

import json
import logging
import os

import h5py
import numpy as np
from mpi4py import MPI

from decomposition.slab import block_range

from pmpm.errors import OutputWriteError
from pmpm.io._parallel import (
    check_all,
    fill_value,
    json_dumps,
    mpio_available,
    owner_bounds,
    to_id_blocks,
    validate_rows,
    write_rows,
)
from pmpm.io.validate import check_hdf5_readable
from pmpm.io.validate import check_checkpoint_schema
from pmpm.io.ownership import check_target

__all__ = ["write_checkpoint", "read_checkpoint", "checkpoint_paths", "latest_checkpoint",
           "lastgood_path"]

logger = logging.getLogger(__name__)

LAYOUT = "pmpm-checkpoint-1"


def checkpoint_paths(path_base):
    """Return the two alternating checkpoint file names of ``path_base``.

    Parameters
    ----------
    path_base : str or os.PathLike
        Common prefix, e.g. ``"out/portal"``.

    Returns
    -------
    list of str
        ``[<path_base>.ckpt0.h5, <path_base>.ckpt1.h5]``.
    """
    base = os.fspath(path_base)
    return [f"{base}.ckpt{i}.h5" for i in (0, 1)]


def lastgood_path(path_base):
    """``<path_base>.lastgood.h5``: the newest state that passed the health checks, written
    when a run fails (never one of the two alternating checkpoints)."""
    return f"{os.fspath(path_base)}.lastgood.h5"


def _checkpoint_step(path):
    """(step, None) of a complete checkpoint file, else (None, why not): missing, cut short,
    not a regular file, crashing libhdf5, or unreadable."""
    if not os.path.lexists(path):
        return None, "missing"
    try:
        check_hdf5_readable(path, _read_schema)  # never a FIFO; damaged metadata tried in a child
        with h5py.File(path, "r") as f:
            if bool(f.attrs.get("complete", False)) and "particles/id" in f:
                return int(f.attrs["step"]), None
        return None, "cut short (not marked complete)"
    except (OSError, KeyError, ValueError, RuntimeError, TypeError) as exc:  # RuntimeError: HDF5
        return None, str(exc) or type(exc).__name__  # (a link loop, a bad node)


def _complete_step(path):
    """Return the step of a complete checkpoint file, or None (missing, cut short, corrupt)."""
    step, why = _checkpoint_step(path)
    if step is None and why != "missing":
        logger.warning("ignoring checkpoint %s: %s", path, why)
    return step


def _read_schema(path):
    """Every read the checks make of one checkpoint file (run in a child: it may crash)."""
    with h5py.File(path, "r") as f:
        dict(f.attrs.items())
        check_checkpoint_schema(f, LAYOUT)  # refuses links first, so the walk follows none
        f.visititems(lambda name, obj: dict(obj.attrs.items()))


def latest_checkpoint(path_base):
    """Return the newest complete checkpoint file (largest step), serially.

    Parameters
    ----------
    path_base : str or os.PathLike
        Common prefix of the checkpoint files.

    Returns
    -------
    str or None
        Path, or None when no complete checkpoint exists.
    """
    steps = [(s, p) for p in checkpoint_paths(path_base) if (s := _complete_step(p)) is not None]
    return max(steps)[1] if steps else None


def _next_slot(path_base):
    """Return the file to overwrite: a missing or incomplete one, else the older one."""
    paths = checkpoint_paths(path_base)
    steps = [_complete_step(p) for p in paths]
    for path, step in zip(paths, steps):
        if step is None:
            return path
    return paths[int(np.argmin(steps))]


def _agreed_specs(comm, fields):
    """Return {name: (trailing, dtype)} agreed by all ranks (collective).

    Ranks with rows decide the trailing shapes, since an empty rank may hand
    ``(0,)`` for a ``(0, 2)`` field.
    """
    nrows = len(np.asarray(fields.get("id", ())).reshape(-1))
    local = {k: (tuple(np.shape(v)[1:]), np.asarray(v).dtype.str) for k, v in fields.items()}
    everyone = comm.allgather((nrows, local))
    names = {frozenset(spec) for _, spec in everyone}
    deciders = [spec for n, spec in everyone if n > 0] or [everyone[0][1]]
    specs = deciders[0]
    ok = len(names) == 1 and all(d == specs for d in deciders) and "id" in specs
    if not ok:
        raise ValueError("checkpoint fields differ between ranks (names, shapes or dtypes) "
                         "or lack 'id'")
    out = {k: (trailing, np.dtype(dt)) for k, (trailing, dt) in sorted(specs.items())}
    out["id"] = ((), np.dtype(np.int64))
    return out


def write_checkpoint(path_base, comm, time, step, fields, attrs, *, n_total=None, mode="mpio",
                     path=None):
    """Write a checkpoint of every particle field (collective).

    Parameters
    ----------
    path_base : str or os.PathLike
        Common prefix; the file written is one of :func:`checkpoint_paths`.
    comm : mpi4py.MPI.Comm
        Communicator; every rank calls, also with zero particles.
    time : float
        Simulation time.
    step : int
        Step number; reading picks the complete checkpoint with the largest step.
    fields : dict of str to numpy.ndarray
        This rank's particles, ``"id"`` included, rows in any order.
    attrs : dict
        JSON-serialisable run state (dt, work of external forces, ...).
    n_total : int, optional
        Number of particle ids; default ``attrs["n_total"]`` or the largest id + 1.
    mode : {"mpio", "gather"}, optional
        Parallel HDF5 (default) or gather to rank 0 and write with plain h5py.
    path : str, optional
        Write this file instead of the next of the two alternating ones (the last good state
        goes to its own file this way and never replaces a regular checkpoint).

    Returns
    -------
    str
        The file written.

    Raises
    ------
    ValueError
        On every rank, if the fields differ between ranks or carry bad ids.
    pmpm.errors.OutputWriteError
        On every rank, if the file cannot be written (a full disk, say); the other checkpoint
        file is untouched.
    """
    rank, size = comm.Get_rank(), comm.Get_size()
    specs = _agreed_specs(comm, fields)
    if n_total is None:
        ids = np.asarray(fields["id"]).reshape(-1)
        n_total = attrs.get("n_total") or comm.allreduce(int(ids.max()) + 1 if len(ids) else 0, op=MPI.MAX)
    n_total = int(n_total)
    message = validate_rows(fields, specs, n_total)
    check_all(comm, message is None, message)
    gather = mode == "gather" or (size > 1 and not mpio_available())
    bounds = owner_bounds(n_total, size, gather=gather)
    blocks, duplicates = to_id_blocks(comm, fields, specs, bounds)
    check_all(comm, duplicates == 0, f"{duplicates} particle ids appear more than once")
    path = comm.bcast((path or _next_slot(path_base)) if rank == 0 else None)
    # Written whole under a fresh temporary name (created exclusively: never a user's file or a
    # link), then renamed into place by rank 0: a checkpoint is there complete with its
    # ownership record, or not at all, whatever rank is killed when (the old file stays until
    # the rename).
    tmp = comm.bcast(_temp_name(path) if rank == 0 else None)
    state = {**attrs, "time": float(time), "step": int(step), "n_total": n_total}
    error = None
    if not gather or rank == 0:
        try:
            _write_file(tmp, comm if not gather and size > 1 else None, state, specs, blocks,
                        int(bounds[rank]))
        except (OSError, RuntimeError, ValueError) as exc:  # h5py reports a full disk as any of these
            error = _write_reason(exc)
    reasons = [r for r in comm.allgather(error) if r is not None]
    if not reasons and rank == 0:
        try:
            check_target(path)  # nothing but pmpm's own file is replaced (checked at start too)
            os.replace(tmp, path)
        except OSError as exc:
            error = _write_reason(exc)
        except Exception as exc:  # noqa: BLE001 - a ForeignFileError at the name; said on every rank
            error = str(exc)
    reasons = reasons or [r for r in comm.allgather(error if rank == 0 else None) if r is not None]
    if reasons:
        if rank == 0:
            try:
                os.remove(tmp)
            except OSError:
                pass
        raise OutputWriteError(path, reasons[0])
    # No rank returns before the file is complete (a caller may read it at once)
    comm.Barrier()
    logger.info("checkpoint step %d (t=%g) written to %s", step, time, path)
    return path


def _write_reason(exc):
    """A short reason for a failed write (errno text if any: 'No space left on device')."""
    import errno
    text = str(exc)
    if getattr(exc, "user_reason", False):  # a reason written for the user (hdf5.LayoutError)
        return text
    for code in (errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EROFS, errno.EIO):
        name = os.strerror(code)
        if name in text or getattr(exc, "errno", None) == code:
            return name
    return getattr(exc, "strerror", None) or type(exc).__name__


def _temp_name(path):
    """A fresh hidden name beside ``path`` for its temporary (the file itself is created
    exclusively by :func:`_write_file`, mode ``w-``)."""
    import secrets
    folder, name = os.path.split(os.fspath(path))
    return os.path.join(folder, f".{name}.{secrets.token_hex(6)}.pmpm-tmp")


def _write_file(path, comm, state, specs, blocks, start):
    """Create one checkpoint file; ``comm`` is given for the mpio driver, else None. The file
    must not exist (mode ``w-``: created exclusively, never through a link)."""
    kwargs = {"driver": "mpio", "comm": comm} if comm is not None else {}
    with h5py.File(path, "w-", **kwargs) as f:
        f.attrs["complete"] = False
        f.attrs["layout"] = LAYOUT
        for key in ("time", "step", "n_total"):
            f.attrs[key] = state[key]
        f.attrs["attrs"] = json_dumps(state)
        if isinstance(state.get("pmpm_owner"), str):  # the record pmpm.io.ownership reads
            f.attrs["pmpm_owner"] = state["pmpm_owner"]
        grp = f.create_group("particles")
        for name, (trailing, dtype) in specs.items():
            dset = grp.create_dataset(name, (state["n_total"],) + trailing, dtype,
                                      fillvalue=fill_value(dtype))
            write_rows(dset, (), start, blocks[name], comm is not None)
        # Data reaches the disk before the flag that vouches for it
        f.flush()
        f.attrs["complete"] = True
        f.flush()


def read_checkpoint(path_base, comm, path=None):
    """Read the newest complete checkpoint; rank ``r`` gets id block ``r`` (collective).

    Parameters
    ----------
    path_base : str or os.PathLike
        Common prefix of the checkpoint files.
    comm : mpi4py.MPI.Comm
        Communicator of the reading ranks (any size, not necessarily the writer's).
    path : str, optional
        Read this complete checkpoint file (e.g. :func:`lastgood_path`) instead of the newest
        of the two alternating ones.

    Returns
    -------
    fields : dict of str to numpy.ndarray
        The existing particles of ids ``block_range(n_total, size, rank)`` (rows of
        removed particles dropped), in id order.
    attrs : dict
        The dict given to :func:`write_checkpoint` plus ``time``, ``step`` and
        ``n_total``.

    Raises
    ------
    FileNotFoundError
        If neither checkpoint file exists.
    ValueError
        If the files exist but none is complete.
    """
    paths = checkpoint_paths(path_base)
    if path is not None:
        why = comm.bcast(_checkpoint_step(path)[1] if comm.Get_rank() == 0 else None)
        if why is not None:  # the file named: its own reason, in the one error line
            raise ValueError(f"{path} is not a usable pmpm checkpoint: {why}")
    path = path or comm.bcast(latest_checkpoint(path_base) if comm.Get_rank() == 0 else None)
    if path is None:
        existing = comm.bcast([p for p in paths if os.path.exists(p)] if comm.Get_rank() == 0 else None)
        if not existing:
            raise FileNotFoundError(f"no checkpoint found: neither {paths[0]} nor {paths[1]} exists")
        raise ValueError(f"no complete checkpoint: {', '.join(existing)} cut short or unreadable")
    # rank 0 checks the whole file before any rank uses it: every dataset's shape and dtype,
    # the counts, the attributes, no links out of the file (pmpm.io.validate)
    problem = None
    if comm.Get_rank() == 0:
        try:
            with h5py.File(path, "r") as f:
                check_checkpoint_schema(f, LAYOUT)
        except ValueError as exc:
            problem = str(exc)
        except (OSError, RuntimeError, KeyError, TypeError) as exc:
            problem = f"an object cannot be read ({type(exc).__name__})"
    problem = comm.bcast(problem)
    if problem:
        raise ValueError(f"{path}: not a usable pmpm checkpoint: {problem}")
    # Reads are independent (each rank its own block): plain h5py is enough
    with h5py.File(path, "r") as f:
        attrs = json.loads(f.attrs["attrs"])
        count, start = block_range(int(f.attrs["n_total"]), comm.Get_size(), comm.Get_rank())
        grp = f["particles"]
        fields = {name: grp[name][start:start + count] for name in grp}
    keep = fields["id"] != -1
    fields = {name: arr[keep] for name, arr in fields.items()}
    logger.info("read checkpoint %s (step %s): %d particles on this rank", path,
                attrs.get("step"), int(keep.sum()))
    return fields, attrs
