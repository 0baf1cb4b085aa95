"""The solver's own phases against the equations, through the paths the solver really takes
(not only the kernels' unit-test entry points): the load scatter of ``particles_to_grid``, the
MUSL strain from the re-mapped momenta (paper eq. 6) and the CFL step."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.core.kernels.reference import basis_matrix, g2p_kinematics_reference, p2g_reference
from pmpm.build import build_solver
from pmpm.core.step import SchemeContext
from pmpm.scene.config import parse_scene

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}
E, NU, RHO = 1000.0, 0.3, 10.0
H = 0.25
CELLS = (12, 8)


def _scene(shape="cubic", velocity=("0.3 * sin(2 * x) * y", "-0.2 * cos(3 * y) + 0.1 * x"),
           forces=True, gravity=(0.5, -9.8), cfl=0.4):
    loads = {"gravity": list(gravity)}
    if forces:
        loads["forces"] = [{"name": "push", "lower": [0.5, 0.5], "upper": [1.25, 1.0],
                            "force": [3.0, -2.0], "time_function": {"type": "step"}}]
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": H, "cells": list(CELLS)},
        "materials": {"m": {"type": "linear_elastic", "E": E, "nu": NU, "density": RHO}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.5, 0.0], "upper": [2.5, 1.5],
                    "velocity": list(velocity)}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [3.0, 0.0]}],
        "loads": loads,
        "solver": {"end_time": 1.0, "cfl": cfl, "shape_function": shape, "scheme": "musl"},
    }, "phases.toml")


@pytest.mark.parametrize("shape", ["linear", "cubic"])
def test_particles_to_grid_scatters_internal_body_and_set_forces(shape):
    """particles_to_grid(forces=True) is what the solver runs: internal force, m g and the force
    set's shares w_p F (through scatter_point_loads, not p2g's load_id path) on the nodes, eq. 2.
    Tolerance: round-off of sums of O(100) terms of O(1)."""
    s = build_solver(_scene(shape), MPI.COMM_SELF)
    p = s.particles
    rng = np.random.default_rng(2)
    p["stress"][:] = rng.normal(size=p["stress"].shape)
    assert (p["load_id"] >= 0).sum() > 4  # the set holds several particles
    s.reset_grid()
    s.particles_to_grid(momentum=True, forces=True)
    F = np.array([3.0, -2.0])
    fext = p["m"][:, None] * np.array([0.5, -9.8]) + np.where(p["load_id"][:, None] >= 0,
                                                              p["load_w"][:, None] * F, 0.0)
    mass, mom, force = p2g_reference(ORDER[shape], p["x"], p["m"], p["v"], p["vol"], p["stress"], fext,
                                     s.grid.origin, H, CELLS)
    G = s.window.G
    assert (s.window.ox, s.window.oy) == (0, 0) and G.shape[:2] == mass.shape
    np.testing.assert_allclose(G[..., 0], mass, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(G[..., 1:3], mom, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(G[..., 3:5], force, rtol=1e-11, atol=1e-11)
    # the loads reach the grid whole and the internal forces cancel (sum_i N_i = 1, so
    # sum_i grad N_i = 0): the nodal forces add up to the external ones
    np.testing.assert_allclose(G[..., 3:5].sum(axis=(0, 1)), fext.sum(0), rtol=1e-10)


def test_musl_strain_comes_from_the_remapped_momenta():
    """Paper eq. 6: after the grid update and the particle velocity update, MUSL maps the new
    particle momenta back to the grid, v_i = sum_p N_ip m_p v_p / m_i (prescribed where the
    supports are), and takes the strain increment from that field, not from the updated grid
    velocity. Rebuilt here with the NumPy basis; tolerance: round-off."""
    s = build_solver(_scene(forces=False), MPI.COMM_SELF)
    p = s.particles
    x0, vol0 = p["x"].copy(), p["vol"].copy()
    dt = s.dt
    s._dt_step = dt
    s.scheme.advance(SchemeContext(s, dt))
    N, _ = basis_matrix(3, x0, s.grid.origin, H, CELLS)
    mass = np.einsum("pij,p->ij", N, p["m"])
    mom = np.einsum("pij,p,pd->ijd", N, p["m"], p["v"])  # p["v"]: the updated particle velocities
    vel = np.where(mass[..., None] > 0, mom / np.where(mass > 0, mass, 1.0)[..., None], 0.0)
    mask = s.window.bc_mask.astype(bool)
    vel[mask] = s.window.bc_vel[mask]
    de_ref, _, vol_ref, _ = g2p_kinematics_reference(3, x0, vol0, vel, 0.0, dt, s.grid.origin, H, CELLS)
    # the updated grid velocity would give a strain increment that differs at order one
    de_grid, _, _, _ = g2p_kinematics_reference(3, x0, vol0, s.window.G[..., 1:3], 0.0, dt,
                                                s.grid.origin, H, CELLS)
    scale = np.abs(de_ref).max()
    assert np.abs(de_grid - de_ref).max() > 1e-3 * scale  # the two fields really differ here
    np.testing.assert_allclose(s._de, de_ref, rtol=1e-9, atol=1e-12 * scale)
    np.testing.assert_allclose(p["vol"], vol_ref, rtol=1e-12)


@pytest.mark.parametrize("v0", [0.0, 40.0])
def test_cfl_step_is_c_h_over_wave_speed_plus_particle_speed(v0):
    """dt = C h / (c + |v|max) with c = sqrt(E / (rho (1 - nu^2))), the plane-stress
    dilatational speed (c = 10.5 here, so v0 = 40 changes dt fivefold)."""
    s = build_solver(_scene(velocity=(v0, 0.0), forces=False), MPI.COMM_SELF)
    c = math.sqrt(E / (RHO * (1 - NU ** 2)))
    assert s.dt == pytest.approx(0.4 * H / (c + v0), rel=1e-12)
    assert s.critical_dt() == pytest.approx(H / (c + v0), rel=1e-12)
