"""Numba kernels of the MPM step: plain functions on plain arrays.

Grid arrays are node-interleaved windows ``G[i - ox, j - oy, field]`` (all fields of a node
together), with fields

    0 mass | 1, 2 momentum, then velocity after the grid update | 3, 4 force, then velocity change
    5, 6 re-mapped momentum (MUSL), then re-mapped velocity

Optional effects are passed as ``None`` when the scene does not ask for them: numba compiles a
separate specialisation in which the branch does not exist (no flag is tested in the loops).
The shape function is passed as a jitted function and inlined the same way.
"""
from pmpm.core.kernels.grid_ops import (elastic_energy, grid_update, kinetic_energy, momentum_to_velocity,
                       stress_power)
from pmpm.core.kernels.transfer import p2g, g2p_velocity, g2p_kinematics
from pmpm.core.kernels.objective import jaumann_rotate, rotate
from pmpm.core.kernels.point_loads import point_load_work, scatter_point_loads
from pmpm.core.kernels.sort import cell_order, is_identity, permute_rows
from pmpm.core.kernels.locate import count_strays, cell_columns
from pmpm.core.kernels.deformation import advance_thickness_stretch, check_deformation, in_plane_trace

__all__ = ["p2g", "g2p_velocity", "stress_power", "kinetic_energy", "elastic_energy", "g2p_kinematics", "grid_update", "momentum_to_velocity",
           "jaumann_rotate", "rotate", "check_deformation", "in_plane_trace", "advance_thickness_stretch", "scatter_point_loads", "point_load_work", "cell_order", "permute_rows", "count_strays", "cell_columns", "N_FIELDS", "MASS", "MOM", "FORCE", "REMAP"]

N_FIELDS = 7
MASS, MOM, FORCE, REMAP = 0, 1, 3, 5
