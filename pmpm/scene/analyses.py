"""Scene keys of the structural analyses beyond a time history: ``[pushover]`` (a displacement-
controlled push, pmpm.physics.pushover) and ``[[events]]`` (bodies removed during the run,
pmpm.physics.events). Each returns plain data for the frozen Scene; nothing here runs physics.
"""
from pmpm.errors import ConfigError
from pmpm.physics.pushover import PUSHED_COMPONENT

__all__ = ["parse_pushover", "parse_events"]


def parse_pushover(t, scene):
    """``[pushover]``: the pushed boundary, displacement, duration, ramp, control track, base
    reactions, and the hinge count that makes the mechanism (None: every cut that reaches Mp).
    Returns a dict, or None without the table."""
    if t is None:
        return None
    name = t.string("boundary")
    match = [b for b in scene.boundaries if b.name == name]
    if not match:
        raise ConfigError(t.path("boundary"), f"no [[boundary]] named {name!r}")
    if match[0].type not in PUSHED_COMPONENT:
        raise ConfigError(t.path("boundary"), f"boundary {name!r} is {match[0].type!r}: a pushover drives a "
                                              f"'roller_y' (pushed along x) or 'roller_x' (along y) boundary")
    displacement = t.number("displacement")
    if displacement == 0:
        raise ConfigError(t.path("displacement"), "must not be 0")
    # the control point cannot be pushed further than the grid reaches: a larger target is a
    # typo, and would drive a step-wise velocity no stable step can follow
    extent = max(c * scene.grid.cell_size for c in scene.grid.cells)
    if abs(displacement) > extent:
        raise ConfigError(t.path("displacement"), f"{displacement:g} m is beyond the grid's extent ({extent:g} m)")
    end = scene.solver.end_time
    duration = t.number("duration", end, low=0.0, low_open=True)
    if duration > end * (1 + 1e-12):
        raise ConfigError(t.path("duration"), f"{duration:g} s is beyond solver.end_time = {end:g} s")
    ramp = t.number("ramp", 0.1 * duration, low=0.0)
    if 2 * ramp > duration:
        raise ConfigError(t.path("ramp"), f"two ramps ({2 * ramp:g} s) do not fit in the duration {duration:g} s")
    control = t.string("control")
    tracks = [k.name for k in scene.output.track]
    if control not in tracks:
        raise ConfigError(t.path("control"), f"no [[output.track]] named {control!r}")
    recorded = [b.name for b in scene.boundaries if b.reaction and b.name != name]
    base = t.raw("base", None)
    if base is None:
        base = recorded
    if not isinstance(base, list) or not all(isinstance(b, str) for b in base):
        raise ConfigError(t.path("base"), "must be a list of [[boundary]] names")
    for b in base:
        if b not in recorded:
            raise ConfigError(t.path("base"), f"no recorded reaction {b!r} (recorded: {', '.join(recorded) or 'none'})")
    if not base:
        raise ConfigError(t.path("base"), "needs the base reactions (output.reactions = true or a boundary's "
                                          "reaction = true)")
    hinges = t.integer("hinges", None, low=1)
    fraction = t.number("hinge_fraction", 1.0, low=0.0, high=1.0, low_open=True)
    t.finish()
    return {"boundary": name, "displacement": displacement, "duration": duration, "ramp": ramp,
            "control": control, "base": tuple(base), "hinges": hinges, "hinge_fraction": fraction}


#: the kinds of ``[[events]]``
EVENT_TYPES = ("remove",)


def parse_events(root, scene):
    """``[[events]]``: bodies removed during the run (pmpm.physics.events). Each: ``type``
    (``remove``), ``body`` (a body's name), ``time`` (s, before solver.end_time) and
    ``duration`` (s, >= 0, the stress fades over it; ``time + duration`` within the run).
    Returns a tuple of dicts."""
    names = [b.name for b in scene.bodies]
    end = scene.solver.end_time
    out = []
    for t in root.tables("events"):
        t.string("type", "remove", choices=EVENT_TYPES)
        body = t.string("body")
        if body not in names:
            raise ConfigError(t.path("body"), f"no body named {body!r} (defined: {', '.join(names)})")
        time = t.number("time", low=0.0)
        duration = t.number("duration", 0.0, low=0.0)
        if time + duration >= end:
            raise ConfigError(t.path("time"), f"the removal ends at {time + duration:g} s, not before "
                                              f"solver.end_time = {end:g} s")
        t.finish()
        if body in [e["body"] for e in out]:
            raise ConfigError(t.path("body"), f"body {body!r} is already removed by an earlier event")
        out.append({"type": "remove", "body": body, "time": time, "duration": duration})
    if len(out) and len(out) == len(names):
        raise ConfigError("events", "every body would be removed")
    return tuple(out)
