"""Section forces and support reactions checked by equilibrium (issue 14, item 4).

A cantilever strip (L = 1, depth 0.2, thickness 0.1; E = 1e6, nu = 0, rho = 1) built into a
wall of fixed nodes at x <= 0, under a downward tip load P spread by mass over its last
particle column (centroid x_P = L - h/2 = 0.975):

- damped (mass-proportional, near critical for the first mode) until it settles: statics says
  Ry = P, Rx = 0, M_wall = P x_P; along the member V = P, N = 0, M = P (x_P - x) (the
  convention of pmpm.results.sections); and the cut next to the wall carries the wall's
  reaction moment transferred to it;
- undamped (a step load: it vibrates about the static shape): Newton's second law for the
  whole body, sum of loads + reactions = d(total momentum)/dt, which the reaction's interval
  mean makes a statement about impulses over each sampling interval.

The tolerances are the issue's: 0.5% for the settled reactions, 1% for the base moment and the
momentum balance, 2% for the section forces along the member. What remains after settling
(the damped run is stopped after about 12 decay times of the slowest mode) is far below them.
"""
import copy

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.results.recorder import StructuralRecorder
from pmpm.scene.config import parse_scene

P, L, H = 0.5, 1.0, 0.05
X_LOAD = L - H / 2  # centroid of the loaded column of particles (x = 0.9625 and 0.9875)

CANTILEVER = {
    "title": "cantilever strip", "thickness": 0.1, "particles_per_cell": 2,
    "grid": {"origin": [-0.2, -0.3], "cell_size": H, "cells": [28, 12]},
    "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.0, "density": 1.0}},
    "bodies": [{"name": "strip", "shape": "rectangle", "material": "m",
                "lower": [0.0, -0.1], "upper": [L, 0.1]}],
    "boundary": [{"name": "wall", "type": "fixed", "lower": [-0.2, -0.3], "upper": [0.0, 0.3],
                  "reaction": True, "moment_about": [0.0, 0.0]}],
    "loads": {"forces": [{"name": "tip", "lower": [L - H, -0.1], "upper": [L, 0.1], "force": [0.0, -P]}]},
    "solver": {"end_time": 1.0},
    "output": {"section": [{"name": f"x{x:g}", "segment": [[x, -0.25], [x, 0.25]]}
                           for x in (0.25, 0.375, 0.5, 0.625, 0.75)]},
}
#: the first cut is the "base section": 5 cells from the wall. Closer in, the clamp's fixed
#: nodes reach the particles (cubic B-splines: 2 cells) and the stresses ring with period 2h
#: for about 3 cells (docs/structural_results.md shows the profile), so a cut there does not
#: see the plain beam the statics describes.
SECTION_X = np.array([0.25, 0.375, 0.5, 0.625, 0.75])


def _solver(damping, comm=MPI.COMM_SELF):
    data = copy.deepcopy(CANTILEVER)
    data["loads"]["damping"] = damping
    return build_solver(parse_scene(data, "cantilever.toml"), comm)


def _momentum(s):
    p = s.particles
    return s.decomp.allreduce_sum((p["m"][:, None] * p["v"]).sum(axis=0))


@pytest.fixture(scope="module")
def settled():
    """Damped run: first-mode omega about 200 rad/s (Euler-Bernoulli with shear softening),
    damping 400 1/s is about critical; 0.15 s is many decay times of every mode."""
    s = _solver(400.0)
    rec = StructuralRecorder(s)
    while s.t < 0.15 - 1e-12:
        s.step()
    # the reactions are interval means: over 400 steps (10 ms, about two periods of the first
    # mode) the small motion left after settling averages out (over 20 steps it reads 0.4%)
    rec.sample()
    for _ in range(400):
        s.step()
    return rec.sample()


def test_settled_reactions_balance_the_load(settled):
    _, ((Rx, Ry, M),) = settled
    assert Ry == pytest.approx(P, rel=0.005)
    assert abs(Rx) < 0.005 * P
    assert M == pytest.approx(P * X_LOAD, rel=0.005)


def test_base_section_moment_equals_the_reaction_moment(settled):
    """The base cut (x = 0.25) carries the wall's reaction, moved to the cut."""
    sections, ((Rx, Ry, M0),) = settled
    N, V, M = sections[0]
    c = np.array([SECTION_X[0], 0.0])
    M_reaction_at_cut = M0 - (c[0] * Ry - c[1] * Rx)   # moment about c of the same forces
    assert M == pytest.approx(M_reaction_at_cut, rel=0.01)
    assert V == pytest.approx(Ry, rel=0.01)


def test_settled_sections_follow_statics(settled):
    sections, _ = settled
    N, V, M = sections[1:].T
    np.testing.assert_allclose(V, P, rtol=0.02)
    np.testing.assert_allclose(M, P * (X_LOAD - SECTION_X[1:]), rtol=0.02)
    assert np.all(np.abs(N) < 0.02 * P)


def test_undamped_momentum_balance_at_every_output():
    """(p(t_k) - p(t_k-1)) / (t_k - t_k-1) = applied load + mean reaction, at every output of
    a vibrating run (two periods of the first mode, outputs every 20 steps)."""
    s = _solver(0.0)
    rec = StructuralRecorder(s)
    rec.sample()
    t_prev, p_prev = s.t, _momentum(s)
    errors = []
    while s.t < 0.06:
        for _ in range(20):
            s.step()
        _, ((Rx, Ry, _M),) = rec.sample()
        p_now = _momentum(s)
        rate = (p_now - p_prev) / (s.t - t_prev)
        load = np.array([0.0, -P])
        errors.append(np.abs(rate - (load + [Rx, Ry])).max() / P)
        t_prev, p_prev = s.t, p_now
    assert max(errors) < 0.01, max(errors)


def report():
    """Print the measured errors of every check (docs/structural_results.md quotes them)."""
    s = _solver(400.0)
    rec = StructuralRecorder(s)
    while s.t < 0.15 - 1e-12:
        s.step()
    rec.sample()
    for _ in range(400):
        s.step()
    sec, ((Rx, Ry, M0),) = rec.sample()
    print(f"settled: Ry/P - 1 = {Ry / P - 1:+.2e}, Rx/P = {Rx / P:+.2e}, M/(P x_P) - 1 = {M0 / (P * X_LOAD) - 1:+.2e}")
    c = SECTION_X[0]
    print(f"base cut x = {c}: M / (reaction moment at the cut) - 1 = {sec[0, 2] / (M0 - c * Ry) - 1:+.2e}")
    for x, (N, V, M) in zip(SECTION_X, sec):
        print(f"cut x = {x}: N/P = {N / P:+.2e}, V/P - 1 = {V / P - 1:+.2e}, M/(P (x_P - x)) - 1 = "
              f"{M / (P * (X_LOAD - x)) - 1:+.2e}")
    s = _solver(0.0)
    rec = StructuralRecorder(s)
    rec.sample()
    t_prev, p_prev, errors = s.t, _momentum(s), []
    while s.t < 0.06:
        for _ in range(20):
            s.step()
        _, ((Rx, Ry, _M),) = rec.sample()
        p_now = _momentum(s)
        errors.append(np.abs((p_now - p_prev) / (s.t - t_prev) - np.array([Rx, Ry - P])).max() / P)
        t_prev, p_prev = s.t, p_now
    print(f"undamped: max over {len(errors)} outputs of |dp/dt - loads - R| / P = {max(errors):.2e}")


if __name__ == "__main__":
    report()
