"""Build the material points of a scene and the decomposition that owns them.

Every rank generates the same global set (bodies are cheap to place), numbers the points in
body order (the stable global id used for output), chooses slab boundaries balanced by particle
count along the decomposition axis, and keeps the points whose cell column it owns.
"""
import logging
import os

import numpy as np

from decomposition import SlabDecomposition, balanced_bounds, max_ranks
from pmpm.scene.bodies import check_overlaps, generate_body
from pmpm.errors import ConfigError
from pmpm.core.grid import Grid
from pmpm.core.particles import CORE_FIELDS, OPTIONAL_FIELDS, Particles
from pmpm.physics.loads import box_load_report
from pmpm.physics.materials import make_material

__all__ = ["place_points", "create_particles", "choose_axis", "make_decomposition", "load_box_report"]
logger = logging.getLogger(__name__)


def place_points(scene, grid, materials, labels):
    """Positions, velocities, volumes, masses, material and body of every point of the scene
    (identical on every rank): the few fields needed to decide who owns what."""
    scene_dir = os.path.dirname(scene.path) if os.path.isabs(scene.path) else "."
    parts = []
    for k, body in enumerate(scene.bodies):
        mat_index = labels.index(body.material)
        pts = generate_body(k, body, grid, materials[mat_index].density, scene_dir)
        n = len(pts["m"])
        pts["mat"] = np.full(n, mat_index, dtype=np.int32)
        pts["body"] = np.full(n, k, dtype=np.int32)
        parts.append(pts)
    check_overlaps(scene.bodies, [p["x"] for p in parts], grid.h)
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def load_box_report(scene):
    """``--check`` lines for the forces whose box (naming no body) catches several bodies: the
    scene's points are placed as a run places them (pmpm.physics.loads.box_load_report)."""
    if not any(not f.body_ids for f in scene.loads.forces):
        return []
    grid = Grid(scene.grid.origin, scene.grid.cell_size, scene.grid.cells)
    labels = list(scene.materials)
    materials = [make_material(scene.materials[k], f"materials.{k}", scene.formulation) for k in labels]
    points = place_points(scene, grid, materials, labels)
    return box_load_report(scene.loads.forces, points["x"], points["body"], points["m"],
                           [b.name for b in scene.bodies])


def create_particles(points, keep, materials, optional=()):
    """The full particle state of the points selected by ``keep`` (a boolean mask): core
    fields, material state (a diagnostic field only when in ``optional``, the fields the
    output asks for), and the global id (the point's index in the scene). Only the
    owned points get full fields, so no rank ever holds the whole scene's state."""
    idx = np.nonzero(keep)[0]
    n = len(idx)
    fields = {name: np.zeros((n, *shape), dtype) for name, (shape, dtype) in CORE_FIELDS.items()}
    for key in ("x", "v", "vol", "m", "mat", "body"):
        fields[key][...] = points[key][idx]
    fields["x0"][...] = fields["x"]
    fields["id"][...] = idx
    particles = Particles(fields)
    for name in optional:
        if name in OPTIONAL_FIELDS:
            shape, dtype = OPTIONAL_FIELDS[name]
            particles.add_field(name, shape, dtype)
    for material in materials:
        for name, shape in material.state_fields.items():
            if name not in material.diagnostic_fields or name in optional:
                particles.add_field(name, shape)
    return particles


def choose_axis(setting, grid):
    """Decomposition axis: the scene's choice, else the axis with more cells."""
    if setting == "x":
        return 0
    if setting == "y":
        return 1
    return 0 if grid.cells[0] >= grid.cells[1] else 1


def make_decomposition(comm, grid, axis, ghost, x):
    """Slabs balanced by the particle count per node column (all ranks pass the same x)."""
    ncols = grid.nodes[axis]
    size = comm.Get_size()
    if size * ghost > ncols:
        raise ConfigError("grid.cells", f"{size} ranks need at least {size * ghost} node columns along "
                                        f"{'xy'[axis]} (have {ncols}); use at most {max_ranks(ncols, ghost)} ranks")
    cols = np.floor((x[:, axis] - grid.origin[axis]) * grid.inv_h).astype(np.int64)
    weights = np.bincount(cols, minlength=ncols).astype(np.float64)
    bounds = balanced_bounds(weights, size, ghost)
    return SlabDecomposition(comm, grid.nodes, axis, ghost, bounds=bounds)
