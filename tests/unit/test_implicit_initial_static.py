"""Gravity brought to static equilibrium before the dynamics (``[solver.implicit]
initial_static = true``, docs/implicit.md): the clamped steel cantilever of
tests/unit/test_implicit_step.py under its weight, then a dynamic run.

Theory: at the end of the static stage the supports carry the weight (the held components'
force sum = m g, to Newton's tolerance 1e-8 of the force scale; asserted to 1e-6 as the issue
asks) and the tip's deflection is Timoshenko's (within 2 %, the static test's tolerance: 0.4 %
measured at 0.1 m cells); the dynamic run then starts in equilibrium at rest, so nothing moves
while the loads stay constant: the tip stays at its static deflection to 1e-5 of it over a
period of the first mode (the residual left by Newton's tolerance drives at most a motion of
that order; without the static stage the tip swings to twice the static deflection).

Shown to fail on a planted bug (restored): the static stage skipped (``substep`` not called in
``initial_equilibrium``): the reaction test fails (no reaction), and so does the drift test (the
tip starts from rest at 4 % of the static deflection and swings).

Also fixed with it: Newton's energy criterion was relative to the first correction's energy, which
for a step that starts in equilibrium is round-off; every step of this run then failed to
converge (pmpm.core.implicit.newton now scales it to the force scale).
"""
import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.benchmarks.implicit import BEAM_Y0, cantilever_scene, timoshenko_tip_deflection
from pmpm.build import build_solver

G = 9.81
DT, T_END = 2.5e-3, 0.05     # the cantilever's first period is about 49 ms


def dynamic_cantilever(initial_static=True):
    scene = cantilever_scene(gravity=G)
    implicit = dict(scene.solver.implicit, initial_static=initial_static)
    solver = dataclasses.replace(scene.solver, analysis="dynamic", time_step=DT, end_time=T_END, implicit=implicit)
    return dataclasses.replace(scene, solver=solver)


def _run(initial_static):
    s = build_solver(dynamic_cantilever(initial_static), MPI.COMM_SELF)
    p = s.particles
    tip = np.argmax(p["x"][:, 0] - 1e-3 * np.abs(p["x"][:, 1] - BEAM_Y0 - 0.2))
    tip_id, y0 = p["id"][tip], p["x"][tip, 1]
    weight = float(np.sum(p["m"])) * G
    w = []
    while s.t < T_END - 1e-12:
        s.step()
        w.append(y0 - s.particles["x"][s.particles["id"] == tip_id, 1][0])
    return s, np.array(w), weight


@pytest.fixture(scope="module")
def run():
    return _run(True)


def test_supports_carry_the_weight_after_the_static_stage(run):
    s, w, weight = run
    reaction = s.scheme.initial_reaction
    assert abs(reaction[0]) < 1e-6 * weight
    assert abs(abs(reaction[1]) - weight) < 1e-6 * weight, (reaction, weight)


def test_no_drift_at_the_start_of_the_dynamics(run):
    s, w, _ = run
    static = timoshenko_tip_deflection(G)
    assert w[0] == pytest.approx(static, rel=0.02)
    assert np.abs(w - w[0]).max() < 1e-5 * w[0], np.abs(w - w[0]).max() / w[0]


def test_without_the_static_stage_the_tip_swings():
    """The same run without the static stage: the weight acts as a step load and the tip swings
    to about twice the static deflection (the effect the stage removes is large)."""
    s, w, _ = _run(False)
    assert w.max() > 1.5 * timoshenko_tip_deflection(G)
