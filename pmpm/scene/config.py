"""The scene: ``case.toml`` parsed once, validated, and frozen into dataclasses.

Every default is filled in here, so ``Scene.to_dict()`` is the complete resolved scene that is
logged at start and written into every output file. The schema is documented in docs/scenes.md.
Materials are validated by their own classes (``pmpm.physics.materials``); bodies are checked against
the grid when the particles are generated (``pmpm.scene.bodies``).
"""
import dataclasses
import logging
import math
import os
import tomllib
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from pmpm.errors import ConfigError
from pmpm.files import read_regular
from pmpm.physics.materials import make_material
from pmpm.scene.expressions import parse_expression
from pmpm.scene.limits import (MAX_XPIC_ORDER, check_memory, check_override_depth, check_time_step,
                               check_work_bounds)
from pmpm.scene.names import check_name, check_output_directory, check_output_files
from pmpm.scene.tables import MAX_MAGNITUDE, REQUIRED, Table
from pmpm.physics.timefunctions import parse_time_function
from pmpm.core.schemes import make_scheme, selectable_scheme_names
from pmpm.core.shape import GIMP_INTERPOLATIONS, GIMP_SHAPES, INTERPOLATIONS
from pmpm.scene.frame import expand_frame
from pmpm.scene.grid import GridConfig, parse_grid
from pmpm.scene.analyses import parse_events, parse_pushover
from pmpm.core.implicit.options import (IMPLICIT_DEFAULTS, check_implicit_scene, read_implicit, read_integrator,
                                        read_petsc, read_static)

__all__ = ["Scene", "load_scene", "resolve_scenes", "check_run_names", "check_written_scene", "parse_scene", "SHAPE_NAMES", "SCHEME_NAMES", "BODY_SHAPES", "STOP_QUANTITIES"]
logger = logging.getLogger(__name__)

SHAPE_NAMES = ("linear", "quadratic", "cubic")
SCHEME_NAMES = selectable_scheme_names()   # the registry (pmpm.core.schemes): usf, usl, musl, mls
BODY_SHAPES = ("rectangle", "polygon", "circle", "i_section", "mesh")
BC_TYPES = ("fixed", "roller_x", "roller_y", "velocity")
BOUNDARY_FACES = ("left", "right", "bottom", "top")
FORMULATIONS = ("plane_stress", "plane_strain")
PARTICLE_FIELDS = ("x", "x0", "v", "m", "vol", "stress", "strain", "F", "mat", "body")


@dataclass(frozen=True)
class BodyConfig:
    name: str
    shape: str
    material: str
    geometry: dict            # shape-specific keys, validated
    particles_per_cell: int
    thickness: float
    velocity: tuple           # numbers or expression strings in x, y


@dataclass(frozen=True)
class BoundaryConfig:
    name: str
    type: str
    lower: Optional[tuple]    # the box (None for a boundary attached to a body's face)
    upper: Optional[tuple]
    velocity: tuple
    body: Optional[str] = None   # body-attached: the body's name and its face (pmpm.physics.boundary)
    face: Optional[str] = None
    reaction: bool = False                 # record the support reaction (pmpm.results)
    moment_about: Optional[tuple] = None   # reaction moment point (None: centroid of the nodes)


@dataclass(frozen=True)
class ForceConfig:
    name: str
    lower: Optional[tuple]                 # the box (None: the whole of the named bodies)
    upper: Optional[tuple]
    force: tuple
    time_function: dict
    bodies: tuple = ()                     # names of the bodies it acts on (empty: any in the box)
    body_ids: tuple = ()                   # their indices in Scene.bodies (set by the scene check)


@dataclass(frozen=True)
class LoadsConfig:
    gravity: Optional[tuple]
    forces: tuple
    ground_motion: Optional[dict] = None   # base acceleration record on the fixed nodes
    damping: float = 0.0                   # mass-proportional damping coefficient (1/s)
    rayleigh: Optional[dict] = None        # {ratio, periods}: Rayleigh damping (pmpm.physics.rayleigh)


@dataclass(frozen=True)
class SolverConfig:
    shape_function: str
    scheme: str
    pic_blend: float
    cfl: float
    end_time: float
    time_step: Optional[float]
    mass_cutoff: float
    large_rotations: bool
    sort_interval: int
    on_particle_exit: str
    max_steps: Optional[int]
    objective_rate: str = "jaumann"   # of the hypoelastic models when large_rotations is on
    interpolation: str = "point"   # or a domain interpolation: "ugimp", "cpgimp", "cpdi" (pmpm.core.shape)
    max_estimated_steps: int = 10_000_000
    allow_unstable_time_step: bool = False
    transfer: str = "flip"   # particle <-> grid velocity transfer: "flip" (with pic_blend), "apic", "xpic"
    xpic_order: int = 2      # m of XPIC(m) (1: PIC)
    integrator: str = "explicit"   # or "implicit" (pmpm.core.implicit, docs/implicit.md)
    analysis: str = "dynamic"      # or "static" (implicit only)
    implicit: dict = field(default_factory=lambda: dict(IMPLICIT_DEFAULTS))   # [solver.implicit]
    petsc: dict = field(default_factory=dict)                                 # [solver.petsc]
    static: Optional[dict] = None   # [solver.static]: a load-factor control (None: the loads' time functions)


@dataclass(frozen=True)
class TrackConfig:
    name: str
    point: tuple


@dataclass(frozen=True)
class StopConfig:
    """A stop condition (``[[stop]]``, pmpm.stop): the run ends cleanly at the first step after
    which a tracked point's quantity is above ``above`` or below ``below``."""
    track: str
    quantity: str
    above: Optional[float] = None
    below: Optional[float] = None
    after: float = 0.0        # (s) not checked before this time


@dataclass(frozen=True)
class SectionConfig:
    """A section cut (pmpm.results.sections): a segment, or a member and a position on it."""
    name: str
    segment: Optional[tuple] = None    # ((x1, y1), (x2, y2))
    body: Optional[str] = None         # an i_section body ...
    position: Optional[float] = None   # ... and the distance of the cut from its start (m)
    width: Optional[float] = None      # band of particles integrated (None: two cells)
    plastic_moment: Optional[float] = None   # Mp (N m); default sigma_y Z of an i_section
    yield_moment: Optional[float] = None     # My (N m); default sigma_y I / (d/2)


@dataclass(frozen=True)
class OutputConfig:
    directory: str
    interval: float
    history_interval: float
    fields: tuple
    track: tuple
    checkpoint_interval: Optional[float]
    deformed_plot: Optional[dict]
    progress_interval: float
    sections: tuple = ()               # SectionConfig
    hysteresis: Optional[dict] = None  # base shear against a tracked drift
    precision: str = "single"          # of the frames' floating-point fields (docs/output.md)


@dataclass(frozen=True)
class ParallelConfig:
    axis: str
    rebalance_threshold: Optional[float]
    rebalance_interval: int
    io: str


@dataclass(frozen=True)
class ContactConfig:
    friction: float
    bodies: tuple             # names of the bodies with their own velocity field


@dataclass(frozen=True)
class Scene:
    """A validated scene; ``materials`` keeps each material's TOML table (validated)."""
    path: str
    title: str
    formulation: str
    thickness: float
    grid: GridConfig
    materials: dict
    bodies: tuple
    boundaries: tuple
    loads: LoadsConfig
    solver: SolverConfig
    output: OutputConfig
    parallel: ParallelConfig
    contact: Optional[ContactConfig] = None
    stop: tuple = ()          # StopConfig
    pushover: Optional[dict] = None   # [pushover] (pmpm.scene.analyses, pmpm.physics.pushover)
    events: tuple = ()        # [[events]] (pmpm.scene.analyses, pmpm.physics.events)
    variants: dict = field(default_factory=dict)
    variant: str = ""

    def to_dict(self):
        """The resolved scene as plain data (for logs and output attributes)."""
        return dataclasses.asdict(self)

    @property
    def stem(self):
        return os.path.splitext(os.path.basename(self.path))[0]


# -- sections -------------------------------------------------------------------------------

def _finite(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _velocity(t, name):
    """Two numbers or expression strings in x, y (parsed here, so --check refuses a bad one)."""
    value = t.raw(name, [0.0, 0.0])
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value)):
        raise ConfigError(t.path(name), "must be two numbers or expressions in x, y (e.g. \"0.1*sin(x)\")")
    for v in value:
        if isinstance(v, str):
            parse_expression(v, t.path(name))
        elif not math.isfinite(v):
            raise ConfigError(t.path(name), "must be finite")
        elif abs(v) > MAX_MAGNITUDE:  # v*v and the kinetic energy must stay finite
            raise ConfigError(t.path(name), f"must be at most {MAX_MAGNITUDE:g} in magnitude (got {v:g})")
    return tuple(float(v) if not isinstance(v, str) else v for v in value)


def _body_box(body, grid):
    """The body's bounding box clipped to the grid box (the whole grid for a mesh)."""
    g_lo = grid.origin
    g_hi = tuple(o + grid.cell_size * n for o, n in zip(grid.origin, grid.cells))
    geo = body.geometry
    if body.shape == "rectangle":
        lo, hi = geo["lower"], geo["upper"]
    elif body.shape == "circle":
        lo = tuple(c - geo["radius"] for c in geo["center"])
        hi = tuple(c + geo["radius"] for c in geo["center"])
    elif body.shape == "polygon":
        xs, ys = zip(*geo["vertices"])
        lo, hi = (min(xs), min(ys)), (max(xs), max(ys))
    elif body.shape == "i_section":
        r = geo["depth"] / 2
        lo = tuple(min(a, b) - r for a, b in zip(geo["start"], geo["end"]))
        hi = tuple(max(a, b) + r for a, b in zip(geo["start"], geo["end"]))
    else:
        lo, hi = g_lo, g_hi
    lo = tuple(max(a, b) for a, b in zip(lo, g_lo))
    hi = tuple(min(a, b) for a, b in zip(hi, g_hi))
    return lo, tuple(max(a, b) for a, b in zip(lo, hi))


def _check_velocity_values(bodies, grid):
    """Refuse velocity expressions that are not finite somewhere on a lattice over the body's
    box (41 x 41 points and the corners): catches ``x/0``, ``sqrt(-1-x)``, overflow at --check.
    The particles' own values are checked again when they are placed."""
    import numpy as np
    for k, body in enumerate(bodies):
        exprs = [v for v in body.velocity if isinstance(v, str)]
        if not exprs:
            continue
        lo, hi = _body_box(body, grid)
        X, Y = np.meshgrid(np.linspace(lo[0], hi[0], 41), np.linspace(lo[1], hi[1], 41), indexing="ij")
        for v in exprs:
            key = f"bodies[{k}].velocity"
            with np.errstate(all="ignore"):  # non-finite values are refused by evaluate
                out = parse_expression(v, key).evaluate(X.ravel(), Y.ravel(), key)
            if np.abs(out).max() > MAX_MAGNITUDE:
                raise ConfigError(key, f"expression {v!r} exceeds {MAX_MAGNITUDE:g} in magnitude "
                                       f"on the body")


def _polygon_vertices(t):
    """A simple polygon of positive area: no repeated vertex, no crossing edges, not collinear."""
    import numpy as np
    verts = t.raw("vertices")
    if (not isinstance(verts, list) or len(verts) < 3 or len(verts) > 10000
            or not all(isinstance(v, list) and len(v) == 2 and all(_finite(c) and abs(c) <= MAX_MAGNITUDE
                                                                   for c in v) for v in verts)):
        raise ConfigError(t.path("vertices"), f"must be a list of 3 to 10000 [x, y] points (each "
                                              f"coordinate at most {MAX_MAGNITUDE:g} in magnitude)")
    P = np.array(verts, dtype=float)
    Q = np.roll(P, -1, axis=0)
    scale = float(np.ptp(P, axis=0).max())
    area = 0.5 * abs(np.dot(P[:, 0], Q[:, 1]) - np.dot(P[:, 1], Q[:, 0]))
    if not scale > 0 or area <= 1e-12 * scale * scale:
        raise ConfigError(t.path("vertices"), "the polygon has zero area (collinear or repeated points)")
    if np.any(np.all(np.abs(P - Q) <= 1e-12 * scale, axis=1)):
        raise ConfigError(t.path("vertices"), "two consecutive vertices coincide")
    # proper crossings of non-adjacent edges (vectorised over all pairs)
    def orient(a, b, c):
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))
    n = len(P)
    # all pairs of edges, a block of first edges at a time (all 50 million pairs of a 10,000-vertex
    # polygon at once took 763 MB): the edges' bounding boxes are compared by broadcasting, the
    # orientation test runs only on the pairs whose boxes overlap
    lo, hi = np.minimum(P, Q), np.maximum(P, Q)
    block = max(1, (1 << 19) // n)
    cols = np.arange(n)
    for first in range(0, n, block):
        rows = np.arange(first, min(first + block, n))
        near = cols[None, :] >= rows[:, None] + 2  # adjacent edges share a vertex
        for d in range(2):
            near &= (lo[rows, None, d] <= hi[None, :, d]) & (lo[None, :, d] <= hi[rows, None, d])
        if first == 0:
            near[0, n - 1] = False  # the first and last edges share a vertex
        i, j = np.nonzero(near)
        i = i + first
        a, b, c, d = P[i], Q[i], P[j], Q[j]
        crosses = (orient(a, b, c) * orient(a, b, d) < 0) & (orient(c, d, a) * orient(c, d, b) < 0)
        if crosses.any():
            raise ConfigError(t.path("vertices"), f"edges {int(i[crosses][0])} and {int(j[crosses][0])} "
                                                  f"cross (the polygon must be simple)")
    return tuple(tuple(float(c) for c in v) for v in verts)


def _geometry(t, shape):
    """Read the shape-specific keys of a body."""
    if shape == "rectangle":
        geo = {"lower": t.vector("lower"), "upper": t.vector("upper")}
        if any(u <= l for l, u in zip(geo["lower"], geo["upper"])):
            raise ConfigError(t.path("upper"), "must be above lower in both coordinates")
    elif shape == "polygon":
        geo = {"vertices": _polygon_vertices(t)}
    elif shape == "circle":
        geo = {"center": t.vector("center"), "radius": t.number("radius", low=0, low_open=True, magnitude=MAX_MAGNITUDE)}
    elif shape == "i_section":
        geo = {"start": t.vector("start"), "end": t.vector("end"),
               "depth": t.number("depth", low=0, low_open=True, magnitude=MAX_MAGNITUDE),
               "flange_width": t.number("flange_width", low=0, low_open=True, magnitude=MAX_MAGNITUDE),
               "flange_thickness": t.number("flange_thickness", low=0, low_open=True, magnitude=MAX_MAGNITUDE),
               "web_thickness": t.number("web_thickness", low=0, low_open=True, magnitude=MAX_MAGNITUDE),
               "area": t.number("area", None, low=0, low_open=True),
               "inertia": t.number("inertia", None, low=0, low_open=True)}
        if 2 * geo["flange_thickness"] >= geo["depth"]:
            raise ConfigError(t.path("flange_thickness"), "two flanges must be thinner than the depth")
        if geo["start"] == geo["end"]:
            raise ConfigError(t.path("end"), "must differ from start")
    else:  # mesh
        geo = {"file": t.string("file"),
               "particles_per_element": t.integer("particles_per_element", 1, low=1, high=16),
               "scale": t.number("scale", 1.0, low=0, low_open=True, magnitude=MAX_MAGNITUDE),
               "offset": t.vector("offset", (0.0, 0.0))}
    return geo


def _bodies(root, materials, ppc_default, thickness):
    tables = root.tables("bodies")
    if not tables:
        raise ConfigError("bodies", "missing: a scene needs at least one [[bodies]] table")
    bodies = []
    for k, t in enumerate(tables):
        shape = t.string("shape", choices=BODY_SHAPES)
        material = t.string("material")
        if material not in materials:
            raise ConfigError(t.path("material"), f"no material {material!r} under [materials] "
                                                  f"(defined: {', '.join(sorted(materials)) or 'none'})")
        bodies.append(BodyConfig(
            name=t.string("name", f"body{k}"), shape=shape, material=material,
            geometry=_geometry(t, shape),
            particles_per_cell=t.integer("particles_per_cell", ppc_default, low=1, high=8),
            thickness=t.number("thickness", thickness, low=0, low_open=True),
            velocity=_velocity(t, "velocity")))
        t.finish()
        previous = [b.name for b in bodies[:-1]]
        if bodies[-1].name in previous:
            raise ConfigError(t.path("name"), f"body name {bodies[-1].name!r} is already used by "
                                              f"bodies[{previous.index(bodies[-1].name)}]")
    return tuple(bodies)


def _boundaries(root, reactions=False):
    """``[[boundary]]`` tables; ``reactions`` (``output.reactions``) is the default of each
    boundary's ``reaction`` key."""
    out = []
    for k, t in enumerate(root.tables("boundary")):
        kind = t.string("type", choices=BC_TYPES)
        body = face = None
        if t.has("body"):
            body = t.string("body")
            face = t.string("face", choices=BOUNDARY_FACES)
            for key in ("lower", "upper"):
                if t.has(key):
                    raise ConfigError(t.path(key), "a boundary attached to a body takes no box")
            lower = upper = None
        else:
            lower, upper = t.vector("lower"), t.vector("upper")
        vel = t.vector("velocity", (0.0, 0.0)) if kind == "velocity" else (0.0, 0.0)
        name = t.string("name", f"boundary{k}")
        reaction = t.boolean("reaction", reactions)
        if reaction:
            _check_file_name(name, t.path("name"))
        out.append(BoundaryConfig(name=name, type=kind, lower=lower, upper=upper, velocity=vel,
                                  reaction=reaction, moment_about=t.vector("moment_about", None),
                                  body=body, face=face))
        t.finish()
    names = [b.name for b in out if b.reaction]
    if len(set(names)) != len(names):
        raise ConfigError("boundary", "boundaries with reactions need unique names")
    return tuple(out)


def _check_file_name(name, key):
    """Refuse a name that cannot be used as (part of) a file name: the one rule of
    pmpm.scene.names (sections, reactions, like tracks and variants)."""
    try:
        check_name(name, key, "name")
    except ConfigError as exc:
        raise ConfigError(key, f"{name!r} is not a valid file name ({exc.reason})") from None


def _segment(t, name):
    value = t.raw(name, None)
    if value is None:
        return None
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(p, list) and len(p) == 2 and all(_finite(c) for c in p) for p in value)):
        raise ConfigError(t.path(name), f"must be two [x, y] points (got {value!r})")
    seg = tuple(tuple(float(c) for c in p) for p in value)
    if seg[0] == seg[1]:
        raise ConfigError(t.path(name), "the two points must differ")
    return seg


def _sections(t, bodies, grid):
    """``[[output.section]]``: validated against the scene's bodies and grid (whether the cut
    meets exactly one member is checked on the particles, pmpm.results.sections)."""
    out = []
    lo = grid.origin
    hi = tuple(o + grid.cell_size * c for o, c in zip(grid.origin, grid.cells))
    by_name = {b.name: b for b in bodies}
    for k, s in enumerate(t.tables("section")):
        name = s.string("name")
        _check_file_name(name, s.path("name"))
        segment = _segment(s, "segment")
        body = s.string("body", None)
        position = s.number("position", None)
        if (segment is None) == (body is None):
            raise ConfigError(s.path("segment"), "give either segment or body (with position)")
        if body is not None:
            if body not in by_name:
                raise ConfigError(s.path("body"), f"no body named {body!r}")
            geo = by_name[body].geometry
            if by_name[body].shape != "i_section":
                raise ConfigError(s.path("body"), f"{body!r} is not an i_section (give a segment)")
            if position is None:
                raise ConfigError(s.path("position"), "missing (required with body)")
            length = math.dist(geo["start"], geo["end"])
            if not 0 <= position <= length:
                raise ConfigError(s.path("position"), f"must lie on the member, in [0, {length:g}] m")
        elif position is not None:
            raise ConfigError(s.path("position"), "only with body")
        sec = SectionConfig(name=name, segment=segment, body=body, position=position,
                            width=s.number("width", None, low=0, low_open=True),
                            plastic_moment=s.number("plastic_moment", None, low=0, low_open=True),
                            yield_moment=s.number("yield_moment", None, low=0, low_open=True))
        s.finish()
        for p in (segment or ()):
            if not all(l <= c <= u for l, c, u in zip(lo, p, hi)):
                raise ConfigError(s.path("segment"), f"point {p} lies outside the grid")
        out.append(sec)
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise ConfigError("output.section", "section names must be unique")
    return tuple(out)


def _check_hysteresis(scene):
    """The hysteresis plot needs recorded reactions, and names only those."""
    spec = scene.output.hysteresis
    if spec is None:
        return
    recorded = [b.name for b in scene.boundaries if b.reaction]
    if not recorded:
        raise ConfigError("output.hysteresis", "needs reactions (output.reactions = true or a boundary's reaction)")
    for name in spec["reactions"] or ():
        if name not in recorded:
            raise ConfigError("output.hysteresis.reactions", f"no recorded reaction {name!r} "
                                                             f"(recorded: {', '.join(recorded)})")


def _hysteresis(t, names):
    """``[output.hysteresis]``: base shear (sum of the listed reactions' Rx, or Ry) against
    a tracked point's displacement, drawn after the run."""
    if t is None:
        return None
    h = {"track": t.string("track"),
         "component": t.string("component", "ux", choices=("ux", "uy")),
         "reactions": t.raw("reactions", None)}
    t.finish()
    if h["track"] not in names:
        raise ConfigError(t.path("track"), f"no [[output.track]] named {h['track']!r}")
    if h["reactions"] is not None and (not isinstance(h["reactions"], list) or not h["reactions"]
                                       or not all(isinstance(r, str) for r in h["reactions"])):
        raise ConfigError(t.path("reactions"), "must be a non-empty list of [[boundary]] names")
    return h


def _ground_motion(t):
    """``[loads.ground_motion]``: an acceleration record applied to the fixed base nodes."""
    if t is None:
        return None
    gm = {"file": t.string("file"),
          "format": t.string("format", "auto", choices=("auto", "two_column", "at2")),
          "direction": t.string("direction", "x", choices=("x", "y")),
          "scale": t.number("scale", 1.0, magnitude=MAX_MAGNITUDE),
          "boundaries": t.raw("boundaries", [])}
    if not isinstance(gm["boundaries"], list) or not all(isinstance(b, str) for b in gm["boundaries"]):
        raise ConfigError(t.path("boundaries"), "must be a list of [[boundary]] names")
    t.finish()
    return gm


def _force_bodies(f):
    """``body``: the name of a body, or a list of names, the force acts on (its particles only)."""
    value = f.raw("body", None)
    if value is None:
        return ()
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise ConfigError(f.path("body"), "must be a body's name or a non-empty list of names")
    return tuple(names)


def _check_force_bodies(scene):
    """Every body a force names exists; record their indices (ForceConfig.body_ids)."""
    names = [b.name for b in scene.bodies]
    forces = []
    for k, f in enumerate(scene.loads.forces):
        for n in f.bodies:
            if n not in names:
                raise ConfigError(f"loads.forces[{k}].body", f"no body named {n!r} (defined: {', '.join(names)})")
        forces.append(dataclasses.replace(f, body_ids=tuple(names.index(n) for n in f.bodies)))
    return dataclasses.replace(scene, loads=dataclasses.replace(scene.loads, forces=tuple(forces)))


def _loads(root):
    t = root.table("loads", None)
    if t is None:
        return LoadsConfig(gravity=None, forces=())
    gravity = t.vector("gravity", None)
    ground_motion = _ground_motion(t.table("ground_motion", None))
    damping, rayleigh = _damping(t)
    forces = []
    for k, f in enumerate(t.tables("forces")):
        bodies = _force_bodies(f)
        # with `body`, the box is optional (it may narrow the body's particles); without, required
        lower = f.vector("lower", None) if bodies else f.vector("lower")
        upper = f.vector("upper", None) if bodies else f.vector("upper")
        if (lower is None) != (upper is None):
            raise ConfigError(f.path("lower" if lower is None else "upper"), "give both lower and upper, or neither")
        forces.append(ForceConfig(
            name=f.string("name", f"force{k}"), lower=lower, upper=upper,
            force=f.vector("force"), bodies=bodies,
            time_function=parse_time_function(f.table("time_function", {"type": "step"}))))
        f.finish()
    t.finish()
    return LoadsConfig(gravity=gravity, forces=tuple(forces), ground_motion=ground_motion, damping=damping,
                       rayleigh=rayleigh)


def _damping(t):
    """``[loads] damping``: a mass-proportional coefficient (1/s), or a table
    ``{ratio = xi, periods = [T1, T2]}`` asking for Rayleigh damping (pmpm.physics.rayleigh).
    Returns (mass coefficient, Rayleigh dict or None); a ratio of 0 is no damping."""
    if not isinstance(t.data.get("damping"), dict):
        return t.number("damping", 0.0, low=0.0, magnitude=MAX_MAGNITUDE), None
    d = t.table("damping")
    ratio = d.number("ratio", low=0.0, high=1.0)
    periods = d.raw("periods")
    if (not isinstance(periods, list) or len(periods) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                       and 1.0 / MAX_MAGNITUDE <= v <= MAX_MAGNITUDE  # the coefficients stay finite
                       for v in periods)):
        raise ConfigError(d.path("periods"), f"must be two periods > 0 in s, [T1, T2] (got {periods!r})")
    d.finish()
    if ratio == 0.0:
        return 0.0, None
    return 0.0, {"ratio": ratio, "periods": tuple(float(v) for v in periods)}


#: objective stress rates of the hypoelastic models (pmpm.core.kernels.objective)
OBJECTIVE_RATES = ("jaumann", "green_naghdi")
#: velocity transfers (pmpm.core.transfers): FLIP (the paper's, with the PIC blend), APIC, XPIC(m)
TRANSFERS = ("flip", "apic", "xpic")


def _solver(t):
    # naming a rate switches large rotations on; saying both "off" and a rate is a contradiction
    rate_given, rotations_given = t.has("objective_rate"), t.has("large_rotations")
    rate = t.string("objective_rate", "jaumann", choices=OBJECTIVE_RATES)
    large_rotations = t.boolean("large_rotations", rate_given)
    if rate_given and rotations_given and not large_rotations:
        raise ConfigError(t.path("objective_rate"), "needs large_rotations = true (or leave "
                                                    "large_rotations out: a rate switches it on)")
    integrator, analysis, implicit_scheme = read_integrator(t)
    s = SolverConfig(
        shape_function=t.string("shape_function", "cubic", choices=SHAPE_NAMES),
        scheme=implicit_scheme or t.string("scheme", "musl", choices=SCHEME_NAMES),
        pic_blend=t.number("pic_blend", 0.0, low=0.0, high=1.0),
        cfl=t.number("cfl", 0.5, low=0.0, high=1.0, low_open=True),
        end_time=t.number("end_time", low=0.0, low_open=True),
        time_step=t.number("time_step", None, low=0.0, low_open=True),
        mass_cutoff=t.number("mass_cutoff", 1e-8, low=0.0, high=1.0),
        large_rotations=large_rotations,
        sort_interval=t.integer("sort_interval", 20, low=0),
        on_particle_exit=t.string("on_particle_exit", "error", choices=("error", "remove")),
        max_steps=t.integer("max_steps", None, low=1),
        objective_rate=rate,
        interpolation=t.string("interpolation", "point", choices=INTERPOLATIONS),
        max_estimated_steps=t.integer("max_estimated_steps", 10_000_000, low=1),
        allow_unstable_time_step=t.boolean("allow_unstable_time_step", False),
        transfer=t.string("transfer", "flip", choices=TRANSFERS),
        xpic_order=t.integer("xpic_order", 2, low=1, high=MAX_XPIC_ORDER),
        integrator=integrator, analysis=analysis,
        implicit=read_implicit(t.table("implicit", None)), petsc=read_petsc(t.table("petsc", None)),
        static=read_static(t.table("static", None), analysis))
    if t.has("xpic_order") and s.transfer != "xpic":
        raise ConfigError(t.path("xpic_order"), "is XPIC's order; set transfer = \"xpic\" (or leave it out)")
    if s.transfer == "xpic":
        if s.interpolation != "point":
            raise ConfigError(t.path("transfer"), f"xpic is defined for point particles, not "
                                                  f"interpolation = {s.interpolation!r}")
        if s.pic_blend:
            raise ConfigError(t.path("pic_blend"), "is FLIP's; xpic updates the velocity from the grid alone")
    if s.transfer == "apic":
        if s.shape_function == "linear":
            raise ConfigError(t.path("transfer"), "apic needs quadratic or cubic B-splines (with linear "
                                                  "ones a particle on a node sees no affine field)")
        if s.interpolation != "point":
            raise ConfigError(t.path("transfer"), f"apic is defined for point particles, not "
                                                  f"interpolation = {s.interpolation!r}")
        if s.pic_blend:
            raise ConfigError(t.path("pic_blend"), "is FLIP's; apic updates the velocity from the grid alone")
    if s.scheme in SCHEME_NAMES:   # the scheme checks the settings it cannot run with (pmpm.core.schemes)
        make_scheme(s.scheme, s)
    if s.interpolation in GIMP_INTERPOLATIONS and s.shape_function not in GIMP_SHAPES:
        raise ConfigError(t.path("interpolation"), f"{s.interpolation} is defined for shape_function "
                                                   f"{' or '.join(map(repr, GIMP_SHAPES))}, not {s.shape_function!r}")
    t.finish()
    return s


def _directory(t):
    value = t.string("directory", None)
    if value is None:
        return None  # filled in by parse_scene: <stem>_results
    if not value.strip() or "\0" in value:
        raise ConfigError(t.path("directory"), "must be a non-empty path")
    return value


def _output(t, stem, end_time, state_fields=(), bodies=(), grid=None):
    t = t or Table({}, "output")
    tracks = []
    for k, tr in enumerate(t.tables("track")):
        name = check_name(tr.string("name", f"point{k}"), tr.path("name"), "track name",
                          also_reserved=("time",))
        tracks.append(TrackConfig(name=name, point=tr.vector("point")))
        tr.finish()
    names = [tr.name for tr in tracks]
    if len(set(names)) != len(names):
        raise ConfigError("output.track", "track names must be unique")
    fields = t.raw("fields", ["x", "v", "stress"])
    if not isinstance(fields, list) or not all(isinstance(f, str) for f in fields):
        raise ConfigError("output.fields", "must be a list of field names")
    known = ("id",) + PARTICLE_FIELDS + tuple(sorted(set(state_fields) - set(PARTICLE_FIELDS)))
    for f in fields:
        if f not in known:
            raise ConfigError("output.fields", f"no particle field {f!r} in this scene (one of: {', '.join(known)})")
    deformed = t.table("deformed_plot", None)
    deformed_plot = None
    if deformed is not None:
        deformed_plot = {"track": deformed.string("track"),
                         "component": deformed.string("component", "ux", choices=("ux", "uy")),
                         "color": deformed.string("color", "eps_p_eq"),
                         "scale": deformed.number("scale", 10.0, low=0, low_open=True)}
        deformed.finish()
        if deformed_plot["track"] not in names:
            raise ConfigError("output.deformed_plot.track", f"no [[output.track]] named {deformed_plot['track']!r}")
    out = OutputConfig(
        directory=_directory(t),
        interval=t.number("interval", end_time / 20, low=0, low_open=True),
        history_interval=t.number("history_interval", end_time / 1000, low=0, low_open=True),
        fields=tuple(fields), track=tuple(tracks),
        precision=t.string("precision", "single", choices=("single", "double")),
        checkpoint_interval=t.number("checkpoint_interval", None, low=0, low_open=True),
        deformed_plot=deformed_plot,
        progress_interval=t.number("progress_interval", 2.0, low=0),
        sections=_sections(t, bodies, grid) if grid is not None else (),
        hysteresis=_hysteresis(t.table("hysteresis", None), names))
    t.used.add("reactions")  # read by _boundaries (it is each boundary's default)
    t.finish()
    return out


#: what a stop condition can watch: a tracked point's history column, or a magnitude
STOP_QUANTITIES = ("ux", "uy", "|u|", "vx", "vy", "|v|", "x", "y", "sxx", "syy", "sxy")


def _stops(root, tracks):
    """``[[stop]]``: each names an ``[[output.track]]``, a quantity and a threshold (or two)."""
    names = [tr.name for tr in tracks]
    out = []
    for t in root.tables("stop"):
        track = t.string("track")
        if track not in names:
            raise ConfigError(t.path("track"), f"no [[output.track]] named {track!r}"
                                               f" (defined: {', '.join(names) or 'none'})")
        stop = StopConfig(track=track, quantity=t.string("quantity", choices=STOP_QUANTITIES),
                          above=t.number("above", None), below=t.number("below", None),
                          after=t.number("after", 0.0, low=0.0))
        t.finish()
        if stop.above is None and stop.below is None:
            raise ConfigError(t.key, "give above or below (or both): the threshold of the quantity")
        if stop.above is not None and stop.below is not None and not stop.below < stop.above:
            raise ConfigError(t.path("below"), f"must be below above = {stop.above:g} "
                                               f"(the run continues while below < quantity < above)")
        out.append(stop)
    return tuple(out)


def _parallel(t):
    t = t or Table({}, "parallel")
    p = ParallelConfig(axis=t.string("axis", "auto", choices=("auto", "x", "y")),
                       rebalance_threshold=t.number("rebalance_threshold", None, low=1.0, low_open=True),
                       rebalance_interval=t.integer("rebalance_interval", 50, low=1),
                       io=t.string("io", "mpio", choices=("mpio", "gather")))
    t.finish()
    return p


def _contact(t, bodies):
    if t is None:
        return None
    names = [b.name for b in bodies]
    listed = t.raw("bodies", list(dict.fromkeys(names)))  # default: every body (names once)
    if not isinstance(listed, list) or not listed or not all(isinstance(n, str) for n in listed):
        raise ConfigError(t.path("bodies"), "must be a non-empty list of body names")
    for n in listed:
        if n not in names:
            raise ConfigError(t.path("bodies"), f"no body named {n!r} (defined: {', '.join(names)})")
    if len(set(listed)) != len(listed):
        raise ConfigError(t.path("bodies"), "names a body twice")
    c = ContactConfig(friction=t.number("friction", low=0.0), bodies=tuple(listed))
    t.finish()
    return c


def _materials(root, formulation):
    t = root.table("materials")
    if not t.data:
        raise ConfigError("materials", "empty: define at least one [materials.<label>] table")
    resolved, state_fields = {}, set()
    for label in t.data:
        table = t.table(label)
        material = make_material(table.data, table.key, formulation)  # validates
        state_fields.update(material.state_fields)
        resolved[label] = dict(table.data)
    return resolved, state_fields


def parse_scene(data, path="<scene>"):
    """Validate the TOML ``data`` of a scene and return a frozen :class:`Scene`.

    A ``[frame]`` table is first expanded into ordinary bodies, boundaries, loads, section
    cuts and tracked points (:func:`pmpm.scene.frame.expand_frame`): nothing after this line
    knows about frames."""
    if isinstance(data, dict) and "frame" in data:
        data = expand_frame(data)
    root = Table(data, "")
    title = root.string("title", os.path.basename(path))
    formulation = root.string("formulation", "plane_stress", choices=FORMULATIONS)
    thickness = root.number("thickness", 1.0, low=0, low_open=True)
    ppc = root.integer("particles_per_cell", 2, low=1, high=8)
    grid = parse_grid(root.table("grid"))
    materials, state_fields = _materials(root, formulation)
    solver = _solver(root.table("solver"))
    stem = os.path.splitext(os.path.basename(path))[0]
    if path != "<scene>":
        check_name(stem, path, "scene file name (its stem names the output files)")
    out_table = root.table("output", None)
    reactions = out_table.boolean("reactions", False) if out_table is not None else False
    bodies = _bodies(root, materials, ppc, thickness)
    variants = root.raw("variants", {})
    if not isinstance(variants, dict) or not all(isinstance(v, dict) for v in variants.values()):
        raise ConfigError("variants", "must be tables [variants.<name>] of dotted-key overrides")
    scene = Scene(path=os.path.abspath(path) if path != "<scene>" else path, title=title,
                  formulation=formulation, thickness=thickness, grid=grid, materials=materials,
                  bodies=bodies, boundaries=_boundaries(root, reactions),
                  loads=_loads(root), solver=solver,
                  output=_output(out_table, stem, solver.end_time, state_fields, bodies, grid),
                  parallel=_parallel(root.table("parallel", None)), variants=variants)
    scene = dataclasses.replace(scene, contact=_contact(root.table("contact", None), scene.bodies),
                                stop=_stops(root, scene.output.track))
    scene = _check_force_bodies(scene)
    names = [b.name for b in scene.bodies]
    for k, bc in enumerate(scene.boundaries):
        if bc.body is not None and bc.body not in names:
            raise ConfigError(f"boundary[{k}].body", f"no body named {bc.body!r} (defined: {', '.join(names)})")
    if scene.contact is not None and solver.transfer != "flip":
        raise ConfigError("solver.transfer", "the contact solver's kernels are FLIP's")
    if scene.contact is not None and solver.interpolation != "point":
        raise ConfigError("solver.interpolation", "the contact solver's kernels use point B-splines only")
    _check_hysteresis(scene)
    scene = dataclasses.replace(scene, pushover=parse_pushover(root.table("pushover", None), scene))
    scene = dataclasses.replace(scene, events=parse_events(root, scene))
    if scene.output.directory is None:
        scene = dataclasses.replace(scene, output=dataclasses.replace(scene.output, directory=f"{stem}_results"))
    root.finish()
    _check_velocity_values(scene.bodies, scene.grid)
    check_work_bounds(scene)  # frames, rows, checkpoints, orders, thicknesses the run can afford
    built = [make_material(materials[k], f"materials.{k}", formulation) for k in materials]
    check_implicit_scene(scene, built)
    check_time_step(scene, built)
    # what no rank count can shrink (every rank places all points and holds a window at
    # least the ghost columns wide); the solver checks its own rank's share before allocating
    check_memory(scene, n_ranks=math.inf)
    return scene


def apply_overrides(data, overrides, where):
    """Copy of TOML ``data`` with dotted-key ``overrides`` (``"materials.steel.type" = ...``)."""
    import copy
    check_override_depth(overrides, where)  # before _flatten and deepcopy recurse into it
    data = copy.deepcopy(data)
    for dotted, value in _flatten(overrides):
        node = data
        parts = dotted.split(".")
        for part in parts[:-1]:
            if isinstance(node, list):
                try:
                    node = node[int(part)]
                except (ValueError, IndexError):
                    raise ConfigError(f"{where}.{dotted}", f"no list entry {part!r}") from None
            elif isinstance(node, dict):
                node = node.setdefault(part, {})
            else:
                raise ConfigError(f"{where}.{dotted}", f"{part!r} is inside a value that is not a table")
        if isinstance(node, list):
            raise ConfigError(f"{where}.{dotted}", "cannot override a whole list entry")
        if not isinstance(node, dict):
            raise ConfigError(f"{where}.{dotted}", f"{parts[-2]!r} is not a table")
        node[parts[-1]] = value
    return data


def _flatten(overrides, prefix=""):
    """(dotted key, value) pairs: a bare dotted key (``solver.cfl = 0.3``) reaches TOML as nested
    tables and must override that one key, not replace the whole ``[solver]`` table. A quoted
    dotted key with a table value (``"materials.steel" = {type = ...}``) replaces that table."""
    for key, value in overrides.items():
        if isinstance(value, dict) and value and "." not in key:
            yield from _flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


#: largest scene file read (a scene is a few kilobytes; this refuses devices and huge files)
MAX_SCENE_BYTES = 1 << 20


def read_toml(path):
    """Read a TOML file; unreadable, oversized, non-UTF-8 or malformed files are a ConfigError
    naming the file (the reason never quotes the file's contents)."""
    try:  # non-blocking open: a FIFO given as the scene is refused, never waited on
        raw = read_regular(path, MAX_SCENE_BYTES)
    except OSError as exc:
        raise ConfigError(path, f"cannot read ({exc.strerror or type(exc).__name__})") from None
    except ValueError as exc:
        reason = str(exc)
        raise ConfigError(path, f"{reason}: not a scene file" if reason.startswith("larger") else reason) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(path, f"not UTF-8 text (byte {exc.start} cannot be decoded)") from None
    if text.startswith("\ufeff"):
        raise ConfigError(path, "starts with a byte-order mark (save it as UTF-8 without BOM)")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = str(exc)
        where = where[where.rfind("(at "):] if "(at " in where else ""
        raise ConfigError(path, f"not valid TOML {where or '(syntax error)'}".strip()) from None
    except RecursionError:
        raise ConfigError(path, "not valid TOML (nested too deeply)") from None


def load_scene(path, variant=None, overrides=None):
    """Read and validate ``path``; with ``variant``, apply ``[variants.<variant>]`` first.

    Returns a list of scenes: one per variant when the scene declares variants and none is
    chosen, else one. See :func:`resolve_scenes` for the checks (every entry point, the CLI and
    the Python API alike, goes through them).
    """
    return resolve_scenes(read_toml(path), path, variant, overrides)


def resolve_scenes(data, path="<scene>", variant=None, overrides=None):
    """The validated scenes of TOML ``data`` read from ``path``: one per variant (or the one
    ``variant``), each with the dotted-key ``overrides`` applied after its variant's own.

    The one validation path of every entry point (``pmpm case.toml``, :func:`pmpm.run`,
    :func:`load_scene`): variant names follow the file-name rule (:mod:`pmpm.scene.names`);
    no two outputs of the runs share a file, none leaves ``output.directory``, and that
    directory can be created (nothing is created here).
    """
    if overrides is not None and not isinstance(overrides, dict):
        raise ConfigError("overrides", f"must be a dict of dotted keys, not {type(overrides).__name__}")
    variants = data.get("variants", {})
    if not isinstance(variants, dict):
        raise ConfigError("variants", "must be tables [variants.<name>]")
    for name in variants:
        check_name(name, "variants", "variant name")  # the key holds no raw name (may hold /)
    if variant is not None and not isinstance(variant, str):
        raise ConfigError("variant", f"must be a variant name, not {type(variant).__name__}")
    if variant and not variants:
        raise ConfigError("variants", f"no variant {variant!r} (defined: none)")
    names = [variant] if variant else list(variants) or [""]
    scenes = []
    for name in names:
        if name and name not in variants:
            raise ConfigError("variants", f"no variant {name!r} (defined: {', '.join(variants)})")
        if name and not isinstance(variants[name], dict):
            raise ConfigError(f"variants.{name}", "must be a table of dotted-key overrides")
        merged = apply_overrides(data, variants[name], f"variants.{name}") if name else data
        if overrides:
            merged = apply_overrides(merged, overrides, "overrides")
        scenes.append(dataclasses.replace(parse_scene(merged, path), variant=name))
    check_run_names(scenes)
    return scenes


def check_run_names(scenes):
    """The checks of names and paths a run's outputs need, on resolved scenes (also those a
    caller built or changed itself): the variant name follows the file-name rule, the output
    directory can be created, no two outputs share a file and none leaves the directory."""
    for scene in scenes:
        if not isinstance(scene.variant, str):
            raise ConfigError("variants", "a variant name must be a string")
        if scene.variant:
            check_name(scene.variant, "variants", "variant name")
        check_output_directory(scene.output.directory)
    check_output_files(scenes)


def check_written_scene(scene):
    """What a run that writes files needs beyond :func:`check_run_names`: a scene file name
    (its stem names the files; a scene given as TOML data has none)."""
    if scene.path == "<scene>":
        raise ConfigError("scene", "a scene given as TOML data has no file name to name its output "
                                   "files: write it to a .toml file to run it with write=True")
    check_name(scene.stem, scene.path, "scene file name (its stem names the output files)")
    check_run_names([scene])
