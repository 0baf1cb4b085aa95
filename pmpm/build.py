"""Build a run's solver from a scene: the one place that turns a Scene into solver parts.

``build_solver(scene, comm)`` does, in order: the grid and its size check, the materials, the
memory check, the strategies (scheme, transfer), the scene's points (every rank places them
all), the effects the scene names (each registered effect's ``create``: boundaries, loads,
ground motion, pushover, damping, events, supports, reactions, section cuts; pmpm.core.effects),
the decomposition, this rank's particles with every field the run keeps, then the solver, and
the time-step check. The solver receives the parts and never sees the scene.

Without ``[contact]`` the grid holds one velocity field (pmpm.core.fields.GridFields); with it
one per body (pmpm.physics.contact.BodyFields).
"""
import logging
import os
from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

import pmpm.physics  # noqa: F401  (registers the materials and effects)
import pmpm.results.reactions  # noqa: F401  (registers the effects of the structural results)
import pmpm.results.sections  # noqa: F401
from decomposition import get_comm
from pmpm.core import kernels as K
from pmpm.core.effects import EffectList, registered_effects
from pmpm.core.fields import GridFields
from pmpm.core.grid import Grid
from pmpm.core.particles import OPTIONAL_FIELDS, start_deformation
from pmpm.core.schemes import make_scheme
from pmpm.core.shape import MAX_HALF_LENGTH, ghost_width, min_cells
from pmpm.core.solver import Solver, StepOptions
from pmpm.core.transfers import make_transfer
from pmpm.errors import ConfigError
from pmpm.physics.contact import BodyFields, contact_slots
from pmpm.physics.materials import make_material
from pmpm.scene.limits import check_memory, check_time_step
from pmpm.scene.setup_particles import choose_axis, create_particles, make_decomposition, place_points

__all__ = ["build_solver", "needs_deformation_gradient", "step_options"]
logger = logging.getLogger(__name__)


def needs_deformation_gradient(scene, materials):
    """Whether the run keeps the deformation gradient F per particle: a material that needs it
    (hyperelastic), the Green-Naghdi rate (the rotation of F), CPDI (its particle domains are
    F times the initial ones), or an output field ``F``.
    Otherwise F is neither stored nor updated (the kernels get None and compile it out).

    Parameters
    ----------
    scene : pmpm.scene.config.Scene
    materials : list of pmpm.physics.materials.Material
    """
    cfg = scene.solver
    return (any(m.needs_deformation_gradient for m in materials)
            or (cfg.large_rotations and cfg.objective_rate == "green_naghdi")
            or cfg.interpolation == "cpdi"
            or "F" in scene.output.fields)


def step_options(scene):
    """The settings of ``scene`` the step reads (pmpm.core.solver.StepOptions)."""
    cfg, par = scene.solver, scene.parallel
    return StepOptions(shape_function=cfg.shape_function, interpolation=cfg.interpolation,
                       end_time=cfg.end_time, cfl=cfg.cfl, time_step=cfg.time_step,
                       sort_interval=cfg.sort_interval, on_particle_exit=cfg.on_particle_exit,
                       objective_rate=cfg.objective_rate, plane_stress=scene.formulation == "plane_stress",
                       rebalance_threshold=par.rebalance_threshold, rebalance_interval=par.rebalance_interval)


def _scene_dir(scene):
    return os.path.dirname(scene.path) if os.path.isabs(scene.path) else "."


def _materials(scene, comm):
    """The scene's materials, after the check that one rank can hold its share of the run."""
    materials = [make_material(scene.materials[k], f"materials.{k}", scene.formulation) for k in scene.materials]
    # before anything big is allocated: this rank's share of grid window and particles
    local = comm.Split_type(MPI.COMM_TYPE_SHARED) if comm.Get_size() > 1 else None
    check_memory(scene, comm.Get_size(), local.Get_size() if local else 1,
                 state_floats=sum(int(np.prod(f)) for m in materials for f in m.state_fields.values()))
    if local is not None:
        local.Free()
    return materials


def _grid(scene):
    cfg = scene.solver
    grid = Grid(scene.grid.origin, scene.grid.cell_size, scene.grid.cells)
    need = min_cells(cfg.shape_function, cfg.interpolation)
    if min(grid.cells) < need:
        raise ConfigError("grid.cells", f"{cfg.shape_function} B-splines"
                          f"{'' if cfg.interpolation == 'point' else ' with ' + cfg.interpolation}"
                          f" need at least {need} cells per axis")
    return grid


def _initial_domains(scene, grid, vol, body):
    """The GIMP particle domains: half-lengths (cells) of the square of the particle's area,
    (h / ppc) / 2 for a body filled on a lattice, capped at ``MAX_HALF_LENGTH``."""
    thickness = np.array([b.thickness for b in scene.bodies])[body]
    half = 0.5 * np.sqrt(vol / thickness) * grid.inv_h
    return np.repeat(np.minimum(half, MAX_HALF_LENGTH)[:, None], 2, axis=1)


def make_effects(scene, setup):
    """The effects ``scene`` names, in registry order (each registered effect's ``create``)."""
    for cls in registered_effects():
        effect = cls.create(scene, setup)
        if effect is not None:
            setup.effects[effect.name] = effect
    return EffectList(setup.effects.values())


def build_solver(scene, comm=None):
    """The solver of ``scene`` on the ranks of ``comm`` (None: COMM_WORLD), at t = 0 (module doc).

    Parameters
    ----------
    scene : pmpm.scene.config.Scene
    comm : mpi4py communicator, optional
    """
    comm = get_comm(comm)
    cfg = scene.solver
    grid = _grid(scene)
    materials = _materials(scene, comm)
    for material in materials:   # a length tied to the cell (the fracture's crack band)
        material.use_cell_size(grid.h)
        material.use_integrator(cfg.integrator)
    scheme = make_scheme(cfg.scheme, cfg)
    transfer = scheme.choose_transfer(make_transfer(cfg.transfer, cfg))   # mls brings its own
    reach = ghost_width(cfg.shape_function, cfg.interpolation)
    points = place_points(scene, grid, materials, list(scene.materials))
    setup = SimpleNamespace(grid=grid, materials=materials, points=points, reach=reach, scene_dir=_scene_dir(scene),
                            shape_function=cfg.shape_function, interpolation=cfg.interpolation,
                            effects={}, decomp=None)
    effects = make_effects(scene, setup)
    axis = choose_axis(scene.parallel.axis, grid)
    decomp = setup.decomp = make_decomposition(comm, grid, axis, reach, points["x"])
    optional = [f for f in scene.output.fields
                if f in OPTIONAL_FIELDS or any(f in m.diagnostic_fields for m in materials)]
    keeps_F = needs_deformation_gradient(scene, materials)
    # the objective rate rotates stresses only a rate-form material integrates: a model that
    # computes its stress from F (neo-Hookean) overwrites a rotated stress unread
    rotates_stress = cfg.large_rotations and not all(
        m.stress_from_F and not m.tensor_state_fields for m in materials)
    cols = K.cell_columns(points["x"], grid.origin, grid.inv_h, axis)
    particles = create_particles(points, decomp.owner_of_columns(cols) == decomp.rank, materials, optional)
    if keeps_F:
        start_deformation(particles)
    for effect in effects:   # the effects' particle fields (supports, viscous stress, load sets)
        effect.add_fields(particles, setup)
    for name, shape in transfer.fields.items():   # APIC's affine velocity; none for FLIP
        particles.add_field(name, shape)
    if cfg.interpolation != "point":
        particles["domain"] = _initial_domains(scene, grid, particles["vol"], particles["body"])
    parts = (grid, decomp, particles, materials, scheme, transfer, effects, step_options(scene), len(points["m"]))
    del points, setup.points
    grid_fields = GridFields()   # one velocity field (pmpm.core.fields); [contact]: one per body
    if scene.contact is not None:
        grid_fields = BodyFields(scene.contact.friction, *contact_slots(scene))
    # the scheme refuses the parts it cannot drive (the implicit one: effects, transfer and
    # grid fields that do not say implicit_support), before anything is allocated for them
    scheme.check_parts(effects, transfer, grid_fields)
    solver = Solver(*parts, mass_cutoff=cfg.mass_cutoff, keeps_F=keeps_F, rotates_stress=rotates_stress,
                    grid_fields=grid_fields)
    check_time_step(scene, materials, solver.vmax)  # positive, finite, not too many steps
    return solver
