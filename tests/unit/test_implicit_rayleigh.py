"""Rayleigh damping as a matrix term under the implicit integrator (pmpm.physics.rayleigh,
RayleighImplicit; docs/implicit.md) against the closed form of a damped oscillator under the
trapezoidal rule.

The bar of design.md section 7 (fixed-free, omega_1 = pi / 5, T_1 = 10) in its first mode, with
``[loads] damping = {ratio = 0.05, periods = [T_1, T_1 / 3]}``: both the mass part a0 M and the
stiffness part a1 K act (the first and second modes are damped at 5 %). The trapezoidal rule is
the Cayley map of the modal equation q'' + 2 xi w q' + w^2 q = 0 written as y' = A y: per step
y_{n+1} = (1 - dt A / 2)^-1 (1 + dt A / 2) y_n, so the mode's displacement is Re(c lambda^n) with
lambda = (1 + dt mu / 2) / (1 - dt mu / 2), mu = w (-xi + i sqrt(1 - xi^2)): its decay and its
phase per step, whatever the step. At 8 steps a period lambda's decay per period is 0.762 and
its period 4.9 % longer than the damped one's; over three periods the amplitude falls to 44 %.

Shown to fail on planted bugs (each restored):
- the stiffness part left out of the residual (``F`` without the viscous stress's force): the
  tip no longer follows lambda^n (deviation 6.5 % of the amplitude against the 1 % allowed);
- the mass part's tangent dropped (``Kb[:, centre]`` not increased): Newton needs 127
  iterations for 24 steps instead of 48 (test_newton_sees_the_damping_matrix);
- the mass part's work counted at v_{n+1} only (not the trapezoid): the energy balance is off
  by 2.8 % (test_energy_dissipated_is_accounted).
"""
import dataclasses
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.benchmarks.implicit import BAR_CFL_STEP, BAR_OMEGA, bar_scene
from pmpm.build import build_solver

XI = 0.05
DT = 50 * BAR_CFL_STEP           # 8 steps a period
PERIODS = 3


def damped_bar(dt=DT, periods=PERIODS, ratio=XI):
    scene = bar_scene(dt, periods * 10.0)
    loads = dataclasses.replace(scene.loads, rayleigh={"ratio": ratio, "periods": (10.0, 10.0 / 3)})
    return dataclasses.replace(scene, loads=loads)


@pytest.fixture(scope="module")
def run():
    scene = damped_bar()
    s = build_solver(scene, MPI.COMM_SELF)
    ids = s.particles["id"].copy()
    tip = ids[np.argmax(s.particles["x"][:, 0] - 10 * s.particles["x"][:, 1])]
    x0 = s.particles["x"][ids == tip, 0][0]
    e0 = s.energies()
    u = []
    while s.t < scene.solver.end_time - 1e-9:
        s.step()
        u.append(s.particles["x"][s.particles["id"] == tip, 0][0] - x0)
    return np.array(u), e0, s


def trapezoidal_multiplier(omega, xi, dt):
    """lambda: the trapezoidal rule's per-step multiplier of the damped oscillator's mode."""
    mu = omega * complex(-xi, math.sqrt(1 - xi * xi))
    return (1 + dt * mu / 2) / (1 - dt * mu / 2)


def test_mode_decays_as_the_trapezoidal_rule_says(run):
    """The tip displacement is Re(c lambda^n) (c fitted: the mode's amplitude and phase at the
    start) within 1 % of the amplitude at every step of three periods; the space discretisation
    moves omega by 0.05 % (test_implicit_step: the undamped bar's period) and the transfers'
    projection takes 0.3 % of the energy over three periods, both far below 1 %. The decay
    itself is large: the closed form's amplitude over three periods is 44 %."""
    u, _, _ = run
    lam = trapezoidal_multiplier(BAR_OMEGA, XI, DT)
    n = np.arange(1, len(u) + 1)
    basis = np.stack([np.real(lam ** n), np.imag(lam ** n)], axis=1)
    c, *_ = np.linalg.lstsq(basis, u, rcond=None)
    assert abs(lam) ** len(u) < 0.5                     # the effect measured is large
    assert np.abs(u - basis @ c).max() < 0.01 * np.abs(u).max()


def test_energy_dissipated_is_accounted(run):
    """Kinetic + strain energy + the two parts' dissipated work = the start's energy (the loss
    left over is the transfers' 0.3 % over three periods: under 1 %, and never a gain); the
    energy the bar lost is mostly dissipated (it loses 1 - |lambda|^(2 n) = 80 %)."""
    _, e0, s = run
    e = s.energies()
    start = e0["kinetic"] + e0["strain"]
    left = e["kinetic"] + e["strain"]
    dissipated = e["damping_work"] + e["viscous_damping_work"]
    assert e["damping_work"] > 0 and e["viscous_damping_work"] > 0
    assert 1 - left / start > 0.7
    assert 0.0 <= (start - left - dissipated) / start < 0.01


def test_newton_sees_the_damping_matrix(run):
    """The bar is linear (v0 tiny): with the damping's exact tangent gamma / (beta dt) C every
    step converges in one correction and one check of the residual (2 iterations)."""
    _, _, s = run
    assert s.scheme.stats["halvings"] == 0
    assert s.scheme.stats["newton_iterations"] <= 2 * s.scheme.stats["steps"]
