"""Newton's method on one step's nodal displacement increment, with an optional line search.

The problem object gives ``residual(u)`` (the owned residual vector and its global norm,
collective), ``tangent(u)`` (assembles and factors the step's matrix at u), ``solve(r)``
(owned correction), ``dot(a, b)`` (global dot product) and ``add(u, du, s)`` (u + s du on the
window, ghosts filled). Convergence (docs/implicit.md):

    |R_k| <= residual_tolerance * max(|R_0|, force scale)       (the residual)
    |du . R_k| <= energy_tolerance * |du_0 . R_0| (scale / |R_0|)^2   (the energy norm)

where du is the correction the last factorisation gives for R_k (a back-substitution, no new
factorisation) and the force scale is the norm of the internal and external forces at the
step's start (so that a step that starts in equilibrium does not chase round-off).

Tangent updates (``newton``): ``"full"`` (the default) assembles and factors the tangent at
every iteration; ``"modified"`` keeps the factorisation it has, also an earlier step's where
the unknowns are the same (``problem.factorisation_fits``), while each iteration cuts the
residual at least by ``REFACTOR_RATE``, and refactors at the iterate where one did not (a
back-substitution and a residual cost a fraction of an assembly and a factorisation: the
factorisation is most of an iteration on the frames, docs/implicit.md). Where the structure
stays elastic the tangent hardly changes from step to step, and most steps then factor
nothing; where it yields the rate test brings the factorisations back.

``"krylov"`` assembles the tangent where ``"modified"`` would refactor it (at the iterate
where the rate was slow: the iterations after it are Newton's with that iterate's consistent
tangent), and the linear solver (pmpm.core.implicit.linear_solver) solves it by GMRES
preconditioned with a kept factorisation, refactored only when the GMRES stalls
(pmpm.core.implicit.kept_factorisation): the iterates are those of ``"modified"`` to the
GMRES's tolerance, but a factorisation serves many tangents and steps, also where the
structure yields. (Assembling at every iteration, as ``"full"`` does, was measured slower on
the frame: an assembly and a few back-substitutions cost more than the iterations saved.)

Line search (``line_search = true``; off by default): the step length s is halved while the
energy slope along the correction does not shrink, |du . R(u + s du)| > |du . R(u)|
(Crisfield's criterion), at most ``LINE_SEARCH_CUTS`` times. Not the residual norm: the
Green-Lagrange strain's quadratic term makes the norm jump after a full Newton step on a
bending structure (the linearised rotation stretches the fibres by theta^2 / 2) even where
the full step is exactly what converges quadratically; a norm-based search halved those steps
and stalled (a cantilever at 2 % tip deflection: 12 iterations without convergence, against 4
with full steps).
"""
import logging
import math

from pmpm.core.implicit.accelerated import REFRESH_AFTER, STALL_RATE, AndersonMixer

__all__ = ["NewtonFailed", "newton"]
logger = logging.getLogger(__name__)

#: line-search cuts of the step length (1/2 each) before the best trial is taken
LINE_SEARCH_CUTS = 5
#: modified Newton: an iteration that leaves more than this fraction of the residual has the
#: tangent refactored at its iterate (a linear rate of 1/4 halves the iterations' cost against
#: a refactoring per iteration, judged by the portal and the frame: docs/implicit.md)
REFACTOR_RATE = 0.25


class NewtonFailed(ArithmeticError):
    """The step did not converge within the iterations allowed (or a solve failed)."""


def newton(problem, u, opts, history=None):
    """Iterate u (window array, updated in place) to equilibrium.

    Parameters
    ----------
    problem : object
        See the module docstring.
    u : ndarray
        The first guess (the predictor), overwritten by the converged increment.
    opts : dict
        ``residual_tolerance``, ``energy_tolerance``, ``max_iterations``, ``line_search``,
        optionally ``newton`` ("full" or "modified").
    history : list, optional
        Receives (|R_k|, energy_k) per iteration.

    Returns
    -------
    int
        Iterations taken (each a linear solve; with ``newton = "modified"`` fewer of them
        assemble the tangent: ``problem.tangents`` counts those, ``linear.factorisations`` the factorisations).
    """
    r, norm = problem.residual(u)
    scale = max(norm, problem.force_scale)
    energy0 = None
    # "krylov" assembles the tangent where "modified" would refactor it (the linear solver then
    # solves it on its kept factorisation: pmpm.core.implicit.kept_factorisation)
    variant = opts.get("newton", "full")
    modified = variant in ("modified", "krylov", "accelerated")
    # "accelerated": the modified corrections mixed in the subspace of the step's earlier ones
    # (pmpm.core.implicit.accelerated), a tangent only where that stalls
    mixer = AndersonMixer(problem.s.decomp.allreduce_sum) if variant == "accelerated" else None
    on_factorisation = 0      # iterations of this step on the current factorisation ("accelerated")
    refactor = not (modified and problem.factorisation_fits())
    if mixer is not None and problem.linear.kept.ready:
        # the kept factorisation of an earlier step, rescaled to the current diagonal, where
        # its rows are this step's (else a new tangent)
        refactor = not problem.fit_kept_factorisation(u)
    for k in range(opts["max_iterations"] + 1):
        if not math.isfinite(norm):
            raise NewtonFailed(f"residual not finite at iteration {k}")
        if norm <= opts["residual_tolerance"] * scale and k > 0:
            du = problem.solve(r)          # the last factorisation: a back-substitution
            energy = abs(problem.dot(du, r))
            if history is not None:
                history.append((norm, energy))
            if energy <= opts["energy_tolerance"] * energy0:
                return k
        elif norm == 0.0:
            if history is not None:
                history.append((0.0, 0.0))
            return k
        if k == opts["max_iterations"]:
            break
        if refactor or not modified:
            problem.tangent(u)
            on_factorisation = 0
            if mixer is not None:
                mixer.clear()
        du = problem.solve(r)
        energy = abs(problem.dot(du, r))
        if energy0 is None:
            # the energy a first correction of the force scale's size would carry (energy goes
            # as |R|^2): a step that starts near equilibrium (|R_0| << the force scale) is not
            # asked to bring its energy 1e-12 below its own round-off level
            energy0 = energy * (scale / norm) ** 2 if energy > 0.0 and norm > 0.0 else 1.0
        if history is not None and not (norm <= opts["residual_tolerance"] * scale and k > 0):
            history.append((norm, energy))
        previous = norm
        if mixer is not None:
            du = mixer.correction(du)
        r, norm = _step(problem, u, du, r, norm, opts["line_search"])
        on_factorisation += 1
        if mixer is None:
            refactor = norm > REFACTOR_RATE * previous
        else:
            # (the first correction on a kept factorisation is the plain modified one, without
            # the subspace: judged from the second on)
            refactor = (on_factorisation >= 2 and norm > STALL_RATE * previous) or on_factorisation >= REFRESH_AFTER
    raise NewtonFailed(f"no convergence in {opts['max_iterations']} iterations (residual {norm:.3g}, "
                       f"{norm / scale:.3g} of the force scale)")


def _step(problem, u, du, r, norm, line_search):
    """u += s du with s = 1, or halved while the energy slope does not shrink (line search)."""
    trial = problem.add(u, du, 1.0)
    r1, n1 = problem.residual(trial)
    if line_search:
        slope0 = abs(problem.dot(du, r))
        s = 1.0
        for _ in range(LINE_SEARCH_CUTS):
            if abs(problem.dot(du, r1)) <= slope0:
                break
            s *= 0.5
            trial = problem.add(u, du, s)
            r1, n1 = problem.residual(trial)
        logger.debug("line search: step %.3g, residual %.3g -> %.3g", s, norm, n1)
    u[...] = trial
    return r1, n1
