"""newton = "accelerated": modified Newton mixed in the subspace of its own corrections
(pmpm/core/implicit/accelerated.py, docs/implicit.md "Accelerated modified Newton").

Theory: on a linear map the accelerated iteration (Anderson's, keeping every column) is GMRES
on P^-1 K (Walker & Ni 2011, SIAM J. Numer. Anal. 49(4), section 4: its iterate k + 1 is the
fixed-point map of GMRES's iterate k): with P^-1 K the identity plus a perturbation of rank r,
GMRES ends at iteration r + 1 and the accelerated iteration at r + 2, where the plain
modified iteration only converges at the rate of the perturbation's spectral radius (and not at
all beyond 1).

Shown to fail on planted bugs (each restored): the mixed correction's sign on dZ flipped
(z - (dU - dZ) gamma: the linear test does not converge in r + 2 iterations); the columns
kept in the wrong order against gamma (dU of one iteration paired with dZ of the next: no
convergence in r + 2); the subspace not cleared after a refactorisation (the cantilever's
step takes more iterations than allowed below or does not converge).
"""
import threading

import numpy as np
import pytest

from pmpm.core.implicit.accelerated import AndersonMixer
from tests.unit.test_implicit_step import _yielding_cantilever, timoshenko_tip_deflection


def _linear_case(n=40, rank=3, spread=3.0, seed=7):
    """K = P + U V^T with P symmetric positive definite, and a right-hand side b: the
    modified iteration u <- u + P^-1 (b - K u) on it; the perturbation large enough that the
    plain iteration diverges (spectral radius of P^-1 U V^T above 1)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    U = rng.standard_normal((n, rank))
    V = rng.standard_normal((n, rank))
    K = P + spread * n * U @ V.T / rank
    b = rng.standard_normal(n)
    return P, K, b


def _iterate(P, K, b, iterations, mixer=None):
    u = np.zeros_like(b)
    norms = []
    for _ in range(iterations):
        r = b - K @ u
        norms.append(np.linalg.norm(r))
        z = np.linalg.solve(P, r)
        u = u + (mixer.correction(z) if mixer is not None else z)
    norms.append(np.linalg.norm(b - K @ u))
    return np.array(norms)


def test_anderson_on_a_linear_map_is_gmres_and_ends_in_rank_plus_two():
    P, K, b = _linear_case(rank=3)
    rho = max(abs(np.linalg.eigvals(np.linalg.solve(P, K - P))))
    assert rho > 1.0   # the plain modified iteration diverges on this system
    plain = _iterate(P, K, b, 8)
    assert plain[-1] > plain[0]
    mixed = _iterate(P, K, b, 3 + 2, AndersonMixer(lambda a: a, depth=10))
    # r + 2 = 5 iterations give the solution, to the round-off of least squares solved by their
    # normal equations (the Gram matrix squares the columns' condition: 1e-8 of the start)
    assert mixed[5] <= 1e-8 * mixed[0], mixed
    assert np.all(mixed[1:5] > 1e-3 * mixed[0]), mixed   # (and not before: rank 3 needs its directions)


class _ThreadAllreduce:
    """An allreduce over threads standing for ranks: each hands its part, all get the sum."""

    def __init__(self, ranks):
        self.barrier = threading.Barrier(ranks)
        self.parts = [None] * ranks

    def for_rank(self, k):
        def allreduce(a):
            self.parts[k] = np.array(a, copy=True)
            self.barrier.wait()
            total = sum(self.parts)
            self.barrier.wait()
            return total
        return allreduce


def test_anderson_ranks_take_the_same_correction():
    """Two ranks holding halves of the vectors (threads with a summing allreduce) take the
    halves of the one-process correction at every iteration: the least squares see the
    global Gram matrix. Fails with the local Gram matrix (allreduce left out)."""
    P, K, b = _linear_case(n=30, rank=2)
    half = 15
    whole = AndersonMixer(lambda a: a)
    reduce = _ThreadAllreduce(2)
    ranks = [AndersonMixer(reduce.for_rank(k)) for k in range(2)]
    u = np.zeros_like(b)
    for _ in range(4):
        z = np.linalg.solve(P, b - K @ u)
        d = whole.correction(z)
        parts = [z[:half], z[half:]]
        got = [None, None]

        def run(k):
            got[k] = ranks[k].correction(parts[k])
        threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert np.allclose(np.concatenate(got), d, rtol=1e-10, atol=1e-12 * np.abs(d).max())
        u = u + d


def test_accelerated_newton_reaches_the_same_equilibrium_with_fewer_tangents():
    """The yielding cantilever's static step (tests/unit/test_implicit_step.py): the same
    equilibrium as full Newton (the weight on the supports to 1e-6, the tip within the
    residual tolerance's share of Timoshenko's deflection), with fewer assembled tangents
    than modified Newton needs."""
    full = _yielding_cantilever("full")
    mod = _yielding_cantilever("modified")
    acc = _yielding_cantilever("accelerated")
    weight = float(acc.particles["m"].sum()) * 981.0
    assert -acc.scheme.held_force[1] == pytest.approx(weight, rel=1e-6)
    tip = lambda s: float(s.particles["x"][np.argmax(s.particles["x"][:, 0]), 1])   # noqa: E731
    assert abs(tip(acc) - tip(full)) <= 1e-6 * abs(timoshenko_tip_deflection(981.0))
    assert acc.scheme.stats["tangents"] < mod.scheme.stats["tangents"], (acc.scheme.stats, mod.scheme.stats)


def test_diagonal_entries_are_the_assembled_centre_blocks():
    """pmpm/core/implicit/diagonal.py against its twin, the diagonal of the centre blocks of
    kernels.assemble_blocks, for particles with a general deformation, stress and tangent
    (unsymmetric D). Fails with the initial-stress term left out, or with B's shear row of
    the y component taken as the x one's."""
    from pmpm.core.implicit import kernels as IK
    from pmpm.core.implicit.diagonal import diagonal_entries
    from pmpm.core.shape import SHAPE_TAGS
    rng = np.random.default_rng(3)
    tag = SHAPE_TAGS["cubic"]
    K = len(tag)
    ncx, ncy, inv_h = 12, 10, 4.0
    origin = np.array([0.0, 0.0])
    n = 40
    x = np.column_stack([rng.uniform(0.8, 2.2, n), rng.uniform(0.8, 1.7, n)])
    vol = rng.uniform(0.5, 1.5, n) * 1e-3
    S = rng.standard_normal((n, 3)) * 1e8
    f = np.tile([1.0, 0.0, 0.0, 1.0], (n, 1)) + 0.05 * rng.standard_normal((n, 4))
    D = rng.standard_normal((n, 3, 3)) * 1e11
    shape = (ncx + 1, ncy + 1)
    lid = np.arange(shape[0] * shape[1]).reshape(shape)
    span = 2 * K - 1
    Kb = np.zeros((lid.size, span * span, 2, 2))
    IK.assemble_blocks(x, vol, S, f, D, lid, Kb, 0, 0, origin, inv_h, ncx, ncy, tag)
    out = np.zeros(shape + (2,))
    diagonal_entries(x, vol, S, f, D, out, 0, 0, origin, inv_h, ncx, ncy, tag)
    centre = (span * span) // 2
    ref = np.stack([Kb[:, centre, 0, 0], Kb[:, centre, 1, 1]], axis=1).reshape(shape + (2,))
    assert np.abs(ref).max() > 0.0
    assert np.allclose(out, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
