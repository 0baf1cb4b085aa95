"""Build the material points of a scene and the decomposition that owns them.

Every rank generates the same global set (bodies are cheap to place), numbers the points in
body order (the stable global id used for output), chooses slab boundaries balanced by particle
count along the decomposition axis, and keeps the points whose cell column it owns.
"""
import logging
import os

import numpy as np

from decomposition import SlabDecomposition, balanced_bounds, max_ranks
from .bodies import generate_body
from .errors import ConfigError
from .particles import CORE_FIELDS, Particles

__all__ = ["create_particles", "choose_axis", "make_decomposition"]
logger = logging.getLogger(__name__)


def create_particles(scene, grid, materials, labels):
    """All of the scene's material points as one ``Particles`` (identical on every rank)."""
    scene_dir = os.path.dirname(scene.path) if os.path.isabs(scene.path) else "."
    parts = []
    for k, body in enumerate(scene.bodies):
        mat_index = labels.index(body.material)
        pts = generate_body(k, body, grid, materials[mat_index].density, scene_dir)
        n = len(pts["m"])
        fields = {name: np.zeros((n, *shape), dtype) for name, (shape, dtype) in CORE_FIELDS.items()}
        fields.update(x=pts["x"], x0=pts["x"].copy(), v=pts["v"], vol=pts["vol"], m=pts["m"])
        fields["mat"][:] = mat_index
        fields["body"][:] = k
        parts.append(Particles(fields))
    particles = Particles.concatenate(parts)
    particles["id"] = np.arange(particles.n, dtype=np.int64)
    for material in materials:
        for name, shape in material.state_fields.items():
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
