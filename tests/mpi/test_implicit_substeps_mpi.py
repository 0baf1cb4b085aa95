"""Halved implicit steps hand on the particles that crossed a slab boundary before the next
sub-step (issue 37; docs/implicit.md).

The solver migrates particles at the end of a scene step; a step the implicit scheme halves is
two sub-steps or more within one scene step. The step's kernels index the rank's grid window
from the particles' start positions without bounds checks, and a cubic B-spline stencil reaches
two nodes above its cell with a ghost width of two: a particle that crossed the upper boundary
of its slab in the first sub-step made the second one read and write one node column past the
window (heap corruption; the step now checks every stencil against the window and stops on
every rank if one leaves it).

The bar of tests/mpi/test_implicit_mpi.py (slabs along it) swings at 0.4 m/s (v0 sin(pi x /
50): about 0.2 m, 0.4 cells, per sub-step at the middle, where the slab boundary of 2 ranks is),
and every full step is made to fail once (a planted Newton failure of the full-length step), so
each scene step is two sub-steps; the result must be the serial run's to 1e-9 (the same halved
sub-steps on one rank, where nothing migrates).

Shown to fail without the fix (the migration between sub-steps, ImplicitNewmark.
migrate_between_substeps, not called): the stencil check stops the run on 2 ranks
("a particle's stencil reaches past its rank's grid window").
Run: ``mpirun -n 2 python -m pytest -q tests/mpi/test_implicit_substeps_mpi.py``.
"""
import os
import sys

import pytest
from mpi4py import MPI

from pmpm.benchmarks.implicit import bar_scene
from pmpm.core.implicit import scheme as scheme_module
from pmpm.core.implicit.newton import NewtonFailed

sys.path.insert(0, os.path.dirname(__file__))
from test_implicit_mpi import _compare  # noqa: E402

comm = MPI.COMM_WORLD
DT = 1.25   # the bar's step in tests/mpi/test_implicit_mpi.py (6 steps of 50 explicit ones)


@pytest.mark.mpi(min_size=2)
def test_halved_steps_hand_on_particles_that_crossed_a_slab(monkeypatch):
    real = scheme_module.newton
    calls = {"failed": 0}

    def newton_failing_full_steps(problem, u, opts, history=None):
        if problem.rule is not None and problem.rule.dt > 0.75 * DT:
            calls["failed"] += 1
            raise NewtonFailed("planted: a full-length step fails")
        return real(problem, u, opts, history)

    monkeypatch.setattr(scheme_module, "newton", newton_failing_full_steps)
    ok, report, s = _compare(bar_scene(DT, 4 * DT, v0=0.4))
    assert calls["failed"] >= 1 and s.scheme.stats["halvings"] >= 1
    assert ok, report
    assert s.decomp.size == comm.Get_size()
