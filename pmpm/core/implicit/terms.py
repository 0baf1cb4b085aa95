"""What an effect adds to the implicit step (docs/implicit.md, "Effects under the implicit
integrator"): the implicit integrator calls none of the explicit step's hooks, so an effect it
carries gives it a *term* (``Effect.implicit_term(s)``, pmpm.core.effects) with these methods,
each called at its place in the step (pmpm.core.implicit.scheme, .problem):

* ``prescribe(s, t0, h, u, dv, a)``: the held components' motion over the step from ``t0`` to
  ``t0 + h``: their displacement increment ``u``, velocity change ``dv`` and end acceleration
  ``a`` (window arrays (nx, ny, 2); held components not written here keep the boundary's
  prescribed velocity, u = h v, dv = 0, a = 0). Called before Newton (u) and at the commit
  (dv, a: what the particles near the supports receive);
* ``prescribe_start(s, t0, v, a)``: the held components' velocity and acceleration at the
  step's start (window arrays; by default the boundary's prescribed velocity and no
  acceleration), before the step's equations are set up (dynamics);
* ``begin(problem)``: the step's equations are set up (start velocities, HHT's start forces);
  returns the term's force at the step's start (window array, halo-complete) or None;
* ``add_residual(problem, u, R)``: add the term's nodal forces at the trial increment ``u`` to
  ``R`` (window array, halo-complete: a force from the particles is folded onto the slaved
  edge nodes and halo-summed by the term, ``problem.fold_and_sum``; the particles read the
  expanded nodal values, ``problem.expand``);
* ``add_tangent(problem, u, Kb)``: add -d(force)/du to the tangent's blocks ``Kb`` (the blocks of
  pmpm.core.implicit.kernels.assemble_blocks: Kb[lid[I], offset(J - I)] 2 x 2; blocks from the
  particles through ``problem.assemble``, which folds them, T^T C T);
* ``commit(s, problem, u)``: the converged step: the term's state and its work (its energy
  terms).

The base class does nothing in each; a term overrides what it needs.
"""

__all__ = ["ImplicitTerm"]


class ImplicitTerm:
    """A part of the implicit step contributed by an effect (module doc)."""

    def prescribe(self, s, t0, h, u, dv, a):
        pass

    def prescribe_start(self, s, t0, v, a):
        pass

    def begin(self, problem):
        return None

    def add_residual(self, problem, u, R):
        pass

    def add_tangent(self, problem, u, Kb):
        pass

    def commit(self, s, problem, u):
        pass
