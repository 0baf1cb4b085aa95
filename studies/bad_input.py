"""Generated bad input (hypothesis): does every entry point keep pmpm's promise?

The promise (docs/scenes.md, tests/integration/test_bad_input.py): bad input gives exit code 2
and exactly one printable line ``pmpm: error: <file or subcommand>: <reason>`` on standard
error, no traceback, nothing written, nothing outside the folder, no foreign file changed.

Four generators, each a hypothesis strategy over mutations of something valid:

- ``scene``: a valid scene (every body shape, a boundary, loads, a track, a stop, a variant)
  with one or more keys replaced by a generated value of another type or range (numbers of
  every size, nan/inf, strings with control characters and paths, lists, tables), deleted,
  or joined by an unknown key; checked with ``pmpm case.toml --check``.
- ``file``: the results file of a real run with one object deleted, retyped, reshaped, a link
  (soft, external, a loop) put in its place, an attribute changed, or its bytes cut or flipped;
  given to ``pmpm plot``, ``pmpm export`` (VTU, XDMF).
- ``restart``: the same mutations of the run's checkpoints, given to ``--restart``; a mutation
  of a particle array's shape, dtype or the particle count must be refused.
- ``api``: :func:`pmpm.run` and :func:`pmpm.load_scene` with generated arguments (variant,
  overrides, write, comm, progress, dataframes).
- ``outputs``: what sits in the output folder before a run (issue 35): at one of the run's
  output names, its old temporary names or the manifest, a symbolic link to a file outside the
  folder, a dangling link, a FIFO, a folder, a user's file, a hard link of the scene, a garbage
  or deeply nested manifest; the run (``case.toml --variant stiff --no-plots``) must refuse in
  one line or leave the planted thing exactly as it was, write nothing outside the folder and
  never hang.

Each case runs in-process (:func:`cli_in_process`), in a fresh folder with a foreign file of the
user beside it; :func:`promise_broken` says what a case broke, if anything. The CI test
(tests/integration/test_bad_input_generated.py) runs a fixed, derandomized budget; this module's
command runs a longer one and prints the count of cases and of broken promises per generator::

    python -m studies.bad_input --cases 2000
"""
import argparse
import contextlib
import hashlib
import io
import json
import logging
import math
import os
import shutil
import stat
import sys
import tempfile
import warnings

import numpy as np

__all__ = ["BASE_SCENE", "to_toml", "cli_in_process", "tree", "promise_broken", "scene_cases",
           "file_cases", "restart_cases", "api_cases", "output_cases", "make_finished_run", "main"]

#: a small valid scene that holds every kind of table a scene can have (docs/scenes.md)
BASE_SCENE = {
    "title": "generated",
    "grid": {"cell_size": 0.5, "cells": [12, 6], "origin": [0.0, 0.0]},
    "materials": {
        "steel": {"type": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0},
        "soft": {"type": "bilinear_vonmises", "E": 100.0, "nu": 0.3, "density": 1.0, "yield_stress": 1.0,
                 "hardening": 0.1},
    },
    "bodies": [
        {"name": "block", "shape": "rectangle", "material": "steel", "lower": [0.5, 0.5],
         "upper": [2.0, 1.5], "velocity": [0.1, 0.0]},
        {"name": "disc", "shape": "circle", "material": "soft", "center": [3.5, 1.0], "radius": 0.4,
         "velocity": ["0.01*x", 0.0]},
        {"name": "tri", "shape": "polygon", "material": "steel",
         "vertices": [[4.5, 0.5], [5.5, 0.5], [5.0, 1.5]]},
    ],
    "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [6.0, 0.0]}],
    "loads": {"gravity": [0.0, -0.1],
              "forces": [{"name": "push", "lower": [0.5, 1.0], "upper": [1.0, 1.5],
                          "force": [0.01, 0.0]}]},
    "solver": {"end_time": 0.01, "cfl": 0.5},
    "output": {"interval": 0.005, "fields": ["x", "v", "stress"],
               "track": [{"name": "tip", "point": [2.0, 1.0]}]},
    "stop": [{"track": "tip", "quantity": "ux", "above": 10.0}],
    "variants": {"stiff": {"materials.steel.E": 200.0}},
}

#: strings an attacker or a careless user puts anywhere: paths out of the folder, devices,
#: control characters, expression escapes, reserved and empty names
ATTACK_STRINGS = [
    "", " ", "..", "../../../x", "/etc/passwd", "/dev/zero", "/proc/self/mem", "a/b", "a\\b",
    "CON", "nul.txt", "time", "a\nb", "a\rb", "\x1b[31mred\x1b[0m", "a\x00b", "\u202eevil",
    "é", "x" * 300, "1e400", "nan", "inf", "x**1000", "10**10**10", "__import__('os')",
    "().__class__", "open('x','w')", "exp(1000*x)", "x/0", "sqrt(-1-x)", "0.1*sin(x)",
]
#: numbers at every edge of double precision and of pmpm's bounds
EDGE_NUMBERS = [0, -1, 1, 2, 3, -0.0, 0.5, 1e-320, 5e-324, 1e-12, 1e15, 1e100, 1.1e100, 1e154,
                1e200, 1e308, -1e308, float("inf"), float("-inf"), float("nan"), 2 ** 31, 2 ** 63 - 1,
                -2 ** 63, 2 ** 64, 10 ** 30]


# ------------------------------------------------------------------------------ TOML writer
def _toml_value(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value).replace("\\/", "/")  # JSON escapes are TOML basic-string escapes
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value).__name__)


def to_toml(data):
    """TOML text of ``data`` (every key quoted, every table inline: any dict tomllib reads)."""
    return "".join(f"{json.dumps(str(k))} = {_toml_value(v)}\n" for k, v in data.items())


# ------------------------------------------------------------------------------ running a case
def tree(root):
    """Every path below ``root`` with a digest of its content."""
    out = {}
    for base, dirs, files in os.walk(root):
        for d in dirs:
            out[os.path.relpath(os.path.join(base, d), root)] = "dir"
        for f in files:
            p = os.path.join(base, f)
            if os.path.islink(p):
                out[os.path.relpath(p, root)] = "link:" + os.readlink(p)
                continue
            with open(p, "rb") as fh:
                out[os.path.relpath(p, root)] = hashlib.sha256(fh.read()).hexdigest()
    return out


@contextlib.contextmanager
def _isolated(cwd):
    """Run in ``cwd`` with the process-wide state the command line changes put back after."""
    old_cwd, hook, err = os.getcwd(), sys.excepthook, np.geterr()
    logger = logging.getLogger("pmpm")
    handlers, level = logger.handlers[:], logger.level
    py_warnings = logging.getLogger("py.warnings")
    propagate = py_warnings.propagate
    os.chdir(cwd)
    try:
        with warnings.catch_warnings():
            yield
    finally:
        os.chdir(old_cwd)
        sys.excepthook = hook
        np.seterr(**err)
        logging.captureWarnings(False)
        py_warnings.propagate = propagate
        logger.handlers[:], logger.level = handlers, level


#: exit codes met, over every case run in this process (the study reports them)
OUTCOMES = {}


def cli_in_process(argv, cwd):
    """``pmpm argv`` in this process: (exit code, stdout, stderr, exception or None)."""
    from pmpm.cli import main
    out, err = io.StringIO(), io.StringIO()
    code, exc = None, None
    with _isolated(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as e:  # argparse
            code = e.code if isinstance(e.code, int) else 2
        except BaseException as e:  # noqa: BLE001 - a traceback is what the promise forbids
            exc = e
    key = f"exit {code}" if exc is None else type(exc).__name__
    OUTCOMES[key] = OUTCOMES.get(key, 0) + 1
    return code, out.getvalue(), err.getvalue(), exc


def promise_broken(code, err, exc, before, after, codes=(0, 2), prefix=None):
    """What a case broke, or None: its exit code is one of ``codes``; an exit 2 says exactly
    one printable line ``pmpm: error: <prefix>...`` and leaves the tree as it was."""
    if exc is not None:
        return f"uncaught {type(exc).__name__}: {str(exc)[:120]!r}"
    if code not in codes:
        return f"exit code {code!r}; stderr {err[-200:]!r}"
    if "Traceback" in err:
        return "a traceback on stderr"
    if code == 2:
        lines = err.splitlines()
        if len(lines) != 1:
            return f"{len(lines)} lines on stderr: {err[:300]!r}"
        line = lines[0]
        if not line.startswith("pmpm: error: ") or ": " not in line[len("pmpm: error: "):]:
            return f"not 'pmpm: error: <where>: <reason>': {line[:200]!r}"
        if prefix and not line.startswith("pmpm: error: " + prefix):
            return f"does not name {prefix!r}: {line[:200]!r}"
        if not line.isprintable():
            return f"unprintable characters: {line[:200]!r}"
        if before != after:
            changed = sorted(set(before) ^ set(after)) + sorted(k for k in before if k in after
                                                                and before[k] != after[k])
            return f"refused but changed files: {changed[:5]}"
    return None


# ------------------------------------------------------------------------------ strategies
def _leaves(data, prefix=()):
    """Every key path of ``data`` (tables, arrays of tables and values), as tuples."""
    out = []
    if isinstance(data, dict):
        for k, v in data.items():
            out.append(prefix + (k,))
            out += _leaves(v, prefix + (k,))
    elif isinstance(data, list) and data and all(isinstance(v, dict) for v in data):
        for i, v in enumerate(data):
            out.append(prefix + (i,))
            out += _leaves(v, prefix + (i,))
    elif isinstance(data, list):
        for i in range(len(data)):
            out.append(prefix + (i,))
    return out


def _values(st):
    """Generated values of every TOML type, weighted to the edges."""
    scalars = st.one_of(
        st.sampled_from(EDGE_NUMBERS), st.sampled_from(ATTACK_STRINGS), st.booleans(),
        st.integers(min_value=-2 ** 70, max_value=2 ** 70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=12))
    return st.recursive(scalars, lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(["a", "x", "name", "type"]), inner,
                                                     max_size=3)), max_leaves=6)


def _set(data, path, value, delete=False):
    node = data
    for k in path[:-1]:
        node = node[k]
    if delete:
        if isinstance(node, dict):
            node.pop(path[-1], None)
        else:
            node.pop(path[-1])
    else:
        node[path[-1]] = value


def scene_cases(st):
    """Strategy of mutated scene dicts (a deep copy of BASE_SCENE, 1 to 3 mutations)."""
    paths = _leaves(BASE_SCENE)

    @st.composite
    def mutated(draw):
        data = json.loads(json.dumps(BASE_SCENE))
        for _ in range(draw(st.integers(1, 3))):
            current = _leaves(data)
            if not current:
                break
            op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown", "scale"]))
            path = draw(st.sampled_from([p for p in paths if p in current] or current))
            if op == "replace":
                _set(data, path, draw(_values(st)))
            elif op == "delete":
                _set(data, path, None, delete=True)
            elif op == "unknown":
                parent = data
                for k in path[:-1]:
                    parent = parent[k]
                if isinstance(parent, dict):
                    parent[draw(st.sampled_from(["colour", "a\nb", "\x1b[2J", "E ", "..", ""]))] = 1
            else:  # a number scaled to an extreme
                node = data
                for k in path[:-1]:
                    node = node[k]
                value = node[path[-1]]
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    node[path[-1]] = value * draw(st.sampled_from([1e300, -1e300, 1e-300, 1e100, 0]))
        return data

    return mutated()


#: mutations of an HDF5 object (dataset or group) or attribute, by name
H5_OPS = ("delete", "strings", "flatten", "extra_column", "to_int", "empty", "scalar",
          "soft_link_missing", "soft_link_loop", "external_link", "attr_string", "attr_nan",
          "attr_delete", "attr_array", "attr_huge", "truncate", "flip_bytes", "external_vds")


def _h5_objects(path):
    import h5py
    names = []
    with h5py.File(path, "r") as f:
        f.visit(lambda n: names.append(n) if "views/" not in n else None)
    return ["/" + n for n in names] + ["/"]


def mutate_h5(path, op, target, attr, where):
    """Apply ``op`` to object ``target`` (attribute ``attr``) of the HDF5 file ``path``."""
    import h5py
    if op == "truncate":
        size = os.path.getsize(path)
        with open(path, "r+b") as fh:
            fh.truncate(int(size * where))
        return
    if op == "flip_bytes":
        size = os.path.getsize(path)
        with open(path, "r+b") as fh:
            fh.seek(int((size - 64) * where))
            fh.write(os.urandom(32))
        return
    with h5py.File(path, "r+") as f:
        obj = f[target] if target != "/" else f
        parent = f[os.path.dirname(target)] if target != "/" else None
        name = os.path.basename(target)
        if op.startswith("attr_"):
            keys = list(obj.attrs) or ["layout"]
            key = attr if attr in keys else keys[int(where * len(keys)) % len(keys)]
            if op == "attr_delete":
                obj.attrs.pop(key, None) if key in obj.attrs else None
            else:
                obj.attrs[key] = {"attr_string": "garbage\n", "attr_nan": np.nan,
                                  "attr_array": np.arange(3.0), "attr_huge": 2 ** 62}[op]
            return
        if parent is None:
            return
        if op == "delete":
            del parent[name]
        elif op in ("soft_link_missing", "soft_link_loop", "external_link"):
            del parent[name]
            parent[name] = {"soft_link_missing": h5py.SoftLink("/nowhere"),
                            "soft_link_loop": h5py.SoftLink(target),
                            "external_link": h5py.ExternalLink("/etc/passwd", "/x")}[op]
        elif op == "external_vds" and isinstance(obj, h5py.Dataset) and obj.ndim >= 1:
            shape, dtype = obj.shape, obj.dtype
            del parent[name]
            layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
            layout[...] = h5py.VirtualSource("/etc/other.h5", "/x", shape=shape, dtype=dtype)
            parent.create_virtual_dataset(name, layout, fillvalue=0)
        elif isinstance(obj, h5py.Dataset):
            data, attrs = obj[()], dict(obj.attrs)
            if op == "strings":
                new = np.full(np.shape(data), b"x", dtype="S4")
            elif op == "flatten":
                new = np.asarray(data).reshape(-1)
            elif op == "extra_column":
                a = np.asarray(data)
                new = np.concatenate([a.reshape(a.shape + (1,)) if a.ndim < 2 else a,
                                      np.zeros(a.shape[:-1] + (1,) if a.ndim >= 2 else a.shape + (1,),
                                               dtype=a.dtype)], axis=-1)
            elif op == "to_int":
                new = np.nan_to_num(np.asarray(data, dtype=float)).astype(np.int8) \
                    if np.asarray(data).dtype.kind in "fiub" else np.zeros(np.shape(data), np.int8)
            elif op == "empty":
                new = np.zeros((0,) + np.shape(data)[1:], dtype=np.asarray(data).dtype)
            else:  # scalar
                new = np.float64(1.0)
            del parent[name]
            d = parent.create_dataset(name, data=new)
            for k, v in attrs.items():
                d.attrs[k] = v


def file_cases(st, objects):
    """Strategy of (command, op, target, attribute, where) for ``pmpm plot|export``."""
    return st.tuples(st.sampled_from(["plot", "export-vtu", "export-xdmf"]), st.sampled_from(H5_OPS),
                     st.sampled_from(objects), st.sampled_from(["layout", "n_total", "columns", "units",
                                                                "scene_file", "particle_id", "kind"]),
                     st.floats(0.0, 1.0))


def restart_cases(st, objects):
    """Strategy of (op, target, attribute, where, both files) for ``--restart``."""
    return st.tuples(st.sampled_from(H5_OPS), st.sampled_from(objects),
                     st.sampled_from(["attrs", "n_total", "time", "step", "complete", "layout"]),
                     st.floats(0.0, 1.0), st.booleans())


def api_cases(st):
    """Strategy of keyword arguments of pmpm.run / pmpm.load_scene."""
    paths = [".".join(str(k) for k in p) for p in _leaves(BASE_SCENE) if p[0] != "variants"]
    junk = st.one_of(st.none(), st.sampled_from(ATTACK_STRINGS), st.integers(-5, 5), st.booleans(),
                     st.just([1]), st.just({"a": 1}), st.just(object))
    overrides = st.one_of(st.none(), st.dictionaries(st.one_of(st.sampled_from(paths), st.sampled_from(ATTACK_STRINGS)),
                                                     _values(st), max_size=2), junk)
    return st.fixed_dictionaries({
        "entry": st.sampled_from(["run", "load_scene"]),
        "variant": st.one_of(st.none(), st.just("stiff"), junk),
        "overrides": overrides, "write": st.one_of(st.booleans(), junk),
        "comm": st.one_of(st.none(), junk), "progress": st.one_of(st.none(), st.booleans(), junk),
        "dataframes": st.one_of(st.none(), st.just(False), junk)})


# ------------------------------------------------------------------------------ the cases
FOREIGN = "notes.txt"  # the user's own file, in the output folder beside pmpm's


def make_finished_run(folder):
    """A real run of BASE_SCENE (its first variant) with checkpoints, in ``folder``."""
    data = json.loads(json.dumps(BASE_SCENE))
    data["output"]["checkpoint_interval"] = 0.005
    data.pop("variants")
    with open(os.path.join(folder, "case.toml"), "w") as fh:
        fh.write(to_toml(data))
    code, out, err, exc = cli_in_process(["case.toml", "-q"], folder)
    if exc is not None or code != 0:
        raise RuntimeError(f"the base run failed: {code} {err[-500:]} {exc!r}")
    with open(os.path.join(folder, "case_results", FOREIGN), "w") as fh:
        fh.write("my own notes\n")
    return folder


def check_scene(data, root):
    """One generated scene through ``pmpm case.toml --check``: what broke, or None."""
    work = os.path.join(root, "a", "b")
    os.makedirs(work)
    with open(os.path.join(root, FOREIGN), "w") as fh:
        fh.write("mine\n")
    try:
        text = to_toml(data)
    except TypeError:
        return None
    with open(os.path.join(work, "case.toml"), "w", encoding="utf-8") as fh:
        fh.write(text)
    before = tree(root)
    code, _out, err, exc = cli_in_process(["case.toml", "--check"], work)
    # --check writes nothing, valid or not
    broken = promise_broken(code, err, exc, before, tree(root))
    if broken is None and code == 0 and tree(root) != before:
        broken = "--check wrote a file"
    return broken


def check_file(case, run_dir, root):
    """One broken results file through plot or export: what broke, or None."""
    command, op, target, attr, where = case
    work = os.path.join(root, "w")
    shutil.copytree(run_dir, work, symlinks=True)
    h5 = os.path.join("case_results", "case.h5")
    try:
        mutate_h5(os.path.join(work, h5), op, target, attr, where)
    except (KeyError, ValueError, TypeError, OSError):
        return None  # the mutation does not apply to this object
    argv = {"plot": ["plot", h5], "export-vtu": ["export", h5],
            "export-xdmf": ["export", h5, "--format", "xdmf", "-o", "xd"]}[command]
    before = tree(root)
    code, _out, err, exc = cli_in_process(argv, work)
    after = tree(root)
    broken = promise_broken(code, err, exc, before, after, prefix=h5)
    if broken is None and before.get(f"w/case_results/{FOREIGN}") != after.get(f"w/case_results/{FOREIGN}"):
        broken = "the user's file changed"
    return broken


#: checkpoint mutations that change what a restart would continue from: must be refused
_MUST_REFUSE = {"strings", "flatten", "extra_column", "empty", "scalar", "soft_link_missing",
                "soft_link_loop", "external_link", "external_vds"}


def _layout_of(path, target):
    """(link kind, shape, dtype) of one object of an HDF5 file, or an error's name."""
    import h5py
    try:
        with h5py.File(path, "r") as f:
            link = f.get(target, getlink=True) if target != "/" else None
            obj = f.get(target) if target != "/" else f
            return (type(link).__name__, getattr(obj, "shape", None), str(getattr(obj, "dtype", "")))
    except Exception as exc:  # noqa: BLE001 - a broken file is a layout of its own
        return type(exc).__name__


def check_restart(case, run_dir, root):
    """One broken checkpoint through --restart: what broke, or None."""
    op, target, attr, where, both = case
    work = os.path.join(root, "w")
    shutil.copytree(run_dir, work, symlinks=True)
    paths = [os.path.join(work, "case_results", f"case.ckpt{k}.h5") for k in (0, 1)]
    from pmpm.io.checkpoint import latest_checkpoint
    newest = latest_checkpoint(os.path.join(work, "case_results", "case"))
    layout_before = _layout_of(newest, target)
    try:
        for p in (paths if both else [newest]):
            mutate_h5(p, op, target, attr, where)
    except (KeyError, ValueError, TypeError, OSError):
        return None
    # what must be refused: the newest checkpoint's particle array changed shape, dtype or kind
    changed = layout_before != _layout_of(newest, target)
    before = tree(root)
    code, _out, err, exc = cli_in_process(["case.toml", "--restart", "case_results/case.h5",
                                           "--no-plots", "-q"], work)
    after = tree(root)
    broken = promise_broken(code, err, exc, before, after, codes=(0, 2))
    if broken is None and code == 0 and op in _MUST_REFUSE and target.startswith("/particles/") and changed:
        # the newest complete checkpoint's particle arrays changed their layout: never continue
        # from it silently
        broken = f"restart accepted a checkpoint whose {target} was mutated ({op})"
    if broken is None and before.get(f"w/case_results/{FOREIGN}") != after.get(f"w/case_results/{FOREIGN}"):
        broken = "the user's file changed"
    return broken


def check_api(kwargs, root):
    """One generated call of pmpm.run / pmpm.load_scene: what broke, or None."""
    import pmpm
    from pmpm.errors import ConfigError
    work = os.path.join(root, "a", "b")
    os.makedirs(work)
    data = json.loads(json.dumps(BASE_SCENE))
    data["output"]["directory"] = "out"
    with open(os.path.join(work, "case.toml"), "w") as fh:
        fh.write(to_toml(data))
    with open(os.path.join(root, FOREIGN), "w") as fh:
        fh.write("mine\n")
    kwargs = dict(kwargs)
    entry = kwargs.pop("entry")
    before = tree(root)
    exc = None
    with _isolated(work), contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        try:
            if entry == "run":
                pmpm.run("case.toml", **kwargs)
            else:
                pmpm.load_scene("case.toml", kwargs["variant"], kwargs["overrides"])
        except (ConfigError, TypeError, ValueError) as e:
            exc = e
        except Exception as e:  # noqa: BLE001 - any other exception breaks the promise
            return f"{type(e).__name__}: {str(e)[:150]!r}"
    after = tree(root)
    key = "refused" if exc is not None else "ran"
    OUTCOMES[key] = OUTCOMES.get(key, 0) + 1
    if exc is not None:
        text = str(exc)
        if "\n" in text or not text.isprintable():
            return f"not one printable line: {text[:200]!r}"
        if before != after:
            return "refused but changed files"
        return None
    outside = [k for k in set(after) - set(before) if not k.startswith(os.path.join("a", "b", "out"))]
    if outside:
        return f"wrote outside the output folder: {sorted(outside)[:3]}"
    if after.get(FOREIGN) != before.get(FOREIGN):
        return "the user's file changed"
    return None


# ------------------------------------------------------------------ what sits in the output folder
#: the names one run of BASE_SCENE's variant "stiff" writes (or wrote, as temporaries), and the
#: manifest: every one the gate must guard
OUTPUT_NAMES = ["case_stiff.h5", "case_stiff.xdmf", "case_stiff.ckpt0.h5", "case_stiff.ckpt1.h5",
                "case_stiff.lastgood.h5", "case_stiff_history_tip.csv", "case_history_tip.png",
                "case_stiff_energies.png", "case_stiff.xdmf.tmp", "pmpm-files.json"]
#: what is planted there
PLANTED = ["link_outside", "dangling_link", "fifo", "folder", "user_file", "hardlink_scene",
           "manifest_garbage", "manifest_deep"]


def output_cases(st):
    """Strategy of (output name, planted thing) pairs, one or two of them."""
    return st.lists(st.tuples(st.sampled_from(OUTPUT_NAMES), st.sampled_from(PLANTED)),
                    min_size=1, max_size=2, unique_by=lambda c: c[0])


def _plant(folder, outside, scene, name, what):
    path = os.path.join(folder, name)
    if what == "link_outside":
        os.symlink(outside, path)
    elif what == "dangling_link":
        os.symlink(outside + ".missing", path)
    elif what == "fifo":
        os.mkfifo(path)
    elif what == "folder":
        os.mkdir(path)
    elif what == "hardlink_scene":
        os.link(scene, path)
    else:
        body = {"user_file": b"the user's own\n", "manifest_garbage": b"\x00\xff{garbage",
                "manifest_deep": b"[" * 5000 + b"]" * 5000}[what]
        with open(path, "wb") as fh:
            fh.write(body)


def _planted_state(folder, outside, names):
    """What the planted things are now: each one's kind and content, and the outside file."""
    state = {}
    for name in names:
        path = os.path.join(folder, name)
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            state[name] = None
            continue
        if stat.S_ISLNK(mode):
            state[name] = ("link", os.readlink(path))
        elif stat.S_ISREG(mode):
            with open(path, "rb") as fh:
                state[name] = ("file", hashlib.sha256(fh.read()).hexdigest())
        else:
            state[name] = ("special", stat.S_IFMT(mode))
    with open(outside, "rb") as fh:
        state["<outside>"] = fh.read()
    state["<outside missing>"] = os.path.lexists(outside + ".missing")
    return state


def check_outputs(case, root):
    """One output folder laid out by ``case`` through a run: what broke, or None."""
    work = os.path.join(root, "w")
    out = os.path.join(work, "case_results")
    os.makedirs(out)
    scene = os.path.join(work, "case.toml")
    with open(scene, "w", encoding="utf-8") as fh:
        fh.write(to_toml(BASE_SCENE))
    outside = os.path.join(root, "outside.txt")
    with open(outside, "w") as fh:
        fh.write("outside the folder\n")
    names = [name for name, _ in case]
    for name, what in case:
        if what.startswith("manifest_") and name != "pmpm-files.json":
            what = "user_file"
        _plant(out, outside, scene, name, what)
    before = _planted_state(out, outside, names)
    with open(scene, "rb") as fh:
        scene_bytes = fh.read()
    tree_before = tree(root) if all(w not in ("fifo",) for _, w in case) else None
    code, _out, err, exc = cli_in_process(["case.toml", "--variant", "stiff", "--no-plots", "-q"], work)
    broken = promise_broken(code, err, exc, {}, {}, codes=(0, 2))
    if broken is not None:
        return broken
    if _planted_state(out, outside, names) != before:
        return f"a planted thing changed (exit {code}): {case}"
    with open(scene, "rb") as fh:
        if fh.read() != scene_bytes:
            return "the scene changed"
    if code == 2 and tree_before is not None and tree(root) != tree_before:
        return "refused but wrote files"
    return None


# ------------------------------------------------------------------------------ the study
def run_generator(kind, cases, derandomize, collect, seed=0):
    """Run ``cases`` generated cases of ``kind``; return (count, [broken promises]).

    ``collect=False`` raises AssertionError at the first broken promise (the CI test, with
    hypothesis shrinking it); True counts them all (the study)."""
    from hypothesis import HealthCheck, given, settings, strategies as st
    broken, count = [], [0]
    base = tempfile.mkdtemp(prefix="pmpm-bad-input-")
    try:
        run_dir = None
        if kind in ("file", "restart"):
            run_dir = make_finished_run(tempfile.mkdtemp(dir=base))
            h5 = os.path.join(run_dir, "case_results", "case.h5" if kind == "file" else "case.ckpt0.h5")
            objects = _h5_objects(h5)
            strategy = file_cases(st, objects) if kind == "file" else restart_cases(st, objects)
        else:
            strategy = {"scene": scene_cases, "api": api_cases, "outputs": output_cases}[kind](st)
        checker = {"scene": lambda c, r: check_scene(c, r), "api": lambda c, r: check_api(c, r),
                   "outputs": lambda c, r: check_outputs(c, r),
                   "file": lambda c, r: check_file(c, run_dir, r),
                   "restart": lambda c, r: check_restart(c, run_dir, r)}[kind]

        @settings(max_examples=cases, derandomize=derandomize, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck), print_blob=False)
        @given(strategy)
        def one(case):
            count[0] += 1
            root = tempfile.mkdtemp(dir=base)
            try:
                what = checker(case, root)
            finally:
                shutil.rmtree(root, ignore_errors=True)
            if what is not None:
                if not collect:
                    raise AssertionError(f"{kind} case {case!r}: {what}")
                broken.append((repr(case)[:300], what))

        if not derandomize:
            from hypothesis import seed as hseed
            one = hseed(seed)(one)
        one()
    finally:
        shutil.rmtree(base, ignore_errors=True)
    return count[0], broken


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.bad_input",
                                description="Generated bad input against pmpm's promise.")
    p.add_argument("--cases", type=int, default=2000, help="cases in all, shared by the generators")
    p.add_argument("--kinds", nargs="+", default=["scene", "file", "restart", "api", "outputs"],
                   choices=["scene", "file", "restart", "api", "outputs"])
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    share = {"scene": 0.45, "file": 0.18, "restart": 0.13, "api": 0.13, "outputs": 0.11}
    total = sum(share[k] for k in args.kinds)
    report = {}
    import time
    for kind in args.kinds:
        n = max(1, int(args.cases * share[kind] / total))
        t0 = time.perf_counter()
        OUTCOMES.clear()
        count, broken = run_generator(kind, n, derandomize=False, collect=True, seed=args.seed)
        report[kind] = {"cases": count, "broken": len(broken), "seconds": round(time.perf_counter() - t0, 1),
                        "outcomes": dict(sorted(OUTCOMES.items()))}
        print(f"{kind}: {count} cases, {len(broken)} broken promises, {report[kind]['seconds']} s, "
              f"exit codes {report[kind]['outcomes']}")
        for case, what in broken[:10]:
            print(f"  {what}\n    {case}")
    print(json.dumps({"study": "bad_input", "seed": args.seed, **report}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
