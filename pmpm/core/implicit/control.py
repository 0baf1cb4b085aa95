"""Displacement control of a static step: the first guess of a step whose held components move
by a prescribed increment (a pushover's nodes, pmpm.physics.pushover).

With the held increment u_h imposed at once and the free nodes left where they were, the first
trial strains all sit in the cells next to the moved nodes (a 5 mm push of a node row on a
0.1 m grid: 5 % strain, forty times the yield strain), so the first residual is that of a
crushed layer of plastic points, and their tangent (perfect plasticity: none along the flow)
sends Newton astray. The consistent start is the linearised step about the start state:

    K_0 du_f = R_f(0) - K_0,fh u_h,      u = u_h + du_f

where K_0,fh u_h, the free rows' reaction to the held increment, is taken as a directional
derivative of the residual, (R(eps u_h) - R(0)) / eps with eps small enough that no point
leaves the elastic range (the start's tangent at points already yielding), and K_0 is the
start state's tangent with the held rows and columns eliminated (the scheme's matrix at u = 0).
For an elastic structure this is the solution up to the geometric terms; Newton then starts
within their reach (tests/unit/test_implicit_control.py: quadratic convergence).
"""
import numpy as np

__all__ = ["linear_predictor", "PROBE_STRAIN"]

#: the largest nodal increment of the directional derivative's probe, in cells: strains of
#: about this size, far below any yield strain (steel's 1e-3) and far above round-off
PROBE_STRAIN = 1e-7


def linear_predictor(problem, u, inv_h):
    """The first guess of a displacement-controlled static step (module doc).

    Parameters
    ----------
    problem : pmpm.core.implicit.problem.GridProblem
    u : ndarray (nx, ny, 2)
        The prescribed increments on the held components, zero elsewhere (window).
    inv_h : float
        1 / cell size (the probe's scale).

    Returns
    -------
    ndarray (nx, ny, 2)
        u with the free nodes' increment of the linearised step (ghosts filled).
    """
    held = np.where(problem.dofs.held, u, 0.0)
    largest = float(problem.s.decomp.allreduce_max(float(np.abs(held).max()) if held.size else 0.0))
    if largest == 0.0:
        return u
    eps = PROBE_STRAIN / (largest * inv_h)
    zero = np.zeros_like(u)
    r0, _ = problem.residual(zero)
    r1, _ = problem.residual(eps * held)
    linearised = r0 + (r1 - r0) / eps
    problem.tangent(zero)
    return problem.add(held, problem.solve(linearised), 1.0)
