"""The implicit step's terms are evaluated in the step's reference configuration to the end of
the commit (issue 37: the Northridge run's heap corruption; docs/implicit.md).

Within a step the kernels take the particles at the step's start positions and volumes (updated
Lagrangian: the grid window, the basis gradients and the stress push-forward all refer to them).
The commit moves the particles and pushes their volumes forward in place, and then evaluates the
terms of the converged increment once more: the moving supports' work (Rayleigh's force in the
residual), Rayleigh's dissipation, and the reactions' forces. Those used to read the particles'
arrays themselves, so they saw the *moved* particles: a frame column particle that crossed the
upper boundary of its rank's slab in the step then had a cubic B-spline stencil reaching one
node column past the rank's grid window (a stencil reaches two nodes above its cell, the ghost
width is two), and the unchecked kernels wrote past the end of the nodal array: glibc's "double
free or corruption" on the three-storey frame under the Northridge record at t = 2.86 s (with
NUMBA_BOUNDSCHECK=1 the same run raised IndexError in deformation_increment called from
RayleighImplicit._force under ImplicitNewmark._support_work).

The test: a term that only records what the problem shows it at every call of a damped bar's
steps (Rayleigh damping, so the terms' evaluations after the move take place) must see the
positions and volumes the step started from, in the commit too, while the particles did move.
Shown to fail without the fix (problem.x and problem.vol as the particles' own arrays, as
before): the commit's call sees moved positions (the assertion on ``after_move``).
"""
import numpy as np
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.core.implicit.terms import ImplicitTerm

from test_implicit_rayleigh import damped_bar


class Recorder(ImplicitTerm):
    """Adds nothing; records whether each call saw the step's start positions and volumes."""

    def __init__(self, s):
        self.s = s
        self.calls = []

    def begin(self, problem):
        p = self.s.particles
        self.x0, self.vol0 = p["x"].copy(), p["vol"].copy()
        self._see("begin", problem)
        return None

    def add_residual(self, problem, u, R):
        self._see("residual", problem)

    def commit(self, s, problem, u):
        self._see("commit", problem)
        self.moved = float(np.abs(s.particles["x"] - self.x0).max())

    def _see(self, where, problem):
        self.calls.append((where, np.array_equal(problem.x, self.x0), np.array_equal(problem.vol, self.vol0)))


def test_terms_see_the_step_start_configuration_after_the_move():
    s = build_solver(damped_bar(periods=0.5), MPI.COMM_SELF)
    s.step()   # (the scheme builds its terms on its first step)
    recorder = Recorder(s)
    s.scheme.terms.append(recorder)
    assert any(type(t).__name__ == "RayleighImplicit" for t in s.scheme.terms)   # evaluated after the move
    for _ in range(2):
        s.step()
    assert recorder.moved > 0.0   # the particles did move in the step (the bar swings)
    wheres = [w for w, _, _ in recorder.calls]
    assert "commit" in wheres and "residual" in wheres
    wrong = [(where, x_ok, vol_ok) for where, x_ok, vol_ok in recorder.calls if not (x_ok and vol_ok)]
    assert not wrong, f"terms saw moved particles or pushed-forward volumes: {wrong[:4]}"
