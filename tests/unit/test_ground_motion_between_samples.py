"""The ground motion between record samples against the exact integrals of the piecewise-linear
acceleration, computed here with a different rule than pmpm's.

The record: irregular sample times that start after t = 0 with a non-zero first acceleration
(before the record the ground is at rest: docs/scenes.md), and time steps that never land on a
sample. On an interval [t_k, t_k+1] the acceleration is linear, so the velocity is quadratic and
the displacement cubic; Simpson's rule is exact for both (cubics), so

    v(t) = sum of the whole intervals' trapezoids (exact for a linear a) + Simpson on [t_k, t]
    u(t) = Simpson on each piece of the velocity (exact for the quadratic v)

are exact to round-off without using pmpm's closed form v_k + a_k tau + (a_k+1 - a_k) tau^2 / 2h.
"""
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.physics.groundmotion import GroundMotion
from pmpm.scene.config import parse_scene

# irregular samples from t0 = 0.013 s (a jump at the start: a(t0) != 0)
T_REC = np.array([0.013, 0.021, 0.040, 0.047, 0.071, 0.090, 0.1105, 0.124, 0.150])
A_REC = np.array([1.7, -2.3, 3.1, 0.4, -4.2, 2.8, -1.1, 3.6, -0.9])


def _a(t):
    return np.interp(t, T_REC, A_REC)


def v_exact(t):
    """Ground velocity: 0 before the record, the record's integral on it, constant after."""
    if t <= T_REC[0]:
        return 0.0
    te = min(t, T_REC[-1])
    k = int(np.searchsorted(T_REC, te) - 1)
    k = min(k, len(T_REC) - 2)
    whole = sum(0.5 * (A_REC[i] + A_REC[i + 1]) * (T_REC[i + 1] - T_REC[i]) for i in range(k))
    lo = T_REC[k]
    part = (te - lo) / 6 * (_a(lo) + 4 * _a(0.5 * (lo + te)) + _a(te))
    return whole + part


def u_exact(t):
    """Ground displacement: Simpson's rule on every piece of [0, t] where v is one quadratic."""
    knots = [0.0] + [x for x in T_REC if x < t] + [t]
    total = 0.0
    for lo, hi in zip(knots[:-1], knots[1:]):
        total += (hi - lo) / 6 * (v_exact(lo) + 4 * v_exact(0.5 * (lo + hi)) + v_exact(hi))
    return total


def _record(tmp_path):
    path = tmp_path / "record.txt"
    np.savetxt(path, np.column_stack([T_REC, A_REC]))
    return path


def test_velocity_at_and_between_samples_is_the_exact_integral(tmp_path):
    from pmpm.scene.config import BoundaryConfig
    bc = BoundaryConfig("ground", "fixed", (0.0, 0.0), (1.0, 0.0), (0.0, 0.0))
    g = GroundMotion({"file": str(_record(tmp_path)), "format": "auto", "scale": 1.0,
                      "direction": "x", "boundaries": []}, [bc], str(tmp_path))
    # at each sample, at 7 irregular points inside every interval, before and after the record
    times = list(T_REC) + [0.0, 0.005, 0.2, 1.0]
    for lo, hi in zip(T_REC[:-1], T_REC[1:]):
        times += list(lo + (hi - lo) * np.array([0.01, 0.13, 0.29, 0.5, 0.61, 0.87, 0.99]))
    scale = np.abs(A_REC).max() * (T_REC[-1] - T_REC[0])
    for t in times:
        # tolerance: round-off of sums of ten terms of the size of the velocity scale
        assert g.velocity(t) == pytest.approx(v_exact(t), abs=1e-13 * scale), t
    assert g.velocity(0.2) == pytest.approx(v_exact(T_REC[-1]), abs=1e-13 * scale)


def test_a_body_carried_by_the_ground_moves_with_it_step_by_step(tmp_path):
    """Every node of the box is driven (all particles carried rigidly), off the origin, along y:
    at every step each particle's velocity is the exact ground velocity at the step's end and
    its displacement the sum of dt times those velocities (the solver moves particles with the
    end-of-step grid velocity), both to round-off; and that displacement approaches the exact
    integral u(t) within max|a| T dt / 2 (the right Riemann sum of v: its error is at most half
    of max|dv/dt| dt per unit time)."""
    scene = parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [-1.3, 0.45], "cell_size": 0.1, "cells": [20, 14]},
        "materials": {"m": {"type": "linear_elastic", "E": 2e5, "nu": 0.3, "density": 100.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [-0.8, 0.75], "upper": [-0.1, 1.15]}],
        "boundary": [{"name": "ground", "type": "fixed", "lower": [-1.3, 0.45], "upper": [0.7, 1.85]}],
        "loads": {"ground_motion": {"file": str(_record(tmp_path)), "direction": "y"}},
        "solver": {"end_time": 0.17, "cfl": 0.37},
    }, str(tmp_path / "carried.toml"))
    s = build_solver(scene, MPI.COMM_SELF)
    p = s.particles
    order = np.argsort(p["id"])
    y0 = p["x"][order, 1].copy()
    x0 = p["x"][order, 0].copy()
    u_sum, vmax, steps = 0.0, 1e-30, 0
    while s.t < scene.solver.end_time - 1e-12:
        t_before = s.t
        s.step()
        steps += 1
        dt = s.t - t_before
        v = v_exact(s.t)
        vmax = max(vmax, abs(v))
        u_sum += dt * v
        order = np.argsort(p["id"])
        assert np.abs(p["v"][:, 1] - v).max() <= 1e-12 * vmax, s.t
        assert np.abs(p["v"][:, 0]).max() <= 1e-12 * vmax
        # round-off of x += dt v on positions of order 1 m, over a few hundred steps
        np.testing.assert_allclose(p["x"][order, 1] - y0, u_sum, rtol=1e-12, atol=1e-13)
    assert steps > 3 * len(T_REC)  # many steps between samples
    np.testing.assert_allclose(p["x"][order, 0], x0, rtol=0, atol=1e-14)
    T = s.t
    assert u_sum == pytest.approx(u_exact(T), abs=0.5 * np.abs(A_REC).max() * T * s.dt)
