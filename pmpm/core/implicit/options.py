"""The scene keys of the implicit integrator, read and checked (pmpm.scene.config calls these).

    [solver]
    integrator = "implicit"        # "explicit" (default, the paper's) | "implicit"
    analysis = "dynamic"           # | "static" (implicit only: load control, no inertia)
    time_step = 2e-4               # required: the implicit step is the scene's, not the CFL rule's

    [solver.implicit]
    residual_tolerance = 1e-8      # |R| <= tol * max(|R_0|, |f_int| + |f_ext| at the start)
    energy_tolerance = 1e-12       # |du . R| <= tol * |du_0 . R_0|
    max_iterations = 25            # Newton iterations before the step is halved
    newton = "full"                # | "modified": refactor the tangent only where the rate is slow
                                   # | "krylov": as "modified", each new tangent solved by GMRES
                                   # on a kept factorisation, refactored when the GMRES stalls
                                   # | "accelerated": as "modified", its corrections mixed in the
                                   # subspace of the step's earlier ones (Anderson; OpenSees'
                                   # KrylovNewton), a tangent only where that stalls
    krylov_tolerance = 1e-6        # "krylov": the GMRES's relative residual tolerance
    krylov_iterations = 10         # "krylov": GMRES iterations before the factorisation is renewed
    line_search = false            # halve the step while the energy slope grows (Crisfield)
    max_halvings = 6               # smallest step: time_step / 2^max_halvings
    hht_alpha = 0.0                # HHT-alpha in [-1/3, 0]: damping of the highest modes
    initial_static = false         # dynamics: first bring the loads at the start time (gravity,
                                   # the force sets' values) to static equilibrium, then go on
    edge_mass_ratio = 0.0          # > 0: slave every edge node lighter than this fraction of its
                                   # two inward neighbours to them (pmpm.core.implicit.edges)

    [solver.static]                # analysis = "static": what drives the steps (docs/implicit.md)
    control = "load"               # "load": the loads' time functions (default) | "displacement":
                                   # a point's displacement, the load factor solved for |
                                   # "arc_length": Crisfield's cylindrical arc length
    pattern = ["floor load"]       # the [[loads.forces]] scaled by the load factor (default all)
    gravity = "fixed"              # "fixed": held at its value | "pattern": scaled with the pattern
    max_load_factor = 1.0          # the load factor is not taken past this (default: no limit)
    point = [6.1, 3.66]            # displacement: the particle nearest this point (initial position)
    component = "y"                # displacement: its component controlled
    displacement = -0.3            # displacement: the point's displacement at end_time (linear in t)
    load_factor_increment = 0.1    # arc_length: the first step's load factor (sets the arc length)
    target_iterations = 4          # arc_length: the arc length follows sqrt(target / iterations)

    [solver.petsc]                 # PETSc options of the linear solve (without the dash)
    ksp_type = "cg"
    pc_type = "gamg"

What the implicit integrator does not support yet and is no part of the solver is refused here,
one line naming the key; the parts (effects, transfer, grid fields) refuse themselves
(``implicit_support``, pmpm.core.implicit.scheme ``check_parts``).
"""
from pmpm.core.implicit.linear_solver import check_option_names, validate_options
from pmpm.errors import ConfigError

__all__ = ["read_integrator", "INTEGRATORS", "ANALYSES", "IMPLICIT_DEFAULTS", "read_implicit", "read_petsc", "check_implicit_scene",
           "IMPLICIT_SCHEME", "read_static", "STATIC_CONTROLS"]

INTEGRATORS = ("explicit", "implicit")
ANALYSES = ("dynamic", "static")
#: tangent updates of Newton's iterations (pmpm.core.implicit.newton)
NEWTON_VARIANTS = ("full", "modified", "krylov", "accelerated")
#: the keys of newton = "krylov" alone (refused with the other variants: they would do nothing)
KRYLOV_KEYS = ("krylov_tolerance", "krylov_iterations")
#: the registry name of the implicit scheme (pmpm.core.schemes)
IMPLICIT_SCHEME = "newmark"
IMPLICIT_DEFAULTS = {"residual_tolerance": 1e-8, "energy_tolerance": 1e-12, "max_iterations": 25,
                     "newton": "full", "line_search": False, "max_halvings": 6, "hht_alpha": 0.0, "initial_static": False,
                     "krylov_tolerance": 1e-6, "krylov_iterations": 10, "edge_mass_ratio": 0.0}


def read_integrator(t):
    """(integrator, analysis, scheme or None) from ``[solver]`` (a Table): the implicit
    integrator's scheme is Newmark's, and the explicit schemes' key is refused with it."""
    integrator = t.string("integrator", "explicit", choices=INTEGRATORS)
    analysis = t.string("analysis", "dynamic", choices=ANALYSES)
    if integrator == "implicit" and t.has("scheme"):
        raise ConfigError(t.path("scheme"), "is the explicit integrator's (MUSL/USL/USF); the implicit one is "
                                            "Newmark's (solver.integrator = \"implicit\")")
    if integrator == "explicit" and analysis != "dynamic":
        raise ConfigError(t.path("analysis"), "static analyses need solver.integrator = \"implicit\"")
    for name in ("implicit", "petsc"):
        if integrator == "explicit" and t.has(name):
            raise ConfigError(t.path(name), "is the implicit integrator's; set solver.integrator = \"implicit\"")
    return integrator, analysis, (IMPLICIT_SCHEME if integrator == "implicit" else None)


def read_implicit(t):
    """``[solver.implicit]`` (a pmpm.scene.tables.Table or None) as a dict with defaults."""
    if t is None:
        return dict(IMPLICIT_DEFAULTS)
    d = IMPLICIT_DEFAULTS
    out = {"residual_tolerance": t.number("residual_tolerance", d["residual_tolerance"], low=0.0, high=1.0,
                                          low_open=True, high_open=True),
           "energy_tolerance": t.number("energy_tolerance", d["energy_tolerance"], low=0.0, high=1.0,
                                        low_open=True, high_open=True),
           "max_iterations": t.integer("max_iterations", d["max_iterations"], low=1, high=1000),
           "newton": t.string("newton", d["newton"], choices=NEWTON_VARIANTS),
           "line_search": t.boolean("line_search", d["line_search"]),
           "max_halvings": t.integer("max_halvings", d["max_halvings"], low=0, high=40),
           # HHT-alpha: 0 is the trapezoidal rule, -1/3 the most damping of the high modes
           "hht_alpha": t.number("hht_alpha", d["hht_alpha"], low=-1.0 / 3.0, high=0.0),
           # gravity (and the loads at the start) to static equilibrium before the dynamics
           "initial_static": t.boolean("initial_static", d["initial_static"]),
           # newton = "krylov": the GMRES on each tangent (pmpm.core.implicit.kept_factorisation)
           "krylov_tolerance": t.number("krylov_tolerance", d["krylov_tolerance"], low=0.0, high=1.0,
                                        low_open=True, high_open=True),
           "krylov_iterations": t.integer("krylov_iterations", d["krylov_iterations"], low=1, high=1000),
           # slave the edge nodes lighter than this fraction of their inward neighbours
           # (pmpm.core.implicit.edges; 0: off)
           "edge_mass_ratio": t.number("edge_mass_ratio", d["edge_mass_ratio"], low=0.0, high=1.0,
                                       high_open=True)}
    if out["newton"] != "krylov":
        for key in KRYLOV_KEYS:
            if t.has(key):
                raise ConfigError(t.path(key), f"sets the GMRES of newton = \"krylov\" (newton is {out['newton']!r})")
    t.finish()
    return out


#: ``solver.static.control``: "load" is the loads' time functions (the scheme's own load control),
#: the others solve for a load factor (pmpm.core.implicit.arclength)
STATIC_CONTROLS = ("load", "displacement", "arc_length")


def read_static(t, analysis):
    """``[solver.static]`` (a Table or None) as a dict, or None for load control by the loads'
    time functions (no table, or ``control = "load"``). Only under ``analysis = "static"``."""
    if t is None:
        return None
    if analysis != "static":
        raise ConfigError(t.key, "drives a static analysis (solver.analysis = \"static\")")
    control = t.string("control", "load", choices=STATIC_CONTROLS)
    out = {"control": control}
    if control == "load":
        t.finish()
        return None
    pattern = t.raw("pattern", None)
    if pattern is not None and (not isinstance(pattern, list) or not pattern
                                or not all(isinstance(n, str) for n in pattern)):
        raise ConfigError(t.path("pattern"), f"must be a non-empty list of [[loads.forces]] names (got {pattern!r})")
    out["pattern"] = None if pattern is None else tuple(pattern)
    out["gravity"] = t.string("gravity", "fixed", choices=("fixed", "pattern"))
    out["max_load_factor"] = t.number("max_load_factor", float("inf"), low=0.0, low_open=True, magnitude=1e12)
    if control == "displacement":
        out["point"] = t.vector("point")
        out["component"] = "xy".index(t.string("component", choices=("x", "y")))
        out["displacement"] = t.number("displacement", magnitude=1e6)
        if out["displacement"] == 0.0:
            raise ConfigError(t.path("displacement"), "must not be zero (the controlled point's displacement at "
                                                      "end_time)")
    else:
        out["load_factor_increment"] = t.number("load_factor_increment", low=0.0, low_open=True, magnitude=1e6)
        out["target_iterations"] = t.integer("target_iterations", 4, low=1, high=100)
    t.finish()
    return out


def read_petsc(t):
    """``[solver.petsc]``: PETSc option names (no dash) and values, checked for form."""
    if t is None:
        return {}
    options = dict(t.data)
    check_option_names(options, t.key)
    t.used.update(options)
    return options


#: (what the scene has, the key to name, why) for what the implicit step refuses and is not a
#: part of the solver. The parts (effects, transfer, grid fields) say themselves whether the
#: implicit step carries them (``implicit_support``; checked by the scheme's ``check_parts``
#: when the solver is built: contact, APIC/XPIC, a PIC blend, events, pushover, ground motion,
#: damping, supports held by bodies, reactions, section cuts, ...).
def _unsupported(scene):
    cfg, out = scene.solver, scene.output
    yield cfg.interpolation != "point", "solver.interpolation", "GIMP and CPDI are explicit-only for now"
    yield cfg.large_rotations, "solver.large_rotations", ("the implicit step is objective by construction "
                                                          "(Green-Lagrange strain of each step); leave it out")
    yield (scene.pushover is not None and cfg.analysis == "dynamic", "pushover",
           "is static only under the implicit integrator for now (solver.analysis = \"static\")")
    yield "F" in out.fields, "output.fields", "F is not kept by the implicit step"


def _check_static(scene):
    """A load-factor control needs a load pattern and nothing else moving the structure."""
    st, loads = scene.solver.static, scene.loads
    names = [f.name for f in loads.forces]
    for n in st["pattern"] or ():
        if n not in names:
            raise ConfigError("solver.static.pattern", f"no [[loads.forces]] named {n!r}"
                                                       + (f" (defined: {', '.join(names)})" if names else ""))
    if not (st["pattern"] or names) and not (st["gravity"] == "pattern" and loads.gravity is not None):
        raise ConfigError("solver.static.pattern", "no load to scale: the scene has no [[loads.forces]] and "
                                                   "gravity is not in the pattern (gravity = \"pattern\")")
    if st["gravity"] == "pattern" and loads.gravity is None:
        raise ConfigError("solver.static.gravity", "is \"pattern\" but the scene has no loads.gravity")
    if scene.pushover is not None:
        raise ConfigError("pushover", f"moves a boundary by its own displacement control; it cannot run "
                                      f"with solver.static.control = {st['control']!r}")
    if scene.output.checkpoint_interval is not None:
        raise ConfigError("output.checkpoint_interval", "the load factor of solver.static.control = "
                                                        f"{st['control']!r} is not checkpointed yet")
    px = st.get("point")
    if px is not None:
        lo = scene.grid.origin
        hi = [lo[i] + scene.grid.cells[i] * scene.grid.cell_size for i in (0, 1)]
        if not all(lo[i] <= px[i] <= hi[i] for i in (0, 1)):
            raise ConfigError("solver.static.point", f"{list(px)} lies outside the grid")


def check_implicit_scene(scene, materials):
    """Refuse what the implicit integrator cannot run (ConfigError naming the key); for an
    explicit scene, refuse the implicit-only keys.

    Parameters
    ----------
    scene : pmpm.scene.config.Scene
    materials : list of pmpm.physics.materials.Material
        Built in the order of ``scene.materials``.
    """
    cfg = scene.solver
    if cfg.integrator == "explicit":
        return
    if cfg.time_step is None:
        raise ConfigError("solver.time_step", "required by the implicit integrator (its step is not the CFL rule's)")
    if cfg.implicit.get("initial_static") and cfg.analysis != "dynamic":
        raise ConfigError("solver.implicit.initial_static", "starts a dynamic analysis from static equilibrium "
                                                            "(solver.analysis = \"static\" is static throughout)")
    for bad, key, why in _unsupported(scene):
        if bad:
            raise ConfigError(key, f"{why} (solver.integrator = \"implicit\")")
    if cfg.static is not None:
        _check_static(scene)
    for label, m in zip(scene.materials, materials):
        if not m.has_tangent:
            raise ConfigError(f"materials.{label}.type", f"{m.name} has no tangent for the implicit integrator yet")
    validate_options(cfg.petsc)
