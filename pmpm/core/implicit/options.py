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
    line_search = false            # halve the step while the energy slope grows (Crisfield)
    max_halvings = 6               # smallest step: time_step / 2^max_halvings
    hht_alpha = 0.0                # HHT-alpha in [-1/3, 0]: damping of the highest modes
    initial_static = false         # dynamics: first bring the loads at the start time (gravity,
                                   # the force sets' values) to static equilibrium, then go on

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
           "IMPLICIT_SCHEME"]

INTEGRATORS = ("explicit", "implicit")
ANALYSES = ("dynamic", "static")
#: tangent updates of Newton's iterations (pmpm.core.implicit.newton)
NEWTON_VARIANTS = ("full", "modified")
#: the registry name of the implicit scheme (pmpm.core.schemes)
IMPLICIT_SCHEME = "newmark"
IMPLICIT_DEFAULTS = {"residual_tolerance": 1e-8, "energy_tolerance": 1e-12, "max_iterations": 25,
                     "newton": "full", "line_search": False, "max_halvings": 6, "hht_alpha": 0.0, "initial_static": False}


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
           "initial_static": t.boolean("initial_static", d["initial_static"])}
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
    for label, m in zip(scene.materials, materials):
        if not m.has_tangent:
            raise ConfigError(f"materials.{label}.type", f"{m.name} has no tangent for the implicit integrator yet")
    validate_options(cfg.petsc)
