"""Where the implicit step's time goes on the Northridge variant, and why its kept factorisation
is renewed (issue 37; docs/implicit.md, "Accelerated modified Newton").

For ``--steps`` steps after the static stage and the first step, on the ranks it is given, it
prints (rank 0):

- the wall time of the step's phases, summed: the tangent (assembly and factorisation), the
  factorisation alone, the residuals, the back-substitutions, the diagonal of the rescaling;
- at every step start on a kept factorisation, the rows that left and the rows that came since
  it was factored (all ranks together), and per kind of step (no change, rows left, rows came,
  both) the Newton iterations and tangents per step;
- one JSON line with the figures.

``--force`` refactors at every step start (what a tangent costs); ``--implicit``/``--petsc``
pass scene keys as ``studies.northridge_implicit`` does. The phases are timed by wrapping the
solver's methods in this process: a study, not a benchmark of the product.

    mpirun -n 2 python -m studies.implicit_step_profile --cell 0.1 --steps 700
    mpirun -n 2 python -m studies.implicit_step_profile --cell 0.05 --steps 4 --force --petsc pc_type=cholesky
"""
import argparse
import dataclasses
import json
import time
from collections import defaultdict

import numpy as np

import pmpm.core.implicit.kept_factorisation as KF
import pmpm.core.implicit.problem as PR
import pmpm.core.implicit.scheme as SCH
from pmpm.benchmarks.implicit import _implicit_keys
from pmpm.benchmarks.implicit_frame import strip_explicit_only
from studies.frame_3storey import scene_at

__all__ = ["main"]

PHASES = [(PR.GridProblem, "tangent"), (PR.GridProblem, "residual"), (PR.GridProblem, "kept_diagonal"),
          (KF.KeptFactorisation, "factor"), (KF.KeptFactorisation, "solve_array")]


class Profile:
    """The wrapped methods' times, the rows at each step start, Newton's counts per step."""

    def __init__(self, force):
        self.time, self.calls = defaultdict(float), defaultdict(int)
        self.rows = []      # (left, came) at each step start on a kept factorisation
        self.steps = []     # (left, came, iterations, tangents) per Newton solve
        self.force = force

    def install(self):
        for cls, name in PHASES:
            self._timed(cls, name)
        fit, newton, prof = PR.GridProblem.fit_kept_factorisation, SCH.newton, self

        def counted_fit(problem, u):
            kept, keys = problem.linear.kept, problem._row_keys()
            if kept.keys is not None:
                left = problem.s.decomp.allreduce_sum(int(np.setdiff1d(kept.keys, keys).size))
                came = problem.s.decomp.allreduce_sum(int(np.setdiff1d(keys, kept.keys).size))
                prof.rows.append((int(left), int(came)))
            return False if prof.force else fit(problem, u)

        def counted_newton(problem, u, opts, history=None):
            h = [] if history is None else history
            before, tangents = len(prof.rows), problem.tangents
            try:
                return newton(problem, u, opts, h)
            finally:
                left, came = prof.rows[-1] if len(prof.rows) > before else (0, 0)
                prof.steps.append((left, came, len(h), problem.tangents - tangents))

        PR.GridProblem.fit_kept_factorisation = counted_fit
        SCH.newton = counted_newton

    def _timed(self, cls, name):
        f, key = getattr(cls, name), f"{cls.__name__}.{name}"

        def g(*a, **k):
            t = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                self.time[key] += time.perf_counter() - t
                self.calls[key] += 1
        setattr(cls, name, g)

    def reset(self):
        self.time.clear()
        self.calls.clear()
        self.rows.clear()
        self.steps.clear()


def main(argv=None):
    from mpi4py import MPI

    from pmpm.build import build_solver
    ap = argparse.ArgumentParser(prog="python -m studies.implicit_step_profile", description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.1)
    ap.add_argument("--ppc", type=int, default=2)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--force", action="store_true", help="refactor at every step start")
    ap.add_argument("--implicit", nargs="*", default=[], metavar="KEY=VALUE")
    ap.add_argument("--petsc", nargs="*", default=[], metavar="NAME=VALUE")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    scene = strip_explicit_only(scene_at(a.cell, a.ppc, "northridge_implicit"))
    scene = dataclasses.replace(scene, solver=dataclasses.replace(
        scene.solver, implicit={**scene.solver.implicit, **_implicit_keys(a.implicit)},
        petsc={**scene.solver.petsc, **_implicit_keys(a.petsc)}))
    prof = Profile(a.force)
    prof.install()
    s = build_solver(scene, comm)
    s.step()                      # the static stage and the first step, not counted
    prof.reset()
    start = time.perf_counter()
    for _ in range(a.steps):
        s.step()
    wall = time.perf_counter() - start
    if comm.rank:
        return 0
    for key in sorted(prof.time, key=lambda k: -prof.time[k]):
        n = max(prof.calls[key], 1)
        print(f"{key:34s} {prof.time[key]:8.2f} s  {prof.calls[key]:6d} calls  {1e3 * prof.time[key] / n:8.1f} ms each")
    S = np.array(prof.steps, dtype=float).reshape(-1, 4)
    kinds = {"no change": (S[:, 0] == 0) & (S[:, 1] == 0), "rows left": (S[:, 0] > 0) & (S[:, 1] == 0),
             "rows came": (S[:, 0] == 0) & (S[:, 1] > 0), "both": (S[:, 0] > 0) & (S[:, 1] > 0)}
    per_kind = {}
    for name, sel in kinds.items():
        if sel.any():
            per_kind[name] = {"steps": int(sel.sum()), "iterations_per_step": float(S[sel, 2].mean()),
                              "tangents_per_step": float(S[sel, 3].mean())}
            print(f"{name:10s} steps {sel.sum():5d}  Newton iterations a step {S[sel, 2].mean():5.2f}  "
                  f"tangents a step {S[sel, 3].mean():4.2f}")
    R = np.array(prof.rows, dtype=float).reshape(-1, 2)
    changed = R[(R[:, 0] > 0) | (R[:, 1] > 0)]
    med = np.median(changed, axis=0) if len(changed) else np.zeros(2)
    print(f"step starts on a kept factorisation {len(R)}, rows changed at {len(changed)}: left median {med[0]:g} "
          f"max {R[:, 0].max(initial=0):g}, came median {med[1]:g} max {R[:, 1].max(initial=0):g}")
    stats = dict(getattr(s.scheme, "stats", {}))
    print(f"wall {wall:.2f} s for {a.steps} steps on {comm.size} rank(s); {stats}")
    print(json.dumps({"study": "implicit_step_profile", "cell": a.cell, "ppc": a.ppc, "ranks": comm.size,
                      "steps": a.steps, "force": a.force, "implicit": a.implicit, "petsc": a.petsc,
                      "wall_s": wall, "phase_s": dict(prof.time), "phase_calls": dict(prof.calls),
                      "kinds": per_kind, "rows_changed_steps": int(len(changed)), "stats": stats}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
