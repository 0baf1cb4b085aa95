"""The part of a resolved scene a checkpoint belongs to, and what may change on restart.

Each checkpoint records :func:`scene_record` (the resolved scene as flat ``dotted.key -> value``
pairs, without the keys in :data:`CHANGEABLE_ON_RESTART`) and its SHA-256 :func:`fingerprint`.
``--restart`` compares the record of the checkpoint with the scene's and refuses the first key
that differs (:func:`first_difference`), so a checkpoint of another scene, or of this scene
with another geometry, material or grid, is never continued.
"""
import hashlib
import json
import math

__all__ = ["scene_record", "fingerprint", "first_difference", "CHANGEABLE_ON_RESTART"]

#: keys (or key prefixes) that may differ between a checkpoint and the scene that continues it
CHANGEABLE_ON_RESTART = (
    "path", "title", "variants",
    "solver.end_time", "solver.max_steps", "solver.max_estimated_steps",
    # the step may change, so a diverged run continues from its last good state with a smaller one
    "solver.cfl", "solver.time_step", "solver.allow_unstable_time_step",
    # and so may the implicit solve's controls (not the answer it converges to within them): a
    # run whose Newton iterations failed continues with other tolerances, iterations or solvers
    "solver.implicit.residual_tolerance", "solver.implicit.energy_tolerance",
    "solver.implicit.max_iterations", "solver.implicit.newton", "solver.implicit.line_search",
    "solver.implicit.max_halvings", "solver.implicit.krylov_tolerance", "solver.implicit.krylov_iterations",
    "solver.petsc",
    "output.directory", "output.interval", "output.history_interval",
    "output.checkpoint_interval", "output.progress_interval", "output.deformed_plot",
    "output.hysteresis",
    "parallel.",
    # a stop condition ends a run like end_time does: a stopped run may continue without it
    "stop",
)


def _changeable(key):
    for k in CHANGEABLE_ON_RESTART:
        if k.endswith(".") and key.startswith(k):
            return True
        if key == k or key.startswith(k + ".") or key.startswith(k + "["):
            return True
    return False


def _flatten(value, prefix, out):
    if isinstance(value, dict):
        for k in sorted(value, key=str):
            _flatten(value[k], f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(value, (list, tuple)) and value and any(isinstance(v, (dict, list, tuple)) for v in value):
        for i, v in enumerate(value):
            _flatten(v, f"{prefix}[{i}]", out)
    else:
        out[prefix] = _plain(value)


def _plain(value):
    """JSON-stable form: tuples as lists, floats by repr (exact), others by str."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        return repr(value) if not math.isfinite(value) else value
    return str(value)


def scene_record(scene):
    """``{dotted key: value}`` of the resolved scene without the keys changeable on restart."""
    flat = {}
    _flatten(scene.to_dict(), "", flat)
    return {k: v for k, v in flat.items() if not _changeable(k)}


def fingerprint(record):
    """SHA-256 (hex) of a :func:`scene_record`."""
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()


def first_difference(ours, theirs):
    """The first dotted key (in sorted order) whose value differs, or None (keys changeable on
    restart are skipped on both sides: a checkpoint written when one of them was not recorded
    it)."""
    for key in sorted(k for k in set(ours) | set(theirs) if not _changeable(k)):
        if ours.get(key, "<absent>") != theirs.get(key, "<absent>"):
            return key
    return None
