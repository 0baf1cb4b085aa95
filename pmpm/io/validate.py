"""Every file pmpm reads is checked before it is used.

- :func:`read_regular`: the bytes of a text input (scene file, ground-motion record), opened
  without blocking (a FIFO given as a file never hangs the run), refused unless it is a regular
  file of at most ``max_bytes``.
- :func:`check_regular`: the same kind check for a file another library opens.
- :func:`check_hdf5_readable`: the one check before any HDF5 file is opened (every read entry
  point: results, checkpoints, files at output names): a regular file that does not crash
  libhdf5 in a forked child.
- :func:`check_links`: no soft or external link and no virtual dataset reading another file
  anywhere in an HDF5 file (pmpm writes none; following one could read outside the file or loop).
- :func:`check_results_schema`, :func:`check_checkpoint_schema`: pmpm's own HDF5 files, every
  group, dataset, shape, dtype, count and attribute the readers use (docs/output.md,
  pmpm/io/checkpoint.py), so ``pmpm export``, ``pmpm plot``, :func:`pmpm.load_results` and
  ``--restart`` meet a crafted or damaged file with one line, never a traceback or a silently
  wrong run.

Each raises ValueError with a short reason that never quotes the file's content.
"""
import json
import os
import stat

import numpy as np

from pmpm.files import _not_regular, read_regular  # noqa: F401  (read_regular: re-exported)
from pmpm.files import check_hdf5_readable, crashes_reading  # noqa: F401  (re-exported)

__all__ = ["read_regular", "check_regular", "check_hdf5_readable", "safe_to_open_hdf5",
           "check_links", "check_results_schema",
           "check_checkpoint_schema", "crashes_reading", "FIELD_TRAILING"]

#: the trailing shape of each frame / checkpoint field pmpm writes (docs/output.md); a field not
#: listed is accepted with any trailing shape
FIELD_TRAILING = {"x": (2,), "x0": (2,), "v": (2,), "stress": (4,), "back_stress": (4,),
                  "strain": (3,), "eps_p": (3,), "F": (5,), "id": (), "m": (), "vol": (),
                  "vol0": (), "eps_p_eq": (), "plastic_work": (), "mat": (), "body": ()}
#: deepest group nesting pmpm writes is 3 (/views/frame_NNNNN/<name>); deeper is a crafted file
MAX_DEPTH = 6
#: most objects walked in one file (a results file of 10,000 frames has ~150,000 views)
MAX_OBJECTS = 2_000_000


def check_regular(path):
    """Raise ValueError unless ``path`` (links followed) is a regular file; FileNotFoundError
    if it does not exist."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(_not_regular(st.st_mode))


def safe_to_open_hdf5(path):
    """True if ``path`` is a regular file (not a link, FIFO or device: lstat, never opened)
    whose opening and root attributes do not crash libhdf5 (:func:`check_hdf5_readable`)."""
    try:
        check_hdf5_readable(path, follow_links=False)
    except (OSError, ValueError):
        return False
    return True


def check_links(f):
    """Refuse (ValueError) soft and external links and virtual datasets of other files
    anywhere below the open h5py File ``f``; never follows a link to do so."""
    import h5py
    count = 0
    stack = [("", f, 0)]
    while stack:
        where, group, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise ValueError(f"groups nested deeper than {MAX_DEPTH} at {where or '/'} (a loop?)")
        for name in group:
            count += 1
            if count > MAX_OBJECTS:
                raise ValueError(f"more than {MAX_OBJECTS} objects")
            path = f"{where}/{name}"
            link = group.get(name, getlink=True)
            if isinstance(link, h5py.ExternalLink):
                raise ValueError(f"{path} is an external link (pmpm files hold none)")
            if isinstance(link, h5py.SoftLink):
                raise ValueError(f"{path} is a soft link (pmpm files hold none)")
            obj = group.get(name)
            if isinstance(obj, h5py.Group):
                stack.append((path, obj, depth + 1))
            elif isinstance(obj, h5py.Dataset) and obj.is_virtual:
                if any(src.file_name != "." for src in obj.virtual_sources()):
                    raise ValueError(f"{path} is a virtual dataset reading another file")
            elif not isinstance(obj, h5py.Dataset):
                raise ValueError(f"{path} is not a group or dataset")


def _text(value):
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else value


#: largest step number a checkpoint may carry: exactly representable as a double (the step
#: is written through JSON too) and far beyond any run's solver.max_estimated_steps
MAX_STEP = 2 ** 53


def _integer(attrs, name, where, low=0, high=None):
    value = attrs.get(name)
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        if isinstance(value, (float, np.floating)) and np.isfinite(value) and float(value).is_integer():
            value = int(value)
        else:
            raise ValueError(f"{where} attribute '{name}' is missing or not an integer")
    if value < low:
        raise ValueError(f"{where} attribute '{name}' is below {low}")
    if high is not None and value > high:
        raise ValueError(f"{where} attribute '{name}' is above {high}")
    return int(value)


def _dataset(group, name, where):
    import h5py
    obj = group.get(name)
    if not isinstance(obj, h5py.Dataset):
        raise ValueError(f"{where}/{name} is missing or not a dataset")
    return obj


def _group(f, name):
    import h5py
    obj = f.get(name)
    if not isinstance(obj, h5py.Group):
        raise ValueError(f"/{name} is missing or not a group")
    return obj


def _numeric(dset, where, kinds="fiu"):
    if dset.dtype.kind not in kinds:
        want = {"f": "floating-point", "i": "integer", "iu": "integer"}.get(kinds, "numeric")
        raise ValueError(f"{where} holds {dset.dtype} values, not {want} numbers")


def _columns(attrs, where):
    cols = attrs.get("columns")
    if cols is None:
        return None
    if not isinstance(cols, np.ndarray) or cols.ndim != 1:
        raise ValueError(f"{where} attribute 'columns' is not a list of names")
    try:
        out = [_text(c) for c in cols]
    except (TypeError, ValueError):
        raise ValueError(f"{where} attribute 'columns' is not a list of names") from None
    if not all(isinstance(c, str) for c in out):
        raise ValueError(f"{where} attribute 'columns' is not a list of names")
    return out


def _series(group, where):
    """A group of equal-length 1-D numeric columns, one of them ``time``."""
    _columns(group.attrs, where)
    lengths = set()
    for name in group:
        d = _dataset(group, name, where)
        _numeric(d, f"{where}/{name}")
        if d.ndim != 1:
            raise ValueError(f"{where}/{name} has shape {d.shape}, not one value per row")
        lengths.add(d.shape[0])
    if "time" not in group:
        raise ValueError(f"{where}/time is missing")
    if len(lengths) > 1:
        raise ValueError(f"the columns of {where} have different lengths {sorted(lengths)}")


def check_results_schema(f):
    """Check an open results file against the layout of docs/output.md (ValueError)."""
    check_links(f)
    n = _integer(f.attrs, "n_total", "the root")
    for key in ("scene_file", "variant", "title", "scene"):
        if key in f.attrs and not isinstance(_text(f.attrs[key]), str):
            raise ValueError(f"the root attribute '{key}' is not text")
    if "scene" in f.attrs:
        try:
            json.loads(_text(f.attrs["scene"]))
        except ValueError:
            raise ValueError("the root attribute 'scene' is not JSON") from None
    frames = _group(f, "frames")
    time = _dataset(frames, "time", "/frames")
    _numeric(time, "/frames/time", "f")
    if time.ndim != 1:
        raise ValueError(f"/frames/time has shape {time.shape}, not one time per frame")
    count = time.shape[0]
    step = _dataset(frames, "step", "/frames")
    _numeric(step, "/frames/step", "iu")
    if step.shape != (count,):
        raise ValueError(f"/frames/step has shape {step.shape}, /frames/time {time.shape}")
    for name in frames:
        if name in ("time", "step"):
            continue
        d = _dataset(frames, name, "/frames")
        _numeric(d, f"/frames/{name}")
        trailing = FIELD_TRAILING.get(name)
        if d.ndim < 2 or d.shape[:2] != (count, n) or (trailing is not None and d.shape[2:] != trailing):
            want = (count, n) + (trailing if trailing is not None else ())
            raise ValueError(f"/frames/{name} has shape {d.shape}, expected {want}")
    if "particles" in f:  # layout 3: the per-particle constants, written once (pmpm.io.layout)
        particles = _group(f, "particles")
        for name in particles:
            d = _dataset(particles, name, "/particles")
            _numeric(d, f"/particles/{name}")
            trailing = FIELD_TRAILING.get(name)
            if d.ndim < 1 or d.shape[0] != n or (trailing is not None and d.shape[1:] != trailing):
                want = (n,) + (trailing if trailing is not None else ())
                raise ValueError(f"/particles/{name} has shape {d.shape}, expected {want}")
            if name in frames:
                raise ValueError(f"/particles/{name} is also a frame field")
    if "x" in frames and frames["x"].dtype.kind != "f":
        raise ValueError("/frames/x holds no floating-point positions")
    hist = _group(f, "history")
    columns = _columns(hist.attrs, "/history")
    if columns is None:
        raise ValueError("/history has no 'columns' attribute")
    ht = _dataset(hist, "time", "/history")
    _numeric(ht, "/history/time", "f")
    if ht.ndim != 1:
        raise ValueError(f"/history/time has shape {ht.shape}, not one time per row")
    for name in hist:
        if name == "time":
            continue
        d = _dataset(hist, name, "/history")
        _numeric(d, f"/history/{name}", "f")
        if d.shape != (ht.shape[0], len(columns)):
            raise ValueError(f"/history/{name} has shape {d.shape}, expected "
                             f"{(ht.shape[0], len(columns))}")
        if "particle_id" in d.attrs:
            _integer(d.attrs, "particle_id", f"/history/{name}")
    _series(_group(f, "energies"), "/energies")
    import h5py
    for name, group in f.items():
        if isinstance(group, h5py.Group) and _text(group.attrs.get("kind")) == "series":
            _series(group, f"/{name}")
    for kind in ("sections", "reactions"):
        if kind in f:
            for name, table in _group(f, kind).items():
                if not isinstance(table, h5py.Group):
                    raise ValueError(f"/{kind}/{name} is not a group")
                _series(table, f"/{kind}/{name}")


def check_checkpoint_schema(f, layout):
    """Check an open checkpoint file (pmpm/io/checkpoint.py) and return its ``attrs`` dict."""
    check_links(f)
    if _text(f.attrs.get("layout")) != layout:
        raise ValueError(f"no 'layout' attribute {layout!r}: not a pmpm checkpoint")
    if not bool(f.attrs.get("complete", False)):
        raise ValueError("cut short (not marked complete)")
    n = _integer(f.attrs, "n_total", "the root")
    step = _integer(f.attrs, "step", "the root", high=MAX_STEP)
    t = f.attrs.get("time")
    if not isinstance(t, (float, int, np.floating, np.integer)) or isinstance(t, (bool, np.bool_)):
        raise ValueError("the root attribute 'time' is missing or not a number")
    raw = _text(f.attrs.get("attrs"))
    try:
        attrs = json.loads(raw) if isinstance(raw, str) else None
    except (ValueError, RecursionError):
        attrs = None
    if not isinstance(attrs, dict):
        raise ValueError("the root attribute 'attrs' is not a JSON table")
    if attrs.get("step", step) != step:
        raise ValueError("its step disagrees between the root and 'attrs'")
    if attrs.get("n_total") != n:
        raise ValueError(f"its counts of particle ids disagree (root {n}, attrs {attrs.get('n_total')!r})")
    particles = _group(f, "particles")
    if "id" not in particles or "x" not in particles:
        raise ValueError("it has no particle ids or positions")
    for name in particles:
        d = _dataset(particles, name, "/particles")
        _numeric(d, f"/particles/{name}", "iu" if name == "id" else "fiu")
        trailing = FIELD_TRAILING.get(name)
        if d.ndim < 1 or d.shape[0] != n or (trailing is not None and d.shape[1:] != trailing):
            want = (n,) + (trailing if trailing is not None else ())
            raise ValueError(f"/particles/{name} has shape {d.shape}, expected {want}")
    _numeric(particles["x"], "/particles/x", "f")
    return attrs
